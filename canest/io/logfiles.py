"""Where logged frames come from: python-can's readers, chosen by file suffix.

``.log`` (candump), ``.asc``, ``.blf``, ``.trc``, ``.csv``, ... : any format
python-can reads. A file that is missing, of an unknown format or
unreadable is a :class:`~canest.errors.LogError` naming the file (and the
frame number where reading stopped).
"""
from __future__ import annotations

import struct
from pathlib import Path

import can

from canest.errors import LogError


def open_log(path) -> can.LogReader:
    path = Path(path)
    if not path.is_file():
        raise LogError(f"{path}: log file not found")
    try:
        return can.LogReader(str(path))
    except ValueError as exc:
        raise LogError(f"{path}: {exc}") from None


def byte_position(reader):
    """A callable giving how far into its file ``reader`` is, or None if it cannot tell."""
    handle = getattr(reader, "file", None)
    handle = getattr(handle, "buffer", handle)  # text readers: the binary buffer can still tell
    if handle is None or not hasattr(handle, "tell"):
        return None
    try:
        handle.tell()
    except OSError:
        return None
    return handle.tell


def frames(reader, log_path):
    """The reader's frames; a frame it cannot parse ends the replay with the file and frame number."""
    count = 0
    iterator = iter(reader)
    while True:
        try:
            msg = next(iterator)
        except StopIteration:
            return
        except (ValueError, IndexError, KeyError, struct.error) as exc:
            raise LogError(f"{log_path}: frame {count + 1} is unreadable ({type(exc).__name__}: {exc})") from None
        count += 1
        yield msg
