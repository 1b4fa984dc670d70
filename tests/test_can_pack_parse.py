"""Packer and parser: every Headway message round-trips over a python-can virtual bus; counters
wrap; the checksum is CRC-8 SAE J1850 and catches any flipped bit; bad frames are counted drops."""
from __future__ import annotations

import random

import can
import pytest

from app.can import CanPacker, CanParser, headway_database
from app.can.checksum import crc8_j1850, frame_checksum
from app.can.parser import MAX_BAD_COUNTER

# One realistic value set per message (and per page of HW_OBJECT), in DBC units.
SAMPLES = {
    "HW_FCW": {"FCW_LEVEL": 2, "FCW_AVAILABLE": 1, "TTC_SOURCE": 1, "TTC_USED_S": 1.87, "LEAD_RANGE_M": 23.45,
               "LEAD_RANGE_RATE_MPS": -12.5, "LEAD_ID": 17},
    "HW_LEAD": {"LEAD_ID": 17, "RANGE_M": 23.45, "LATERAL_M": -0.36, "RANGE_RATE_MPS": -12.5, "CONFIDENCE": 0.86},
    "HW_LEAD_TTC": {"LEAD_ID": 17, "TTC_RANGE_S": 1.87, "TTC_SCALE_S": 2.05},
    "HW_OBJECT_HEADER": {"OBJECT_COUNT": 3, "FRAME_NUMBER": 4711, "LEAD_ID": 17},
    "HW_OBJECT/0": {"OBJECT_INDEX": 2, "OBJECT_PAGE": 0, "OBJECT_ID": 17, "RANGE_M": 64.2, "LATERAL_M": 3.52,
                    "RANGE_RATE_MPS": 4.3},
    "HW_OBJECT/1": {"OBJECT_INDEX": 2, "OBJECT_PAGE": 1, "OBJECT_ID": 17, "AZIMUTH_RAD": -0.124, "WIDTH_RAD": 0.031,
                    "LANE": 1, "IN_PATH": 0, "CONFIDENCE": 0.64, "CONFIRMED": 1},
    "HW_STATUS": {"STATE": 2, "FAULT_EGO_SPEED_STALE": 1, "FAULT_CAN_ERROR": 1, "FRAME_RATE_HZ": 29.75,
                  "LATENCY_P99_MS": 41.5},
}


def resolution(db, name, signal):
    return db.get_message_by_name(name).get_signal_by_name(signal).scale


@pytest.fixture
def db():
    return headway_database()


def test_every_message_round_trips_over_a_virtual_bus(db):
    packer = CanPacker(db)
    parser = CanParser(db)
    with can.Bus(interface="virtual", channel="roundtrip") as tx, \
            can.Bus(interface="virtual", channel="roundtrip") as rx:
        for key, signals in SAMPLES.items():
            name = key.split("/")[0]
            tx.send(packer.pack(name, signals))
            got = rx.recv(timeout=1.0)
            assert got is not None, key
            decoded = parser.update(got)
            assert decoded is not None and decoded[0] == name, (key, parser.stats())
            values = decoded[1]
            for sig, v in signals.items():
                assert values[sig] == pytest.approx(v, abs=resolution(db, name, sig) / 2 + 1e-9), (key, sig)
            for sig in db.get_message_by_name(name).signals:  # left out: SNA (None) or raw 0
                if sig.name not in signals and sig.name not in ("COUNTER", "CHECKSUM") and \
                        (sig.multiplexer_ids is None or signals.get("OBJECT_PAGE") in sig.multiplexer_ids):
                    assert values[sig.name] in (None, 0), (key, sig.name)
    assert parser.accepted == len(SAMPLES) and not parser.drops


def test_not_available_goes_out_as_sna_and_comes_back_as_none(db):
    packer, parser = CanPacker(db), CanParser(db)
    msg = packer.pack("HW_FCW", {"FCW_LEVEL": 0, "FCW_AVAILABLE": 0, "TTC_USED_S": None,
                                 "LEAD_RANGE_M": float("nan"), "LEAD_RANGE_RATE_MPS": None, "LEAD_ID": 0})
    _, v = parser.update(msg)
    assert v["TTC_USED_S"] is None and v["LEAD_RANGE_M"] is None and v["LEAD_RANGE_RATE_MPS"] is None
    assert v["LEAD_ID"] == 0 and v["FCW_AVAILABLE"] == 0


