"""Firmware bridge, the bytes: CRC-32C, COBS, message layouts, the streaming frame decoder under
garbage, truncation and bit flips, a seeded fuzz run, and the protocol document's examples.
The link against the MCU simulator over a pseudo-terminal is in tests/firmware/test_link.py."""
from __future__ import annotations

import random
import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from firmware_bridge import cobs, crc, examples, framing
from firmware_bridge import messages as m
from firmware_bridge.errors import FieldRangeError
from firmware_bridge.errors import (CobsError, CrcError, FieldRangeError, FrameLengthError, PayloadLengthError,
                                    ProtocolError, UnknownMessageError)

DOC = Path(__file__).resolve().parent.parent / "docs" / "firmware-protocol.md"


def random_message(rng: random.Random) -> m.Message:
    """A valid message of a random type with random field values (None where allowed)."""

    def centi():
        return None if rng.random() < 0.1 else rng.randrange(0, 65535) / 100

    kind = rng.randrange(5)
    if kind == 0:
        return m.Hello(rng.randrange(256), rng.randrange(256), rng.randrange(1, 65536), rng.randrange(1, 65536))
    if kind == 1:
        name = "".join(chr(rng.randrange(0x20, 0x7F)) for _ in range(rng.randrange(9)))
        return m.HelloAck(*(rng.randrange(256) for _ in range(5)), fw_name=name)
    if kind == 2:
        return m.Heartbeat(rng.randrange(2**32), rng.randrange(16))
    if kind == 3:
        return m.FcwWarning(rng.randrange(3), centi(), centi())
    speed = centi()
    return m.VehicleSignals(None if speed is None else min(speed, m.MAX_SPEED_MPS), rng.random() < 0.5,
                            rng.random() < 0.5, rng.random() < 0.5)


def frame_stream(msgs: list[m.Message], first_seq: int = 0):
    """Wire bytes for the messages (seq counting up), the frames a receiver must get back, and each
    frame's byte span [start, end) on the wire, delimiters included."""
    wire, frames, spans = bytearray(), [], []
    for i, msg in enumerate(msgs):
        seq = (first_seq + i) % 256
        start = len(wire)
        wire += framing.encode_message(msg, seq)
        frames.append(framing.Frame(msg.MSG_ID, seq, msg.pack()))
        spans.append((start, len(wire)))
    return bytes(wire), frames, spans


def is_subsequence(got: list, sent: list) -> bool:
    it = iter(sent)
    return all(any(g == s for s in it) for g in got)


def nonempty_runs(data: bytes) -> int:
    return sum(1 for part in data.split(b"\x00") if part)


# ---- CRC-32C ---------------------------------------------------------------------------------------

@pytest.mark.parametrize("data,check", [
    (b"123456789", 0xE3069283),  # the catalogue check value
    (b"", 0x00000000),
    (bytes(32), 0x8A9136AA),  # RFC 3720 B.4
    (b"\xff" * 32, 0x62A8AB43),
    (bytes(range(32)), 0x46DD794E),
    (bytes(range(31, -1, -1)), 0x113FDB5C),
])
def test_crc32c_test_vectors(data, check):
    assert crc.crc32c(data) == check
    assert crc.crc32c_bitwise(data) == check


def test_crc32c_table_matches_the_bitwise_definition_and_residue_holds():
    rng = random.Random(7)
    for n in range(0, 300, 7):
        data = rng.randbytes(n)
        value = crc.crc32c(data)
        assert value == crc.crc32c_bitwise(data)
        assert crc.crc32c(data + value.to_bytes(4, "little")) == crc.GOOD_FRAME == 0x48674BC7


