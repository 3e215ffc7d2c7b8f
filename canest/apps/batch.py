"""Fleet replay on Dask: every (log, filter) pair an independent task.

The engine is ``dask.distributed``: a ``LocalCluster`` sized to the machine
by default, or any running cluster by its scheduler address, so the same
command scales from a laptop to many nodes (logs, configs and the output
folder on a file system every worker sees). canest adds only what a fleet
replay needs on top:

- results per task under ``OUT/<log path relative to the common root>/<filter>/``:
  ``estimates.csv`` and ``summary.json``, the latter written last and
  atomically, with the row count and size of the CSV and a fingerprint of the
  config, so a rerun skips exactly the tasks whose results are complete and
  valid and an interrupted batch resumes;
- a corrupt or unreadable log fails its own task only, with the reason;
  tasks of a lost worker are rerun by the scheduler, and a failing task is
  retried ``retries`` times;
- a progress bar over tasks, the dashboard address, and a fleet summary
  (``OUT/fleet_summary.csv`` and a table per filter; optionally a PNG of the
  error distribution over the logs).
"""
from __future__ import annotations

import dataclasses
import glob
import hashlib
import json
import logging
import math
import os
import time
from pathlib import Path

import numpy as np

from canest.errors import UsageError
from canest.settings import Config
from canest.estimation.estimate import VALID_BITS
from canest.apps.evaluate import read_table, score

SUMMARY = "summary.json"
ESTIMATES = "estimates.csv"
TRUTH_SUFFIXES = (".truth.csv", "_truth.csv")
STATES = ("vx", "yaw_rate", "beta")


def find_logs(patterns) -> list:
    """Every file matching the glob patterns (``**`` recurses), sorted, without duplicates."""
    paths = sorted({Path(p).resolve() for pattern in patterns for p in glob.glob(str(pattern), recursive=True)
                    if Path(p).is_file() and not p.endswith(TRUTH_SUFFIXES)})
    if not paths:
        raise UsageError(f"no log matches {' '.join(map(str, patterns))}")
    return paths


def truth_for(log: Path):
    stem = log.with_suffix("")
    return next((Path(f"{stem}{suffix}") for suffix in TRUTH_SUFFIXES if Path(f"{stem}{suffix}").is_file()), None)


def fingerprint(config: Config) -> str:
    """Changes whenever anything that shapes the estimates changes (config values and DBC contents)."""
    digest = hashlib.sha256(repr(dataclasses.astuple(config)).encode())
    for path in (config.input_dbc, config.output_dbc):
        digest.update(Path(path).read_bytes())
    return digest.hexdigest()[:16]


@dataclasses.dataclass(frozen=True)
class Task:
    log: Path
    filter: str
    out: Path  # folder of this task's results


def plan(logs, filters, out: Path) -> list:
    root = Path(os.path.commonpath([str(p.parent) for p in logs]))
    return [Task(log, name, out / log.relative_to(root).with_suffix("") / name) for log in logs for name in filters]


def complete(task: Task, config_fingerprint: str):
    """The task's summary if its results are complete and valid, else None."""
    try:
        summary = json.loads((task.out / SUMMARY).read_text())
        csv = task.out / ESTIMATES
        valid = (summary.get("config") == config_fingerprint and summary.get("status") == "ok"
                 and csv.stat().st_size == summary["csv_bytes"])
        return summary if valid else None
    except (OSError, ValueError, KeyError):
        return None


def _write_atomically(path: Path, text: str) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


def run_task(config: Config, task: Task, config_fingerprint: str) -> dict:
    """Replay one log with one filter (runs on a worker); returns its summary row."""
    from canest.apps.compare import with_filter
    from canest.apps.replay import replay

    started = time.perf_counter()
    task.out.mkdir(parents=True, exist_ok=True)
    csv = task.out / ESTIMATES
    partial = csv.with_name(csv.name + ".tmp")
    frames = replay(with_filter(config, task.filter), task.log, out_csv=partial, progress=False)
    os.replace(partial, csv)
    table = read_table(csv)
    valid = table["valid"].astype(int)
    all_states = sum(1 << VALID_BITS.index(s) for s in STATES)
    row = {
        "log": str(task.log), "filter": task.filter, "status": "ok", "config": config_fingerprint,
        "duration_s": float(table["t"][-1] - table["t"][0]) if table["t"].size else 0.0,
        "ticks": int(table["t"].size), "frames": int(frames.get("frames", 0)),
        "decoded": int(frames.get("decoded", 0)), "resets": int(frames.get("resets", 0)),
        "rejected": {k: int(v) for k, v in frames.items() if k.startswith("rejected_") and v},
        "valid_share": float(np.mean((valid & all_states) == all_states)) if valid.size else 0.0,
        "csv_bytes": csv.stat().st_size, "seconds": time.perf_counter() - started,
    }
    truth = truth_for(task.log)
    if truth is not None:
        row.update({f"rmse_{s.state}": s.rmse for s in score(table, read_table(truth), STATES, skip=0.5)})
    _write_atomically(task.out / SUMMARY, json.dumps(row, indent=1))
    return row


