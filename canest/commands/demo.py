"""canest demo: the whole service on virtual CAN buses with a simulated vehicle; no setup needed."""
from __future__ import annotations

import sys
from contextlib import ExitStack

from canest.commands.common import FORMATTER, add_config, config_from_args
from canest.commands.simulate import check_speed_and_seed, parse_mu
from canest.errors import UsageError
from canest.apps.demo import run_demo
from canest.io.sinks import CsvSink
from canest.sim.maneuvers import MANEUVERS

MAX_PLAYBACK = 10.0  # times real time: the service and the monitor keep up on a busy machine

EPILOG = """A simulated vehicle drives the maneuver; its frames go onto a python-can
virtual bus in real time; the estimation service decodes them, runs the filter
and sends estimate frames onto a second virtual bus; a monitor decodes those
and prints them next to the simulator's truth. An accuracy table ends the run.

examples:
  canest demo
  canest demo --maneuver sine --mu 0.35 --csv est.csv"""


def register(subparsers) -> None:
    p = subparsers.add_parser("demo", help="live demonstration on virtual CAN with a simulated vehicle",
                              description=__doc__, epilog=EPILOG, formatter_class=FORMATTER)
    add_config(p)
    p.add_argument("--maneuver", "-m", choices=MANEUVERS, default="dlc", help="maneuver (default dlc, ISO 3888-1)")
    p.add_argument("--speed", type=float, default=80.0, help="km/h (default 80)")
    p.add_argument("--mu", default="0.85", help="road friction (default 0.85)")
    p.add_argument("--seed", type=int, default=0, help="random seed of the sensor errors (default 0)")
    p.add_argument("--playback-speed", type=float, default=1.0,
                   help=f"1 = real time (default), 2 = twice as fast, up to {MAX_PLAYBACK:g}; the service reads each "
                        "frame's arrival time, so at another speed it estimates a car whose motion is squeezed (or "
                        "stretched) in time: the accuracy table means what it says at 1 only")
    p.add_argument("--csv", help="also write the estimates to this CSV")
    p.set_defaults(func=run)


def run(args) -> int:
    check_speed_and_seed(args.speed, args.seed)
    if not 0.0 < args.playback_speed <= MAX_PLAYBACK:  # also refuses nan
        raise UsageError(f"--playback-speed: a factor above 0 and up to {MAX_PLAYBACK:g} (1: real time), got "
                         f"{args.playback_speed}")
    config = config_from_args(args)
    with ExitStack() as stack:
        sinks = [stack.enter_context(CsvSink(args.csv))] if args.csv else []
        run_demo(config, args.maneuver, args.speed, parse_mu(args.mu), args.seed, args.playback_speed, sys.stdout,
                 sinks)
    return 0
