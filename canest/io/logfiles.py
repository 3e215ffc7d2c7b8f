"""Where logged frames come from: python-can's readers, chosen by file suffix, read as far as they can.

``.log`` (candump), ``.asc``, ``.trc``, ``.csv`` (each also ``.gz``-compressed),
``.blf``, and whatever else python-can reads (``.db``, ``.mf4``, plug-ins).
A log whose suffix python-can does not know (``.candump``, ``.txt``, none)
is read in the format its first lines show (:mod:`canest.io.sniff`); a
``kind`` (``--format``) overrides both. ``-`` is standard input, read as it
arrives (a pipe from ``candump -L``), in one of the formats python-can reads
from a stream (:data:`STREAM_FORMATS`, candump text by default). A log of
several buses is read for one channel when ``channel`` (``--log-channel``)
names it; the frames of the others are counted (``log_other_channel``). :func:`open_log` gives a :class:`LogSource`: iterate it for the frames. What
cannot be read does not end the replay: a text line python-can cannot parse is
skipped and counted (:mod:`canest.io.textlogs`), a truncated or corrupt binary
log ends where it can no longer be decoded (:mod:`canest.io.blflogs`), and
:attr:`LogSource.damage` holds it all, by cause, for the frame summary and the
warnings. A log of which nothing at all could be read is a
:class:`~canest.errors.LogError` (exit 65); a missing or forbidden one an
:class:`~canest.errors.InputFileError` (66); a read that fails midway (a device
error) a :class:`~canest.errors.FileIOError` (74).
"""
from __future__ import annotations

import glob
import gzip
import logging
import sys
import threading
import zlib
from collections import Counter
from pathlib import Path

import can

from canest.errors import CanestError, DependencyError, FileIOError, InputFileError, LogError, UsageError
from canest.io.blflogs import blf_frames
from canest.io.damage import LogDamage
from canest.io.outputs import is_stdio
from canest.io.sniff import SNIFF_BYTES, SNIFFED, sniff_format
from canest.io.textlogs import TEXT_READERS, text_frames


STREAM_FORMATS = (*(kind.lstrip(".") for kind in TEXT_READERS), "blf")  # readable from standard input
# suffixes whose readers canest or python-can pick by name (its plug-ins' too); any other suffix is sniffed
KNOWN_SUFFIXES = frozenset((*TEXT_READERS, ".blf", *can.io.player.MESSAGE_READERS))


def log_format(path: Path):
    """(the format's suffix, whether the file is gzip-compressed): ``drive.asc.gz`` -> (``.asc``, True)."""
    suffixes = [s.lower() for s in path.suffixes]
    if suffixes and suffixes[-1] == ".gz":
        return (suffixes[-2] if len(suffixes) > 1 else ""), True
    return (suffixes[-1] if suffixes else ""), False


class ReaderWarnings(logging.Handler):
    """python-can's readers log what they skip (an unknown BLF compression, ...): count it as damage."""

    def __init__(self, damage: LogDamage):
        super().__init__(logging.WARNING)
        self.damage = damage
        self.thread = threading.get_ident()  # batch replays several logs at once, one per thread

    def emit(self, record) -> None:
        if record.thread == self.thread:
            self.damage.note("reader_warnings", record.getMessage())


