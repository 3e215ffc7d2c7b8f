"""canest replay: estimate offline from a log, or play a log onto a bus."""
from __future__ import annotations

import sys

from canest.errors import UsageError
from canest.io.bus import open_bus
from canest.commands.common import FORMATTER, add_bus_overrides, add_config, config_from_args
from canest.pipeline import format_summary
from canest.apps.replay import play, replay

EPILOG = """examples:
  canest replay drive.log --out est.log --csv est.csv
  canest replay drive.blf --config configs/dckf_1525kg.yaml --csv est.csv
  canest replay drive.log --realtime --channel vcan0      # like canplayer, for a running daemon

Offline, the log is read as fast as possible and every frame is accounted for
in the summary printed at the end (decoded, ignored by ID, rejected by cause).
The CSV has one row per tick: t, vx, vy, beta, yaw_rate (SI units, rad), their
_std columns, valid (bit mask: 0 vx, 1 vy, 2 beta, 3 yaw rate, 4 forces,
5 friction) and mode."""


def register(subparsers) -> None:
    p = subparsers.add_parser("replay", help="run a CAN log through the estimator, or play it onto a bus",
                              description=__doc__, epilog=EPILOG, formatter_class=FORMATTER)
    p.add_argument("log", help="input log: .log (candump), .asc, .blf, .trc, .csv, ... (any python-can reads)")
    add_config(p)
    p.add_argument("--out", "-o", help="write the estimate frames to this log (format by suffix)")
    p.add_argument("--csv", help="write one row per tick to this CSV")
    p.add_argument("--realtime", action="store_true",
                   help="instead of estimating, send the log's frames onto the input bus at recorded timing")
    p.add_argument("--speed", type=float, default=1.0, help="with --realtime: playback speed factor (default 1)")
    p.add_argument("--quiet", "-q", action="store_true", help="no progress bar")
    add_bus_overrides(p)
    p.set_defaults(func=run)


def run(args) -> int:
    config = config_from_args(args)
    if args.realtime:
        if args.out or args.csv:
            raise UsageError("--realtime plays the log onto a bus; --out and --csv belong to offline replay")
        bus = open_bus(config.input_bus.kwargs(), "playback")
        try:
            sent = play(args.log, bus, speed=args.speed, progress=not args.quiet)
        finally:
            bus.shutdown()
        print(f"sent {sent} frames to {config.input_bus.interface}:{config.input_bus.channel}")
        return 0
    if not (args.out or args.csv):
        print("note: neither --out nor --csv given; only the frame summary is printed", file=sys.stderr)
    summary = replay(config, args.log, out_log=args.out, out_csv=args.csv, progress=not args.quiet)
    print(format_summary(summary))
    return 0
