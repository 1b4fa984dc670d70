"""Real CAN: 60 s of a 2018 Toyota RAV4 powertrain bus (comma2k19) replayed through the vehicle
inputs with opendbc's Toyota DBC. The ego speed must match the recorder's own speed.csv (the mean
of the four WHEEL_SPEEDS, km/h / 3.6) within 0.5 m/s; cutting the log must make the speed stale
and the status frame say so; garbage lines in the log must change nothing but a count."""
from __future__ import annotations

import bisect
import csv
import random

import pytest

from app.can import CanLogReader, CanParser, CanSession, VehicleInput, headway_database
from app.bench.can_output import fake_result
from app.can.config_schema import defaults
from tests.conftest import data_path

FPS = 30.0
T0 = 1700000000.0  # the log's first timestamp


@pytest.fixture(scope="module")
def rav4():
    root = data_path("comma2k19")
    rows = [(float(t), float(v)) for t, v in list(csv.reader(open(root / "speed.csv")))[1:]]
    return root, rows


def toyota_cfg(root) -> dict:
    cfg = defaults()
    cfg["vehicle"].update(dbc=str(root / "dbc" / "_toyota_2017.dbc"), channel="can0",
                          speed_message="WHEEL_SPEEDS",
                          speed_signals="WHEEL_SPEED_FL,WHEEL_SPEED_FR,WHEEL_SPEED_RL,WHEEL_SPEED_RR")
    return cfg


def latest(rows, t):
    """speed.csv's value at time t: the newest row at or before t."""
    i = bisect.bisect_right([r[0] for r in rows], t) - 1
    return rows[i][1] if i >= 0 else None


def test_every_wheel_speed_frame_matches_speed_csv(rav4):
    root, rows = rav4
    vi = VehicleInput.from_config(toyota_cfg(root)["vehicle"])
    reader = CanLogReader(root / "rav4_segment.log", ids=vi.frame_ids())
    errors = []
    for (t, msg), (t_csv, v_csv) in zip(reader, rows):
        assert t == pytest.approx(t_csv, abs=2e-6)  # epoch seconds in a double: ~0.2 us
        vi.on_message(msg, t)
        errors.append(abs(vi.snapshot(t).speed_mps - v_csv))
    assert len(errors) == len(rows) == 4974
    print(f"\nRAV4 ego speed vs speed.csv, {len(errors)} frames: max {max(errors):.2e} m/s, "
          f"mean {sum(errors) / len(errors):.2e} m/s")
    assert max(errors) < 0.5
    assert max(errors) < 1e-5  # in fact identical but for the CSV's six decimals


def test_replay_on_the_frame_clock_gives_speed_csv(rav4, tmp_path):
    root, rows = rav4
    errors, missing = [], 0
    with CanSession.for_replay(toyota_cfg(root), root / "rav4_segment.log", tmp_path / "out.log") as s:
        for k in range(int(59.9 * FPS)):
            t = k / FPS
            speed = s.vehicle_state(t).speed_mps
            s.publish(t)
            if latest(rows, t) is None:
                assert speed is None  # nothing received yet: not available, never guessed
                missing += 1
                continue
            errors.append(abs(speed - latest(rows, t)))
    assert missing == 1 and max(errors) < 0.5
    print(f"\nRAV4 replay at {FPS:.0f} fps: {len(errors)} frames, max error {max(errors):.2e} m/s, "
          f"mean {sum(errors) / len(errors):.2e} m/s")


def status_and_fcw(log_path):
    """[(t, FAULT_EGO_SPEED_STALE, STATE)] and [(t, FCW_AVAILABLE)] from a Headway output log."""
    parser = CanParser(headway_database())
    status, fcw = [], []
    for t, msg in CanLogReader(log_path):
        name, v = parser.update(msg)
        if name == "HW_STATUS":
            status.append((t, v["FAULT_EGO_SPEED_STALE"], v["STATE"]))
        elif name == "HW_FCW":
            fcw.append((t, v["FCW_AVAILABLE"]))
    assert parser.accepted > 0 and not parser.drops, parser.stats()
    return status, fcw


def test_a_speed_that_stops_arriving_is_stale_within_the_configured_time(rav4, tmp_path):
    root, _rows = rav4
    cut_s = 30.0
    cut = tmp_path / "cut.log"
    with open(root / "rav4_segment.log") as src, open(cut, "w") as dst:
        for line in src:
            if float(line[1:line.index(")")]) - T0 < cut_s or " 0AA#" not in line:
                dst.write(line)
    cfg = toyota_cfg(root)
    stale_after = cfg["vehicle"]["speed_stale_after_s"]
    gone = None
    with CanSession.for_replay(cfg, cut, tmp_path / "out.log") as s:
        for k in range(int(35 * FPS)):
            t = k / FPS
            state = s.vehicle_state(t)
            s.publish(t, fake_result(k, 2), fcw={"level": 0, "available": state.speed_mps is not None})
            if t > 1.0 and state.speed_mps is None and gone is None:
                gone = t
                assert state.faults == {"ego_speed_stale"} and state.inputs["speed"].stale
    print(f"\nspeed frames stop at {cut_s} s: reported stale at frame t = {gone:.3f} s (stale_after_s {stale_after})")
    last_frame = 29.99  # the last WHEEL_SPEEDS frame before the cut is within 12 ms of it
    assert last_frame + stale_after < gone <= cut_s + stale_after + 1 / FPS
    status, fcw = status_and_fcw(tmp_path / "out.log")
    # the output log starts at the input log's t0 (frame 0), so its replay times are the frame clock
    assert all(bit == 0 and state == 1 for t, bit, state in status if 1.0 < t < cut_s)
    after = [(bit, state) for t, bit, state in status if t > gone]
    assert len(after) > 40 and all(bit == 1 and state == 2 for bit, state in after)  # degraded
    assert all(a == 0 for t, a in fcw if t >= gone) and all(a == 1 for t, a in fcw if 1.0 < t < cut_s)


def test_garbage_lines_are_counted_and_change_nothing(rav4, tmp_path):
    root, rows = rav4
    rng = random.Random(3)
    garbage = ["garbage", "(1700000001.5) can0 0AA#25B525B", "(1700000001.5) can0 0AA#ZZ", "#", "\x00\x01\x02",
               "(abc) can0 0AA#00", "(1700000002.0) can0 0AA#25B525B525A0258D25", "(1700000002.0) can0"]
    lines = open(root / "rav4_segment.log").read().splitlines()
    inserted = 0
    for i in sorted(rng.sample(range(len(lines)), 200), reverse=True):
        lines.insert(i, rng.choice(garbage))
        inserted += 1
    dirty = tmp_path / "dirty.log"
    dirty.write_text("\n".join(lines) + "\n")
    vi = VehicleInput.from_config(toyota_cfg(root)["vehicle"])
    reader = CanLogReader(dirty, ids=vi.frame_ids())
    speeds = []
    for t, msg in reader:
        vi.on_message(msg, t)
        speeds.append(vi.snapshot(t).speed_mps)
    assert reader.bad_lines == inserted == 200
    assert "200 malformed lines skipped, first at line" in reader.summary()
    assert len(speeds) == len(rows) and max(abs(a - b[1]) for a, b in zip(speeds, rows)) < 1e-5