def test_values_beyond_the_range_saturate_instead_of_failing(db):
    packer, parser = CanPacker(db), CanParser(db)
    _, v = parser.update(packer.pack("HW_LEAD_TTC", {"LEAD_ID": 1, "TTC_RANGE_S": 75.0, "TTC_SCALE_S": -3.0}))
    assert v["TTC_RANGE_S"] == pytest.approx(20.46) and v["TTC_SCALE_S"] == 0.0
    _, v = parser.update(packer.pack("HW_LEAD", {"LEAD_ID": 1, "RANGE_M": 250.0, "LATERAL_M": -30.0}))
    assert v["RANGE_M"] == pytest.approx(204.7) and v["LATERAL_M"] == pytest.approx(-20.44)


def test_unknown_names_are_programming_errors(db):
    packer = CanPacker(db)
    with pytest.raises(KeyError, match="HW_NOPE"):
        packer.pack("HW_NOPE", {})
    with pytest.raises(KeyError, match="RANGE"):
        packer.pack("HW_LEAD", {"RANGE": 3.0})
    with pytest.raises(KeyError, match="OBJECT_PAGE"):
        packer.pack("HW_OBJECT", {"OBJECT_INDEX": 0})
    with pytest.raises(KeyError, match="AZIMUTH_RAD for OBJECT_PAGE = 0"):
        packer.pack("HW_OBJECT", {"OBJECT_PAGE": 0, "AZIMUTH_RAD": 0.1})


def test_rolling_counter_counts_per_message_and_wraps(db):
    packer, parser = CanPacker(db), CanParser(db)
    counters = [parser.update(packer.pack("HW_STATUS", {"STATE": 1}))[1]["COUNTER"] for _ in range(35)]
    assert counters == [i % 16 for i in range(35)]
    assert parser.update(packer.pack("HW_LEAD", {}))[1]["COUNTER"] == 0  # its own counter
    assert parser.counter_jumps == 0 and parser.accepted == 36


def test_crc8_sae_j1850_check_value_and_worked_example():
    assert crc8_j1850(b"123456789") == 0x4B  # the published check value of CRC-8/SAE-J1850
    assert crc8_j1850(b"") == 0x00
    # docs/can.md worked example: HW_FCW, level 2, TTC 1.87 s by range, lead 23.45 m closing 12.5 m/s, id 17
    data = bytes.fromhex("6e17d5e1581100")
    assert frame_checksum(0x600, data + b"\x00", 7) == crc8_j1850(bytes([0x00, 0x06]) + data) == 0xBF


def test_worked_example_matches_the_packer(db):
    msg = CanPacker(db).pack("HW_FCW", SAMPLES["HW_FCW"])
    assert msg.arbitration_id == 0x600 and bytes(msg.data).hex() == "6e17d5e1581100bf"


