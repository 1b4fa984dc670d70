"""The checksum on every Headway frame: CRC-8 SAE J1850.

Polynomial x^8 + x^4 + x^3 + x^2 + 1 (0x1D), initial value 0xFF, final XOR 0xFF, no reflection (the
CRC of AUTOSAR E2E profiles 1 and 2). Check value over ASCII "123456789": 0x4B. Input: the 11-bit id
as two bytes, low byte first, then every data byte except the checksum byte, in order. Including
the id means a frame that lands on a wrong id (a misconfigured gateway, a stuck bit in the
arbitration field) fails the check too.
"""
from __future__ import annotations

from typing import Iterable

POLY = 0x1D
INIT = 0xFF
XOR_OUT = 0xFF


def _table() -> tuple[int, ...]:
    table = []
    for byte in range(256):
        crc = byte
        for _ in range(8):
            crc = ((crc << 1) ^ POLY) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
        table.append(crc)
    return tuple(table)


_TABLE = _table()


def crc8_j1850(data: Iterable[int]) -> int:
    crc = INIT
    for b in data:
        crc = _TABLE[crc ^ b]
    return crc ^ XOR_OUT


def frame_checksum(frame_id: int, data: bytes, checksum_byte: int) -> int:
    """The checksum of a frame: CRC over id (low, high byte) and the data without its checksum byte."""
    return crc8_j1850((frame_id & 0xFF, (frame_id >> 8) & 0xFF,
                       *data[:checksum_byte], *data[checksum_byte + 1:]))
