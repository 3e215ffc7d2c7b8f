"""Command line: argument parsing only; each sub-command lives in canest/commands/."""
from __future__ import annotations

import argparse
import signal
import sys

from canest import __version__
from canest.commands import batch, check, compare, demo, evaluate, monitor, replay, run, simulate
from canest.errors import CanestError

DESCRIPTION = """canest: online vehicle state estimation on CAN.

Decodes steering, wheel speeds, motor torques and IMU frames through a DBC,
runs a nonlinear Kalman filter on a vehicle model at a fixed rate, and sends
longitudinal velocity, yaw rate and sideslip (with standard deviations and
validity) as CAN frames of an output DBC.

start here:
  canest demo                      simulated vehicle on virtual CAN, live, with an accuracy table
  canest check                     what the built-in config maps (use --config for yours)
  canest simulate -o d.log --truth t.csv && canest replay d.log --csv e.csv && canest evaluate e.csv t.csv"""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="canest", description=DESCRIPTION,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--version", action="version", version=f"canest {__version__}")
    subparsers = parser.add_subparsers(title="commands", metavar="COMMAND", required=True)
    for command in (demo, run, monitor, replay, simulate, evaluate, compare, batch, check):
        command.register(subparsers)
    return parser


def main(argv=None) -> None:
    signal.signal(signal.SIGPIPE, signal.SIG_DFL)  # `canest check | head` ends quietly
    args = build_parser().parse_args(argv)
    try:
        sys.exit(args.func(args))
    except CanestError as exc:  # a problem of the input: one line; anything else is a bug and keeps its traceback
        print(f"canest: error: {exc}", file=sys.stderr)
        sys.exit(2)
    except KeyboardInterrupt:
        sys.exit(130)
