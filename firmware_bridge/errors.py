"""Protocol errors: one exception type per thing that can be wrong with received or outgoing bytes.

Every type is a `ProtocolError` (a `ValueError`), so a caller that only wants "bad input" catches one
type; the receive path (`framing.FrameDecoder`) catches them all and counts them by type instead of
raising. The message of each exception names what was wrong (field, offset, expected and actual).
"""
from __future__ import annotations


class ProtocolError(ValueError):
    """Base class: bytes or values that do not follow docs/firmware-protocol.md."""


class CobsError(ProtocolError):
    """The bytes between two delimiters are not a valid COBS encoding."""


class FrameLengthError(ProtocolError):
    """A frame shorter than header + CRC, or longer than the maximum frame length."""


class CrcError(ProtocolError):
    """The CRC-32C at the end of a frame does not match its contents."""


class UnknownMessageError(ProtocolError):
    """A frame with a good CRC whose message id this protocol version does not define."""


class PayloadLengthError(ProtocolError):
    """A known message whose payload is shorter than its layout."""


class FieldRangeError(ProtocolError):
    """A field value outside the range its message defines (on encode or decode)."""
