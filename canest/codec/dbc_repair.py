"""Text repairs for DBC files that work in practice but that cantools' DBC grammar refuses.

Only used when cantools cannot load a ``.dbc`` file even with ``strict=False``
(no cantools option accepts these; ``prune_choices`` only shortens value
names). Each repair is one function over the file's lines: it edits the lines
in place and returns a :class:`Repair` per line it changed, naming the line and
what it did. A repair never adds or removes a line (a dropped line becomes
empty), so every line number, in a repair or in a later cantools error, is the
line of the file on disk. Measured on opendbc 0.3.1: 31 of its 94 DBCs need one.
"""
from __future__ import annotations

import re
from dataclasses import dataclass

EXTENDED_FLAG = 0x80000000  # the DBC convention: bit 31 of a BO_ id marks a 29-bit (extended) frame id
STANDARD_LIMIT = 0x7FF
EXTENDED_LIMIT = 0x1FFFFFFF

# the statements that name a message by its id (the id is always on the statement's first line)
_ID_STATEMENT = re.compile(
    r'^(?P<head>BO_ |BO_TX_BU_ |VAL_ |SIG_VALTYPE_ |SG_MUL_VAL_ |CM_ (?:BO_|SG_) |BA_ "[^"]*"\s+(?:BO_|SG_) )'
    r'(?P<id>\d+)\b')
_MESSAGE = re.compile(r"^BO_ (?P<id>\d+) (?P<name>\w+)")
_SIGNAL_LINE = re.compile(r"^\s+SG_ ")


@dataclass(frozen=True)
class Repair:
    """One changed line: its number (1-based, of the file on disk), what was done, the message it dropped if any."""

    line: int
    what: str
    dropped_message: str = ""


def signal_comment_without_signal(lines: list) -> list:
    """``CM_ SG_ 304 "text";`` (no signal name, as in opendbc's Honda DBCs) becomes the message's comment."""
    return _substitute(lines, re.compile(r'^CM_ SG_ (\d+) "'), r'CM_ BO_ \1 "',
                       "signal comment without a signal name made the message's comment")


def comment_without_object(lines: list) -> list:
    """``CM_ 145 "text";`` (an id without ``BO_``, as in opendbc's hyundai_kia_generic) becomes a message comment."""
    return _substitute(lines, re.compile(r'^CM_ (\d+) "'), r'CM_ BO_ \1 "', "comment of id without BO_ made a message comment")


def missing_semicolon(lines: list) -> list:
    """A one-line file comment ``CM_ "text"`` or value table ``VAL_ 320 NAME 1 "ON" 0 "OFF"`` gets its closing ``;``."""
    return _substitute(lines, re.compile(r'^(CM_ "[^"]*"|VAL_ \d+ \w+(?: [-+]?\d+ "[^"]*")*)\s*$'), r"\1;",
                       "missing ';' at the end of the statement added")


def bare_decimal_point(lines: list) -> list:
    """A signal's factor, offset or range written ``.25`` (no digit before the point) is written ``0.25``."""
    return _substitute(lines, re.compile(r"(?<=[(,\[|])([-+]?)\.(?=\d)"), r"\g<1>0.",
                       "number without a digit before its decimal point written with a leading 0",
                       only=_SIGNAL_LINE)


def name_starting_with_digit(lines: list) -> list:
    """A message or signal named ``2017_5`` or ``0_COUNTER`` (read as a number and a word) is renamed ``_2017_5``.

    The new name replaces the old one on every line (comments, value tables,
    attributes), so whatever refers to it still does.
    """
    definition = re.compile(r"^(?:BO_ \d+ |\s+SG_ )(\d+[A-Za-z_]\w*)\b")
    repairs, names = [], set()
    for number, line in enumerate(lines, 1):
        match = definition.match(line)
        if match:
            names.add(match.group(1))
            repairs.append(Repair(number, f"name {match.group(1)!r} starts with a digit: renamed '_{match.group(1)}'"))
    for name in names:
        word = re.compile(rf"(?<![\w.]){re.escape(name)}(?![\w.])")
        lines[:] = [word.sub(f"_{name}", line) for line in lines]
    return repairs


