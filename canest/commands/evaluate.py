"""canest evaluate: RMSE and MAE of an estimate CSV against a truth CSV."""
from __future__ import annotations

from canest.errors import DependencyError, InputFileError, TableError
from canest.commands.common import FORMATTER
from canest.apps.evaluate import DISPLAY, format_table, plot, read_table, score
from canest.io.outputs import OutputFile, check_outputs

EPILOG = """example:
  canest evaluate est.csv truth.csv --plot est.png

Truth is interpolated onto the estimate's ticks. By default a tick counts for
a state only when the estimate flags that state valid, and the first --skip
seconds (filter convergence) are left out. Angles in deg, speeds in m/s."""


def register(subparsers) -> None:
    p = subparsers.add_parser("evaluate", help="accuracy of estimates against truth (RMSE, MAE, plot)",
                              description=__doc__, epilog=EPILOG, formatter_class=FORMATTER)
    p.add_argument("estimate", help="estimate CSV from canest replay/run/demo")
    p.add_argument("truth", help="truth CSV from canest simulate")
    p.add_argument("--states", help=f"comma-separated states (default: those of {','.join(DISPLAY)} in both files)")
    p.add_argument("--skip", type=float, default=0.5, help="seconds at the start to leave out (default 0.5)")
    p.add_argument("--all", action="store_true", help="score every tick, valid or not")
    p.add_argument("--plot", help="write a PNG of estimate vs truth (needs matplotlib)")
    p.set_defaults(func=run)


def read_input(path) -> dict:
    try:
        return read_table(path)
    except OSError as exc:
        raise InputFileError(f"{path}: cannot read: {exc.strerror or exc}; name an existing CSV this user may read") \
            from None


def run(args) -> int:
    if args.plot:
        DependencyError.require("matplotlib", "--plot", "pip install matplotlib")
        check_outputs({"--plot": args.plot}, {"the estimate CSV": args.estimate, "the truth CSV": args.truth})
    estimate, truth = read_input(args.estimate), read_input(args.truth)
    if args.states is None:
        states = [s for s in DISPLAY if s in estimate and s in truth]
    else:
        states = [s.strip() for s in args.states.split(",") if s.strip()]
    for state in states:
        for table, path in ((estimate, args.estimate), (truth, args.truth)):
            if state not in table:
                raise TableError(f"{path}: no column '{state}'")
    print(format_table(score(estimate, truth, states, only_valid=not args.all, skip=args.skip),
                       f"{args.estimate} vs {args.truth}"))
    if args.plot:
        with OutputFile(args.plot) as path:
            plot(estimate, truth, states, path)
        print(f"plot written to {args.plot}")
    return 0
