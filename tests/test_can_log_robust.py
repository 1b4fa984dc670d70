"""A CAN log is read to its end whatever one line holds, and its clock is set by its first frames, not by the
first alone: a bad .asc line is counted and skipped, a stray frame a second early does not shift the inputs."""
from __future__ import annotations

import can
import pytest

from app.can import CanLogReader, CanSession
from tests.test_can_input_drops import adds_up, cfg
from tests.test_can_replay import T0, ego_messages, write_log


@pytest.mark.parametrize("suffix", [".asc", ".log"])
def test_one_bad_line_in_the_first_hundred_is_counted_and_the_log_read_to_its_end(tmp_path, suffix):
    msgs = ego_messages(duration_s=60.0)   # 3,000 frames
    log = write_log(tmp_path / f"ego{suffix}", msgs)
    lines = log.read_text().splitlines()
    frame_lines = [i for i, line in enumerate(lines) if "3E9" in line.upper() or "#" in line]
    k = frame_lines[60]
    lines[k] = lines[k][:-6] + " 1G 2Z" if suffix == ".asc" else lines[k].replace("#", "#Z", 1)
    (tmp_path / f"bad{suffix}").write_text("\n".join(lines) + "\n")
    reader = CanLogReader(tmp_path / f"bad{suffix}")
    delivered = sum(1 for _ in reader)
    assert delivered == 2999 and reader.frames_read == 2999 and reader.bad_lines == 1
    assert "1 malformed lines skipped" in reader.summary() and reader.read_error is None


def stray_first(msgs, early_s: float):
    stray = can.Message(timestamp=msgs[0].timestamp - early_s, arbitration_id=msgs[0].arbitration_id,
                        is_extended_id=False, channel="can0", data=msgs[5].data)
    return [stray, *msgs]


@pytest.mark.parametrize("suffix", [".log", ".asc"])
def test_one_stray_early_frame_uses_the_same_speed_frames_as_the_clean_log(tmp_path, suffix):
    clean = write_log(tmp_path / f"clean{suffix}", ego_messages())
    stray = write_log(tmp_path / f"stray{suffix}", stray_first(ego_messages(), 1.0))
    got = {}
    for name, log in (("clean", clean), ("stray", stray)):
        reader = CanLogReader(log)
        got[name] = ([round(t, 6) for t, _ in reader], reader)
    # the first real frame (an .asc log counts its times from its first line, the stray one)
    assert got["stray"][1].t0 == pytest.approx(T0 if suffix == ".log" else 1.0, abs=1e-6)
    assert got["stray"][0] == got["clean"][0] and len(got["clean"][0]) == 300
    assert got["stray"][1].drops["out_of_order"] == 1   # the frame outside the log's time, counted
    times = [k / 30 for k in range(15, 180)]
    used = {}
    for name, log in (("clean", clean), ("stray", stray)):
        with CanSession.for_replay(cfg(), log, None) as s:
            speeds = [s.vehicle_state(t).speed_mps for t in times]
        used[name] = (speeds, s.summary()["input"])
    assert used["stray"][0] == used["clean"][0]
    assert used["stray"][1]["used"] == used["clean"][1]["used"] >= 298
    assert used["stray"][1]["dropped"] == {"out_of_order": 1} and adds_up(used["stray"][1])


def test_the_clock_of_a_clean_log_is_its_first_frame(tmp_path):
    msgs = ego_messages()
    msgs[0].timestamp -= 0.3   # a pause inside the reorder window is the log's own start, not a stray
    reader = CanLogReader(write_log(tmp_path / "pause.log", msgs))
    assert reader.t0 == pytest.approx(T0 - 0.3, abs=1e-6) and sum(1 for _ in reader) == 300
