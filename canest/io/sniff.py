"""Which log format a file holds, from its first bytes: for logs whose name does not say it.

candump logs are named ``.candump``, ``.txt``, ``.log`` or nothing at all; a
suffix python-can does not know says nothing about the content. The first
lines do: candump ``-L`` lines ``(1487342025.615950) can0 187#E21408C8``,
Vector ASC's ``date``/``base hex`` header, PEAK TRC's ``;$FILEVERSION`` (or
``;`` comment) header, python-can CSV's ``timestamp,arbitration_id,...``
header, or BLF's ``LOGG`` signature. :func:`sniff_format` gives the format's
suffix (``.log``, ``.asc``, ``.trc``, ``.csv``, ``.blf``) as
:class:`canest.io.logfiles.LogSource` names its readers.
"""
from __future__ import annotations

import re

SNIFF_BYTES = 4096  # the head read to decide; a header of every format fits in its first lines
CANDUMP_LINE = re.compile(rb"\(\s*\d+(\.\d+)?\)\s+\S+\s+[0-9A-Fa-f]{1,8}#")
ASC_HEADER = re.compile(rb"(date\s|base\s+(hex|dec)\b|begin\s+triggerblock\b|no\s+internal\s+events\b|"
                        rb"internal\s+events\s+logged\b)", re.IGNORECASE)
TRC_HEADER = re.compile(rb";(\$FILEVERSION|\s*#{5,})")
CSV_HEADER = re.compile(rb"timestamp\s*,\s*arbitration_id\s*,", re.IGNORECASE)
BLF_SIGNATURE = b"LOGG"

# what each format is recognized by, in the order tried (the error message lists them)
SNIFFED = {"candump -L": ".log", "Vector ASC": ".asc", "PEAK TRC": ".trc", "python-can CSV": ".csv", "BLF": ".blf"}


def first_lines(head: bytes) -> list:
    """The non-blank lines of ``head`` (a byte-order mark dropped), the last one only if complete."""
    lines = head.removeprefix(b"\xef\xbb\xbf").splitlines(keepends=True)
    if lines and not lines[-1].endswith((b"\n", b"\r")) and len(head) >= SNIFF_BYTES:
        lines.pop()  # cut by the head's size, not by the file's end
    return [line.strip() for line in lines if line.strip()]


def sniff_format(head: bytes) -> str | None:
    """The format's suffix (``.log`` for candump) of a log starting with ``head``; None if none fits."""
    if head.startswith(BLF_SIGNATURE):
        return ".blf"
    lines = first_lines(head)
    if not lines:
        return None
    first = lines[0]
    if CSV_HEADER.match(first):
        return ".csv"
    if TRC_HEADER.match(first):
        return ".trc"
    if ASC_HEADER.match(first):
        return ".asc"
    if any(CANDUMP_LINE.match(line) for line in lines[:5]):  # a comment or two may come first
        return ".log"
    if first.startswith(b";"):  # TRC 1.x files open with comment lines, not always the row of '#'
        return ".trc"
    return None