@pytest.mark.parametrize("key", sorted(SAMPLES))
def test_checksum_catches_every_single_flipped_bit(db, key):
    name = key.split("/")[0]
    good = CanPacker(db).pack(name, SAMPLES[key])
    for bit in range(64):
        parser = CanParser(db)
        data = bytearray(good.data)
        data[bit // 8] ^= 1 << (bit % 8)
        bad = can.Message(arbitration_id=good.arbitration_id, is_extended_id=False, data=data)
        assert parser.update(bad) is None, (key, bit)
        assert parser.drops == {"bad_checksum": 1}, (key, bit)


def test_a_frame_on_another_id_fails_the_checksum(db):
    good = CanPacker(db).pack("HW_LEAD", SAMPLES["HW_LEAD"])
    moved = can.Message(arbitration_id=0x602, is_extended_id=False, data=good.data)  # HW_LEAD_TTC's id
    parser = CanParser(db)
    assert parser.update(moved) is None and parser.drops == {"bad_checksum": 1}


def test_bad_frames_are_counted_by_reason_and_never_raise(db):
    packer, parser = CanPacker(db), CanParser(db)
    good = packer.pack("HW_STATUS", {"STATE": 1})
    frames = [
        can.Message(arbitration_id=0x123, is_extended_id=False, data=b"\x00" * 8),              # unknown id
        can.Message(arbitration_id=0x605, is_extended_id=True, data=good.data),                 # extended: unknown
        can.Message(arbitration_id=0x605, is_extended_id=False, data=good.data[:6]),            # short
        can.Message(arbitration_id=0x605, is_extended_id=False, data=bytes(good.data) + b"\x00", is_fd=True),
        can.Message(arbitration_id=0x605, is_extended_id=False, data=bytes(good.data[:7]) + b"\x00"),  # checksum
        can.Message(arbitration_id=0x605, is_extended_id=False, is_remote_frame=True, dlc=8),
        can.Message(is_error_frame=True),
    ]
    for f in frames:
        assert parser.update(f) is None
    assert parser.drops == {"unknown_id": 2, "wrong_length": 2, "bad_checksum": 1, "remote_frame": 1,
                            "error_frame": 1}
    assert parser.update(good) is not None and parser.accepted == 1


def test_random_garbage_never_raises(db):
    rng = random.Random(7)
    parser = CanParser(db)
    ids = [m.frame_id for m in db.messages] + [0x000, 0x7FF]
    for _ in range(3000):
        n = rng.choice([0, 1, 7, 8, 8, 8])
        parser.update(can.Message(arbitration_id=rng.choice(ids), is_extended_id=False,
                                  data=bytes(rng.randrange(256) for _ in range(n))))
    assert parser.received == 3000 and sum(parser.drops.values()) + parser.accepted == 3000
    assert parser.drops["bad_checksum"] > 1000  # random bytes pass an 8-bit CRC about 1 time in 256
    assert parser.accepted < 3000 / 256 * 3


def test_a_lost_frame_is_counted_but_a_stuck_counter_is_dropped(db):
    packer, parser = CanPacker(db), CanParser(db)
    frames = [packer.pack("HW_LEAD", {"LEAD_ID": i}) for i in range(10)]
    for f in frames[:3] + frames[4:]:  # frame 3 lost on the way
        assert parser.update(f) is not None
    assert parser.counter_jumps == 1 and not parser.drops
    stuck = frames[-1]
    results = [parser.update(stuck) for _ in range(MAX_BAD_COUNTER + 3)]
    assert all(r is not None for r in results[:MAX_BAD_COUNTER - 1])   # a few repeats: still trusted
    assert all(r is None for r in results[MAX_BAD_COUNTER - 1:])        # then dropped until it recovers
    assert parser.drops["counter_jump"] == 4


def test_freshness_is_per_signal_on_the_bus_clock(db):
    packer = CanPacker(db)
    parser = CanParser(db, ["HW_OBJECT", "HW_STATUS"], timeouts={"HW_STATUS": 0.3})
    assert parser.is_stale("HW_STATUS", now_s=0.0) and parser.age_s("HW_STATUS", now_s=0.0) is None
    parser.update(packer.pack("HW_STATUS", {"STATE": 1}), t_s=10.0)
    assert parser.age_s("HW_STATUS", "STATE", now_s=10.25) == pytest.approx(0.25)
    assert not parser.is_stale("HW_STATUS", "STATE", now_s=10.29)
    assert parser.is_stale("HW_STATUS", "STATE", now_s=10.31)
    parser.update(packer.pack("HW_OBJECT", SAMPLES["HW_OBJECT/0"]), t_s=11.0)
    assert parser.age_s("HW_OBJECT", "RANGE_M", now_s=11.0) == 0.0
    assert parser.age_s("HW_OBJECT", "AZIMUTH_RAD", now_s=11.0) is None  # page 1 never came
    parser.update(packer.pack("HW_LEAD", {}), t_s=11.0)
    assert parser.drops == {"unknown_id": 1}  # not one of this parser's messages
