"""Options several sub-commands share."""
from __future__ import annotations

import argparse

from canest.config import DEFAULT_CONFIG, load_config
from canest.settings import BusConfig


FORMATTER = argparse.RawDescriptionHelpFormatter


def add_config(parser) -> None:
    parser.add_argument("--config", "-c", default=None,
                        help=f"vehicle config YAML (default: the built-in {DEFAULT_CONFIG.name}, "
                             "the 1845 kg distributed-drive EV)")


def add_bus_overrides(parser) -> None:
    group = parser.add_argument_group("buses (override the config)")
    group.add_argument("--interface", help="python-can interface of the input bus, e.g. socketcan, virtual, pcan")
    group.add_argument("--channel", help="input channel, e.g. vcan0, can0")
    group.add_argument("--output-interface", help="interface of the output bus (default: the input's if overridden)")
    group.add_argument("--output-channel", help="output channel, e.g. vcan1; same as input to answer on one bus")


def config_from_args(args):
    config = load_config(args.config or DEFAULT_CONFIG)
    if getattr(args, "interface", None) or getattr(args, "channel", None):
        config = config.with_buses(input_bus=BusConfig(args.interface or config.input_bus.interface,
                                                       args.channel or config.input_bus.channel,
                                                       config.input_bus.options))
    if getattr(args, "output_interface", None) or getattr(args, "output_channel", None) or getattr(args, "interface", None):
        config = config.with_buses(output_bus=BusConfig(
            args.output_interface or args.interface or config.output_bus.interface,
            args.output_channel or config.output_bus.channel, config.output_bus.options))
    return config

