"""What a fleet replay has to do: the logs, their truth files, one task per (log, filter), and which are done.

A task's results live under ``OUT/<log path relative to the input root>/<filter>/``
(the input root being the folder the glob patterns start in, before their first
wildcard; the log's suffix kept, so ``day1/a.log`` and ``day1/a.blf`` are two
results). A result is complete and current when its summary records the
fingerprints of the config (values and DBCs, and the canest code that
computed it: a result of another build is redone) and of the inputs (log and truth
file: size, modification time, hash of the first and last 64 KiB) that a rerun
computes again, and the CSV has the size the summary says: :func:`complete`.
"""
from __future__ import annotations

import contextlib
import dataclasses
import glob
import hashlib
import itertools
import json
import os
import uuid
from pathlib import Path

from canest.errors import UsageError
from canest.settings import Config

SUMMARY = "summary.json"
ESTIMATES = "estimates.csv"
FLEET_SUMMARY = "fleet_summary.csv"
TRUTH_SUFFIXES = (".truth.csv", "_truth.csv")
SAMPLE_BYTES = 64 * 1024  # hashed at the head and at the tail of every input file
WILDCARDS = "*?["
CODE = Path(__file__).resolve().parents[1]  # the canest package
CODE_SUFFIXES = (".py", ".dbc", ".yaml")


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


def fingerprint(config: Config, code: Path = CODE) -> str:
    """Changes whenever anything that shapes the estimates changes: config values, DBC contents and the code of
    canest (every file of the package below ``code``: a result of an older estimator, or with other columns, is
    redone)."""
    digest = hashlib.sha256(repr(dataclasses.astuple(config)).encode())
    for path in (config.input_dbc, config.output_dbc):
        digest.update(Path(path).read_bytes())
    for path in sorted(code.rglob("*")):
        if path.is_file() and path.suffix in CODE_SUFFIXES:
            digest.update(str(path.relative_to(code)).encode() + b"\0" + path.read_bytes())
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
