"""canest replay: estimate offline from a log, or play a log onto a bus."""
from __future__ import annotations

import argparse
import json
import math
import signal
import sys
from contextlib import contextmanager

import can

from canest.config import DEFAULT_CONFIG
from canest.errors import FileIOError, LogError, UsageError
from canest.io.bus import open_bus
from canest.io.outputs import check_outputs, is_stdio
from canest.commands.common import (FORMATTER, add_bus_overrides, add_config, add_log_reading, add_state_file,
                                    config_from_args, log_reading, state_file_output, warnings_to_stderr)
from canest.pipeline import format_summary
from canest.apps.replay import play, replay

EPILOG = """examples:
  canest replay drive.log --out est.log --csv est.csv
  canest replay drive.blf --config configs/dckf_1525kg.yaml --csv est.csv
  canest replay drive.log --realtime -c vcan0             # like canplayer, for a running daemon
  canest replay drive.log --realtime -i udp_multicast -c 239.74.163.2 --rate 2   # no SocketCAN (canest run --help)
  candump -L vcan0 | canest replay - --csv - | head       # a pipe: stdin in, CSV rows out as ticks complete
  canest replay drive.log --json                           # the frame summary as one JSON object

- as the log reads standard input as it arrives (candump -L text; --format
for asc, trc, csv or blf); - as --csv or --out writes standard output (--out -
as candump text). Standard input is read line by line (bounded memory), and
the ticks follow the stream's timestamps. With an output on standard output
the frame summary goes to stderr.

Offline, the log is read as fast as possible and every frame is accounted for
in the summary printed at the end (decoded, ignored by ID, rejected by cause).
The CSV has one row per tick: t, vx, vy, beta, yaw_rate (SI units, rad) and
the model's forces and frictions, their _std columns, valid (bit mask: 0 vx,
1 vy, 2 beta, 3 yaw rate, 4 forces, 5 friction, 6 friction observable,
7-14 per-wheel forces and frictions), mode and why_vx, why_yaw_rate,
why_beta, why_forces, why_friction (why a bit is clear).

A log whose suffix names no format (.candump, .txt, none) is read in the
format its first lines show (candump -L, ASC, TRC, python-can CSV, BLF);
--format overrides. A log of several buses mixes them unless --log-channel
selects one: the others' frames are counted (log_other_channel), and a log
of several channels read as one gets a warning listing them.

Damaged logs: a line python-can cannot parse is skipped and counted
(log_bad_lines, log_torn_line for a last line cut mid-write, log_junk_lines
in ASC), a truncated or corrupt BLF is read up to the damage (log_truncated,
log_corrupt, log_unread_bytes); a warning on stderr gives the first line
numbers. A log of which nothing can be read is an error (exit 65); an empty
log gives outputs without ticks (the CSV has its header) and a warning. A log
whose frames were read but none decoded into an input (all of other IDs, or
all rejected: CAN FD flags, checksums, ranges) writes its outputs and the
summary, then exits 65 naming the causes.

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
    p.add_argument("log", help="input log: .log (candump), .asc, .blf, .trc, .csv, .mf4, ... (any python-can reads; "
                               "another suffix or none: the format its first lines show); - for standard input")
    add_config(p, short_option=False)
    add_log_reading(p)
    add_state_file(p)
    p.add_argument("--out", "-o", help="write the estimate frames to this log (format by suffix; - for candump text "
                                       "on standard output)")
    p.add_argument("--csv", help="write one row per tick to this CSV (- for standard output)")
    p.add_argument("--json", action="store_true", help="print the frame summary as one JSON object (the keys of "
                                                      "the text summary)")
    p.add_argument("--realtime", action="store_true",
                   help="instead of estimating, send the log's frames onto the input bus at recorded timing")
    p.add_argument("--rate", "--playback-speed", dest="rate", type=float, default=None,
                   help="with --realtime: playback speed factor, 2 = twice as fast (default 1)")
    p.add_argument("--speed", dest="old_speed", type=float, help=argparse.SUPPRESS)
    p.add_argument("--quiet", "-q", action="store_true", help="no progress bar (there is none when stderr is not "
                                                              "a terminal)")
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


def playback_rate(args) -> float:
    """--rate (or the deprecated --speed, which said the same but read like simulate's km/h)."""
    option, rate = ("--rate", args.rate) if args.old_speed is None else ("--speed", args.old_speed)
    if rate is None:
        return 1.0
    if not args.realtime:
        raise UsageError(f"{option} is the playback speed of --realtime; offline replay runs as fast as it can")
    if not (math.isfinite(rate) and rate > 0):
        raise UsageError(f"{option}: a playback speed factor above 0, e.g. 1 or 10, got {rate}")
    if option == "--speed":
        print(f"canest: warning: replay --speed is deprecated (simulate's --speed is km/h); type --rate {rate:g} "
              "now", file=sys.stderr)
    return rate


def check_mode_options(args) -> None:
    """A UsageError naming the options the chosen mode would ignore: offline, the buses (it reads the log; only
    --output-channel, the channel its --out frames carry, counts); with --realtime, what belongs to the estimation
    (a running daemon's: it reads the bus the log is played onto)."""
    if args.realtime:
        ignored = {"--out": args.out, "--csv": args.csv, "--json": args.json, "--state-file": args.state_file,
                   "--output-interface": args.output_interface, "--output-channel": args.output_channel}
        why = "--realtime plays the log onto a bus (a running daemon estimates); {} {} to offline replay"
        verbs = ("belongs", "belong")
    else:
        ignored = {"-i/--interface": args.interface, "-c/--channel": args.channel, "-b/--bitrate": args.bitrate,
                   "--fd": args.fd, "--bus-kwargs": args.bus_kwargs, "--output-interface": args.output_interface}
        why = "offline replay reads the log and opens no bus; {} {} the bus --realtime plays onto"
        verbs = ("chooses", "choose")
    given = [option for option, value in ignored.items() if value]
    if given:
        raise UsageError(why.format(" and ".join(given), verbs[len(given) > 1]))


def run(args) -> int:
    check_mode_options(args)
    config = config_from_args(args)
    warnings_to_stderr()
    rate = playback_rate(args)
    if args.realtime:
        bus = open_bus(config.input_bus.kwargs(), "playback")
        try:
            sent = play(args.log, bus, speed=rate, progress=not args.quiet, **log_reading(args))
        except can.CanError as exc:  # the interface went down or away under the player
            raise FileIOError(f"{config.input_bus.interface}:{config.input_bus.channel}: sending failed: {exc}; "
                              "check the interface (ip link) and play the log again") from None
        finally:
            bus.shutdown()
        print(f"sent {sent} frames to {config.input_bus.interface}:{config.input_bus.channel}")
        return 0
    if not (args.out or args.csv or args.json):
        print("note: neither --out nor --csv given; only the frame summary is printed", file=sys.stderr)
    check_outputs({"--out": args.out, "--csv": args.csv, **state_file_output(config, args)},
                  {"the input log": args.log, "the config": args.config or DEFAULT_CONFIG,
                   "the input DBC": config.input_dbc, "the output DBC": config.output_dbc})
    with StopRequest().on_signals() as stop:
        summary = replay(config, args.log, out_log=args.out, out_csv=args.csv, progress=not args.quiet, stop=stop,
                         **log_reading(args))
    report = sys.stderr if is_stdio(args.out) or is_stdio(args.csv) else sys.stdout
    print(json.dumps(summary, sort_keys=True) if args.json else format_summary(summary), file=report)
    if stop.is_set():
        print(f"canest: replay stopped by {stop.signal} after {summary.get('frames', 0)} frames; the outputs are "
              "complete up to the last tick", file=sys.stderr)
    else:
        nothing_decoded(args.log, summary)
    return 0


# the most frequent cause of a log none of whose frames decoded -> what to do
NOTHING_DECODED = {
    "": "compare the log's IDs and CAN FD flags with the config's input DBC (canest check --config ...)",
    "rejected_timestamp": "its frames have no finite timestamp; re-export the log with the logger's own times",
}


def nothing_decoded(log, summary: dict) -> None:
    """A LogError (exit 65) when frames were read and none decoded into an input: every tick was ``no_input``."""
    if summary.get("frames", 0) and not summary.get("decoded", 0):
        causes = sorted(((n, k) for k, n in summary.items() if k.startswith(("rejected_", "ignored_")) and n),
                        reverse=True)
        named = ", ".join(f"{k}={n}" for n, k in causes[:3]) or "no cause counted"
        remedy = NOTHING_DECODED.get(causes[0][1] if causes else "", NOTHING_DECODED[""])
        raise LogError(f"{log}: none of its {summary['frames']} frames decoded into an input ({named}); "
                       f"the outputs hold only no_input ticks: {remedy}")
