"""Fleet replay on Dask: every (log, filter) pair an independent task.

The engine is ``dask.distributed``: a ``LocalCluster`` sized to the machine
by default, or any running cluster by its scheduler address, so the same
command scales from a laptop to many nodes (logs, configs and the output
folder on a file system every worker sees). canest adds only what a fleet
replay needs on top:

- results per task under ``OUT/<log path relative to the input root>/<filter>/``,
  the input root being the folder the glob patterns start in (before their
  first wildcard) and the log's suffix kept, so ``day1/a.log`` and
  ``day1/a.blf`` are two results: ``estimates.csv`` and ``summary.json``;
- a task writes under temporary names and renames when it succeeds, the
  summary last, so a result folder holds a complete result or none; the
  summary records the size of the CSV and the fingerprints of the config
  (values and DBCs) and of the inputs (log and truth file: size,
  modification time, hash of the first and last 64 KiB), so a rerun skips
  exactly the tasks whose results are complete and current and redoes the
  rest (an interrupted batch resumes; a replaced log is estimated again);
- a corrupt or unreadable log fails its own task only, with the reason, and
  leaves nothing behind; tasks of a lost worker are rerun by the scheduler,
  and a failing task is retried ``retries`` times;
- tasks are submitted as workers free up, so a :class:`Stop` request ends
  the batch in order: no new task, the running ones finish (or, at a second
  request, are cancelled), and the fleet summary lists every task, those not
  run as ``stopped``;
- a progress bar over tasks, the dashboard address, and a fleet summary
  (``OUT/fleet_summary.csv`` and a table per filter; optionally a PNG of the
  error distribution over the logs).
"""
from __future__ import annotations

import contextlib
import dataclasses
import glob
import hashlib
import itertools
import json
import logging
import math
import os
import signal
import threading
import time
import uuid
from pathlib import Path

import numpy as np

from canest.errors import ClusterError, UsageError
from canest.settings import Config
from canest.estimation.estimate import VALID_BITS
from canest.apps.evaluate import read_table, score

SUMMARY = "summary.json"
ESTIMATES = "estimates.csv"
FLEET_SUMMARY = "fleet_summary.csv"
TRUTH_SUFFIXES = (".truth.csv", "_truth.csv")
STATES = ("vx", "yaw_rate", "beta")
SAMPLE_BYTES = 64 * 1024  # hashed at the head and at the tail of every input file
CONNECT_TIMEOUT_S = 10.0  # to reach a --scheduler
POLL_S = 0.25  # how often the submission loop looks at a stop request while tasks run
WILDCARDS = "*?["


class Stop:
    """A request to end a batch early: the first stops submitting, the second also cancels the running tasks.

    :meth:`request` only counts and remembers the reason, so a signal handler may call it.
    """

    def __init__(self):
        self.requests = 0
        self.reason = ""

    def request(self, reason: str) -> None:
        self.requests += 1
        self.reason = reason

    @property
    def requested(self) -> bool:
        return self.requests >= 1

    @property
    def cancelling(self) -> bool:
        return self.requests >= 2


def input_root(patterns) -> Path:
    """The folder all patterns start in: their common fixed part before the first wildcard (a file's folder)."""
    folders = []
    for pattern in patterns:
        parts = Path(pattern).parts
        fixed = list(itertools.takewhile(lambda part: not any(c in part for c in WILDCARDS), parts))
        if len(fixed) == len(parts):  # no wildcard: a file
            fixed = fixed[:-1]
        folders.append(os.path.abspath(Path(*fixed)))
    return Path(os.path.commonpath(folders))


def _batch_output(path: str, results: str) -> bool:
    """Whether a file is one the batch writes under its results folder (which may hold the logs too)."""
    name = os.path.basename(path)
    return (name in (ESTIMATES, SUMMARY, FLEET_SUMMARY) or name.endswith(".tmp")) and \
        os.path.commonpath([path, results]) == results


def find_logs(patterns, results: Path) -> list:
    """Every file matching the glob patterns (``**`` recurses), sorted, without duplicates.

    Truth files and the files the batch writes under ``results`` are left out.
    """
    results = os.path.abspath(results)
    paths = sorted({Path(os.path.abspath(p)) for pattern in patterns for p in glob.glob(str(pattern), recursive=True)
                    if os.path.isfile(p) and not p.endswith(TRUTH_SUFFIXES)
                    and not _batch_output(os.path.abspath(p), results)})
    if not paths:
        raise UsageError(f"no log matches {' '.join(map(str, patterns))}")
    return paths


