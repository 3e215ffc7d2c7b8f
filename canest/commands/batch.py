"""canest batch: re-estimate many logs on a Dask cluster (local by default)."""
from __future__ import annotations

import json
import math
import signal
import sys
import time
from contextlib import contextmanager
from pathlib import Path

from canest.apps.batch import CONNECT_TIMEOUT_S, Stop, run_batch
from canest.apps.batch_plan import FLEET_SUMMARY
from canest.apps.fleet_report import fleet_json, fleet_table, plot_errors, totals
from canest.commands.common import FORMATTER, add_config, add_log_reading, check_plot, config_from_args, log_reading
from canest.apps.compare import runnable
from canest.errors import DependencyError, OutputFileError, UsageError

EPILOG = """examples:
  canest batch 'logs/**/*.log' --config configs/dici_ev.yaml --out results/
  canest batch 'logs/**/*.blf' --out results/ --filters ckf,fckf,svd-fckf --plot errors.png
  canest batch 'fleet/**/*.log' --out results/ --scheduler tcp://scheduler:8786

Each (log, filter) is one task. Results: OUT/<log>/<filter>/estimates.csv and
summary.json, <log> being the log's path below the folder the patterns start
in, suffix kept (logs/day1/a.log -> OUT/day1/a.log/ckf/), and
OUT/fleet_summary.csv. A truth file beside a log adds RMSE columns: for a.log
the first of a.log.truth.csv, a.log_truth.csv, a.truth.csv, a_truth.csv.
Rerunning skips the tasks whose results are complete and whose config, DBCs,
log and truth file are unchanged; a corrupt log fails only its own task.
SIGINT or SIGTERM: no new tasks, the running ones finish (a second signal
cancels them), the fleet summary lists the rest as stopped; rerun to resume.
Exit status: 0 all tasks done (also after such a stop), 1 some task failed;
an error before any task ran (config, DBC, missing dask, unreachable
scheduler, ...) is one line with the status of its kind (canest --help).
--json prints {tasks: [one object per task: log, filter, status, result
(its folder), duration_s, ticks, frames, decoded, resets, valid_share,
vx_rmse_m_s, yaw_rate_rmse_deg_s, beta_rmse_deg (null without a truth file),
rejected, error], totals: {tasks, ok, failed, stopped, drive_hours, frames,
seconds, tasks_per_min, drive_hours_per_min}, summary_csv, plot, stopped_by}.
On a multi-node cluster the logs, the config, its DBCs and OUT must be on a
file system every worker sees (start workers with: dask worker tcp://HOST:8786)."""


def register(subparsers) -> None:
    p = subparsers.add_parser("batch", help="replay many logs on a Dask cluster and summarize the fleet",
                              description=__doc__, epilog=EPILOG, formatter_class=FORMATTER)
    p.add_argument("logs", nargs="+", help="glob pattern(s) of logs; quote them, '**' recurses")
    add_config(p)
    add_log_reading(p)
    p.add_argument("--out", "-o", required=True, help="results folder")
    p.add_argument("--filters", default=None,
                   help="comma-separated filters to sweep, or 'all' (every filter the config's inputs can run; "
                        "default: the config's)")
    p.add_argument("--scheduler", help="address of a running Dask scheduler, e.g. tcp://host:8786")
    p.add_argument("--connect-timeout", type=float, default=CONNECT_TIMEOUT_S, metavar="SECONDS",
                   help=f"give up on --scheduler after this long (default {CONNECT_TIMEOUT_S:g})")
    p.add_argument("--workers", type=int, help="worker processes of the local cluster (default: one per core)")
    p.add_argument("--retries", type=int, default=1,
                   help="retries of a task that raised (default 1); tasks of a lost worker are rerun anyway")
    p.add_argument("--plot", help="PNG of the RMSE distribution over the logs (needs truth files)")
    p.add_argument("--json", action="store_true", help="print the batch summary as one JSON object (keys below); "
                                                      "the other messages go to stderr")
    p.add_argument("--quiet", "-q", action="store_true", help="no progress bar (there is none when stderr is not "
                                                              "a terminal)")
    p.set_defaults(func=run)


@contextmanager
def stop_on_signals(stop: Stop):
    """SIGINT and SIGTERM request ``stop`` (instead of ending the process) while the block runs."""
    def handler(signum, _frame):
        stop.request(signal.Signals(signum).name)

    previous = {signum: signal.signal(signum, handler) for signum in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for signum, action in previous.items():
            signal.signal(signum, action)


def check_cluster_options(args) -> None:
    """--workers, --retries, --connect-timeout and --out, before anything runs (a negative worker count hung the
    local cluster; a nan timeout read as a connection failure; a file as --out failed every task)."""
    if args.workers is not None and args.workers < 1:
        raise UsageError(f"--workers: worker processes of the local cluster, at least 1, got {args.workers}")
    if args.retries < 0:
        raise UsageError(f"--retries: retries of a failed task, 0 or more, got {args.retries}")
    if not 0.0 < args.connect_timeout < math.inf:
        raise UsageError(f"--connect-timeout: seconds above 0, got {args.connect_timeout}")
    if Path(args.out).exists() and not Path(args.out).is_dir():
        raise OutputFileError(f"--out {args.out}: that is a file; name the results folder (created if missing)")


def run(args) -> int:
    DependencyError.require("dask.distributed", "canest batch", "pip install 'canest[fleet]'")
    if args.plot:  # before the batch, not after it
        check_plot(args.plot)
    check_cluster_options(args)
    config = config_from_args(args)
    filters = runnable(config, args.filters) if args.filters else [config.estimator.filter]
    say = print if not args.json else lambda *line: print(*line, file=sys.stderr)
    summary_csv = Path(args.out) / FLEET_SUMMARY
    started = time.perf_counter()
    stop = Stop()
    with stop_on_signals(stop):
        rows = run_batch(config, args.logs, Path(args.out), filters, args.scheduler, args.workers, args.retries,
                         progress=not args.quiet, report=say, stop=stop, connect_timeout=args.connect_timeout,
                         **log_reading(args))
    elapsed = time.perf_counter() - started
    total = totals(rows, elapsed)
    say(fleet_table(rows))
    say(f"{total['tasks']} tasks in {elapsed:.1f} s: {total['tasks_per_min']:.1f} tasks/min, "
        f"{total['drive_hours_per_min']:.3f} drive-hours/min; summary in {summary_csv}")
    if stop.requested:
        say(f"stopped by {stop.reason}: {total['stopped']} of {total['tasks']} tasks not done; "
            "run the same command again to resume")
    if args.plot:
        plot_errors(rows, args.plot)
        say(f"plot written to {args.plot}")
    if args.json:
        print(json.dumps({**fleet_json(rows, elapsed), "summary_csv": str(summary_csv), "plot": args.plot,
                          "stopped_by": stop.reason if stop.requested else None}))
    return 1 if total["failed"] else 0
