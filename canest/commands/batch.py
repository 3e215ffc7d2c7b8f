"""canest batch: re-estimate many logs on a Dask cluster (local by default)."""
from __future__ import annotations

import time
from pathlib import Path

from canest.apps.batch import fleet_table, plot_errors, run_batch
from canest.commands.common import FORMATTER, add_config, config_from_args
from canest.apps.compare import parse_filters

EPILOG = """examples:
  canest batch 'logs/**/*.log' --config configs/dici_ev.yaml --out results/
  canest batch 'logs/**/*.blf' --out results/ --filters ckf,fckf,svd-fckf --plot errors.png
  canest batch 'fleet/**/*.log' --out results/ --scheduler tcp://scheduler:8786

Each (log, filter) is one task. Results: OUT/<log>/<filter>/estimates.csv and
summary.json, and OUT/fleet_summary.csv. A truth file beside a log
(<log>.truth.csv or <log>_truth.csv) adds RMSE columns. Rerunning skips the
tasks whose results are complete; a corrupt log fails only its own task.
On a multi-node cluster the logs, the config, its DBCs and OUT must be on a
file system every worker sees (start workers with: dask worker tcp://HOST:8786)."""


def register(subparsers) -> None:
    p = subparsers.add_parser("batch", help="replay many logs on a Dask cluster and summarize the fleet",
                              description=__doc__, epilog=EPILOG, formatter_class=FORMATTER)
    p.add_argument("logs", nargs="+", help="glob pattern(s) of logs; quote them, '**' recurses")
    add_config(p)
    p.add_argument("--out", "-o", required=True, help="results folder")
    p.add_argument("--filters", default=None, help="comma-separated filters to sweep (default: the config's)")
    p.add_argument("--scheduler", help="address of a running Dask scheduler, e.g. tcp://host:8786")
    p.add_argument("--workers", type=int, help="worker processes of the local cluster (default: one per core)")
    p.add_argument("--retries", type=int, default=1,
                   help="retries of a task that raised (default 1); tasks of a lost worker are rerun anyway")
    p.add_argument("--plot", help="PNG of the RMSE distribution over the logs (needs truth files)")
    p.add_argument("--quiet", "-q", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def run(args) -> int:
    config = config_from_args(args)
    filters = parse_filters(args.filters) if args.filters else [config.estimator.filter]
    started = time.perf_counter()
    rows = run_batch(config, args.logs, Path(args.out), filters, args.scheduler, args.workers, args.retries,
                     progress=not args.quiet)
    elapsed = time.perf_counter() - started
    print(fleet_table(rows))
    ran = [r for r in rows if r["status"] == "ok"]
    hours = sum(r["duration_s"] for r in ran) / 3600.0
    print(f"{len(rows)} tasks in {elapsed:.1f} s: {60 * len(rows) / elapsed:.1f} tasks/min, "
          f"{60 * hours / elapsed:.3f} drive-hours/min; summary in {Path(args.out) / 'fleet_summary.csv'}")
    if args.plot:
        plot_errors(rows, args.plot)
        print(f"plot written to {args.plot}")
    failed = [r for r in rows if r["status"] != "ok"]
    return 1 if failed else 0
