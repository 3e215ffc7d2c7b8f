"""Options several sub-commands share: the config, and the buses as python-can's tools spell them.

A bus setting comes from, lowest first (each source overrides the ones before):

1. canest's defaults (the built-in config: SocketCAN vcan0 in, vcan1 out);
2. python-can's own configuration, in python-can's order (``can.util.load_config``:
   ``~/.canrc`` and the other config files, then ``CAN_INTERFACE``, ``CAN_CHANNEL``,
   ``CAN_BITRATE`` and ``CAN_CONFIG`` from the environment);
3. what the ``--config`` file's ``bus:`` sections set;
4. the command line: ``-i/--interface``, ``-c/--channel``, ``-b/--bitrate``, ``--fd``,
   ``--bus-kwargs KEY=VALUE``.
"""
from __future__ import annotations

import argparse
import dataclasses
import logging
import math
import sys
from pathlib import Path

FORMATTER = argparse.RawDescriptionHelpFormatter
CONFIG_SUFFIXES = (".yaml", ".yml")
BUS_SOURCES = """bus settings, lowest first: canest's defaults (SocketCAN vcan0 in, vcan1 out), python-can's
configuration (~/.canrc, then CAN_INTERFACE, CAN_CHANNEL, CAN_BITRATE), the --config file's bus:
sections, the command line."""


def warn_config_short_option(value: str) -> None:
    print(f"canest: warning: -c for the config is deprecated (python-can's tools use -c for the channel); type "
          f"--config {value} now", file=sys.stderr)


class LegacyConfig(argparse.Action):
    """``-c FILE`` where it still means the config: works for one more release, and says what to type now."""

    def __call__(self, parser, namespace, value, option_string=None):
        warn_config_short_option(value)
        namespace.config = value


class ChannelOrLegacyConfig(argparse.Action):
    """``-c``: the channel, as in python-can's tools; a value ending in .yaml/.yml is still taken as the config."""

    def __call__(self, parser, namespace, value, option_string=None):
        if option_string == "-c" and value.lower().endswith(CONFIG_SUFFIXES):
            warn_config_short_option(value)
            namespace.config = value
        else:
            namespace.channel = value


class BusKeyword(argparse.Action):
    """``--bus-kwargs KEY=VALUE`` (repeatable): a keyword for ``can.Bus``, its value cast as python-can casts."""

    def __call__(self, parser, namespace, value, option_string=None):
        key, equals, text = value.partition("=")
        if not (key and equals):
            parser.error(f"{option_string} {value}: expected KEY=VALUE, e.g. {option_string} receive_own_messages=true")
        from can.util import cast_from_string

        keywords = dict(getattr(namespace, self.dest) or {})
        keywords[key] = cast_from_string(text)
        setattr(namespace, self.dest, keywords)


def add_config(parser, short_option: bool = True) -> None:
    from canest.config import DEFAULT_CONFIG

    parser.add_argument("--config", default=None,
                        help=f"vehicle config YAML (default: the built-in {DEFAULT_CONFIG.name}, "
                             "the 1845 kg distributed-drive EV)")
    if short_option:
        parser.add_argument("-c", action=LegacyConfig, dest="config", help=argparse.SUPPRESS)


def add_state_file(parser) -> None:
    parser.add_argument("--state-file", metavar="PATH",
                        help="the online calibration's state: reloaded at start, saved every minute and at the end "
                             "(overrides estimator.state_file; README \"Online calibration\")")


def state_file_output(config, args) -> dict:
    """The online calibration's state file as an output of the run (it is written over: :func:`check_outputs` keeps
    it off the run's inputs), under the option or config key that named it; an OutputFileError (73) for a folder."""
    from canest.errors import OutputFileError

    path = config.estimator.state_file
    if not path:
        return {}
    named = "--state-file" if getattr(args, "state_file", None) else "estimator.state_file"
    if Path(path).is_dir():
        raise OutputFileError(f"{named} {path}: that is a folder; name the calibration state file in it")
    return {named: path}


def check_plot(path) -> None:
    """``--plot PATH``, before any work: matplotlib installed (a DependencyError, 69) and a format it writes by the
    name's suffix (a UsageError, 2; no suffix: PNG, matplotlib's default)."""
    from canest.errors import DependencyError, UsageError

    DependencyError.require("matplotlib", "--plot", "pip install 'canest[plot]'")
    from matplotlib.figure import Figure

    formats = Figure().canvas.get_supported_filetypes()
    suffix = Path(path).suffix.lower().removeprefix(".")
    if suffix and suffix not in formats:
        raise UsageError(f"--plot {path}: matplotlib cannot write '.{suffix}' files; name a .png (or "
                         f"{', '.join(f'.{name}' for name in sorted(formats) if name != 'png')})")


def check_skip(seconds: float) -> None:
    """``--skip`` (evaluate, compare): seconds from 0; nan scored nothing and blamed the clocks."""
    from canest.errors import UsageError

    if not 0.0 <= seconds < math.inf:
        raise UsageError(f"--skip: seconds from 0 at the start to leave out, got {seconds}")


