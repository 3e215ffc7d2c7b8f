"""canest evaluate: RMSE and MAE of an estimate CSV against a truth CSV."""
from __future__ import annotations

import json
import math

from canest.errors import TableError, UsageError
from canest.commands.common import FORMATTER, check_plot, check_skip, warnings_to_stderr
from canest.apps.evaluate import DISPLAY, align, as_json, format_table, plot, read_table, score, time_span
from canest.io.outputs import OutputFile, check_outputs

EPILOG = """examples:
  canest evaluate est.csv truth.csv --plot est.png
  canest evaluate live.csv truth.csv --align first         # a live CSV has epoch timestamps
  canest replay d.log --csv - | canest evaluate - truth.csv --json

Truth is interpolated onto the estimate's ticks. By default a tick counts for
a state only when the estimate flags that state valid, and the first --skip
seconds (filter convergence) are left out. Angles in deg, speeds in m/s.

--json prints {state: {unit, rmse, mae, max_error, samples, valid, cov1, cov2,
cov3, nees, vbw, wrong_sign}} (NaN as null). When no tick of any state could
be scored (the estimate's times lie outside the truth's: try --align) the
exit status is 65."""


def register(subparsers) -> None:
    p = subparsers.add_parser("evaluate", help="accuracy of estimates against truth (RMSE, MAE, plot)",
                              description=__doc__, epilog=EPILOG, formatter_class=FORMATTER)
    p.add_argument("estimate", help="estimate CSV from canest replay/run/demo (- for standard input)")
    p.add_argument("truth", help="truth CSV from canest simulate")
    p.add_argument("--states", help=f"comma-separated states (default: those of {','.join(DISPLAY)} in both files)")
    p.add_argument("--skip", type=float, default=0.5, help="seconds at the start to leave out (default 0.5)")
    p.add_argument("--all", action="store_true", help="score every tick, valid or not")
    p.add_argument("--plot", help="write a PNG of estimate vs truth (needs matplotlib)")
    p.add_argument("--align", nargs="+", metavar="MODE", default=["none"],
                   help="put the estimate on the truth's clock: 'first' (its first tick at the truth's first time) "
                        "or 'offset SECONDS' (subtract SECONDS from its times) (default none)")
    p.add_argument("--json", action="store_true", help="print the scores as one JSON object (keys below)")
    p.set_defaults(func=run)


def parse_align(words: list) -> tuple:
    """``['first']``, ``['none']`` or ``['offset', SECONDS]`` -> (mode, seconds)."""
    if words in (["first"], ["none"]):
        return words[0], 0.0
    if len(words) == 2 and words[0] == "offset":
        try:
            seconds = float(words[1])
        except ValueError:
            seconds = math.nan
        if math.isfinite(seconds):
            return "offset", seconds
    raise UsageError(f"--align {' '.join(words)}: expected first, none or offset SECONDS, e.g. --align offset "
                     "1712345678.5")


def run(args) -> int:
    mode, offset = parse_align(args.align)
    check_skip(args.skip)
    if args.plot:
        check_plot(args.plot)
        check_outputs({"--plot": args.plot}, {"the estimate CSV": args.estimate, "the truth CSV": args.truth})
    warnings_to_stderr()  # a CSV's left-out lines
    estimate, truth = read_table(args.estimate), read_table(args.truth)
    check_roles(args, estimate, truth)
    estimate = align(estimate, truth, mode, offset)
    if args.states is None:
        states = [s for s in DISPLAY if s in estimate and s in truth]
    else:
        states = [s.strip() for s in args.states.split(",") if s.strip()]
    for state in states:
        for table, path in ((estimate, args.estimate), (truth, args.truth)):
            if state not in table:
                raise TableError(f"{path}: no column '{state}'")
    scores = score(estimate, truth, states, only_valid=not args.all, skip=args.skip)
    print(json.dumps(as_json(scores)) if args.json else format_table(scores, f"{args.estimate} vs {args.truth}"))
    if args.plot:
        with OutputFile(args.plot) as path:
            plot(estimate, truth, states, path)
        print(f"plot written to {args.plot}")
    if not any(s.samples for s in scores):
        raise TableError(nothing_scored(args, estimate, truth))
    return 0


def check_roles(args, estimate: dict, truth: dict) -> None:
    """A UsageError where the truth CSV has the estimate's ``valid`` column and the estimate has none (the
    arguments swapped: the truth would be scored against the estimate, every tick valid, no std)."""
    if "valid" in truth and "valid" not in estimate:
        raise UsageError(f"{args.truth} has the 'valid' column of an estimate and {args.estimate} has none: the "
                         "arguments look swapped; give the estimate first: canest evaluate ESTIMATE TRUTH")


def nothing_scored(args, estimate, truth) -> str:
    """Why no tick could be scored, and what to try."""
    return (f"{args.estimate}: no tick could be scored against {args.truth}: estimate times "
            f"{time_span(estimate['t'])}, truth {time_span(truth['t'])}; put them on one clock with --align first or "
            "--align offset SECONDS, or check the valid column (--all scores every tick)")
