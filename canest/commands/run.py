"""canest run: the live estimation daemon."""
from __future__ import annotations

import sys
from contextlib import ExitStack

from canest.apps import journal
from canest.commands.common import FORMATTER, add_bus_overrides, add_config, config_from_args
from canest.io.sinks import CsvSink
from canest.pipeline import format_summary
from canest.apps.service import Service

EPILOG = """examples:
  canest run --config configs/dici_ev.yaml                 # vcan0 -> vcan1 as configured
  canest run --config my_car.yaml --channel can0 --output-channel can0
  canest run --interface virtual --channel in --output-channel out

Signals: SIGINT/SIGTERM stop cleanly and print where every input frame went;
SIGHUP reloads the config (buses reopened only if their settings changed);
SIGUSR1 logs counters and loop latency now. Under systemd (Type=notify) it
reports READY, WATCHDOG and STATUS; see tools/systemd/."""


def register(subparsers) -> None:
    p = subparsers.add_parser("run", help="live daemon: estimate from a CAN bus, send estimates to a CAN bus",
                              description=__doc__, epilog=EPILOG, formatter_class=FORMATTER)
    add_config(p)
    add_bus_overrides(p)
    p.add_argument("--csv", help="also write one row per tick to this CSV")
    p.add_argument("--log-level", default="INFO", choices=["DEBUG", "INFO", "WARNING", "ERROR"],
                   help="log level on stderr (default INFO)")
    p.set_defaults(func=run)


def run(args) -> int:
    config = config_from_args(args)
    journal.setup(args.log_level)
    with ExitStack() as stack:
        sinks = [stack.enter_context(CsvSink(args.csv))] if args.csv else []
        service = Service(config, sinks=sinks, reload_config=lambda: config_from_args(args))
        service.install_signal_handlers()
        summary = service.run()
    print(format_summary(summary), file=sys.stderr)
    return 0
