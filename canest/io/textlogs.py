"""Text logs (candump ``.log``, ``.asc``, ``.trc``, python-can ``.csv``): a bad line is skipped, not the end.

python-can's text readers parse inside one loop over their file, and the first
line they cannot parse ends that loop. Here the reader's file is a
:class:`LineFeed`, which hands it the log's lines one at a time and learns each
line's fate: a frame, a line the reader skipped on purpose (blank, comment,
header, event), or an error. After an error the reader's own loop is simply
entered again and goes on at the next line; the parsing is python-can's
throughout. The subclasses here only make re-entering safe: the header is read
once (ASC, TRC), the CSV reader's header line is not dropped twice, and the TRC
reader's short lines are counted instead of dropped silently.
"""
from __future__ import annotations

import gzip
import re
import zlib

import can
from can.io.asc import ASC_MESSAGE_REGEX

from canest.errors import CanestError, LogError

ASC_HEADER_OR_EVENT = re.compile(r"(date\s|base\s|(no\s+)?internal\s+events\s+logged|begin\s+triggerblock|"
                                 r"end\s+triggerblock|//)|\d+\.\d+\s", re.IGNORECASE)


class LineFeed:
    """A text log's lines, as the file object a python-can reader iterates, each line's fate recorded in ``damage``.

    ``is_metadata(text)`` tells a line the reader skipped on purpose (kept uncounted) from junk (counted).
    A binary stream is read and decoded here (UTF-8, undecodable bytes replaced, so the parser judges them).
    A last line without its newline was cut mid-write: it is counted (``torn_line``) and never parsed, as what
    python-can would read from it may be a frame cut short.
    """

    def __init__(self, stream, damage, is_metadata):
        self.stream = stream
        self.damage = damage
        self.is_metadata = is_metadata
        self.number = 0  # of the last line handed out
        self.pending = None  # text of the last line handed out, until its fate is known
        self.pushed = []

    def __iter__(self):
        return self

    def __next__(self) -> str:
        if self.pushed:
            return self.pushed.pop()
        self._settle()
        try:
            raw = self.stream.readline()
        except (EOFError, zlib.error, gzip.BadGzipFile) as exc:  # a damaged .gz
            self.damage.stop("corrupt", 0, f"decompression failed after line {self.number}, the rest is "
                                           f"unreadable ({type(exc).__name__}: {exc})")
            raise StopIteration from None
        if not raw:
            raise StopIteration
        self.number += 1
        self.damage.lines = self.number
        text = raw.decode("utf-8", errors="replace")
        if not raw.endswith(b"\n") and text.strip():  # the file ends mid-line: never parsed, it may be cut short
            self.damage.skip("torn_line", self.number, repr(text.strip()[:60]))
            raise StopIteration
        self.pending = text
        return text

    def _settle(self) -> None:
        """The line handed out last gave neither a frame nor an error: the reader skipped it."""
        if self.pending is None:
            return
        text, self.pending = self.pending.strip(), None
        if not text or self.is_metadata(text):
            self.damage.quiet_lines += 1
        else:
            self.damage.skip("junk_lines", self.number, repr(text[:60]))

    def produced(self) -> None:
        """The line handed out last was a frame."""
        self.pending = None

    def failed(self, exc: Exception) -> None:
        """The reader could not parse the line handed out last."""
        self.pending = None
        self.damage.skip("bad_lines", self.number, f"{type(exc).__name__}: {exc}")

    def finish(self) -> None:
        self._settle()

    def unread(self, text: str) -> None:
        """Hand ``text`` out next, outside the numbering."""
        self.pushed.append(text)

    def close(self) -> None:
        self.stream.close()


def is_any_skipped_line_metadata(text: str) -> bool:
    """candump, TRC and CSV readers skip only blank, comment, header and event lines."""
    return True


class Resumable:
    """A python-can text reader whose loop may be entered again after a line it could not parse."""

    header_read = True  # nothing to read before the lines (formats without a header)
    is_metadata = staticmethod(is_any_skipped_line_metadata)

    def resume(self) -> None:
        """Prepare the reader's loop to be entered again at the next line."""


class HeaderOnce(Resumable):
    """python-can reads the header when its loop starts; entered again, the loop must not read it again."""

    header_read = False

    def _extract_header(self):
        if self.header_read:
            return None
        line = super()._extract_header()
        self.header_read = True
        return line


class CandumpLines(Resumable, can.CanutilsLogReader):
    """candump ``-L`` lines; an error frame keeps its line's interface (python-can's reader leaves its channel None,
    and a log of several buses then listed a channel "None")."""

    def __iter__(self):
        for msg in super().__iter__():
            if msg.is_error_frame and msg.channel is None:
                interface = self.file.pending.split()[1]
                msg.channel = int(interface) if interface.isdigit() else interface
            yield msg


class AscLines(HeaderOnce, can.ASCReader):
    """Vector ASC; a skipped line that is no header, comment or event line (or a frame line it passed by) is junk."""

    @staticmethod
    def is_metadata(text: str) -> bool:
        return not ASC_MESSAGE_REGEX.match(text) and bool(ASC_HEADER_OR_EVENT.match(text))


class TrcLines(HeaderOnce, can.TRCReader):
    """PEAK TRC."""

    def _parse_line(self, line: str):
        """python-can's, but a short line raises (python-can logs it and drops it uncounted)."""
        if not line:
            return None  # the header ran to the end of the file
        return self._parse_cols(tuple(line.split(maxsplit=self._num_columns)))


class CsvLines(Resumable, can.CSVReader):
    """python-can's CSV format."""

    def resume(self) -> None:
        self.file.unread("")  # its loop drops one header line each time it starts


TEXT_READERS = {".log": CandumpLines, ".asc": AscLines, ".trc": TrcLines, ".csv": CsvLines}


def text_frames(path, kind: str, stream, damage):
    """The frames of a text log of format ``kind`` (``.log``, ...); each line the reader cannot parse is counted
    in ``damage`` and skipped."""
    reader_class = TEXT_READERS[kind]
    feed = LineFeed(stream, damage, reader_class.is_metadata)
    reader = reader_class(feed)
    while True:  # every entry of the reader's loop reads a line first, so each failure is a line further on
        try:
            for msg in reader:
                feed.produced()
                yield msg
            break
        except (CanestError, OSError):
            raise  # the file itself failed, not a line
        except Exception as exc:  # whatever python-can's parser raises for a line it cannot read
            if not reader.header_read:
                raise LogError(f"{path}: unreadable header (line {feed.number}: {type(exc).__name__}: {exc}); "
                               f"is it a {kind} log?") from None
            feed.failed(exc)
            reader.resume()
    feed.finish()
