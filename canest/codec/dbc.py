"""The one place DBC files are read: each database is parsed once and shared.

The config loader, the input decoder, the estimate encoder and the monitor
all ask :func:`load_database`; a file is parsed again only when it changed on
disk (its size or modification time), so a SIGHUP reload sees an edited DBC.
"""
from __future__ import annotations

import math
import os
from pathlib import Path

from canest.errors import DbcError

_CACHE: dict = {}  # resolved path -> ((size, mtime_ns), database)


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
    try:
        database = cantools.database.load_file(str(path), strict=True)
    except Exception as exc:  # cantools raises several parser exception types
        raise DbcError(f"{path}: cannot load DBC (referenced by {owner}): {exc}") from None
    _CACHE[path] = (stamp, database)
    return database


def clamp_to_signal(signal, value: float) -> float:
    """Limit a physical value to the signal's DBC range."""
    low = signal.minimum if signal.minimum is not None else -math.inf
    high = signal.maximum if signal.maximum is not None else math.inf
    return min(max(value, low), high)
