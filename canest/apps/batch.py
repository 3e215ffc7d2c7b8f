"""Fleet replay on Dask: every (log, filter) pair an independent task.

The engine is ``dask.distributed``: a ``LocalCluster`` sized to the machine
by default, or any running cluster by its scheduler address, so the same
command scales from a laptop to many nodes (logs, configs and the output
folder on a file system every worker sees). canest adds only what a fleet
replay needs on top:

- results per task in a folder of their own, redone only when stale
  (:mod:`canest.apps.batch_plan`); a task writes under temporary names and
  renames when it succeeds, the summary last, so a result folder holds a
  complete result or none;
- a corrupt or unreadable log fails its own task only, with the reason, and
  leaves nothing behind; tasks of a lost worker are rerun by the scheduler,
  and a failing task is retried ``retries`` times;
- tasks are submitted as workers free up, so a :class:`Stop` request ends
  the batch in order: no new task, the running ones finish (or, at a second
  request, are cancelled), and the fleet summary lists every task, those not
  run as ``stopped``;
- a progress bar over tasks, the dashboard address, and a fleet summary
  (:mod:`canest.apps.fleet_report`).
"""
from __future__ import annotations

import contextlib
import json
import logging
import os
import signal
import threading
import time
from pathlib import Path

import numpy as np

from canest.apps.batch_plan import (ESTIMATES, FLEET_SUMMARY, SUMMARY, Task, complete, find_logs, fingerprint,
                                    input_root, plan, replacing)
from canest.apps.evaluate import read_table, score
from canest.apps.fleet_report import STATES, rmse_key, write_fleet_summary
from canest.apps.progress import terminal_bar
from canest.errors import ClusterError
from canest.estimation.estimate import VALID_BITS
from canest.settings import Config

CONNECT_TIMEOUT_S = 10.0  # to reach a --scheduler
POLL_S = 0.25  # how often the submission loop looks at a stop request while tasks run


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
            row.update({rmse_key(s.state): s.rmse for s in score(table, truth, STATES, skip=0.5)})
    with replacing(task.out / SUMMARY) as partial:
        partial.write_text(json.dumps(row, indent=1))
    return row


def failure_row(task: Task, error: BaseException) -> dict:
    return {"log": str(task.log), "filter": task.filter, "status": "failed",
            "error": f"{type(error).__name__}: {error}"}


def stopped_row(task: Task, note: str) -> dict:
    return {"log": str(task.log), "filter": task.filter, "status": "stopped", "error": note}


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

    pending = {submit(task): task for task in todo}
    finished = as_completed(pending)
    rows, stopped = [], []
    withdrawn = False
    with terminal_bar(progress, total=len(todo), unit="task") as bar:
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
    folders = {(str(task.log), task.filter): str(task.out) for task in tasks}
    for row in rows:  # where it is now, also for a result written by an earlier run
        row["result"] = folders[row["log"], row["filter"]]
    rows.sort(key=lambda r: (r["log"], r["filter"]))
    out.mkdir(parents=True, exist_ok=True)
    write_fleet_summary(rows, out / FLEET_SUMMARY)
    return rows
