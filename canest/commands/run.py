"""canest run: the live estimation daemon."""
from __future__ import annotations

import sys
from contextlib import ExitStack

from canest.apps import journal
from canest.commands.common import (FORMATTER, add_bus_overrides, add_config, add_state_file, config_from_args,
                                    state_file_output)
from canest.codec.dbc import load_database
from canest.config import DEFAULT_CONFIG
from canest.config.buses import id_clash, same_bus
from canest.errors import UsageError
from canest.io.outputs import check_outputs
from canest.io.sinks import CsvSink
from canest.pipeline import format_summary
from canest.apps.service import Service, StartupSignals

EPILOG = """examples:
  canest run --config configs/dici_ev.yaml                 # vcan0 -> vcan1 as configured
  canest run --config my_car.yaml -c can0 --output-channel can0 -b 500000
  canest run -i udp_multicast -c 239.74.163.2 --output-channel 239.74.163.3   # no SocketCAN: see below

Without SocketCAN, processes on one machine share a bus through python-can's
udp_multicast interface (loopback multicast; virtual stays inside one
process). In three terminals:
  canest run -i udp_multicast -c 239.74.163.2 --output-channel 239.74.163.3
  canest monitor -i udp_multicast -c 239.74.163.3
  canest replay drive.log --realtime -i udp_multicast -c 239.74.163.2

Until the first input frame (vehicle off, cable not yet connected) every
tick is published as no_input, so canest monitor --once finds the daemon.

Signals: SIGINT/SIGTERM stop cleanly (frames queued at the stop are still
estimated, for at most 2 s) and print where every input frame went;
SIGHUP reloads the config (buses reopened only if their settings changed; a
config that does not load, or whose buses do not open, is logged and the
running one kept);
SIGUSR1 logs counters and loop latency now. Under systemd (Type=notify) it
reports READY, WATCHDOG and STATUS; see tools/systemd/."""


def register(subparsers) -> None:
    p = subparsers.add_parser("run", help="live daemon: estimate from a CAN bus, send estimates to a CAN bus",
                              description=__doc__, epilog=EPILOG, formatter_class=FORMATTER)
    add_config(p, short_option=False)
    add_bus_overrides(p)
    p.add_argument("--csv", help="also write one row per tick to this CSV")
    add_state_file(p)
    p.add_argument("--log-level", default="INFO", choices=["DEBUG", "INFO", "WARNING", "ERROR"],
                   help="log level on stderr (default INFO)")
    p.set_defaults(func=run)


def check_bus_ids(config) -> None:
    """A UsageError where the command line put the output on the input's bus and an output ID is one the car sends
    (the config's own buses are checked when it loads: :func:`canest.config.buses.id_clash`)."""
    if same_bus(config.input_bus, config.output_bus):
        clash = id_clash(load_database(config.input_dbc, "input"), load_database(config.output_dbc, "output"))
        if clash:
            raise UsageError(f"{config.input_bus.interface}:{config.input_bus.channel}: {clash}")


def run(args) -> int:
    startup = StartupSignals()
    config = config_from_args(args)
    check_bus_ids(config)
    check_outputs({"--csv": args.csv, **state_file_output(config, args)},
                  {"the config": args.config or DEFAULT_CONFIG, "the input DBC": config.input_dbc,
                   "the output DBC": config.output_dbc})
    journal.setup(args.log_level)
    with ExitStack() as stack:
        sinks = [stack.enter_context(CsvSink(args.csv))] if args.csv else []
        service = Service(config, sinks=sinks, reload_config=lambda: config_from_args(args))
        startup.hand_over(service)
        summary = service.run()
    print(format_summary(summary), file=sys.stderr)
    return 0
