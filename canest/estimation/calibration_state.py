"""The online calibration's state file: saved atomically, reloaded with its variances widened, never trusted blindly.

JSON, one object per learned parameter (value, variance, evidence seconds,
applied value) under ``parameters``, with a ``version``. :meth:`CalibrationStore.save`
writes a temporary file in the same directory, flushes it to disk and renames it
over the old one, so a crash or power loss leaves the old state or the new one,
never half of either. :meth:`CalibrationStore.load` multiplies every variance by
``RELOAD_INFLATION`` (the car may have changed while off: tires, load, a
steering alignment); a file that cannot be read, is not the format, or holds a
value outside its parameter's bounds is ignored with one warning naming the
file, and learning starts afresh. A file that is no calibration state at all
(not JSON, or no ``version`` of this format: a config or a log named by
mistake) is never written over: the first save moves it aside to
``NAME.unreadable`` (``.unreadable.1``, ... if taken) and says so. A parameter
the file does not hold (one a newer canest learns than the one that wrote it)
starts from its prior, the others are restored, and one line says which. A save
the disk refuses is warned about and counted, never raised: the daemon estimates on.
"""
from __future__ import annotations

import json
import logging
import math
import os
import tempfile
from pathlib import Path

log = logging.getLogger("canest.calibration")

VERSION = 1
RELOAD_INFLATION = 1.5
SAVE_INTERVAL = 60.0  # s of driving between saves
FIELDS = ("value", "variance", "evidence", "applied")


class CalibrationStore:
    def __init__(self, path, interval: float = SAVE_INTERVAL):
        self.path = Path(path)
        self.interval = interval
        self.foreign = False  # the file at ``path`` is no calibration state (:meth:`load`): moved aside before a save
        self.failed_saves = 0
        self.failure = None  # why the last save failed, until one succeeds

    def save(self, parameters: dict) -> bool:
        """Write ``parameters`` (name -> FIELDS) atomically: temporary file, fsync, rename; a file that is no
        calibration state moved aside first (module docstring). A save the disk refuses (full, read-only, a folder
        gone) is warned about, counted in :attr:`failed_saves` and False: the estimation goes on, what was learned
        stays in memory for the next save (every ``SAVE_INTERVAL`` s and at shutdown). It ended the daemon (exit 74)
        mid-drive until now, and a full disk under systemd meant a restart a minute."""
        try:
            self._write(json.dumps({"version": VERSION, "parameters": parameters}, indent=1, sort_keys=True))
        except OSError as exc:
            reason = exc.strerror or str(exc)
            if reason != self.failure:  # None while saves succeed: the first failure is said too
                log.warning("cannot save the calibration state to %s: %s; estimating on, the learned values kept "
                            "in memory for the next save", self.path, reason)
            self.failed_saves += 1
            self.failure = reason
            return False
        if self.failure is not None:
            log.info("saved the calibration state to %s again", self.path)
            self.failure = None
        return True

    def _write(self, text: str) -> None:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        if self.foreign and self.path.exists():
            self._move_aside()
        self.foreign = False
        handle, temporary = tempfile.mkstemp(prefix=f".{self.path.name}.", suffix=".tmp", dir=self.path.parent)
        try:
            with os.fdopen(handle, "w") as stream:
                stream.write(text)
                stream.flush()
                os.fsync(stream.fileno())
            os.replace(temporary, self.path)
        except BaseException:
            Path(temporary).unlink(missing_ok=True)
            raise

    def _move_aside(self) -> None:
        kept = self.path.with_name(f"{self.path.name}.unreadable")
        number = 0
        while kept.exists():
            number += 1
            kept = self.path.with_name(f"{self.path.name}.unreadable.{number}")
        os.replace(self.path, kept)
        log.warning("%s was no calibration state; kept it as %s and saved the calibration in its place", self.path,
                    kept)

    def _ignored(self, reason) -> None:
        log.warning("ignoring the calibration state file %s: %s; learning from scratch", self.path, reason)

    def load(self, specs) -> dict | None:
        """The saved parameters with variances times ``RELOAD_INFLATION``, or None (no file; or unusable: warned)."""
        if not self.path.exists():
            return None
        try:
            document = json.loads(self.path.read_text())
        except (OSError, UnicodeDecodeError, ValueError) as exc:  # a JSONDecodeError is a ValueError
            self.foreign = True
            return self._ignored(exc)
        self.foreign = not (isinstance(document, dict) and document.get("version") == VERSION)
        try:
            parameters = _checked(document, specs)
        except ValueError as exc:
            return self._ignored(exc)
        missing = [spec.name for spec in specs if spec.name not in parameters]
        if missing:
            log.info("%s holds no %s (written by an older canest): learning them from their prior", self.path,
                     ", ".join(missing))
        for entry in parameters.values():
            entry["variance"] *= RELOAD_INFLATION
        log.info("restored the calibration state from %s (%s), variances widened %gx", self.path,
                 ", ".join(parameters), RELOAD_INFLATION)
        return parameters


def _checked(document, specs) -> dict:
    """The parameters of a state document that ``specs`` names, each finite and within its bounds, at least one;
    else ValueError. One the document lacks is left out."""
    if not isinstance(document, dict) or document.get("version") != VERSION:
        raise ValueError(f"not a version {VERSION} calibration state")
    saved = document.get("parameters")
    if not isinstance(saved, dict):
        raise ValueError("no 'parameters' object")
    parameters = {}
    for spec in specs:
        entry = saved.get(spec.name)
        if entry is None:
            continue
        if not isinstance(entry, dict) or not all(_finite_number(entry.get(f)) for f in FIELDS):
            raise ValueError(f"parameter '{spec.name}' lacks a finite {', '.join(FIELDS)}")
        for f in ("value", "applied"):
            if not spec.low <= entry[f] <= spec.high:
                raise ValueError(f"{spec.name} {f} {entry[f]:g} is outside its bounds [{spec.low:g}, {spec.high:g}]")
        if entry["variance"] <= 0.0 or entry["evidence"] < 0.0:
            raise ValueError(f"{spec.name}: variance must be above 0 and evidence at least 0")
        parameters[spec.name] = {f: float(entry[f]) for f in FIELDS}
    if not parameters:
        raise ValueError("no parameter canest learns")
    return parameters


def _finite_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
