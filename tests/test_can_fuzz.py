"""Fuzzing the CAN input path (log reader -> vehicle inputs): 10,000 random corruptions of candump, .asc
and .blf logs with a fixed seed. Each replays or fails with a named error (CanLogError), never another
exception, and every frame read is accounted once: used, dropped by reason, or not reached."""
from __future__ import annotations

import os
import random
import tempfile
from pathlib import Path

import can
import cantools

from app.can import CanLogError, CanLogReader, VehicleInput
from app.can.config_schema import defaults
from app.can.log_replay import channel_map
from app.can.vehicle_input import specs_from_config
from tests.test_can_replay import EGO_DBC, T0

CASES = {".log": 5000, ".asc": 3000, ".blf": 2000}   # 10,000 in all
SEED = 14
FRAMES = 12


def clean_log(path, suffix: str, rng: random.Random) -> bytes:
    db = cantools.database.load_file(str(EGO_DBC))
    m = db.get_message_by_name("EGO_SPEED")
    writer = {".log": lambda: can.CanutilsLogWriter(str(path)), ".asc": lambda: can.ASCWriter(str(path)),
              ".blf": lambda: can.BLFWriter(str(path))}[suffix]()
    for k in range(FRAMES):
        fid, data = (m.frame_id, m.encode({"SPEED_MPS": 20.0 + k, "COUNTER": k % 16})) if k % 3 else \
            (0x123, bytes(rng.randrange(256) for _ in range(8)))
        writer.on_message_received(can.Message(timestamp=T0 + k / 50, arbitration_id=fid, is_extended_id=False,
                                               data=data, channel="can0"))
    writer.stop()
    return path.read_bytes()


TEXT_JUNK = [b"(0.000000) can0 3E9#0011223344556677", b"(9999999999.0) can0 3E9#00", b"can0 3E9#00",
             b"(1.5) can0 3E9#001", b"(1600000000.1) can1 3E9#0011223344556677", b"(1600000000.1) can0 3E9#0011",
             b"\x00\xff\xfe", b"   0.1 1 3E9 Rx d 8 00 11 22 33 44 55 66 77", b"date Mon Jan 1", b"\t\t"]


def mutate_text(rng: random.Random, data: bytes) -> bytes:
    lines = data.split(b"\n")
    for _ in range(rng.randint(1, 4)):
        i = rng.randrange(len(lines))
        op = rng.randrange(6)
        if op == 0 and lines[i]:
            j = rng.randrange(len(lines[i]))
            lines[i] = lines[i][:j] + bytes([rng.randrange(256)]) + lines[i][j + 1:]
        elif op == 1:
            lines.insert(i, rng.choice(TEXT_JUNK))
        elif op == 2:
            k = rng.randrange(len(lines))
            lines[i], lines[k] = lines[k], lines[i]
        elif op == 3:
            lines.insert(i, lines[i])
        elif op == 4 and lines[i]:
            lines[i] = lines[i][:rng.randrange(len(lines[i]))]
        else:
            del lines[i:i + rng.randint(1, 3)]
            if not lines:
                lines = [b""]
    return b"\n".join(lines)


def mutate_binary(rng: random.Random, data: bytes) -> bytes:
    b = bytearray(data)
    for _ in range(rng.randint(1, 6)):
        op = rng.randrange(4)
        i = rng.randrange(len(b)) if b else 0
        if op == 0 and b:
            b[i] ^= 1 << rng.randrange(8)
        elif op == 1:
            b[i:i] = bytes(rng.randrange(256) for _ in range(rng.randint(1, 16)))
        elif op == 2:
            del b[i:i + rng.randint(1, 32)]
        else:
            b = b[:i]
    return bytes(b)


def test_corrupted_logs_replay_or_fail_by_name_and_every_frame_is_accounted(tmp_path):
    # the case files in memory where there is a tmpfs: 10,000 small writes to a slow disk dominate otherwise
    shm = Path("/dev/shm")
    with tempfile.TemporaryDirectory(dir=shm if shm.is_dir() and os.access(shm, os.W_OK) else tmp_path) as tmp:
        fuzz(Path(tmp))


def fuzz(tmp_path: Path) -> None:
    rng = random.Random(SEED)
    vehicle = defaults()["vehicle"]
    vehicle.update(dbc=str(EGO_DBC), speed_message="EGO_SPEED", speed_signals="SPEED_MPS", channel="can0")
    databases: dict = {}
    specs = specs_from_config(vehicle, databases)
    outcomes = {"replayed": 0, "named_error": 0, "used": 0}
    for suffix, n in CASES.items():
        clean = clean_log(tmp_path / f"clean{suffix}", suffix, rng)
        path = tmp_path / f"case{suffix}"
        for case in range(n):
            path.write_bytes(mutate_binary(rng, clean) if suffix == ".blf" or case % 5 == 0 else
                             mutate_text(rng, clean))
            vi = VehicleInput(specs, "can0", databases)
            try:
                reader = CanLogReader(path, ids=vi.frame_ids(), channels=channel_map(rng.choice(["", "any"])))
            except CanLogError as exc:
                assert str(path) in str(exc)
                outcomes["named_error"] += 1
                continue
            for t, msg in reader:
                vi.on_message(msg, t)
            vi.snapshot(1.0)
            r, v = reader.counts(), vi.counts()
            assert r["not_reached"] == 0 and r["delivered"] == v["used"] + sum(v["dropped"].values()), (suffix, case)
            assert r["read"] == v["used"] + sum(v["dropped"].values()) + sum(r["dropped"].values()), (suffix, case)
            outcomes["replayed"] += 1
            outcomes["used"] += v["used"] > 0
    assert sum(outcomes[k] for k in ("replayed", "named_error")) == sum(CASES.values())
    assert outcomes["used"] > sum(CASES.values()) // 2, outcomes  # most corruptions leave some ego-speed frames usable