def truth_for(log: Path):
    """The truth CSV beside a log, first found of: ``a.log.truth.csv``, ``a.log_truth.csv``, ``a.truth.csv``,
    ``a_truth.csv`` (for ``a.log``); None if there is none."""
    for base in dict.fromkeys((str(log), str(log.with_suffix("")))):
        for suffix in TRUTH_SUFFIXES:
            if os.path.isfile(base + suffix):
                return Path(base + suffix)
    return None


def fingerprint(config: Config) -> str:
    """Changes whenever anything that shapes the estimates changes (config values and DBC contents)."""
    digest = hashlib.sha256(repr(dataclasses.astuple(config)).encode())
    for path in (config.input_dbc, config.output_dbc):
        digest.update(Path(path).read_bytes())
    return digest.hexdigest()[:16]


def file_fingerprint(path: Path) -> dict:
    """Path, size, modification time and a hash of the first and last 64 KiB: changes when the file is replaced."""
    stat = os.stat(path)
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        digest.update(handle.read(SAMPLE_BYTES))
        if stat.st_size > SAMPLE_BYTES:
            handle.seek(max(SAMPLE_BYTES, stat.st_size - SAMPLE_BYTES))
            digest.update(handle.read(SAMPLE_BYTES))
    return {"path": str(path), "bytes": stat.st_size, "mtime_ns": stat.st_mtime_ns,
            "sha256_head_tail": digest.hexdigest()[:16]}


@dataclasses.dataclass(frozen=True)
class Task:
    log: Path
    filter: str
    out: Path  # folder of this task's results
    log_format: str | None = None  # --format, --log-channel: how the log is read (see canest.apps.replay.replay)
    log_channel: str | None = None

    def reading(self) -> dict:
        """The replay's keywords for reading the log, those given."""
        given = {"log_format": self.log_format, "log_channel": self.log_channel}
        return {key: value for key, value in given.items() if value is not None}

    def inputs(self) -> dict:
        """Fingerprints of the log and of its truth file (None without one), and how the log is read if said."""
        truth = truth_for(self.log)
        reading = {"reading": self.reading()} if self.reading() else {}
        return {"log": file_fingerprint(self.log), "truth": file_fingerprint(truth) if truth else None, **reading}


def plan(logs, filters, root: Path, out: Path, **reading) -> list:
    """One task per log and filter; results under OUT/<log relative to root, suffix kept>/<filter>.
    ``reading``: how every log is read (``log_format``, ``log_channel``)."""
    tasks = [Task(log, name, out / log.relative_to(root) / name, **reading) for log in logs for name in filters]
    clash = next((task for task in tasks if task.out.parent.is_file()), None)
    if clash is not None:  # OUT is the logs' own folder: OUT/a.log/ckf would be inside the log a.log
        raise UsageError(f"--out {out}: the results of {clash.log} would go into {clash.out.parent}, which is a "
                         f"file; give the results a folder of their own, e.g. --out {out / 'results'}")
    return tasks


def complete(task: Task, config_fingerprint: str):
    """The task's summary if its results are complete and of the current config and inputs, else None."""
    try:
        summary = json.loads((task.out / SUMMARY).read_text())
        valid = (summary.get("status") == "ok" and summary.get("config") == config_fingerprint
                 and summary.get("inputs") == task.inputs()
                 and (task.out / ESTIMATES).stat().st_size == summary["csv_bytes"])
        return summary if valid else None
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return None


@contextlib.contextmanager
def replacing(path: Path):
    """A new temporary path beside ``path`` that replaces it when the block succeeds and is removed if it fails."""
    temporary = path.with_name(f"{path.name}.{uuid.uuid4().hex[:12]}.tmp")
    try:
        yield temporary
        os.replace(temporary, path)
    finally:
        temporary.unlink(missing_ok=True)


