"""What could not be read from a log: counted by cause, with where, for the frame summary and the warnings.

Causes (summary key ``log_<cause>``):

- ``bad_lines``: lines python-can's parser for the format rejects;
- ``torn_line``: the last line, cut mid-write (no newline at its end; never parsed);
- ``junk_lines``: ASC lines that are neither frames nor ASC header or event lines;
- ``reader_warnings``: things python-can's reader itself reported skipping (an
  unknown BLF compression method or object version, ...);
- ``truncated`` / ``corrupt``: a binary log that ends inside a block, or that
  cannot be decoded from some byte on (reading stops there); ``unread_bytes``
  says how much of the file was not turned into frames.
"""
from __future__ import annotations

from collections import Counter, defaultdict

FIRST = 5  # locations listed per cause


class LogDamage:
    def __init__(self, path):
        self.path = path
        self.counts = Counter()
        self.where = defaultdict(list)  # cause -> first FIRST line numbers
        self.detail = {}  # cause -> the first error's text
        self.unread_bytes = 0
        self.stopped = None  # why reading ended before the end of the file, if it did
        self.lines = 0  # text logs: lines read, each a frame, a quiet line or counted by cause
        self.quiet_lines = 0  # blank, comment, header and event lines (skipped on purpose, not damage)

    def skip(self, cause: str, line: int, detail: str = "") -> None:
        """One line skipped for ``cause``."""
        self.counts[cause] += 1
        if len(self.where[cause]) < FIRST:
            self.where[cause].append(line)
        self.detail.setdefault(cause, detail)

    def note(self, cause: str, detail: str) -> None:
        """One event of ``cause`` without a line number (a reader's own warning)."""
        self.counts[cause] += 1
        self.detail.setdefault(cause, detail)

    def stop(self, cause: str, unread_bytes: int, explanation: str) -> None:
        """Reading ended early (a binary log truncated or corrupt): ``explanation`` says how far it got."""
        self.counts[cause] += 1
        self.unread_bytes += max(unread_bytes, 0)
        self.stopped = explanation

    def __bool__(self) -> bool:
        return bool(self.counts)

    def summary(self) -> dict:
        """``log_<cause>`` counts and ``log_unread_bytes``, for the frame summary."""
        counts = {f"log_{cause}": n for cause, n in self.counts.items()}
        if self.unread_bytes:
            counts["log_unread_bytes"] = self.unread_bytes
        return counts

    def warnings(self) -> list:
        """One line per cause, naming the file, the first locations and the first error."""
        return [f"{self.path}: {text}" for text in self.descriptions()]

    def descriptions(self) -> list:
        """As :meth:`warnings`, without the file name."""
        lines = []
        for cause, n in sorted(self.counts.items()):
            if cause in self.where:
                shown = ", ".join(map(str, self.where[cause])) + (", ..." if n > len(self.where[cause]) else "")
                what = {"bad_lines": f"skipped {n} line(s) the reader could not parse",
                        "torn_line": "skipped the last line, cut mid-write (the logger stopped while writing it)",
                        "junk_lines": f"skipped {n} line(s) that are neither frames nor header or event lines",
                        }.get(cause, f"skipped {n} line(s): {cause}")
                detail = f"; first: {self.detail[cause]}" if self.detail.get(cause) else ""
                lines.append(f"{what} (line {shown}){detail}")
            elif cause == "reader_warnings":
                lines.append(f"the reader skipped data {n} time(s); first: {self.detail[cause]}")
        if self.stopped:
            lines.append(self.stopped)
        return lines