def long_standard_ids(lines: list) -> list:
    """A BO_ id above 11 bits without the extended flag: flagged extended if it fits 29 bits, else dropped.

    Tools write 29-bit ids without bit 31 (opendbc's GM, VW MEB, FCA and
    Chrysler DBCs); cantools reads them as 11-bit ids and refuses the file.
    Such an id is given the flag on every statement naming it. An id above 29
    bits (opendbc's toyota_2017_ref_pt, 0x40140639) is no CAN frame id at all:
    the message and every statement naming it are dropped.
    """
    too_long = {int(match.group("id")) for match in map(_MESSAGE.match, lines)
                if match and STANDARD_LIMIT < int(match.group("id")) < EXTENDED_FLAG}
    names = {int(match.group("id")): match.group("name") for match in map(_MESSAGE.match, lines) if match}
    repairs = []
    dropping = None  # the rest of a dropped statement: "signals" (of a BO_) or "statement" (up to its ';')
    for number, line in enumerate(lines, 1):
        if dropping == "signals" and _SIGNAL_LINE.match(line):
            lines[number - 1] = ""
            continue
        if dropping == "statement":
            lines[number - 1] = ""
            if line.rstrip().endswith(";"):
                dropping = None
            continue
        dropping = None
        match = _ID_STATEMENT.match(line)
        frame_id = int(match.group("id")) if match else None
        if frame_id not in too_long:
            continue
        if frame_id <= EXTENDED_LIMIT:
            lines[number - 1] = line[:match.start("id")] + str(frame_id | EXTENDED_FLAG) + line[match.end("id"):]
            repairs.append(Repair(number, f"id {frame_id:#x} ({names[frame_id]}) has more than 11 bits: "
                                          "flagged extended (29-bit)"))
            continue
        lines[number - 1] = ""
        repairs.append(Repair(number, f"id {frame_id:#x} of {names[frame_id]} has more than 29 bits, no CAN id: "
                                      "statement dropped", dropped_message=names[frame_id]))
        if match.group("head") == "BO_ ":
            dropping = "signals"
        elif not line.rstrip().endswith(";"):
            dropping = "statement"
    return repairs


def unused_value_tables(lines: list, cantools_error: str) -> list:
    """Drop the ``VAL_`` statements cantools names as unused (a value table of a signal the message lacks).

    cantools lists them all in one error (``unused VAL_ entries in DBC:``), after
    the whole file parsed; opendbc's GM, Hyundai, Rivian and Tesla DBCs have such
    leftovers.
    """
    if "unused VAL_ entries" not in cantools_error:
        return []
    unused = set(re.findall(r"^\s*VAL_ (\d+) (\w+)\b", cantools_error, re.M))
    repairs = []
    for number, line in enumerate(lines, 1):
        match = re.match(r"^VAL_ (\d+) (\w+) ", line)
        if match and match.groups() in unused:
            lines[number - 1] = ""
            repairs.append(Repair(number, f"value table of {match.group(2)}, a signal message {match.group(1)} "
                                          "does not have: dropped"))
    return repairs


LINE_REPAIRS = (signal_comment_without_signal, comment_without_object, missing_semicolon,
                bare_decimal_point, name_starting_with_digit, long_standard_ids)


def repair_lines(lines: list) -> list:
    """Apply every line repair to ``lines`` (in place); the repairs made, by line."""
    repairs = []
    for repair in LINE_REPAIRS:
        repairs.extend(repair(lines))
    return sorted(repairs, key=lambda repair: repair.line)


def _substitute(lines: list, pattern, replacement: str, what: str, only=None) -> list:
    repairs = []
    for number, line in enumerate(lines, 1):
        if only is not None and not only.match(line):
            continue
        repaired = pattern.sub(replacement, line)
        if repaired != line:
            lines[number - 1] = repaired
            repairs.append(Repair(number, what))
    return repairs