def run_task(config: Config, task: Task, config_fingerprint: str) -> dict:
    """Replay one log with one filter (runs on a worker); returns its summary row."""
    from canest.apps.compare import with_filter
    from canest.apps.replay import replay

    started = time.perf_counter()
    inputs = task.inputs()
    task.out.mkdir(parents=True, exist_ok=True)
    for stale in (SUMMARY, ESTIMATES):  # a folder holds a complete result or none
        (task.out / stale).unlink(missing_ok=True)
    with replacing(task.out / ESTIMATES) as partial:
        frames = replay(with_filter(config, task.filter), task.log, out_csv=partial, progress=False,
                        **task.reading())
        table = read_table(partial)
        valid = table["valid"].astype(int)
        all_states = sum(1 << VALID_BITS.index(s) for s in STATES)
        row = {
            "log": str(task.log), "filter": task.filter, "status": "ok", "config": config_fingerprint,
            "inputs": inputs,
            "duration_s": float(table["t"][-1] - table["t"][0]) if table["t"].size else 0.0,
            "ticks": int(table["t"].size), "frames": int(frames.get("frames", 0)),
            "decoded": int(frames.get("decoded", 0)), "resets": int(frames.get("resets", 0)),
            "rejected": {k: int(v) for k, v in frames.items() if k.startswith("rejected_") and v},
            "valid_share": float(np.mean((valid & all_states) == all_states)) if valid.size else 0.0,
            "csv_bytes": partial.stat().st_size, "seconds": time.perf_counter() - started,
        }
        if inputs["truth"] is not None:
            truth = read_table(inputs["truth"]["path"])
            row.update({f"rmse_{s.state}": s.rmse for s in score(table, truth, STATES, skip=0.5)})
    with replacing(task.out / SUMMARY) as partial:
        partial.write_text(json.dumps(row, indent=1))
    return row


def failure_row(task: Task, error: BaseException) -> dict:
    return {"log": str(task.log), "filter": task.filter, "status": "failed",
            "error": f"{type(error).__name__}: {error}"}


def stopped_row(task: Task, note: str) -> dict:
    return {"log": str(task.log), "filter": task.filter, "status": "stopped", "error": note}


def fleet_table(rows) -> str:
    """Per filter: logs done, failed and stopped, drive hours, mean share valid, median and p95 RMSE."""
    lines = [f"{'filter':<9} {'logs':>5} {'failed':>6} {'stopped':>7} {'hours':>7} {'valid':>6} | "
             + " | ".join(f"{s} RMSE median / p95" for s in STATES)]
    for name in sorted({r["filter"] for r in rows}):
        mine = [r for r in rows if r["filter"] == name]
        ok = [r for r in mine if r["status"] == "ok"]
        failed = sum(r["status"] == "failed" for r in mine)
        hours = sum(r["duration_s"] for r in ok) / 3600.0
        valid = np.mean([r["valid_share"] for r in ok]) if ok else math.nan
        cells = []
        for state in STATES:
            values = np.array([r[f"rmse_{state}"] for r in ok if f"rmse_{state}" in r])
            cells.append(f"{np.median(values):.4f} / {np.percentile(values, 95):.4f}" if values.size else "-")
        lines.append(f"{name:<9} {len(ok):>5} {failed:>6} {len(mine) - len(ok) - failed:>7} {hours:>7.3f} "
                     f"{valid:>6.1%} | " + " | ".join(f"{c:>22}" for c in cells))
    return "\n".join(lines)


def write_fleet_summary(rows, path: Path) -> None:
    import csv

    columns = ["log", "filter", "status", "duration_s", "frames", "decoded", "resets", "valid_share",
               *[f"rmse_{s}" for s in STATES], "rejected", "error"]
    with replacing(path) as partial, open(partial, "w", newline="") as handle:
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


@contextlib.contextmanager
def sigint_ignored():
    """SIGINT ignored while the block runs, so that worker processes started in it inherit that.

    A Ctrl-C in a terminal reaches every process of the group; it is meant for the batch (which stops in
    order, see :class:`Stop`), not for its workers, which would die mid-task. The price: a Ctrl-C while the
    local cluster starts (a second or two) is not seen; SIGTERM is.
    """
    if threading.current_thread() is not threading.main_thread():  # only the main thread may set handlers
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def _reason(error: BaseException) -> str:
    """An exception and its direct cause on one line (Dask's connect error names the address, its cause why)."""
    parts = [str(error) or type(error).__name__]
    if error.__cause__ is not None and str(error.__cause__):
        parts.append(str(error.__cause__).split(">: ")[-1])  # without the repr of Dask's connector object
    return ": ".join(parts).replace("\n", " ")


