"""Command line: argument parsing only; each sub-command lives in canest/commands/."""
from __future__ import annotations

import argparse
import importlib
import signal
import sys

from canest import __version__
from canest.errors import CanestError, FileIOError

LOG_LEVELS = ("DEBUG", "INFO", "WARNING", "ERROR")
# command -> what `canest --help` lists; a command's module (and numpy, python-can, cantools behind it) is imported
# only when that command runs or shows its own help, so `canest --version` and `canest --help` start fast
COMMANDS = {
    "demo": "live demonstration on virtual CAN with a simulated vehicle",
    "run": "live daemon: estimate from a CAN bus, send estimates to a CAN bus",
    "monitor": "live view of a running daemon's estimates and health",
    "replay": "run a CAN log through the estimator, or play it onto a bus",
    "simulate": "simulate a maneuver into a CAN log and a truth CSV",
    "evaluate": "accuracy of estimates against truth (RMSE, MAE, plot)",
    "compare": "run several filters on one log and compare accuracy and speed",
    "batch": "replay many logs on a Dask cluster and summarize the fleet",
    "check": "validate config and DBCs, print the resolved signal map",
    "init": "write a starting config from a DBC (or an opendbc car)",
    "calibrate": "fit stiffnesses, steering, wheel radius and sensor biases to logged drives",
}

DESCRIPTION = """canest: online vehicle state estimation on CAN.

Decodes steering, wheel speeds, motor torques and IMU frames through a DBC,
runs a nonlinear Kalman filter on a vehicle model at a fixed rate, and sends
longitudinal and lateral velocity, yaw rate, sideslip, tire lateral forces
and road friction (with standard deviations and validity) as CAN frames of an
output DBC.

start here:
  canest demo                      # simulated vehicle on virtual CAN, live, with an accuracy table
  canest check                     # what the built-in config maps (use --config for yours)
  canest simulate -o d.log --truth t.csv && canest replay d.log --csv e.csv && canest evaluate e.csv t.csv"""

EPILOG = """exit status (as BSD sysexits.h):
   0  done; also a replay stopped in order by SIGINT or SIGTERM (its summary says stopped=1)
   1  a bug in canest (printed with its traceback; please report it)
   2  usage or config: arguments, config file, DBC, bus
  65  input data: a log or table that cannot be read
  66  no input: an input file that does not exist or may not be read
  69  unavailable: an optional package the feature needs (the message names it)
  73  cannot create an output file (read-only or missing folder, a folder named as file)
  74  I/O error: reading or writing failed midway (disk full, file size limit, device)
 130  interrupted (Ctrl-C) in a command other than run and replay, or a second Ctrl-C during a replay
every error but 1 is one line: canest: error: FILE: what happened; what to do"""


def build_parser(argv=None) -> argparse.ArgumentParser:
    """The parser; given ``argv``, only the command it names is registered in full (the others list their help)."""
    parser = argparse.ArgumentParser(prog="canest", description=DESCRIPTION, epilog=EPILOG,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--version", action="version", version=f"canest {__version__}")
    subparsers = parser.add_subparsers(title="commands", metavar="COMMAND", required=True)
    named = None if argv is None else next((word for word in argv if word in COMMANDS), "")
    for name, summary in COMMANDS.items():
        if named is None or name == named:
            importlib.import_module(f"canest.commands.{name}").register(subparsers)
            _add_log_level(subparsers.choices[name])
        else:
            subparsers.add_parser(name, help=summary)
    return parser


def _add_log_level(command: argparse.ArgumentParser) -> None:
    """``--log-level`` on every command (``run`` has its own, default INFO, for the journal)."""
    if "--log-level" not in command._option_string_actions:
        command.add_argument("--log-level", dest="logging_level", choices=LOG_LEVELS,
                             help="log records of canest and python-can at this level and above to stderr "
                                  "(default: warnings only, as plain lines)")


def main(argv=None) -> None:
    signal.signal(signal.SIGPIPE, signal.SIG_DFL)  # `canest check | head` ends quietly
    args = build_parser(sys.argv[1:] if argv is None else argv).parse_args(argv)
    if getattr(args, "logging_level", None):
        from canest.apps import journal  # deferred: `canest --version` stays fast
        journal.setup(args.logging_level)
    try:
        sys.exit(args.func(args))
    except CanestError as exc:  # a problem of the input: one line; anything else is a bug and keeps its traceback
        fail(exc)
    except OSError as exc:  # a file or device failing where no command names it better: still one line, 74
        where = f"{exc.filename}: " if exc.filename else ""
        fail(FileIOError(f"{where}{exc.strerror or exc}; check the file, the disk and the permissions"))
    except KeyboardInterrupt:
        sys.exit(130)


def fail(error: CanestError) -> None:
    print(f"canest: error: {error}", file=sys.stderr)
    sys.exit(error.exit_status)