def failure_row(task: Task, error: BaseException) -> dict:
    return {"log": str(task.log), "filter": task.filter, "status": "failed",
            "error": f"{type(error).__name__}: {error}"}


def fleet_table(rows) -> str:
    """Per filter: logs done and failed, drive hours, mean share valid, median and p95 RMSE."""
    lines = [f"{'filter':<9} {'logs':>5} {'failed':>6} {'hours':>7} {'valid':>6} | "
             + " | ".join(f"{s} RMSE median / p95" for s in STATES)]
    for name in sorted({r["filter"] for r in rows}):
        mine = [r for r in rows if r["filter"] == name]
        ok = [r for r in mine if r["status"] == "ok"]
        hours = sum(r["duration_s"] for r in ok) / 3600.0
        valid = np.mean([r["valid_share"] for r in ok]) if ok else math.nan
        cells = []
        for state in STATES:
            values = np.array([r[f"rmse_{state}"] for r in ok if f"rmse_{state}" in r])
            cells.append(f"{np.median(values):.4f} / {np.percentile(values, 95):.4f}" if values.size else "-")
        lines.append(f"{name:<9} {len(ok):>5} {len(mine) - len(ok):>6} {hours:>7.3f} {valid:>6.1%} | "
                     + " | ".join(f"{c:>22}" for c in cells))
    return "\n".join(lines)


def write_fleet_summary(rows, path: Path) -> None:
    import csv

    columns = ["log", "filter", "status", "duration_s", "frames", "decoded", "resets", "valid_share",
               *[f"rmse_{s}" for s in STATES], "rejected", "error"]
    with open(path, "w", newline="") as handle:
        writer = csv.DictWriter(handle, columns, extrasaction="ignore")
        writer.writeheader()
        for row in rows:
            writer.writerow({**row, "rejected": json.dumps(row.get("rejected", {}))})


def plot_errors(rows, path) -> None:
    """Box plot of the RMSE of each state over the logs, one box per filter."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = sorted({r["filter"] for r in rows})
    fig, axes = plt.subplots(1, len(STATES), figsize=(4.5 * len(STATES), 4))
    for ax, state in zip(axes, STATES):
        data = [[r[f"rmse_{state}"] for r in rows if r["filter"] == n and f"rmse_{state}" in r] for n in names]
        ax.boxplot(data, tick_labels=names)
        ax.set_title(f"{state} RMSE over logs")
        ax.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def run_batch(config: Config, patterns, out: Path, filters, scheduler=None, workers=None, retries: int = 1,
              progress: bool = True, report=print) -> list:
    """Run every (log, filter) task not already complete; return one summary row per task."""
    from dask.distributed import Client, LocalCluster, as_completed
    from tqdm import tqdm

    out.mkdir(parents=True, exist_ok=True)
    tasks = plan(find_logs(patterns), filters, out)
    config_fingerprint = fingerprint(config)
    finished = {task: complete(task, config_fingerprint) for task in tasks}
    rows = [row for row in finished.values() if row is not None]
    todo = [task for task, row in finished.items() if row is None]
    report(f"{len(tasks)} tasks ({len(tasks) // len(filters)} logs x {len(filters)} filters): "
           f"{len(rows)} already complete, {len(todo)} to run")
    if todo:
        cluster = None if scheduler else LocalCluster(n_workers=workers or os.cpu_count(), threads_per_worker=1,
                                                      processes=True, dashboard_address=":0",
                                                      silence_logs=logging.CRITICAL)  # failures are reported below
        client = Client(scheduler or cluster)
        try:
            report(f"dask scheduler {client.scheduler.address}, dashboard {client.dashboard_link}")
            futures = {client.submit(run_task, config, task, config_fingerprint, retries=retries, pure=False): task
                       for task in todo}
            for future in tqdm(as_completed(futures), total=len(futures), unit="task", disable=not progress):
                task = futures[future]
                try:
                    rows.append(future.result())
                except Exception as exc:  # a corrupt log fails its own task: report it, keep going
                    rows.append(failure_row(task, exc))
                    report(f"failed: {task.log} ({task.filter}): {rows[-1]['error']}")
        finally:
            client.close()
            if cluster is not None:
                cluster.close()
    rows.sort(key=lambda r: (r["log"], r["filter"]))
    write_fleet_summary(rows, out / "fleet_summary.csv")
    return rows