def warnings_to_stderr() -> None:
    """canest's warnings (a damaged log or CSV, an empty log, an input never delivered) as ``canest: warning: ...``
    lines on stderr, once however often it is called."""
    logger = logging.getLogger("canest")
    if any(handler.name == "canest-warnings" for handler in logger.handlers):
        return
    handler = logging.StreamHandler(sys.stderr)
    handler.name = "canest-warnings"
    handler.setFormatter(logging.Formatter("canest: warning: %(message)s"))
    logger.addHandler(handler)
    logger.propagate = False


def add_log_reading(parser) -> None:
    """--format and --log-channel: how a log is read where its name and content do not settle it."""
    from canest.io.logfiles import STREAM_FORMATS

    parser.add_argument("--format", "-f", choices=STREAM_FORMATS,
                        help="format of the log (log = candump -L); by default its suffix says it, else its first "
                             "lines do (standard input: log)")
    parser.add_argument("--log-channel", metavar="NAME",
                        help="read only this channel of a log of several buses, as the log names it (can0; ASC "
                             "and BLF count from 0); the other channels' frames are counted as log_other_channel")


def log_reading(args) -> dict:
    """The keywords of :func:`canest.apps.replay.replay` that --format and --log-channel give."""
    return {"log_format": args.format, "log_channel": args.log_channel}


def add_bus_overrides(parser, title: str = "buses (override the config and python-can's configuration)",
                      output: bool = True) -> None:
    """-i, -c, -b, --fd, --bus-kwargs (and the output bus's interface and channel when ``output``)."""
    group = parser.add_argument_group(title, BUS_SOURCES)
    group.add_argument("-i", "--interface", help="python-can interface, e.g. socketcan, udp_multicast, virtual, pcan")
    group.add_argument("-c", "--channel", action=ChannelOrLegacyConfig,
                       help="channel, e.g. vcan0, can0, 239.74.163.2 (udp_multicast)")
    group.add_argument("-b", "--bitrate", type=int, help="bitrate in bit/s, e.g. 500000")
    group.add_argument("--fd", action="store_true", default=None, help="CAN FD")
    group.add_argument("--bus-kwargs", "--bus-option", action=BusKeyword, dest="bus_kwargs", metavar="KEY=VALUE",
                       help="any other keyword of python-can's bus (repeatable), e.g. receive_own_messages=true")
    if output:
        group.add_argument("--output-interface", help="interface of the output bus (default: the input's)")
        group.add_argument("--output-channel", help="output channel, e.g. vcan1; same as input to answer on one bus")


def explicit_bus_keys(path, section: str) -> set:
    """The keys (interface, channel, options) the config file at ``path`` sets under ``<section>.bus``."""
    if path is None:
        return set()  # the built-in config: canest's defaults, below python-can's configuration
    import yaml

    try:
        with open(path) as handle:
            document = yaml.safe_load(handle)
    except (OSError, yaml.YAMLError):
        return set()  # load_config has reported it already
    bus = ((document or {}).get(section) or {}).get("bus") if isinstance(document, dict) else None
    return set(bus) if isinstance(bus, dict) else set()


def command_line_options(args) -> dict:
    """The bus keywords the command line gives beyond interface and channel."""
    options = dict(getattr(args, "bus_kwargs", None) or {})
    if getattr(args, "bitrate", None) is not None:
        options["bitrate"] = args.bitrate
    if getattr(args, "fd", None):
        options["fd"] = True
    return options


def layered_bus(configured, explicit: set, python_can: dict, interface, channel, options: dict):
    """One bus's settings from the four sources of the module's list (``configured`` holds 1 and 3)."""
    from canest.settings import BusConfig

    def pick(key, given, default):
        if given:
            return given
        if key in explicit or key not in python_can:
            return default
        return python_can[key]

    others = {k: v for k, v in python_can.items() if k not in ("interface", "channel")}
    layers = (others, configured.options) if "options" in explicit else (configured.options, others)
    return BusConfig(pick("interface", interface, configured.interface),
                     str(pick("channel", channel, configured.channel)), {**layers[0], **layers[1], **options})


def config_from_args(args):
    """The config file (or the built-in one) with the buses of the command line and python-can's configuration."""
    from canest.config import DEFAULT_CONFIG, load_config
    from canest.io.bus import python_can_config

    config = load_config(args.config or DEFAULT_CONFIG)
    if getattr(args, "state_file", None):
        config = dataclasses.replace(config, estimator=dataclasses.replace(config.estimator,
                                                                           state_file=args.state_file))
    if not hasattr(args, "interface"):
        return config  # a command without a bus
    python_can = python_can_config()
    options = command_line_options(args)
    if not hasattr(args, "output_channel"):  # monitor: its bus options name the output bus it watches
        return config.with_buses(output_bus=output_bus(config, args, python_can, args.interface, args.channel))
    input_bus = layered_bus(config.input_bus, explicit_bus_keys(args.config, "input"), python_can,
                            args.interface, args.channel, options)
    return config.with_buses(input_bus=input_bus, output_bus=output_bus(
        config, args, python_can, args.output_interface or args.interface, args.output_channel))


def output_bus(config, args, python_can: dict, interface, channel):
    """The output bus: python-can's configuration gives only its interface (its channel is the input's)."""
    interface_only = {k: v for k, v in python_can.items() if k == "interface"}
    return layered_bus(config.output_bus, explicit_bus_keys(args.config, "output"), interface_only, interface,
                       channel, command_line_options(args))
