"""canest demo: the whole service on virtual CAN buses with a simulated vehicle; no setup needed."""
from __future__ import annotations

import sys
from contextlib import ExitStack

from canest.commands.common import FORMATTER, add_config, config_from_args
from canest.commands.simulate import parse_mu
from canest.apps.demo import run_demo
from canest.io.sinks import CsvSink
from canest.sim.maneuvers import MANEUVERS

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
    p.add_argument("--playback-speed", type=float, default=1.0, help="1 = real time (default), 2 = twice as fast")
    p.add_argument("--csv", help="also write the estimates to this CSV")
    p.set_defaults(func=run)


def run(args) -> int:
    config = config_from_args(args)
    with ExitStack() as stack:
        sinks = [stack.enter_context(CsvSink(args.csv))] if args.csv else []
        run_demo(config, args.maneuver, args.speed, parse_mu(args.mu), args.seed, args.playback_speed, sys.stdout,
                 sinks)
    return 0
