"""The one place DBC files are read: each database is parsed once and shared.

The config loader, the input decoder, the estimate encoder and the monitor
all ask :func:`load_database`; a file is parsed again only when it changed on
disk (its size or modification time), so a SIGHUP reload sees an edited DBC.

A messy DBC still loads: when cantools refuses it strictly (overlapping
signals, a signal that does not fit its message), it is loaded leniently and
each message is checked on its own; :func:`tolerated_problems` names the broken
ones. Whoever uses a message must refuse it if it is broken (the signal map,
the estimate encoder); the others are only reported. A ``.dbc`` file cantools
cannot parse at all is parsed again after the text repairs of
:mod:`canest.codec.dbc_repair`, each logged as a warning naming its line.
"""
from __future__ import annotations

import logging
import math
import os
from pathlib import Path

from canest.codec.dbc_repair import repair_lines, unused_value_tables
from canest.errors import DbcError

LOG = logging.getLogger("canest.dbc")
DBC_ENCODING = "cp1252"  # cantools' default for a .dbc file
CANTOOLS_FORMATS = ("arxml", "dbc", "kcd", "sym", "cdd")  # what cantools reads, by the file's suffix

_CACHE: dict = {}  # resolved path -> ((size, mtime_ns), database, {message name: problem})


def load_database(path, owner: str):
    """The cantools database of ``path``; a :class:`DbcError` naming the file and ``owner`` if it cannot load."""
    path = Path(path).resolve()
    try:
        stat = os.stat(path)
    except OSError as exc:
        raise DbcError(f"{path}: cannot read DBC (referenced by {owner}): {exc.strerror}") from None
    stamp = (stat.st_size, stat.st_mtime_ns)
    cached = _CACHE.get(path)
    if cached is not None and cached[0] == stamp:
        return cached[1]
    database, problems = _parse(path, owner)
    _CACHE[path] = (stamp, database, problems)
    return database


def _parse(path: Path, owner: str):
    """(database, {message name: problem}): strict, else lenient, else (a DBC) after the text repairs. A file whose
    suffix names no format cantools reads (none, ``.txt``) is read as a DBC, as ``canest init`` reads it."""
    import cantools

    known = path.suffix.lower().removeprefix(".") in CANTOOLS_FORMATS
    database_format = None if known else "dbc"
    try:
        return cantools.database.load_file(str(path), database_format, strict=True), {}
    except Exception as strict_error:  # cantools raises several parser exception types
        try:
            database = cantools.database.load_file(str(path), database_format, strict=False)
        except Exception as exc:
            if known and path.suffix.lower() != ".dbc":
                raise DbcError(f"{path}: cannot load DBC (referenced by {owner}): {exc}") from None
            try:
                text = path.read_text(encoding=DBC_ENCODING)
            except UnicodeDecodeError as undecodable:  # a binary file (a log named by mistake)
                raise DbcError(f"{path}: cannot load DBC (referenced by {owner}): not DBC text (byte "
                               f"{undecodable.start} is no {DBC_ENCODING} character)") from None
            database, repairs = parse_dbc_text(text, str(path), f" (referenced by {owner})")
            return database, _repaired_problems(database, repairs)
        return database, _message_problems(database) or {"": str(strict_error)}


def parse_dbc_text(text: str, label: str, context: str = ""):
    """(database, repairs) of the DBC ``text``, read leniently; if cantools refuses it, after
    :mod:`canest.codec.dbc_repair`'s repairs, each logged as a warning naming ``label`` and its line.

    A text no repair makes loadable is a one-line :class:`DbcError` ``LABEL: cannot load DBC CONTEXT: why``.
    """
    import cantools

    lines, repairs = None, []
    while True:
        try:
            database = cantools.database.load_string(text if lines is None else "\n".join(lines),
                                                      database_format="dbc", strict=False)
            break
        except Exception as exc:  # cantools raises several parser exception types
            if lines is None:
                lines = text.split("\n")
                repairs = repair_lines(lines)
                continue
            more = unused_value_tables(lines, str(exc))
            if not more:
                note = f" (after {len(repairs)} repairs)" if repairs else ""
                reason = " ".join(str(exc).split())[:300]
                raise DbcError(f"{label}: cannot load DBC{context}: {reason}{note}") from None
            repairs.extend(more)
    for repair in repairs:
        LOG.warning("%s:%d: %s (repaired before parsing)", label, repair.line, repair.what)
    return database, repairs


def _repaired_problems(database, repairs) -> dict:
    """The strict check's problems of a repaired DBC, its dropped messages, and '' for the repairs themselves."""
    problems = _message_problems(database)
    problems.update({repair.dropped_message: repair.what for repair in repairs if repair.dropped_message})
    shown = "; ".join(f"line {repair.line}: {repair.what}" for repair in repairs[:3])
    more = f"; and {len(repairs) - 3} more" if len(repairs) > 3 else ""
    problems[""] = f"{len(repairs)} lines repaired before parsing: {shown}{more}"
    return problems


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
