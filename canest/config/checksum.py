"""``input.messages.<MSG>.checksum``: the checksum signal and its algorithm.

``checksum: SIGNAL`` (canest's CRC-8/SAE-J1850, as before), ``checksum: {signal: SIGNAL, algorithm: toyota}`` (an
opendbc brand's, :data:`canest.codec.checksums.BRANDS`) or ``{signal: SIGNAL, algorithm: crc, width: 8,
polynomial: 0x2F, ...}`` (a CRC described by its parameters, :class:`canest.settings.CrcParameters`).
"""
from __future__ import annotations

from canest.codec.checksums import ALGORITHMS, CRC_WIDTHS
from canest.settings import CrcParameters
from canest.yamldoc import Document

CHECKSUM_KEYS = ("signal", "algorithm")
CRC_KEYS = ("width", "polynomial", "init", "xor_out", "reflect_in", "reflect_out", "data_id", "data_id_at", "bytes")
DATA_ID_AT = ("start", "end")
MAX_DATA_ID = 8  # bytes


def _integer(doc: Document, where: tuple, given, low: int, high: int, what: str) -> int:
    if isinstance(given, bool) or not isinstance(given, int) or not low <= given <= high:
        raise doc.error(where, f"must be {what}, an integer from {low} to {high:#x}, got {given!r}")
    return given


def _flag(doc: Document, where: tuple, entry: dict, key: str) -> bool:
    value = entry.get(key, False)
    if not isinstance(value, bool):
        raise doc.error(where + (key,), f"must be true or false, got {value!r}")
    return value


def _crc(doc: Document, where: tuple, entry: dict, length: int) -> CrcParameters:
    for key in ("width", "polynomial"):
        if key not in entry:
            raise doc.error(where, f"algorithm crc needs '{key}' (and optionally {', '.join(CRC_KEYS[2:])})")
    width = entry["width"]
    if isinstance(width, bool) or width not in CRC_WIDTHS:
        raise doc.error(where + ("width",), f"must be {', '.join(map(str, CRC_WIDTHS[:-1]))} or {CRC_WIDTHS[-1]} "
                                            f"bits, got {width!r}")
    top = (1 << width) - 1
    polynomial = _integer(doc, where + ("polynomial",), entry["polynomial"], 1, top,
                          "the generator without its top bit (0x1D for CRC-8/SAE-J1850)")
    init = _integer(doc, where + ("init",), entry.get("init", 0), 0, top, "the register's initial value")
    xor_out = _integer(doc, where + ("xor_out",), entry.get("xor_out", 0), 0, top, "XORed into the result")
    data_id = entry.get("data_id", [])
    data_id = data_id if isinstance(data_id, list) else [data_id]
    if len(data_id) > MAX_DATA_ID:
        raise doc.error(where + ("data_id",), f"at most {MAX_DATA_ID} bytes, got {len(data_id)}")
    data_id = tuple(_integer(doc, where + ("data_id",), b, 0, 0xFF, "a list of bytes") for b in data_id)
    data_id_at = entry.get("data_id_at", "end")
    if data_id_at not in DATA_ID_AT:
        raise doc.error(where + ("data_id_at",), f"must be start or end (fed before or after the data), got "
                                                 f"{data_id_at!r}")
    covered = entry.get("bytes", [0, length - 1])
    if not isinstance(covered, list) or len(covered) != 2:
        raise doc.error(where + ("bytes",), f"must be [first, last] data byte covered, got {covered!r}")
    first, last = (_integer(doc, where + ("bytes",), b, 0, length - 1, "a data byte of the message") for b in covered)
    if first > last:
        raise doc.error(where + ("bytes",), f"first must not lie after last, got {covered!r}")
    return CrcParameters(width, polynomial, init, xor_out, _flag(doc, where, entry, "reflect_in"),
                         _flag(doc, where, entry, "reflect_out"), data_id, data_id_at, first, last)


def read_checksum(doc: Document, where: tuple, given, length: int) -> tuple:
    """(signal name, algorithm, CrcParameters or None) of a ``checksum`` entry of a message of ``length`` bytes."""
    if isinstance(given, str):
        return given, "canest", None
    if not isinstance(given, dict):
        raise doc.error(where, f"must be a signal name or {{signal: NAME, algorithm: ...}}, got {given!r}")
    algorithm = given.get("algorithm", "canest")
    if algorithm not in ALGORITHMS:
        raise doc.error(where + ("algorithm",), f"unknown checksum algorithm {algorithm!r}; valid: "
                                                f"{', '.join(ALGORITHMS)}")
    doc.reject_unknown(where, given, CHECKSUM_KEYS + (CRC_KEYS if algorithm == "crc" else ()),
                       "" if algorithm == "crc" else " (CRC parameters belong to algorithm: crc)")
    signal = doc.text(where, given, "signal")
    if signal is None:
        raise doc.error(where, "needs 'signal: NAME' (the checksum signal of the message)")
    return signal, algorithm, _crc(doc, where, given, length) if algorithm == "crc" else None
