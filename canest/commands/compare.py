"""canest compare: every filter on the same log, scored against truth, timed."""
from __future__ import annotations

import json
import sys

from canest.commands.common import (FORMATTER, add_config, add_log_reading, check_plot, check_skip,
                                    config_from_args, log_reading, warnings_to_stderr)
from canest.apps.compare import comparison_json, format_comparison, plot_comparison, run_filter, runnable
from canest.apps.evaluate import read_table, time_span
from canest.errors import TableError, UsageError

EPILOG = """examples:
  canest simulate --maneuver dlc --speed 80 --mu 0.85 -o dlc.log --truth dlc.csv
  canest compare dlc.log dlc.csv --filters all --plot dlc.png
  canest compare sine.blf sine.csv --filters ckf,fckf,svd-fckf

Each filter gets the config's noise settings and its own default factorization
and options. RMSE and MAE over valid ticks after --skip seconds; CPU us/step
is the median CPU time of one predict + update (the replaying thread's, so a
busy machine does not inflate it). --json prints a list, one object per
filter: filter, cpu_us_per_step, repairs, scores {state: {rmse, mae, unit}}."""


def register(subparsers) -> None:
    p = subparsers.add_parser("compare", help="run several filters on one log and compare accuracy and speed",
                              description=__doc__, epilog=EPILOG, formatter_class=FORMATTER)
    p.add_argument("log", help="input log (any format python-can reads, or one its first lines show)")
    p.add_argument("truth", help="truth CSV from canest simulate")
    add_config(p)
    add_log_reading(p)
    p.add_argument("--filters", default="all",
                   help="'all' (every filter the config's inputs can run) or a comma-separated list (default all)")
    p.add_argument("--skip", type=float, default=0.5, help="seconds at the start to leave out (default 0.5)")
    p.add_argument("--plot", help="PNG with estimate vs truth and the errors of every filter")
    p.add_argument("--json", action="store_true", help="print the comparison as JSON (progress lines go to stderr)")
    p.set_defaults(func=run)


def run(args) -> int:
    if args.plot:  # before the replays, not after them
        check_plot(args.plot)
    check_skip(args.skip)
    warnings_to_stderr()  # a damaged log's or truth CSV's warnings
    config = config_from_args(args)
    names = runnable(config, args.filters)
    truth = read_table(args.truth)
    if "valid" in truth:
        raise UsageError(f"{args.truth} has the 'valid' column of an estimate CSV: give the drive's truth (canest "
                         "simulate --truth writes one), the filters' estimates are what compare makes")
    runs = []
    for name in names:
        runs.append(run_filter(config, args.log, truth, name, args.skip, **log_reading(args)))
        print(f"  {name}: done", flush=True, file=sys.stderr if args.json else sys.stdout)
    if args.json:
        print(json.dumps(comparison_json(runs)))
    else:
        print(format_comparison(runs, f"{args.log} ({config.vehicle.name})"))
        repaired = [f"{r.name} ({r.repairs})" for r in runs if r.repairs]
        if repaired:
            print("covariance repairs: " + ", ".join(repaired))
    if args.plot:
        plot_comparison(runs, truth, args.plot)
        print(f"plot written to {args.plot}", file=sys.stderr if args.json else sys.stdout)
    if not any(score.samples for run in runs for score in run.scores.values()):
        raise TableError(f"{args.log}: no tick of any filter could be scored against {args.truth} (truth "
                         f"{time_span(truth['t'])}, estimates {time_span(runs[0].table['t'])}): is it this log's "
                         "truth? (--skip, the valid bits: canest evaluate --all scores every tick)")
    return 0