class LogSource:
    """A log's frames (iterate once), ``damage`` (what could not be read), ``position()`` (bytes read, for progress).

    ``path`` ``-`` is standard input; ``kind`` (``log``, ``asc``, ``trc``, ``csv``, ``blf``) names the format where
    the suffix does not (standard input: candump ``log`` by default; a file of an unknown suffix: sniffed).
    ``channel``: only that channel's frames (as :attr:`channels` names them); the others are counted.
    """

    def __init__(self, path, kind: str | None = None, channel: str | None = None):
        self.stdin = is_stdio(path)
        self.path = Path("<stdin>" if self.stdin else path)
        self.damage = LogDamage(self.path)
        self.frames = 0
        self.channel = channel
        self.read_per_channel = Counter()  # frames read per channel as the reader gives it (str, int or None)
        if self.stdin:
            kind, compressed = f".{kind or 'log'}", False
            if kind.lstrip(".") not in STREAM_FORMATS:
                raise UsageError(f"--format {kind.lstrip('.')}: standard input can be read as "
                                 f"{', '.join(STREAM_FORMATS)}; write other formats to a file first")
            self.handle = sys.stdin.buffer
            stream = self.handle
        else:
            stream, kind, compressed = self._open_file(kind)
        if kind in TEXT_READERS:
            self.reader = None
            self._frames = text_frames(self.path, kind, stream, self.damage)
        elif kind == ".blf":
            self.reader = None
            size = None if compressed or self.stdin else self.path.stat().st_size
            self._frames = blf_frames(self.path, stream, size, self.damage)
        else:
            self.handle.close()
            self.reader = python_can_reader(self.path)
            self._frames = until_unreadable(self.reader, self.damage)

    def _open_file(self, kind):
        """(the stream, its format's suffix, whether gzip-compressed) of a log file; ``kind`` overrides the suffix."""
        if self.path.is_dir():
            raise InputFileError(f"{self.path}: that is a folder; name a log file")
        if not self.path.exists():
            raise InputFileError(f"{self.path}: log file not found")
        suffix, compressed = log_format(self.path)
        try:
            self.handle = open(self.path, "rb")
            stream = gzip.GzipFile(fileobj=self.handle) if compressed else self.handle
        except OSError as exc:
            raise InputFileError(f"{self.path}: cannot read: {exc.strerror}; check that the file may be read "
                                 "by this user") from None
        if kind:
            return stream, f".{kind}", compressed
        if suffix not in KNOWN_SUFFIXES:
            suffix = self._sniff(stream, suffix)
        return stream, suffix, compressed

    def _sniff(self, stream, suffix: str) -> str:
        """The format of a log whose suffix does not say it, from its first bytes; the stream is rewound."""
        try:
            head = stream.read(SNIFF_BYTES)
            stream.seek(0)
        except (EOFError, OSError, zlib.error) as exc:  # a damaged .gz, a device error
            raise LogError(f"{self.path}: cannot read its first bytes to tell its format ({exc}); name it with "
                           "--format") from None
        kind = sniff_format(head)
        if kind is None:
            tried = ", ".join(SNIFFED)
            raise LogError(f"{self.path}: not a log canest can read: its suffix {suffix or '(none)'!r} names no "
                           f"format and its first lines are none of {tried}; convert it, or name the format with "
                           f"--format {'|'.join(STREAM_FORMATS)}")
        return kind

    def size(self):
        """Bytes of the log file (None for standard input or a file python-can reads itself)."""
        return None if self.stdin or self.reader is not None else self.path.stat().st_size

    def __iter__(self):
        warnings = ReaderWarnings(self.damage)
        logging.getLogger("can.io").addHandler(warnings)
        try:
            read, selected = self.read_per_channel, {}  # a channel as the reader gives it -> whether it is read
            for msg in self._frames:
                read[msg.channel] += 1
                keep = selected.get(msg.channel)
                if keep is None:
                    keep = selected[msg.channel] = self.channel is None or str(msg.channel) == self.channel
                if keep:
                    self.frames += 1
                    yield msg
        except OSError as exc:
            raise FileIOError(f"{self.path}: cannot read: {exc.strerror or exc}; check the disk or device, or "
                              "copy the log elsewhere") from None
        finally:
            logging.getLogger("can.io").removeHandler(warnings)
        if not self.frames and self.damage and not self.read_per_channel:
            raise LogError(f"{self.path}: no frame could be read: {self.damage.descriptions()[0]}")

    def position(self) -> int:
        """Bytes of the file read so far (0 where python-can reads the file itself or for standard input)."""
        return 0 if self.stdin or self.handle.closed else self.handle.tell()

    @property
    def channels(self) -> Counter:
        """Frames read per channel, by the name ``--log-channel`` takes."""
        return Counter({str(channel): count for channel, count in self.read_per_channel.items()})

    def other_channels(self) -> int:
        """Frames read but left out: they are on another channel than the one selected."""
        return sum(self.read_per_channel.values()) - self.frames

    def summary(self) -> dict:
        """What was not read (``log_<cause>``) and what was left out (``log_other_channel``), for the frame summary."""
        return {**self.damage.summary(), **({"log_other_channel": self.other_channels()} if self.other_channels()
                                            else {})}

    def warnings(self) -> list:
        """One line per cause of what could not be read, a line for a log without frames, one for its channels."""
        listed = ", ".join(f"{name} ({count} frames)" for name, count in self.channels.most_common())
        if self.channel is not None and not self.frames and self.channels:
            return self.damage.warnings() + [f"{self.path}: no frame on channel {self.channel!r} (--log-channel); "
                                             f"the log's channels: {listed}"]
        empty = [] if self.frames else [f"{self.path}: the log holds no CAN frames; the outputs have no ticks"]
        mixed = [f"{self.path}: the log holds several channels, {listed}, all read as one bus; select one with "
                 "--log-channel NAME"] if self.channel is None and len(self.channels) > 1 else []
        return self.damage.warnings() + empty + mixed

    def stop(self) -> None:
        if self.reader is not None:
            self.reader.stop()
        if not self.stdin:
            self.handle.close()


def python_can_reader(path: Path):
    """python-can's reader for any other suffix (``.db``, ``.mf4``, a plug-in's)."""
    try:
        return can.LogReader(str(path))
    except (ImportError, NotImplementedError) as exc:  # the MF4 reader without asammdf
        raise DependencyError(f"{path}: {exc}; pip install 'canest[mf4]'") from None
    except ValueError as exc:
        raise LogError(f"{path}: {exc}; canest reads .log (candump), .asc, .blf, .trc, .csv (also .gz), .db, .mf4") \
            from None
    except OSError:
        raise
    except Exception as exc:
        raise LogError(f"{path}: not readable as a {path.suffix} log ({type(exc).__name__}: {exc})") from None


def until_unreadable(reader, damage: LogDamage):
    """python-can's frames until it cannot read on; that is reported with the number of frames read."""
    frames = 0
    try:
        for msg in reader:
            frames += 1
            yield msg
    except (CanestError, OSError):
        raise
    except Exception as exc:
        damage.stop("corrupt", 0, f"corrupt: reading stopped after {frames} frames ({type(exc).__name__}: {exc})")


def open_log(path, kind: str | None = None, channel: str | None = None) -> LogSource:
    return LogSource(path, kind, channel)


def expand_logs(names) -> list:
    """The logs named: each name as given, or, for a glob pattern (``*``, ``?``, ``[...]``; ``**`` recurses,
    quoted so the program sees it, as on Windows shells), the files it matches, sorted; each log once.
    A pattern that matches no file is an :class:`~canest.errors.InputFileError` naming it."""
    logs = {}
    for name in map(str, names):
        if not glob.has_magic(name):
            logs.setdefault(name)
            continue
        matches = sorted(path for path in glob.glob(name, recursive=True) if Path(path).is_file())
        if not matches:
            raise InputFileError(f"{name}: no log matches this pattern; check the folder and the quotes")
        logs.update(dict.fromkeys(matches))
    return list(logs)
