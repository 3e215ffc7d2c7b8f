"""canest replay: estimate offline from a log, or play a log onto a bus."""
from __future__ import annotations

import logging
import math
import signal
import sys
from contextlib import contextmanager

from canest.config import DEFAULT_CONFIG
from canest.errors import UsageError
from canest.io.bus import open_bus
from canest.io.outputs import check_outputs
from canest.commands.common import FORMATTER, add_bus_overrides, add_config, config_from_args
from canest.pipeline import format_summary
from canest.apps.replay import play, replay

EPILOG = """examples:
  canest replay drive.log --out est.log --csv est.csv
  canest replay drive.blf --config configs/dckf_1525kg.yaml --csv est.csv
  canest replay drive.log --realtime --channel vcan0      # like canplayer, for a running daemon

Offline, the log is read as fast as possible and every frame is accounted for
in the summary printed at the end (decoded, ignored by ID, rejected by cause).
The CSV has one row per tick: t, vx, vy, beta, yaw_rate (SI units, rad) and
the model's forces and frictions, their _std columns, valid (bit mask: 0 vx,
1 vy, 2 beta, 3 yaw rate, 4 forces, 5 friction, 6 friction observable,
7-14 per-wheel forces and frictions), mode and why_vx, why_yaw_rate,
why_beta, why_forces, why_friction (why a bit is clear).

Damaged logs: a line python-can cannot parse is skipped and counted
(log_bad_lines, log_torn_line for a last line cut mid-write, log_junk_lines
in ASC), a truncated or corrupt BLF is read up to the damage (log_truncated,
log_corrupt, log_unread_bytes); a warning on stderr gives the first line
numbers. A log of which nothing can be read is an error (exit 65); an empty
log gives outputs without ticks (the CSV has its header) and a warning.

Outputs are written to a hidden temporary file beside them and renamed when
the replay ends well: a failed run leaves no partial file. An existing output
is replaced; an output naming an input (log, config, DBC; also through a hard
or symbolic link) is refused.

SIGINT (Ctrl-C) or SIGTERM stops the replay in order: reading stops, the
outputs are completed up to the last tick, the summary (with stopped=1) is
printed and the exit status is 0. A second signal aborts at once (exit 130,
no outputs)."""


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


class StopRequest:
    """Set by the first SIGINT or SIGTERM (``is_set()``, as a ``threading.Event``); ``signal`` names it."""

    def __init__(self):
        self.signal = None

    def is_set(self) -> bool:
        return self.signal is not None

    @contextmanager
    def on_signals(self):
        """While inside: the first SIGINT or SIGTERM sets the request, a second one interrupts at once."""
        def handler(signum, frame):
            if self.is_set():
                raise KeyboardInterrupt
            self.signal = signal.Signals(signum).name

        previous = {s: signal.signal(s, handler) for s in (signal.SIGINT, signal.SIGTERM)}
        try:
            yield self
        finally:
            for s, h in previous.items():
                signal.signal(s, h)


def warnings_to_stderr() -> None:
    """The replay's warnings (damaged log, empty log) as ``canest: warning: ...`` lines on stderr."""
    logger = logging.getLogger("canest")
    if any(handler.name == "canest-warnings" for handler in logger.handlers):
        return
    handler = logging.StreamHandler(sys.stderr)
    handler.name = "canest-warnings"
    handler.setFormatter(logging.Formatter("canest: warning: %(message)s"))
    logger.addHandler(handler)
    logger.propagate = False


def run(args) -> int:
    config = config_from_args(args)
    warnings_to_stderr()
    if args.realtime:
        if args.out or args.csv:
            raise UsageError("--realtime plays the log onto a bus; --out and --csv belong to offline replay")
        if not (math.isfinite(args.speed) and args.speed > 0):
            raise UsageError(f"--speed: a playback speed factor above 0, e.g. 1 or 10, got {args.speed}")
        bus = open_bus(config.input_bus.kwargs(), "playback")
        try:
            sent = play(args.log, bus, speed=args.speed, progress=not args.quiet)
        finally:
            bus.shutdown()
        print(f"sent {sent} frames to {config.input_bus.interface}:{config.input_bus.channel}")
        return 0
    if not (args.out or args.csv):
        print("note: neither --out nor --csv given; only the frame summary is printed", file=sys.stderr)
    check_outputs({"--out": args.out, "--csv": args.csv},
                  {"the input log": args.log, "the config": args.config or DEFAULT_CONFIG,
                   "the input DBC": config.input_dbc, "the output DBC": config.output_dbc})
    with StopRequest().on_signals() as stop:
        summary = replay(config, args.log, out_log=args.out, out_csv=args.csv, progress=not args.quiet, stop=stop)
    print(format_summary(summary))
    if stop.is_set():
        print(f"canest: replay stopped by {stop.signal} after {summary.get('frames', 0)} frames; the outputs are "
              "complete up to the last tick", file=sys.stderr)
    return 0
