"""A frame whose CRC is right can still carry nonsense: 200,000 random frames with valid checksums reach
the host's decoder, and exactly those whose content docs/firmware-protocol.md allows become messages."""
from __future__ import annotations

import random
import struct

from firmware_bridge import framing
from firmware_bridge import messages as m

FRAMES = 200_000
SEED = 40
SIZES = {int(i): cls.LAYOUT.size for i, cls in m.MESSAGES.items()}


def allowed(msg_id: int, p: bytes) -> bool:
    """The protocol document's rules (section 6), written out apart from the decoder's code: a message from a
    peer of protocol 1.0 has exactly its layout's length, its reserved bits 0, its values in range."""
    if msg_id not in SIZES or len(p) < SIZES[msg_id]:
        return False
    if msg_id in (m.MsgId.HELLO, m.MsgId.HELLO_ACK):
        if len(p) > SIZES[msg_id] and p[1] == 0:   # longer only from a newer minor version, which says so
            return False
    elif len(p) != SIZES[msg_id]:
        return False
    if msg_id == m.MsgId.HELLO:
        _, _, period, timeout = struct.unpack_from("<BBHH", p)
        return period >= 1 and timeout >= 1
    if msg_id == m.MsgId.HELLO_ACK:
        name = p[5:13].rstrip(b"\0")
        return all(0x20 <= c <= 0x7E for c in name)
    if msg_id == m.MsgId.HEARTBEAT:
        return p[4] & 0xF0 == 0
    if msg_id == m.MsgId.WARNING:
        return p[0] in (0, 1, 2)
    if msg_id == m.MsgId.VEHICLE_SIGNALS:
        speed, flags = struct.unpack_from("<HB", p)
        return flags & 0xF8 == 0 and (speed == 0xFFFF or speed <= 15000)
    return False


def random_frame(rng: random.Random) -> tuple[int, bytes]:
    """An id (half of them a defined one) and a payload (half of them of that message's length), random bytes."""
    known = rng.random() < 0.5
    msg_id = rng.choice(list(SIZES)) if known else rng.randrange(256)
    n = SIZES[msg_id] + (rng.random() < 0.1) if known and rng.random() < 0.6 else rng.randrange(65)
    return msg_id, bytes(rng.randrange(256) for _ in range(n))


def test_200000_random_frames_with_valid_crc_become_messages_only_when_their_content_is_valid():
    rng = random.Random(SEED)
    dec = framing.FrameDecoder()
    accepted = valid = 0
    for seq in range(FRAMES):
        msg_id, payload = random_frame(rng)
        got = dec.feed_messages(framing.encode_frame(msg_id, seq % 256, payload))
        ok = allowed(msg_id, payload)
        assert (len(got) == 1) == ok, (hex(msg_id), payload.hex(), got, dec.last_error)
        if got:
            assert got[0][1].MSG_ID == msg_id and got[0][1].pack() == payload[:SIZES[msg_id]] or \
                msg_id == m.MsgId.VEHICLE_SIGNALS and got[0][1].pack()[:2] == payload[:2]
        accepted += len(got)
        valid += ok
    s = dec.stats
    assert s.frames_ok == FRAMES and s.frame_errors() == 0
    assert accepted == valid and s.unknown_messages + s.bad_payloads + accepted == FRAMES
    assert 1000 < accepted < FRAMES // 4, accepted   # both outcomes are exercised