def test_crc32c_detects_every_error_of_up_to_5_bits_in_the_longest_frame():
    """Hamming distance >= 6 over a 70-byte frame, proven by enumeration of syndromes.

    The CRC is linear: a set of bit errors goes undetected iff the XOR of the single-bit syndromes is 0.
    Every single-bit syndrome has odd weight, so every odd number of errors (1, 3, 5) leaves an odd, non-
    zero syndrome; all single syndromes distinct rules out 2-bit errors; all pair-XORs distinct rules
    out 4-bit errors.
    """
    data_len = framing.MAX_FRAME_LEN - framing.CRC_LEN
    base = crc.crc32c(bytes(data_len))
    syndromes = []
    for bit in range(data_len * 8):
        d = bytearray(data_len)
        d[bit // 8] ^= 1 << (bit % 8)
        syndromes.append(crc.crc32c(bytes(d)) ^ base)
    syndromes += [1 << k for k in range(32)]  # errors in the CRC field itself
    assert len(syndromes) == 560
    assert all(bin(s).count("1") % 2 == 1 for s in syndromes)
    s = np.array(syndromes, dtype=np.uint64)
    assert len(np.unique(s)) == 560
    a, b = np.triu_indices(len(s), 1)
    pairs = s[a] ^ s[b]
    assert len(pairs) == 156_520
    assert len(np.unique(pairs)) == len(pairs)


# ---- COBS ------------------------------------------------------------------------------------------

R = bytes.fromhex
COBS_VECTORS = [  # (data, encoding): Cheshire & Baker's rules, the usual published examples
    (b"", R("01")),
    (R("00"), R("0101")),
    (R("0000"), R("010101")),
    (R("001100"), R("01021101")),
    (R("11220033"), R("0311220233")),
    (R("11223344"), R("0511223344")),
    (R("11000000"), R("0211010101")),
    (bytes(range(1, 255)), R("ff") + bytes(range(1, 255))),  # 254 non-zero: one full block, no 01 after
    (R("00") + bytes(range(1, 255)), R("01ff") + bytes(range(1, 255))),
    (bytes(range(1, 256)), R("ff") + bytes(range(1, 255)) + R("02ff")),  # 255 non-zero bytes
    (bytes(range(2, 256)) + R("00"), R("ff") + bytes(range(2, 256)) + R("0101")),
    (bytes(range(3, 256)) + R("0001"), R("fe") + bytes(range(3, 256)) + R("0201")),
    (bytes(300), bytes([1]) * 301),  # all zeros
    (b"\xaa" * 508, b"\xff" + b"\xaa" * 254 + b"\xff" + b"\xaa" * 254),  # two full blocks exactly
]


@pytest.mark.parametrize("data,encoded", COBS_VECTORS, ids=lambda v: f"{len(v)}B" if isinstance(v, bytes) else None)
def test_cobs_vectors(data, encoded):
    assert cobs.encode(data) == encoded
    assert cobs.decode(encoded) == data
    assert 0 not in encoded
    assert len(encoded) <= cobs.max_encoded_len(len(data))


def test_cobs_round_trip_random_data_of_every_length_up_to_600():
    rng = random.Random(11)
    for n in range(601):
        data = bytes(0 if rng.random() < 0.2 else rng.randrange(1, 256) for _ in range(n))
        enc = cobs.encode(data)
        assert 0 not in enc and len(enc) <= cobs.max_encoded_len(n)
        assert cobs.decode(enc) == data


@pytest.mark.parametrize("bad,where", [(b"", "empty"), (R("0511"), "offset 0"), (R("021100"), "offset 2"),
                                       (R("0311"), "claims 2 bytes"), (R("00"), "offset 0"),
                                       (R("031100"), "data byte 0x00 at offset 2")])
def test_cobs_decode_rejects_malformed_input_naming_the_offset(bad, where):
    with pytest.raises(CobsError, match=where):
        cobs.decode(bad)


# ---- messages --------------------------------------------------------------------------------------

ROUND_TRIPS = [
    m.Hello(), m.Hello(3, 7, 1, 65535),
    m.HelloAck(), m.HelloAck(1, 2, 3, 4, 5, "ABCDEFGH"), m.HelloAck(fw_name="x y~"),
    m.Heartbeat(), m.Heartbeat(2**32 - 1, 0x0F),
    m.FcwWarning(), m.FcwWarning(m.WarningLevel.WARNING, 1.85, 23.4), m.FcwWarning(1, 0.0, 655.34),
    m.FcwWarning(2, 655.34, None),
    m.VehicleSignals(), m.VehicleSignals(27.78, True, False, True), m.VehicleSignals(0.0, False, True, False),
    m.VehicleSignals(m.MAX_SPEED_MPS, True, True, True),
] + [msg for _, msg, _ in examples.EXAMPLES]


@pytest.mark.parametrize("msg", ROUND_TRIPS, ids=repr)
def test_every_message_round_trips_through_payload_and_frame(msg):
    payload = msg.pack()
    assert len(payload) == msg.LAYOUT.size
    assert m.decode(msg.MSG_ID, payload) == msg
    wire = framing.encode_message(msg, 200)
    assert wire[0] == 0 and wire[-1] == 0 and 0 not in wire[1:-1]
    dec = framing.FrameDecoder()
    assert dec.feed_messages(wire) == [(200, msg)]
    assert dec.stats.frames_ok == 1 and dec.stats.frame_errors() == 0


def test_layout_sizes_and_ids_are_the_documented_ones():
    sizes = {name: cls.LAYOUT.size for name, cls in ((c.MSG_ID.name, c) for c in m.MESSAGES.values())}
    assert sizes == {"HELLO": 6, "HELLO_ACK": 13, "HEARTBEAT": 5, "WARNING": 5, "VEHICLE_SIGNALS": 3}
    assert [int(i) for i in m.MESSAGES] == [0x01, 0x02, 0x03, 0x10, 0x20]
    assert (m.PROTOCOL_MAJOR, m.PROTOCOL_MINOR) == (1, 0)


def test_fixed_point_scaling_and_not_available():
    assert m.FcwWarning(2, 1.85, 23.4).pack() == R("02b9002409")  # 185 cs, 2340 cm
    assert m.FcwWarning(0, None, None).pack() == R("00ffffffff")
    assert m.VehicleSignals(None, brake=True).pack() == R("ffff01")
    assert m.VehicleSignals(13.89, turn_left=True, turn_right=True).pack() == R("6d0506")
    assert m.decode(m.MsgId.WARNING, R("01feff0a00")) == m.FcwWarning(1, 655.34, 0.1)
    # reserved bits: ignored from a peer of a newer minor version (it may use them), nonsense from one of ours
    assert m.decode(m.MsgId.VEHICLE_SIGNALS, R("e803f8"), peer_minor=m.PROTOCOL_MINOR + 1) == m.VehicleSignals(10.0)
    with pytest.raises(FieldRangeError, match="reserved bits"):
        m.decode(m.MsgId.VEHICLE_SIGNALS, R("e803f8"))


@given(ttc=st.floats(0, 655.34), rng=st.one_of(st.none(), st.floats(0, 655.34)), level=st.sampled_from([0, 1, 2]))
def test_warning_fixed_point_error_is_at_most_half_a_count(ttc, rng, level):
    back = m.decode(m.MsgId.WARNING, m.FcwWarning(level, ttc, rng).pack())
    assert abs(back.ttc_s - ttc) <= 0.005 + 1e-9
    assert (back.lead_range_m is None) == (rng is None)
    assert back.pack() == m.FcwWarning(level, ttc, rng).pack()  # decode -> encode is exact


@pytest.mark.parametrize("make,field", [
    (lambda: m.FcwWarning(3, 1.0, 1.0), "WARNING.level=3"),
    (lambda: m.FcwWarning(True, 1.0, 1.0), "WARNING.level=True"),
    (lambda: m.FcwWarning(1, -0.5, 1.0), "WARNING.ttc_s=-0.5"),
    (lambda: m.FcwWarning(1, 655.35, 1.0), "WARNING.ttc_s=655.35"),
    (lambda: m.FcwWarning(1, float("nan"), 1.0), "WARNING.ttc_s=nan"),
    (lambda: m.FcwWarning(1, 1.0, float("inf")), "WARNING.lead_range_m=inf"),
    (lambda: m.VehicleSignals(-1.0), "VEHICLE_SIGNALS.speed_mps=-1.0"),
    (lambda: m.VehicleSignals(1.0, brake=1), "VEHICLE_SIGNALS.brake=1"),
    (lambda: m.Hello(256), "HELLO.protocol_major=256"),
    (lambda: m.Hello(heartbeat_period_ms=0), "HELLO.heartbeat_period_ms=0"),
    (lambda: m.Hello(host_timeout_ms=70000), "HELLO.host_timeout_ms=70000"),
    (lambda: m.Heartbeat(-1), "HEARTBEAT.uptime_ms=-1"),
    (lambda: m.Heartbeat(0, 256), "HEARTBEAT.status=256"),
    (lambda: m.HelloAck(fw_name="NINECHARS"), "HELLO_ACK.fw_name='NINECHARS'"),
    (lambda: m.HelloAck(fw_name="caf\u00e9"), "HELLO_ACK.fw_name"),
    (lambda: m.HelloAck(fw_major=-1), "HELLO_ACK.fw_major=-1"),
])
def test_out_of_range_fields_raise_field_range_error_naming_the_field(make, field):
    with pytest.raises(FieldRangeError) as e:
        make()
    assert field in str(e.value)
    assert isinstance(e.value, ProtocolError) and isinstance(e.value, ValueError)


def test_decoding_bad_payloads_raises_the_specific_error():
    with pytest.raises(PayloadLengthError, match="WARNING payload is 4 bytes, its layout needs 5"):
        m.decode(m.MsgId.WARNING, R("02b90024"))
    with pytest.raises(UnknownMessageError, match="0x7F"):
        m.decode(0x7F, b"")
    with pytest.raises(FieldRangeError, match="WARNING.level=9"):
        m.decode(m.MsgId.WARNING, R("09ffffffff"))
    with pytest.raises(FieldRangeError, match="NUL before"):
        m.decode(m.MsgId.HELLO_ACK, R("0100000000") + b"AB\0C\0\0\0\0")
    with pytest.raises(FieldRangeError, match="fw_name"):
        m.decode(m.MsgId.HELLO_ACK, R("0100000000") + b"\xff" * 8)
    # A longer payload from a peer of a later minor version (it appended fields) decodes, the extra bytes
    # ignored; from a peer of this version it is nonsense.
    longer = R("02b9002409") + b"\x55\x66"
    assert m.decode(m.MsgId.WARNING, longer, peer_minor=m.PROTOCOL_MINOR + 1) == m.FcwWarning(2, 1.85, 23.4)
    with pytest.raises(PayloadLengthError, match="WARNING payload is 7 bytes, its layout in protocol 1.0 is 5"):
        m.decode(m.MsgId.WARNING, longer)


# ---- framing ---------------------------------------------------------------------------------------

def test_frame_layout_and_limits():
    raw = framing.pack_frame(0x10, 7, R("02b9002409"))
    assert raw[:2] == R("1007") and raw[2:-4] == R("02b9002409")
    assert int.from_bytes(raw[-4:], "little") == crc.crc32c(raw[:-4])
    assert framing.unpack_frame(raw) == framing.Frame(0x10, 7, R("02b9002409"))
    assert (framing.MIN_FRAME_LEN, framing.MAX_FRAME_LEN, framing.MAX_ENCODED_LEN) == (6, 70, 71)
    longest = framing.encode_frame(0x20, 1, b"\x01" * 64)
    assert len(longest) == framing.MAX_ENCODED_LEN + 2
    assert framing.FrameDecoder().feed(longest) == [framing.Frame(0x20, 1, b"\x01" * 64)]
    with pytest.raises(FrameLengthError, match="65 bytes"):
        framing.pack_frame(0x20, 1, bytes(65))
    with pytest.raises(FrameLengthError):
        framing.unpack_frame(raw[:5])
    with pytest.raises(CrcError, match="computed over 7 bytes"):
        framing.unpack_frame(raw[:-1] + bytes([raw[-1] ^ 0x80]))


def test_decoder_output_is_the_same_for_any_chunking():
    rng = random.Random(3)
    wire, frames, _ = frame_stream([random_message(rng) for _ in range(300)])
    wire = wire + rng.randbytes(500) + wire  # garbage in the middle as well
    whole = framing.FrameDecoder()
    expected = whole.feed(wire)
    assert expected == frames + frames
    one = framing.FrameDecoder()
    assert [f for b in wire for f in one.feed(bytes([b]))] == expected
    for trial in range(20):
        dec, out, i = framing.FrameDecoder(), [], 0
        while i < len(wire):
            n = rng.choice([1, 2, 3, 7, 16, 64, 500, 4096])
            out += dec.feed(wire[i:i + n])
            i += n
        assert out == expected
        assert dec.stats == whole.stats == one.stats


def test_every_good_frame_after_garbage_is_decoded_and_garbage_is_counted_exactly():
    rng = random.Random(5)
    msgs = [random_message(rng) for _ in range(400)]
    wire, frames, _ = frame_stream(msgs)
    stream, expected_errors, garbage_bytes = bytearray(), 0, 0
    for i, msg in enumerate(msgs):
        if rng.random() < 0.5:  # random garbage, zeros included, before half of the frames
            garbage = rng.randbytes(rng.randrange(1, 120))
            stream += garbage
            expected_errors += nonempty_runs(garbage)
            garbage_bytes += len(garbage) - garbage.count(0)
        stream += framing.encode_message(msg, i % 256)
    dec = framing.FrameDecoder()
    got = dec.feed(bytes(stream))
    assert got == frames  # every one of the 400, in order
    assert dec.stats.frames_ok == 400
    assert dec.stats.frame_errors() == expected_errors
    assert dec.stats.bytes_discarded == garbage_bytes
    assert expected_errors > 150  # the test did inject a lot


def test_idle_zeros_are_ignored_and_an_overlong_run_is_one_length_error():
    frame = framing.encode_message(m.Heartbeat(1, 0), 1)
    dec = framing.FrameDecoder()
    assert dec.feed(bytes(50) + frame + bytes(50)) == [framing.Frame(0x03, 1, m.Heartbeat(1, 0).pack())]
    assert dec.stats.frame_errors() == 0 and dec.stats.bytes_discarded == 0
    dec.feed(b"\x07" * 1000)  # no delimiter for 1000 bytes (e.g. a wrong baud rate)
    assert dec.stats.length_errors == 1
    assert dec.feed(frame) == [framing.Frame(0x03, 1, m.Heartbeat(1, 0).pack())]
    assert dec.stats.length_errors == 1 and dec.stats.bytes_discarded == 1000


def test_truncated_frames_are_dropped_and_the_next_frame_survives_at_every_cut_point():
    msgs = [msg for _, msg, _ in examples.EXAMPLES]
    for victim in msgs:
        encoded = framing.encode_message(victim, 9)[:-1]  # without its closing 0x00
        for cut in range(1, len(encoded)):  # every length of the cut frame, leading 0x00 kept
            nxt = m.VehicleSignals(3.0, brake=True)
            dec = framing.FrameDecoder()
            got = dec.feed_messages(encoded[:cut] + framing.encode_message(nxt, 10))
            assert got == [(10, nxt)], (victim, cut)
            assert dec.stats.frame_errors() == (1 if cut > 1 else 0)
            assert dec.stats.frames_ok == 1


def test_every_single_bit_flip_loses_only_the_frame_it_hits():
    msgs = [msg for _, msg, _ in examples.EXAMPLES]
    wire, frames, spans = frame_stream(msgs)
    for bit in range(len(wire) * 8):
        bad = bytearray(wire)
        bad[bit // 8] ^= 1 << (bit % 8)
        dec = framing.FrameDecoder()
        got = dec.feed(bytes(bad) + b"\x00")  # an idle 0x00 after, in case the last delimiter was hit
        hit = next(i for i, (a, b) in enumerate(spans) if a <= bit // 8 < b)
        # Stuffed byte or delimiter: that frame is lost (CRC, COBS or length error), its neighbours
        # are intact thanks to their own delimiters, and nothing else comes out.
        assert got == frames[:hit] + frames[hit + 1:], bit
        assert dec.stats.frame_errors() >= 1


def test_feed_messages_counts_unknown_ids_and_bad_payloads():
    dec = framing.FrameDecoder()
    stream = (framing.encode_frame(0x7F, 1, b"future") + framing.encode_frame(m.MsgId.WARNING, 2, R("09ffffffff"))
              + framing.encode_frame(m.MsgId.VEHICLE_SIGNALS, 3, R("01")) + framing.encode_message(m.Heartbeat(5), 4))
    assert dec.feed_messages(stream) == [(4, m.Heartbeat(5))]
    s = dec.stats
    assert (s.frames_ok, s.unknown_messages, s.bad_payloads, s.frame_errors()) == (4, 1, 2, 0)
    assert "VEHICLE_SIGNALS payload is 1 bytes" in dec.last_error
    dec.feed(framing.encode_message(m.Heartbeat(5), 4)[:-3])
    dec.reset()
    assert dec.stats.bytes_discarded == 10


def test_a_long_run_of_random_garbage_never_yields_a_frame():
    dec = framing.FrameDecoder()
    garbage = random.Random(99).randbytes(300_000)
    assert dec.feed(garbage + b"\x00") == []
    assert dec.stats.frames_ok == 0
    assert dec.stats.frame_errors() == nonempty_runs(garbage) > 1000


FUZZ_ITERATIONS = 20_000


def test_fuzz_mutated_streams_never_raise_and_never_invent_a_frame():
    """20,000 streams of valid frames with 1-4 random mutations each (bit flip, byte replaced,
    inserted or deleted, a frame cut short, a garbage burst), fed in random chunks: the decoder
    never raises, returns only frames that were sent, in order, and every frame no mutation
    touched."""
    rng = random.Random(20240611)
    msgs = [random_message(rng) for _ in range(2000)]
    pool = list(zip(frame_stream(msgs)[1], (framing.encode_message(msg, i % 256) for i, msg in enumerate(msgs))))
    totals = dict(sent=0, decoded=0, untouched=0, rejected=0)
    for _ in range(FUZZ_ITERATIONS):
        picks = rng.sample(pool, rng.randrange(1, 6))
        frames = [f for f, _ in picks]
        wire = b"".join(w for _, w in picks)
        spans, pos = [], 0
        for _, w in picks:
            spans.append((pos, pos + len(w)))
            pos += len(w)
        data, touched, shift = bytearray(wire), set(), [0] * len(frames)
        where = rng.sample(range(len(wire)), min(len(wire), rng.randrange(1, 5)))
        for p in sorted(where, reverse=True):  # distinct, from the end: positions are the original's
            kind = rng.randrange(6)
            hit = next(i for i, (a, b) in enumerate(spans) if a <= p < b)
            if kind == 0:
                data[p] ^= 1 << rng.randrange(8)
            elif kind == 1:
                data[p] = rng.randrange(256)
            elif kind == 2:
                del data[p]
                shift[hit] -= 1
            elif kind == 4:  # the rest of this frame, closing 0x00 included
                end = spans[hit][1] + shift[hit]
                shift[hit] -= end - p
                del data[p:end]
            else:  # a garbage burst, or (kind 5) one stray non-zero byte
                extra = rng.randbytes(rng.randrange(1, 40)) if kind == 3 else bytes([rng.randrange(1, 256)])
                data[p:p] = extra
                shift[hit] += len(extra)
                if p == spans[hit][0]:
                    continue  # inserted before the frame's leading 0x00: the frame is not touched
            touched.add(hit)
        dec, got, i = framing.FrameDecoder(), [], 0
        while i < len(data):
            n = rng.randrange(1, 40)
            got += dec.feed(bytes(data[i:i + n]))
            i += n
        assert is_subsequence(got, frames)
        untouched = [f for k, f in enumerate(frames) if k not in touched]
        assert is_subsequence(untouched, got)
        totals["sent"] += len(frames)
        totals["decoded"] += len(got)
        totals["untouched"] += len(untouched)
        totals["rejected"] += dec.stats.frame_errors()
    # The mutations did bite, and no corruption ever got through as a frame.
    assert totals["decoded"] >= totals["untouched"] > 0.3 * totals["sent"]
    assert totals["decoded"] < 0.8 * totals["sent"]
    assert totals["rejected"] > FUZZ_ITERATIONS


# ---- the protocol document -------------------------------------------------------------------------

def test_doc_examples_are_what_the_encoder_produces():
    text = DOC.read_text()
    block = re.search(r"<!-- examples:begin -->\n```text\n(.*?)```\n<!-- examples:end -->", text, re.S)
    assert block, "examples block missing from docs/firmware-protocol.md"
    assert block.group(1) == examples.render(), "regenerate with: python -m firmware_bridge.examples"


def test_doc_message_table_and_crc_check_match_the_code():
    text = DOC.read_text()
    rows = re.findall(r"^\| (0x[0-9a-f]{2}) \| ([A-Z_]+) \| (host|MCU|both) \| (\d+) \| (.+) \|$", text, re.M)
    assert sorted((int(i, 16), name, sender.lower(), int(size), when) for i, name, sender, size, when in rows) == [
        (cls.MSG_ID, cls.MSG_ID.name, cls.SENDER, cls.LAYOUT.size, cls.RATE) for cls in m.MESSAGES.values()]
    assert f"0x{crc.CHECK:08X}" in text and f"0x{crc.GOOD_FRAME:08X}" in text
    assert f"version {m.PROTOCOL_MAJOR}.{m.PROTOCOL_MINOR}" in text
