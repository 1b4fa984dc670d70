"""Frames on the wire and the streaming decoder that finds them again after any garbage.

A frame, before stuffing, is

    msg_id (u8) | seq (u8) | payload (0..64 bytes) | CRC-32C of the bytes before it (u32, little-endian)

and it is sent as 0x00, COBS(frame), 0x00. The leading 0x00 ends whatever garbage or truncated frame
came before, so the frame itself arrives intact; consecutive 0x00 are idle and ignored.

`FrameDecoder.feed()` takes received bytes in chunks of any size (a byte at a time or a megabyte) and
returns the good frames in order; it never raises on bad input. Each rejected frame is counted
exactly once, by the first check it fails: COBS, then length, then CRC.
"""
from __future__ import annotations

import struct
from dataclasses import asdict, dataclass

from . import cobs, messages
from .crc import crc32c
from .errors import (CobsError, CrcError, FieldRangeError, FrameLengthError, PayloadLengthError,
                     UnknownMessageError)

HEADER = struct.Struct("<BB")  # msg_id, seq
CRC_LEN = 4
MIN_FRAME_LEN = HEADER.size + CRC_LEN  # 6: a message with an empty payload
MAX_FRAME_LEN = HEADER.size + messages.MAX_PAYLOAD_LEN + CRC_LEN  # 70
MAX_ENCODED_LEN = cobs.max_encoded_len(MAX_FRAME_LEN)  # 71: longer without a 0x00 is a length error
DELIMITER = b"\x00"


@dataclass(frozen=True)
class Frame:
    msg_id: int
    seq: int
    payload: bytes


def pack_frame(msg_id: int, seq: int, payload: bytes) -> bytes:
    """The frame before stuffing: header, payload, CRC."""
    if not 0 <= msg_id <= 0xFF or not 0 <= seq <= 0xFF:
        raise FrameLengthError(f"msg_id={msg_id} and seq={seq} must each fit one byte")
    if len(payload) > messages.MAX_PAYLOAD_LEN:
        raise FrameLengthError(f"payload is {len(payload)} bytes, at most {messages.MAX_PAYLOAD_LEN}")
    body = HEADER.pack(msg_id, seq) + bytes(payload)
    return body + crc32c(body).to_bytes(CRC_LEN, "little")


def encode_frame(msg_id: int, seq: int, payload: bytes) -> bytes:
    """The bytes to write: 0x00, COBS(frame), 0x00."""
    return DELIMITER + cobs.encode(pack_frame(msg_id, seq, payload)) + DELIMITER


def encode_message(msg: messages.Message, seq: int) -> bytes:
    return encode_frame(msg.MSG_ID, seq, msg.pack())


def unpack_frame(raw: bytes) -> Frame:
    """Check length and CRC of an unstuffed frame."""
    if not MIN_FRAME_LEN <= len(raw) <= MAX_FRAME_LEN:
        raise FrameLengthError(f"frame is {len(raw)} bytes, must be {MIN_FRAME_LEN}..{MAX_FRAME_LEN}")
    body = raw[:-CRC_LEN]
    got = int.from_bytes(raw[-CRC_LEN:], "little")
    want = crc32c(body)
    if got != want:
        raise CrcError(f"CRC 0x{got:08X} does not match 0x{want:08X} computed over {len(body)} bytes")
    msg_id, seq = HEADER.unpack_from(body)
    return Frame(msg_id, seq, bytes(body[HEADER.size:]))


def decode_frame(encoded: bytes) -> Frame:
    """One frame from the bytes between two delimiters."""
    return unpack_frame(cobs.decode(encoded))


@dataclass
class DecoderStats:
    frames_ok: int = 0  # frames that passed COBS, length and CRC (known message or not)
    crc_errors: int = 0
    cobs_errors: int = 0
    length_errors: int = 0  # shorter than MIN_FRAME_LEN, or no 0x00 within MAX_ENCODED_LEN bytes
    unknown_messages: int = 0  # good frame, message id not in this protocol version
    bad_payloads: int = 0  # good frame, known id, payload too short or a field out of range
    bytes_discarded: int = 0  # bytes of rejected frames and of partial frames dropped by reset()

    def frame_errors(self) -> int:
        return self.crc_errors + self.cobs_errors + self.length_errors

    def as_dict(self) -> dict[str, int]:
        return asdict(self)


class FrameDecoder:
    """Streaming frame decoder: feed() any chunks, get whole good frames; counts what it drops."""

    def __init__(self, max_encoded_len: int = MAX_ENCODED_LEN):
        self.max_encoded_len = max_encoded_len
        self.stats = DecoderStats()
        self.last_error: str | None = None  # text of the last rejection, for health reports
        # the peer's protocol minor version, once its HELLO or HELLO_ACK said it: a newer one may append fields
        self.peer_minor = messages.PROTOCOL_MINOR
        self._buf = bytearray()
        self._overflow = False  # too long: dropping bytes up to the next delimiter

    def reset(self) -> None:
        """Forget a partial frame (the port was closed): its bytes count as discarded."""
        self.stats.bytes_discarded += len(self._buf)
        self._buf.clear()
        self._overflow = False

    def feed(self, data: bytes) -> list[Frame]:
        data = bytes(data)
        frames: list[Frame] = []
        start, n = 0, len(data)
        while start < n:
            zero = data.find(0, start)
            end = n if zero < 0 else zero
            if self._overflow:
                self.stats.bytes_discarded += end - start
            else:
                self._buf += data[start:end]
                if len(self._buf) > self.max_encoded_len:
                    self._reject(FrameLengthError(f"no delimiter within {self.max_encoded_len} bytes"),
                                 len(self._buf))
                    self._buf.clear()
                    self._overflow = True
            if zero < 0:
                break
            if self._overflow:
                self._overflow = False
            elif self._buf:
                frame = self._close_frame()
                if frame is not None:
                    frames.append(frame)
            start = zero + 1
        return frames

    def feed_messages(self, data: bytes) -> list[tuple[int, messages.Message]]:
        """Like feed(), decoded to (seq, message); unknown ids and bad payloads are counted, dropped."""
        out = []
        for frame in self.feed(data):
            try:
                out.append((frame.seq, messages.decode(frame.msg_id, frame.payload, self.peer_minor)))
            except UnknownMessageError as e:
                self.stats.unknown_messages += 1
                self.last_error = str(e)
            except (PayloadLengthError, FieldRangeError) as e:
                self.stats.bad_payloads += 1
                self.last_error = str(e)
        return out

    def _close_frame(self) -> Frame | None:
        encoded = bytes(self._buf)
        self._buf.clear()
        try:
            frame = decode_frame(encoded)
        except (CobsError, FrameLengthError, CrcError) as e:
            self._reject(e, len(encoded))
            return None
        self.stats.frames_ok += 1
        return frame

    def _reject(self, error: Exception, nbytes: int) -> None:
        if isinstance(error, CobsError):
            self.stats.cobs_errors += 1
        elif isinstance(error, CrcError):
            self.stats.crc_errors += 1
        else:
            self.stats.length_errors += 1
        self.stats.bytes_discarded += nbytes
        self.last_error = str(error)
