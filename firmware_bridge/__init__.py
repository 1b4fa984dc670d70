"""Serial link to the cabin MCU (buzzer/LED out, vehicle signals in); see docs/firmware-protocol.md.

Layers, one job per file: cobs (byte stuffing) -> crc (CRC-32C) -> messages (ids, layouts,
versions) -> framing (frames, streaming decoder) -> link (the host end, McuLink) and mcu_sim (the
MCU end, for tests and the bench).
"""
from .errors import ProtocolError
from .link import LinkConfig, LinkState, LinkThread, McuLink
from .messages import PROTOCOL_MAJOR, PROTOCOL_MINOR, WarningLevel

__all__ = ["LinkConfig", "LinkState", "LinkThread", "McuLink", "PROTOCOL_MAJOR", "PROTOCOL_MINOR",
           "ProtocolError", "WarningLevel"]
