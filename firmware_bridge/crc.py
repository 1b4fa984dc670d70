"""CRC-32C (Castagnoli), the check value at the end of every frame.

Parameters (Rocksoft/Williams model, as in the CRC RevEng catalogue "CRC-32/ISCSI"):

    width 32, poly 0x1EDC6F41 (reflected form 0x82F63B78), init 0xFFFFFFFF,
    refin true, refout true, xorout 0xFFFFFFFF,
    check:   crc32c(b"123456789") == 0xE3069283
    residue: 0xB798B438 (before xorout), so crc32c(data + crc32c(data) as 4 bytes little-endian)
             == 0x48674BC7 for every data: a receiver may check a frame in one pass

More vectors (RFC 3720, appendix B.4): 32 x 0x00 -> 0x8A9136AA, 32 x 0xFF -> 0x62A8AB43,
bytes 0x00..0x1F -> 0x46DD794E, bytes 0x1F..0x00 -> 0x113FDB5C.

Why CRC-32C: Hamming distance 6 up to 5243 data bits (Koopman 2002), far above the longest frame
here (70 bytes), so every error of up to 5 bits in a frame is detected, every burst up to 32 bits,
and any other corruption slips through with probability about 2^-32. Hardware CRC units of many
MCUs with a programmable polynomial compute it; the bitwise loop below is the portable fallback.
"""
from __future__ import annotations

POLY_REFLECTED = 0x82F63B78
INIT = 0xFFFFFFFF
XOROUT = 0xFFFFFFFF
CHECK = 0xE3069283  # crc32c(b"123456789")
GOOD_FRAME = 0x48674BC7  # crc32c(data + CRC little-endian) for any data


def crc32c_bitwise(data: bytes) -> int:
    """The reference definition, one bit at a time (the same loop as the C in the protocol doc)."""
    crc = INIT
    for b in data:
        crc ^= b
        for _ in range(8):
            crc = (crc >> 1) ^ POLY_REFLECTED if crc & 1 else crc >> 1
    return crc ^ XOROUT


def _table() -> tuple[int, ...]:
    rows = []
    for i in range(256):
        c = i
        for _ in range(8):
            c = (c >> 1) ^ POLY_REFLECTED if c & 1 else c >> 1
        rows.append(c)
    return tuple(rows)


TABLE = _table()


def crc32c(data: bytes) -> int:
    """CRC-32C of data, one table look-up per byte."""
    crc = INIT
    table = TABLE
    for b in data:
        crc = (crc >> 8) ^ table[(crc ^ b) & 0xFF]
    return crc ^ XOROUT
