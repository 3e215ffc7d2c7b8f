"""Rolling counters and checksums of CAN frames (input and output DBC alike).

Checksum: CRC-8/SAE-J1850 (poly 0x1D, init 0xFF, xor-out 0xFF; check value
0x4B for "123456789"; computed by crcmod's C extension, 0.2 us a frame) over
the two little-endian bytes of the frame ID
followed by every data byte except the one holding the checksum. The checksum
signal must fill exactly one byte. Counter: 4-bit (or the signal's width)
value incremented by one per frame, wrapping to zero.
"""
from __future__ import annotations

import crcmod

# crcmod's initCrc is the register's initial value XORed with xorOut: 0xFF ^ 0xFF.
_crc8 = crcmod.mkCrcFun(0x11D, initCrc=0x00, rev=False, xorOut=0xFF)


def checksum_byte(signal) -> int:
    """Index of the data byte a checksum signal occupies; ValueError if it is not one whole byte."""
    if signal.length != 8 or (signal.byte_order == "little_endian" and signal.start % 8 != 0) or \
            (signal.byte_order == "big_endian" and signal.start % 8 != 7):
        raise ValueError(f"checksum signal {signal.name} must occupy exactly one byte")
    return signal.start // 8


def frame_crc(frame_id: int, data: bytes, crc_index: int) -> int:
    payload = frame_id.to_bytes(4, "little")[:2] + data[:crc_index] + data[crc_index + 1:]
    return _crc8(payload)


def seal(frame_id: int, data: bytearray, crc_index: int) -> bytes:
    """Write the checksum into ``data`` and return it as bytes."""
    data[crc_index] = frame_crc(frame_id, data, crc_index)
    return bytes(data)


def checksum_ok(frame_id: int, data: bytes, crc_index: int) -> bool:
    return len(data) > crc_index and data[crc_index] == frame_crc(frame_id, data, crc_index)
