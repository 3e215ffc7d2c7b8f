"""canest init: a starting config from a DBC (a file or opendbc's) and, for a car opendbc describes, its numbers."""
from __future__ import annotations

import sys

from canest.commands.common import FORMATTER
from canest.errors import UsageError

EPILOG = """examples:
  canest init ford_lincoln_base_pt.dbc --out fusion.yaml      # or --dbc ford_lincoln_base_pt.dbc
  canest init --car TOYOTA_RAV4_TSS2 --out rav4.yaml          # opendbc's car: its DBC and its numbers
  canest init --dbc opendbc:vw_mqb --car VOLKSWAGEN_GOLF_MK7 --out golf.yaml

The inputs (wheel speeds, steering wheel angle, yaw rate, ax, ay, motor
torques) are found by their names and units; each is marked CONFIRM in the
file with the runners-up. With --car (an opendbc platform, e.g. TOYOTA_RAV4;
needs `pip install 'canest[opendbc]'`), mass, centre of gravity, steering
ratio, yaw inertia and cornering stiffnesses come from opendbc's car
parameters, each with its source in a comment; the rest are canest's
defaults, marked as such. A signal whose DBC range is written in raw counts
(Toyota's [0|65535] for signed values) gets `range: none`. The config is
loaded as `canest check` loads it before it is written.

A DBC without a signal for an input every model needs (steering, wheel
speeds, yaw rate, ax, ay) is an error naming those inputs (exit 2); nothing
is written. An existing --out file is never replaced (exit 73)."""


def register(subparsers) -> None:
    p = subparsers.add_parser("init", help="write a starting config from a DBC (or an opendbc car)",
                              description=__doc__, epilog=EPILOG, formatter_class=FORMATTER)
    p.add_argument("dbc_file", nargs="?", metavar="DBC", help="the car's DBC, as --dbc")
    p.add_argument("--dbc", help="the car's DBC: a file, or opendbc:NAME for one of opendbc's (default with --car: "
                                 "the car's own powertrain DBC)")
    p.add_argument("--car", help="an opendbc platform name (e.g. TOYOTA_RAV4): the vehicle's numbers from opendbc")
    p.add_argument("--out", "-o", default="-", help="the config file to write, never an existing one "
                                                    "(default: standard output)")
    p.set_defaults(func=run)


def run(args) -> int:
    from canest.apps.init import starting_config, write_new

    if args.dbc_file and args.dbc and args.dbc_file != args.dbc:
        raise UsageError(f"init: two DBCs given ({args.dbc_file} and --dbc {args.dbc}); name one")
    args.dbc = args.dbc or args.dbc_file
    if not (args.dbc or args.car):
        raise UsageError("init: name the car's DBC (canest init PATH, --dbc PATH or --dbc opendbc:NAME), or an "
                         "opendbc car with --car NAME")
    text, found = starting_config(args.dbc, args.car, args.out)
    write_new(args.out, text)
    if args.out != "-":
        print(f"wrote {args.out}: {len(found)} inputs found, each marked CONFIRM; next: canest check --config "
              f"{args.out}", file=sys.stderr)
    return 0
