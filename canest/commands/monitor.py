"""canest monitor: a live terminal view of the estimates a running daemon sends."""
from __future__ import annotations

import sys

from canest.io.bus import open_bus
from canest.commands.common import FORMATTER, add_config
from canest.codec.dbc import load_database
from canest.config import DEFAULT_CONFIG, load_config
from canest.apps.monitor import run_monitor

EPILOG = """examples:
  canest monitor --channel vcan1
  canest monitor --config configs/dici_ev.yaml          # the config's output bus
  canest monitor --interface virtual --channel out --duration 5

Shows each estimate with its standard deviation and validity, the status
message (filter, mode, missing inputs, resets, NIS), and the stream's own
health: frame rate, CRC failures and rolling-counter gaps."""


def register(subparsers) -> None:
    p = subparsers.add_parser("monitor", help="live view of a running daemon's estimates and health",
                              description=__doc__, epilog=EPILOG, formatter_class=FORMATTER)
    add_config(p)
    p.add_argument("--interface", help="python-can interface (default: the config's output bus)")
    p.add_argument("--channel", help="channel to watch (default: the config's output bus, e.g. vcan1)")
    p.add_argument("--refresh", type=float, default=0.5, help="seconds between redraws (default 0.5)")
    p.add_argument("--duration", type=float, help="stop after this many seconds (default: until Ctrl-C)")
    p.set_defaults(func=run)


def run(args) -> int:
    config = load_config(args.config or DEFAULT_CONFIG)  # its --interface/--channel name the watched bus
    bus_config = config.output_bus
    kwargs = {**bus_config.kwargs(), "interface": args.interface or bus_config.interface,
              "channel": args.channel or bus_config.channel}
    database = load_database(config.output_dbc, "monitor")
    bus = open_bus(kwargs, "monitored")
    try:
        run_monitor(bus, database, f"{kwargs['interface']}:{kwargs['channel']}", sys.stdout, args.refresh,
                    args.duration, clear=sys.stdout.isatty())
    except KeyboardInterrupt:
        pass
    finally:
        bus.shutdown()
    return 0

