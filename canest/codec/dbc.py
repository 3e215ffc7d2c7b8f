"""The one place DBC files are read: each database is parsed once and shared.

The config loader, the input decoder, the estimate encoder and the monitor
all ask :func:`load_database`; a file is parsed again only when it changed on
disk (its size or modification time), so a SIGHUP reload sees an edited DBC.

A messy DBC still loads: when cantools refuses it strictly (overlapping
signals, a signal that does not fit its message), it is loaded leniently and
each message is checked on its own; :func:`tolerated_problems` names the broken
ones. Whoever uses a message must refuse it if it is broken (the signal map,
the estimate encoder); the others are only reported.
"""
from __future__ import annotations

import math
import os
from pathlib import Path

from canest.errors import DbcError

_CACHE: dict = {}  # resolved path -> ((size, mtime_ns), database, {message name: problem})


def load_database(path, owner: str):
    """The cantools database of ``path``; a :class:`DbcError` naming the file and ``owner`` if it cannot load."""
    import cantools

    path = Path(path).resolve()
    try:
        stat = os.stat(path)
    except OSError as exc:
        raise DbcError(f"{path}: cannot read DBC (referenced by {owner}): {exc.strerror}") from None
    stamp = (stat.st_size, stat.st_mtime_ns)
    cached = _CACHE.get(path)
    if cached is not None and cached[0] == stamp:
        return cached[1]
    problems = {}
    try:
        database = cantools.database.load_file(str(path), strict=True)
    except Exception as strict_error:  # cantools raises several parser exception types
        try:
            database = cantools.database.load_file(str(path), strict=False)
        except Exception as exc:
            raise DbcError(f"{path}: cannot load DBC (referenced by {owner}): {exc}") from None
        problems = _message_problems(database) or {"": str(strict_error)}
    _CACHE[path] = (stamp, database, problems)
    return database


def _message_problems(database) -> dict:
    """{message name: what cantools' strict check says of it} for every message it refuses."""
    problems = {}
    for message in database.messages:
        try:
            message.refresh(strict=True)
        except Exception as exc:  # cantools.database.Error, or a signal length it cannot lay out
            problems[message.name] = str(exc)
            message.refresh(strict=False)
    return problems


def tolerated_problems(path, owner: str) -> dict:
    """{message name: problem} of the messages of ``path`` a strict load refuses ('' for the whole file)."""
    load_database(path, owner)
    return dict(_CACHE[Path(path).resolve()][2])


def clamp_to_signal(signal, value: float) -> float:
    """Limit a physical value to the signal's DBC range."""
    low = signal.minimum if signal.minimum is not None else -math.inf
    high = signal.maximum if signal.maximum is not None else math.inf
    return min(max(value, low), high)
