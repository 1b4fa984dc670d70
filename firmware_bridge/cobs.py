"""COBS (Consistent Overhead Byte Stuffing, Cheshire & Baker 1999): the frame body contains no 0x00,
so 0x00 can delimit frames and a receiver resynchronises at the next 0x00 after any garbage.

Encoding: the data is cut at every 0x00 and after every run of 254 non-zero bytes; each block is
sent as one code byte (block length + 1) followed by the block's bytes. Code 0xFF means "254 bytes,
no zero follows"; any other code means "code - 1 bytes, then a zero" except for the last block, whose
implied zero is dropped. Overhead: one byte per started 254 bytes, at least one byte.

    encode(b"")                   == b"\\x01"
    encode(b"\\x00")               == b"\\x01\\x01"
    encode(b"\\x11\\x22\\x00\\x33")   == b"\\x03\\x11\\x22\\x02\\x33"
    encode(bytes(range(1, 255)))  == b"\\xff" + bytes(range(1, 255))   (no trailing 0x01)
"""
from __future__ import annotations

from .errors import CobsError

MAX_BLOCK = 254  # non-zero data bytes per block (code byte 0xFF)


def max_encoded_len(n: int) -> int:
    """Largest encoding of n data bytes (without the delimiter)."""
    return n + n // MAX_BLOCK + 1


def encode(data: bytes) -> bytes:
    """COBS-encode data; the result contains no 0x00 and carries no delimiter."""
    out = bytearray()
    runs = bytes(data).split(b"\x00")  # the zero-free runs; a zero stands after all but the last
    for k, run in enumerate(runs):
        i = 0
        while len(run) - i >= MAX_BLOCK:  # full blocks: code 0xFF, no zero implied
            out.append(0xFF)
            out += run[i:i + MAX_BLOCK]
            i += MAX_BLOCK
        rest = run[i:]
        if rest or i == 0 or k < len(runs) - 1:  # a full last block needs no empty block after it
            out.append(len(rest) + 1)
            out += rest
    return bytes(out)


def decode(encoded: bytes) -> bytes:
    """Decode one COBS block sequence (no delimiter); raise CobsError naming the bad offset."""
    if not encoded:
        raise CobsError("empty COBS frame (an encoding is at least one code byte)")
    out = bytearray()
    i, n = 0, len(encoded)
    while i < n:
        code = encoded[i]
        if code == 0:
            raise CobsError(f"code byte 0x00 at offset {i}")
        end = i + code
        if end > n:
            raise CobsError(f"block at offset {i} claims {code - 1} bytes but only {n - i - 1} follow")
        block = encoded[i + 1:end]
        zero = block.find(0)
        if zero >= 0:
            raise CobsError(f"data byte 0x00 at offset {i + 1 + zero}")
        out += block
        i = end
        if code != 0xFF and i < n:
            out.append(0)
    return bytes(out)
