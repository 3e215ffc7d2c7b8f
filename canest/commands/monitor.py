"""canest monitor: a live view of the estimates a running daemon sends."""
from __future__ import annotations

import math
import sys
from collections import Counter

from canest.commands.common import FORMATTER, add_bus_overrides, add_config, config_from_args
from canest.errors import BusOpenError, UsageError

MIN_REFRESH = 0.05  # s: a terminal redraws no faster than a person reads
MAX_REFRESH = 60.0

EPILOG = """examples:
  canest monitor -c vcan1
  canest monitor --config configs/dici_ev.yaml          # the config's output bus
  canest monitor -i udp_multicast -c 239.74.163.3       # a daemon in another process, no SocketCAN
  canest monitor -c vcan1 --once                        # one snapshot for a script, then exit

Shows each estimate with its standard deviation and validity, the status
message (filter, mode, missing inputs, resets, NIS), the online calibration
(one line per learned parameter: value, std, state prior/learning/converged;
angles in deg, speed, ratio, front and rear as factors) and the stream's own health: frame
rate, CRC failures and rolling-counter gaps. On a terminal the view is redrawn
in place; when standard output is not a terminal (a pipe, a file) each
refresh is one line: frames=N mode=M vx=... yaw_rate=... (a state flagged
invalid ends in '?') calib_speed=... calib_speed_std=... calib_speed_state=...
--once prints one view (or line) as soon as the status message and the
estimates have arrived (and the calibration, waiting at most 1.2 s for it),
and exits; 69 when nothing arrived within --duration (default 5 s with --once)."""


class NoEstimates(BusOpenError):
    """The watched bus carried no estimates in time (EX_UNAVAILABLE: the daemon is not there)."""

    exit_status = 69


def register(subparsers) -> None:
    p = subparsers.add_parser("monitor", help="live view of a running daemon's estimates and health",
                              description=__doc__, epilog=EPILOG, formatter_class=FORMATTER)
    add_config(p, short_option=False)
    add_bus_overrides(p, "watched bus (default: the config's output bus)", output=False)
    p.add_argument("--refresh", type=float, default=0.5,
                   help=f"seconds between redraws, {MIN_REFRESH:g} to {MAX_REFRESH:g} (default 0.5)")
    p.add_argument("--duration", type=float, help="stop after this many seconds, above 0 (default: until Ctrl-C)")
    p.add_argument("--once", action="store_true", help="print one view once the estimates have arrived, then exit")
    p.add_argument("--lines", action="store_true", help="one line per refresh even on a terminal")
    p.set_defaults(func=run)


def run(args) -> int:
    from canest.apps.monitor import run_monitor
    from canest.codec.dbc import load_database
    from canest.io.bus import BusLink

    if not MIN_REFRESH <= args.refresh <= MAX_REFRESH:  # also refuses nan
        raise UsageError(f"--refresh: seconds from {MIN_REFRESH:g} to {MAX_REFRESH:g}, got {args.refresh}")
    if args.duration is not None and not 0.0 < args.duration < math.inf:
        raise UsageError(f"--duration: seconds above 0, got {args.duration}")
    config = config_from_args(args)
    bus_config = config.output_bus
    database = load_database(config.output_dbc, "monitor")
    bus = BusLink(bus_config.kwargs(), "monitored", Counter())  # a bus down or gone is waited for, as by the daemon
    line_mode = args.lines or not sys.stdout.isatty()
    duration = 5.0 if args.once and args.duration is None else args.duration
    try:
        monitor = run_monitor(bus, database, f"{bus_config.interface}:{bus_config.channel}", sys.stdout,
                              args.refresh, duration, clear=not line_mode, lines=line_mode, once=args.once)
    except KeyboardInterrupt:
        return 0
    finally:
        bus.close()
    if args.once and not monitor.complete():
        raise NoEstimates(f"{bus_config.interface}:{bus_config.channel}: no estimate frames within {duration:g} s; "
                          "is the daemon running and sending on this bus?")
    return 0
