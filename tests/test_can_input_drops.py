"""Vehicle-bus input: every frame read is used or counted under the reason it was dropped (wrong channel,
wrong length, undecodable, unknown id, out of order, outlying time), the counts add up, and an ego-speed
message that was never decoded is said plainly with its likely cause. A stray timestamp or frames out of
order no longer derail the input clock."""
from __future__ import annotations

import can
import cv2
import numpy as np
import pytest

from app.can import CanLogReader, CanSession
from app.can.config_schema import defaults
from app.replay import replay
from tests.test_can_replay import EGO_DBC, T0, ego_messages, write_log


def cfg(**vehicle) -> dict:
    c = defaults()
    c["vehicle"].update(dbc=str(EGO_DBC), speed_message="EGO_SPEED", speed_signals="SPEED_MPS", **vehicle)
    return c


def speeds(config, log, times=(0.5, 1.0, 2.0, 4.0, 6.0)):
    """The ego speed at each replay time, and the session's summary."""
    with CanSession.for_replay(config, log, None) as s:
        out = [s.vehicle_state(t).speed_mps for t in times]
    return out, s.summary()


def adds_up(counts: dict) -> bool:
    return counts["read"] == counts["used"] + sum(counts["dropped"].values()) + counts.get("not_reached", 0)


def test_asc_log_on_channel_0_against_can0_is_counted_named_and_mappable(tmp_path):
    log = write_log(tmp_path / "ego.asc", ego_messages())
    got, summary = speeds(cfg(channel="can0"), log)
    assert got == [None] * 5
    c = summary["input"]
    assert c["used"] == 0 and c["dropped"]["wrong_channel"] == 300 and adds_up(c)
    assert len(summary["never_decoded"]) == 1
    line = summary["never_decoded"][0]
    assert "EGO_SPEED" in line and "came on channel 0" in line and "vehicle.log_channels" in line
    for mapping in ("any", "0=can0"):
        got, summary = speeds(cfg(channel="can0", log_channels=mapping), log)
        assert all(v is not None for v in got) and summary["never_decoded"] == []
        assert summary["input"]["used"] == 300 and adds_up(summary["input"])


def test_frames_shorter_than_the_dbc_message_are_counted_and_explained(tmp_path):
    msgs = ego_messages()
    for m in msgs:
        m.data, m.dlc = m.data[:6], 6
    got, summary = speeds(cfg(), write_log(tmp_path / "short.log", msgs))
    assert got == [None] * 5 and summary["input"]["dropped"] == {"wrong_length": 300} and adds_up(summary["input"])
    assert "are 6 bytes long but the DBC gives 8" in summary["never_decoded"][0]


def test_an_undecodable_signal_is_caught_by_config_check_and_counted_in_replay(tmp_path):
    from app import config as configuration
    from app.config_check import problems

    dbc = tmp_path / "wide.dbc"
    dbc.write_text(EGO_DBC.read_text().replace("SPEED_MPS : 0|16", "SPEED_MPS : 0|99"))
    c = configuration.load(None, {"vehicle": {"dbc": str(dbc), "speed_message": "EGO_SPEED",
                                              "speed_signals": "SPEED_MPS", "speed_unit": "m/s"}})
    found = problems(c, open_bus=False)
    assert len(found) == 1 and "vehicle.speed_message: EGO_SPEED in wide.dbc cannot be decoded" in found[0]
    got, summary = speeds(c, write_log(tmp_path / "ego.log", ego_messages()))
    assert got == [None] * 5 and summary["input"]["dropped"] == {"undecodable": 300}
    assert "could not be decoded with the DBC" in summary["never_decoded"][0]


def test_stray_line_at_time_zero_does_not_derail_the_clock(tmp_path):
    log = write_log(tmp_path / "ego.log", ego_messages())
    lines = log.read_text().splitlines()
    stray = "(0.000000) can0 " + lines[0].split()[2]
    (tmp_path / "stray.log").write_text("\n".join([stray, *lines]) + "\n")
    reader = CanLogReader(tmp_path / "stray.log")
    assert reader.t0 == pytest.approx(T0)
    assert sum(1 for _ in reader) == 300 and reader.drops["time_outlier"] == 1
    got, summary = speeds(cfg(), tmp_path / "stray.log")
    assert got == pytest.approx([20.25, 20.5, 21.0, 22.0, 22.99], abs=0.02)
    assert summary["input"]["dropped"] == {"time_outlier": 1} and adds_up(summary["input"])


def test_one_frame_in_four_out_of_order_is_dropped_and_the_speed_stays_fresh(tmp_path):
    msgs = ego_messages()
    for k in range(3, len(msgs), 4):
        msgs[k].timestamp -= 2.0  # far beyond the reorder window
    log = write_log(tmp_path / "ooo.log", msgs)
    with CanSession.for_replay(cfg(), log, None) as s:
        states = [s.vehicle_state(k / 30) for k in range(30, 150)]
    assert all(st.speed_mps is not None and not st.faults for st in states)
    c = s.summary()["input"]
    assert c["dropped"]["out_of_order"] >= 60 and adds_up(c)


def test_replay_summary_counts_dropped_frames_and_names_the_cause(tmp_path):
    frames = tmp_path / "frames"
    frames.mkdir()
    for i in range(20):
        cv2.imwrite(str(frames / f"{i:03d}.png"), np.full((120, 160), 60 + i, np.uint8))
    msgs = ego_messages()
    msgs.insert(5, can.Message(timestamp=T0 + 0.1, arbitration_id=0x123, data=b"\x00" * 8, channel="can0"))
    log = write_log(tmp_path / "ego.asc", msgs)
    config = tmp_path / "config.yaml"
    config.write_text(f"vehicle: {{dbc: {EGO_DBC}, speed_message: EGO_SPEED, speed_signals: SPEED_MPS, "
                      f"channel: can0}}\n")
    s = replay(str(frames), config_path=str(config), fps=10, can_in=str(log), progress=False)
    text = s.text()
    c = s.can["input"]
    assert c["used"] == 0 and c["dropped"]["unknown_id"] == 1 and c["dropped"]["wrong_channel"] > 0 and adds_up(c)
    assert f"CAN in: {c['read']} frames read, 0 used, dropped:" in text
    assert "WARNING: vehicle.speed: EGO_SPEED (id 0x3E9) was never decoded: its" in text
