"""canest run: the live estimation daemon."""
from __future__ import annotations

import logging
import sys

from canest.commands.common import FORMATTER, add_bus_overrides, add_config, config_from_args
from canest.outputs import EstimateCsvWriter
from canest.pipeline import format_summary
from canest.service import Service

EPILOG = """examples:
  canest run --config configs/dici_ev.yaml                 # vcan0 -> vcan1 as configured
  canest run --config my_car.yaml --channel can0 --output-channel can0
  canest run --interface virtual --channel in --output-channel out

Stops cleanly on SIGINT or SIGTERM and prints where every input frame went."""


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
    logging.basicConfig(level=args.log_level, stream=sys.stderr, format="%(levelname)s %(name)s: %(message)s")
    writer = EstimateCsvWriter(args.csv) if args.csv else None
    service = Service(config, csv_writer=writer)
    service.install_signal_handlers()
    try:
        summary = service.run()
    finally:
        if writer:
            writer.close()
    print(format_summary(summary), file=sys.stderr)
    return 0
