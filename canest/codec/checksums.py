"""Checksum algorithms of input frames, chosen per message by name and resolved once at start.

``canest``: canest's own CRC-8/SAE-J1850 over the frame ID and the data
(:mod:`canest.codec.integrity`; the default). An opendbc brand's (``toyota``,
``honda``, ``vw_mqb``, ...): opendbc's own checksum function is called (its
code is not copied; needs ``pip install canest[opendbc]``). ``crc``: any CRC of
width 8, 16, 24 or 32 described by its parameters (:class:`canest.settings.CrcParameters`),
computed by crcmod's C extension, for an OEM opendbc does not describe.

Each :func:`make_checksum` result answers ``ok(frame_id, data)`` (the decoder,
per frame) and ``seal(frame_id, data)`` (the simulator writing frames).
"""
from __future__ import annotations

import crcmod

from canest.codec import integrity
from canest.codec.opendbc_dbcs import INSTALL as OPENDBC_INSTALL
from canest.errors import DependencyError
from canest.settings import CrcParameters

# algorithm name -> an opendbc DBC name (prefix) it checks: opendbc's own get_checksum_state gives its function
BRANDS = {
    "toyota": "toyota_", "honda": "honda_", "hyundai_canfd": "hyundai_canfd_generated", "vw_mqb": "vw_mqb",
    "vw_mlb": "vw_mlb", "vw_pq": "vw_pq", "subaru": "subaru_global_", "chrysler": "chrysler_",
    "fca_giorgio": "fca_giorgio", "tesla": "tesla_model3_party", "psa": "psa_", "comma_body": "comma_body",
}
ALGORITHMS = ("canest", "crc", *BRANDS)
CRC_WIDTHS = (8, 16, 24, 32)  # the widths crcmod computes


class BitField:
    """Raw unsigned bits of one DBC signal in a frame of ``length`` bytes: read and written by shift and mask."""

    def __init__(self, signal, length: int):
        self.mask = (1 << signal.length) - 1
        self.order = "little" if signal.byte_order == "little_endian" else "big"
        if self.order == "little":
            self.shift = signal.start
            positions = range(signal.start, signal.start + signal.length)  # bit numbers, LSB of byte 0 first
            self.bytes = sorted({p // 8 for p in positions})
        else:  # Motorola: start is the MSB; count positions MSB of byte 0 first
            first = 8 * (signal.start // 8) + 7 - signal.start % 8
            self.shift = 8 * length - first - signal.length
            self.bytes = sorted({p // 8 for p in range(first, first + signal.length)})
        if self.shift < 0 or self.bytes[-1] >= length:
            raise ValueError(f"checksum signal {signal.name} does not fit in {length} bytes")
        self.length = length

    def read(self, data) -> int:
        return (int.from_bytes(data, self.order) >> self.shift) & self.mask

    def write(self, data: bytearray, value: int) -> None:
        whole = int.from_bytes(data, self.order) & ~(self.mask << self.shift) | (value & self.mask) << self.shift
        data[:] = whole.to_bytes(self.length, self.order)


class CanestCrc:
    """CRC-8/SAE-J1850 over the frame ID's two little-endian bytes and the data but the checksum byte."""

    def __init__(self, signal):
        self.index = integrity.checksum_byte(signal)

    def ok(self, frame_id: int, data) -> bool:
        return integrity.checksum_ok(frame_id, data, self.index)

    def seal(self, frame_id: int, data: bytearray) -> bytes:
        return integrity.seal(frame_id, data, self.index)


class BrandChecksum:
    """opendbc's checksum function of a brand, called as opendbc's CAN parser and packer call it."""

    def __init__(self, algorithm: str, signal, length: int, feature: str):
        dbc = DependencyError.require("opendbc.can.dbc", f"{feature} (checksum algorithm {algorithm})",
                                      OPENDBC_INSTALL)
        self.function = dbc.get_checksum_state(BRANDS[algorithm]).calc_checksum
        self.field = BitField(signal, length)
        self.signal = _opendbc_signal(dbc.Signal, signal)

    def ok(self, frame_id: int, data) -> bool:
        return self.function(frame_id, self.signal, bytearray(data)) == self.field.read(data)

    def seal(self, frame_id: int, data: bytearray) -> bytes:
        self.field.write(data, self.function(frame_id, self.signal, bytearray(data)))
        return bytes(data)


def _opendbc_signal(opendbc_signal, signal):
    """opendbc's description (``opendbc.can.dbc.Signal``) of a cantools signal (its functions read the start bit
    of some)."""
    little = signal.byte_order == "little_endian"
    if little:
        msb, lsb = signal.start + signal.length - 1, signal.start
    else:
        last = 8 * (signal.start // 8) + 7 - signal.start % 8 + signal.length - 1
        msb, lsb = signal.start, 8 * (last // 8) + 7 - last % 8
    return opendbc_signal(signal.name, signal.start, msb, lsb, signal.length, signal.is_signed, signal.scale,
                          signal.offset, little)


def _reflect(value: int, width: int) -> int:
    return int(f"{value:0{width}b}"[::-1], 2)


class GenericCrc:
    """A CRC given by its Rocksoft-model parameters over a chosen range of data bytes and a data ID."""

    def __init__(self, crc: CrcParameters, signal, length: int):
        if crc.width not in CRC_WIDTHS:
            raise ValueError(f"width must be one of {', '.join(map(str, CRC_WIDTHS))}, got {crc.width}")
        self.field = BitField(signal, length)
        if signal.length != crc.width or len(self.field.bytes) * 8 != crc.width:
            raise ValueError(f"checksum signal {signal.name} must fill {crc.width // 8} whole byte(s) for a "
                             f"{crc.width}-bit CRC")
        last = length - 1 if crc.last_byte is None else crc.last_byte
        if not 0 <= crc.first_byte <= last < length:
            raise ValueError(f"bytes [{crc.first_byte}, {last}] must lie within the frame's {length} bytes")
        self.covered = [i for i in range(crc.first_byte, last + 1) if i not in self.field.bytes]
        self.data_id = bytes(crc.data_id)
        self.id_first = crc.data_id_at == "start"
        start = _reflect(crc.init, crc.width) if crc.reflect_in else crc.init
        self.function = crcmod.mkCrcFun((1 << crc.width) | crc.polynomial, initCrc=start, rev=crc.reflect_in, xorOut=0)
        self.reflect_result = crc.reflect_in != crc.reflect_out
        self.width, self.xor_out = crc.width, crc.xor_out

    def value(self, data) -> int:
        covered = bytes(map(data.__getitem__, self.covered))
        register = self.function(self.data_id + covered if self.id_first else covered + self.data_id)
        return (_reflect(register, self.width) if self.reflect_result else register) ^ self.xor_out

    def ok(self, frame_id: int, data) -> bool:
        return self.value(data) == self.field.read(data)

    def seal(self, frame_id: int, data: bytearray) -> bytes:
        self.field.write(data, self.value(data))
        return bytes(data)


def make_checksum(algorithm: str, crc: CrcParameters | None, signal, length: int, feature: str):
    """The checker of ``signal`` in frames of ``length`` bytes; ValueError if the signal does not suit it,
    :class:`DependencyError` if a brand's algorithm lacks opendbc."""
    if algorithm == "canest":
        return CanestCrc(signal)
    if algorithm == "crc":
        return GenericCrc(crc, signal, length)
    return BrandChecksum(algorithm, signal, length, feature)
