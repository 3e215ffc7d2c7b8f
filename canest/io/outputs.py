"""Output files that never clobber an input and never show a half-written file under their name.

:func:`check_outputs` refuses an output that is one of the run's inputs (the
same file, a hard link to it or a symbolic link to it) or another output.

:class:`OutputFile` is where one output goes. Staged (the default), it is
written to a hidden temporary file in the same folder (``.NAME.XXXXXXXX.partial``
plus the suffix that tells python-can the format) and renamed over the final
name by :meth:`OutputFile.commit`, atomically; :meth:`OutputFile.discard`
removes it after a failure, so a failed run leaves neither a partial file
under the final name nor a stray temporary file (a run killed by SIGKILL
leaves its hidden ``.partial`` file, never a partial final file). An existing
file of that name is replaced, as python-can's writers, ``cp`` and ``gcc -o``
do: the inputs are protected by :func:`check_outputs`, and the old file stays
intact until the new one is complete. A symbolic link is written through (the
file it points to is replaced); a device or pipe (``/dev/null``, a FIFO) is
written directly. ``-`` names standard output: written directly, never staged,
and only one output of a run may take it. Every ``OSError`` becomes one line naming the file and the
remedy: :class:`~canest.errors.OutputFileError` (exit 73) when the file cannot
be created, :class:`~canest.errors.FileIOError` (exit 74) when writing fails.
"""
from __future__ import annotations

import errno
import os
import secrets
import stat
import sys
from pathlib import Path

from canest.errors import FileIOError, OutputFileError, UsageError

CANNOT_CREATE = {  # errno -> what to do; anything else is an I/O error while writing
    errno.EACCES: "choose a folder you may write to",
    errno.EPERM: "choose a folder you may write to",
    errno.EROFS: "the file system is read-only; write elsewhere",
    errno.ENOENT: "the folder does not exist; create it first",
    errno.ENOTDIR: "a part of the path is not a folder",
    errno.EISDIR: "that is a folder; name a file in it",
    errno.ENAMETOOLONG: "choose a shorter name",
    errno.ELOOP: "the path has a loop of symbolic links",
}
WRITE_FAILED = {
    errno.ENOSPC: "the disk is full; free space or write elsewhere",
    errno.EDQUOT: "the disk quota is used up; free space or write elsewhere",
    errno.EFBIG: "the file exceeds the size limit (file system or `ulimit -f`); write elsewhere",
}


STDIO = "-"  # as a log: standard input; as an output: standard output


def is_stdio(path) -> bool:
    """Whether ``path`` is ``-``: standard input as a log, standard output as an output."""
    return path is not None and str(path) == STDIO


def open_stdout():
    """Standard output as a text file of its own (closing it leaves fd 1 open), line-buffered for pipes."""
    sys.stdout.flush()
    return open(sys.stdout.fileno(), "w", newline="", buffering=1, closefd=False)


def _identity(path):
    """What makes two names one file: device and inode if it exists, else the resolved path."""
    try:
        info = os.stat(path)
    except OSError:
        return ("path", os.path.realpath(path))
    if not stat.S_ISREG(info.st_mode):
        return None  # devices, pipes: /dev/null may take every output
    return ("inode", info.st_dev, info.st_ino)


def _how_same(output, other) -> str:
    if os.path.realpath(output) == os.path.realpath(other) and os.path.abspath(output) != os.path.abspath(other):
        return "a symbolic link to it"
    if os.path.realpath(output) != os.path.realpath(other):
        return "a hard link to it"
    return "the same file"


def check_outputs(outputs: dict, inputs: dict) -> None:
    """Refuse an output that is an input or another output; ``{option or role: path or None}`` each."""
    to_stdout = [option for option, path in outputs.items() if is_stdio(path)]
    if len(to_stdout) > 1:
        raise UsageError(f"{' and '.join(to_stdout)} all name - (standard output); only one output can go there: "
                         "name files for the others")
    taken = {}
    for role, path in inputs.items():
        if path is not None and _identity(path) is not None:
            taken.setdefault(_identity(path), (role, path))
    for option, path in outputs.items():
        if path is None or is_stdio(path):
            continue
        key = _identity(path)
        if key is None:
            continue
        if key in taken:
            role, other = taken[key]
            raise UsageError(f"{option} {path}: that is {role} {other} ({_how_same(path, other)}); "
                             "writing it would destroy it: choose another output name")
        taken[key] = (option, path)


class OutputFile:
    """One output file, staged beside its final name and renamed on :meth:`commit` (see the module)."""

    def __init__(self, path, staged: bool = True):
        self.path = Path(path)
        self.stdout = is_stdio(path)
        if self.stdout:
            self.target, self.temp, self.write_path = self.path, None, None
            return
        self.target = Path(os.path.realpath(path))
        if self.target.is_dir():
            raise OutputFileError(f"{self.path}: cannot create: that is a folder; name a file in it")
        regular_or_new = self.target.is_file() or not self.target.exists()
        self.temp = self._reserve() if staged and regular_or_new else None
        self.write_path = self.temp or self.path  # the name as given: its suffix tells python-can the format

    def _reserve(self) -> Path:
        """Create an empty hidden file beside the target (exclusively: never someone else's file)."""
        kind = "".join(self.target.suffixes[-2:]) if self.target.suffix.lower() == ".gz" else self.target.suffix
        while True:
            temp = self.target.with_name(f".{self.target.name}.{secrets.token_hex(4)}.partial{kind}")
            try:
                os.close(os.open(temp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))
                return temp
            except FileExistsError:
                continue
            except OSError as exc:
                raise self.error(exc) from None

    def open_text(self):
        """The output as a text file (for ``csv``: no newline translation); standard output for ``-``."""
        return open_stdout() if self.stdout else open(self.write_path, "w", newline="")

    def error(self, exc: OSError):
        """The one-line error for an ``OSError`` while creating or writing this output."""
        reason = exc.strerror or str(exc)
        if self.stdout:
            return FileIOError(f"standard output: cannot write: {reason}; check where it is redirected")
        if exc.errno in CANNOT_CREATE:
            return OutputFileError(f"{self.path}: cannot create: {reason}; {CANNOT_CREATE[exc.errno]}")
        remedy = WRITE_FAILED.get(exc.errno, "check the disk and the device, or write elsewhere")
        return FileIOError(f"{self.path}: cannot write: {reason}; {remedy}")

    def commit(self) -> None:
        """Put the complete file under its final name."""
        if self.temp is not None:
            try:
                os.replace(self.temp, self.target)
            except OSError as exc:
                self.discard()
                raise self.error(exc) from None
            self.temp = None

    def discard(self) -> None:
        """Remove the temporary file of a failed run (the final name keeps what it had)."""
        if self.temp is not None:
            self.temp.unlink(missing_ok=True)
            self.temp = None

    def __enter__(self) -> Path:
        return self.write_path

    def __exit__(self, exc_type, exc, traceback):
        if exc_type is None:
            self.commit()
            return False
        self.discard()
        if isinstance(exc, OSError):
            raise self.error(exc) from None
        return False