@contextlib.contextmanager
def connected(scheduler, workers, timeout: float):
    """A Dask client of the running scheduler at ``scheduler``, or of a new local cluster of ``workers`` processes.

    Yields (client, local): ``local`` is True when the cluster is this process's own.
    """
    from dask.distributed import Client, LocalCluster

    cluster = None
    if scheduler:
        try:
            client = Client(scheduler, timeout=timeout)
        except Exception as exc:  # refused, timed out, a malformed address, or something else answering
            raise ClusterError(f"--scheduler {scheduler}: cannot connect to a Dask scheduler ({_reason(exc)}); "
                               "check the address, start one with `dask scheduler`, or wait longer with "
                               f"--connect-timeout (now {timeout:g} s)") from None
    else:
        with sigint_ignored():
            cluster = LocalCluster(n_workers=workers or os.cpu_count(), threads_per_worker=1, processes=True,
                                   dashboard_address=":0", silence_logs=logging.CRITICAL)  # failures are rows
        client = Client(cluster)
    try:
        yield client, cluster is not None
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def _outcome(future, task: Task, report) -> dict:
    try:
        return future.result()
    except Exception as exc:  # a corrupt log fails its own task: report it, keep going
        row = failure_row(task, exc)
        report(f"failed: {task.log} ({task.filter}): {row['error']}")
        return row


def run_tasks(client, todo, submit, stop: Stop, progress: bool, report):
    """Run the tasks; returns (a row per task done or failed, [(task, why) for each task stopped]).

    ``submit(task)`` returns a future. After a stop request the tasks no worker has started are withdrawn
    and the running ones finish; after a second request the running ones are cancelled too.
    """
    from dask.distributed import as_completed
    from tqdm import tqdm

    pending = {submit(task): task for task in todo}
    finished = as_completed(pending)
    rows, stopped = [], []
    withdrawn = False
    with tqdm(total=len(todo), unit="task", disable=not progress) as bar:
        while pending:
            if stop.cancelling:
                client.cancel(list(pending))
                stopped += [(task, f"cancelled ({stop.reason})") for task in pending.values()]
                break
            if stop.requested and not withdrawn:
                withdrawn = True
                started = {key for keys in client.processing().values() for key in keys}
                queued = [future for future in pending if future.key not in started]
                client.cancel(queued)
                stopped += [(pending.pop(future), f"not started ({stop.reason})") for future in queued]
                report(f"{stop.reason}: {len(queued)} tasks withdrawn; waiting for the {len(pending)} running "
                       "to finish (signal again to cancel them)")
            done = [future for future in finished.next_batch(block=False) if future in pending]
            if not done:
                time.sleep(POLL_S)
            for future in done:
                rows.append(_outcome(future, pending.pop(future), report))
                bar.update()
    return rows, stopped


def discard_partial(tasks) -> None:
    """Remove the temporary files of tasks whose workers were stopped mid-write."""
    for task in tasks:
        for partial in task.out.glob("*.tmp"):
            partial.unlink(missing_ok=True)


def run_batch(config: Config, patterns, out: Path, filters, scheduler=None, workers=None, retries: int = 1,
              progress: bool = True, report=print, stop: Stop = None,
              connect_timeout: float = CONNECT_TIMEOUT_S, **reading) -> list:
    """Run every (log, filter) task not already complete; return one summary row per task.

    ``reading``: how every log is read (``log_format``, ``log_channel``: see :func:`canest.apps.replay.replay`).

    ``stop`` (a :class:`Stop`) ends the batch early and in order; the fleet summary is written in any case.
    """
    stop = stop or Stop()
    out = Path(out)
    tasks = plan(find_logs(patterns, out), filters, input_root(patterns), out, **reading)
    config_fingerprint = fingerprint(config)
    finished = {task: complete(task, config_fingerprint) for task in tasks}
    rows = [row for row in finished.values() if row is not None]
    todo = [task for task, row in finished.items() if row is None]
    report(f"{len(tasks)} tasks ({len(tasks) // len(filters)} logs x {len(filters)} filters): "
           f"{len(rows)} already complete, {len(todo)} to run")
    if todo and stop.requested:
        rows += [stopped_row(task, f"not started ({stop.reason})") for task in todo]
    elif todo:
        with connected(scheduler, workers, connect_timeout) as (client, local):
            report(f"dask scheduler {client.scheduler.address}, dashboard {client.dashboard_link}")
            ran, stopped = run_tasks(
                client, todo, lambda task: client.submit(run_task, config, task, config_fingerprint, retries=retries,
                                                         pure=False), stop, progress, report)
        if local:  # its workers are gone: what they were writing can go too
            discard_partial(task for task, _ in stopped)
        # a task withdrawn or cancelled as it finished may have completed after all
        rows += ran + [complete(task, config_fingerprint) or stopped_row(task, why) for task, why in stopped]
    rows.sort(key=lambda r: (r["log"], r["filter"]))
    out.mkdir(parents=True, exist_ok=True)
    write_fleet_summary(rows, out / FLEET_SUMMARY)
    return rows
