"""HW_CALIBRATION: the supervisor sends self-calibration's pitch, yaw, height, their 1-sigma and the
state at can.calibration_rate_hz; a receiver decodes them with cantools off a python-can virtual bus to
the DBC's resolution; out-of-range values go out saturated with SATURATED set, never wrapped; nothing
is sent without a current estimate. From a real replay the frame carries what the tracks file records."""
from __future__ import annotations

import json
from types import SimpleNamespace

import can
import pytest

from app.can import CanOutput, CanSession, headway_database
from app.bench.can_output import fake_result
from app.can.config_schema import defaults
from app.can.messages import CALIBRATION_STATES
from app.can.vehicle_input import VehicleInput

CAL = {"pitch_deg": 1.234, "yaw_deg": -0.567, "height_m": 1.3125, "pitch_sigma_deg": 0.0371,
       "yaw_sigma_deg": 0.0402, "height_sigma_m": 0.0051, "updates": 97, "active": True, "state": "converged"}


def _result(frame: int, cal) -> SimpleNamespace:
    r = fake_result(frame, 2)
    r.calibration = cal
    return r


def _send_and_receive(results, channel: str, fps: float = 30.0, **can_keys) -> list:
    """Publishes results[k] at k / fps through a session on a virtual bus; the HW_CALIBRATION frames a
    second node on that bus receives, decoded by cantools: [(publish time, page values)] (the virtual bus
    stamps frames with the wall clock)."""
    cfg = defaults()
    cfg["can"].update(interface="virtual", channel=channel, **can_keys)
    db = headway_database()
    cal_id = db.get_message_by_name("HW_CALIBRATION").frame_id
    out = []
    with can.Bus(interface="virtual", channel=channel) as rx, can.Bus(interface="virtual", channel=channel) as tx:
        session = CanSession(cfg, CanOutput(tx, None, channel=channel), VehicleInput([]), deterministic=True)
        for k, r in enumerate(results):
            session.publish(k / fps, r)
            while (msg := rx.recv(timeout=0)) is not None:
                if msg.arbitration_id == cal_id:
                    out.append((round(k / fps, 4), db.decode_message(msg.arbitration_id, msg.data,
                                                                           decode_choices=False)))
        session.close()
    return out


def test_estimate_uncertainty_and_state_decode_to_the_dbc_resolution():
    frames = _send_and_receive([_result(k, CAL) for k in range(90)], "cal-values")
    # 1 Hz, both pages each time, page 0 first: at 0, 1 and 2 s
    assert [(t, v["CAL_PAGE"]) for t, v in frames] == [(0.0, 0), (0.0, 1), (1.0, 0), (1.0, 1), (2.0, 0), (2.0, 1)]
    p0, p1 = frames[0][1], frames[1][1]
    assert p0["STATE"] == p1["STATE"] == 2 and p0["SATURATED"] == p1["SATURATED"] == 0
    assert p0["PITCH_DEG"] == pytest.approx(1.23, abs=0.0051) and p0["YAW_DEG"] == pytest.approx(-0.57, abs=0.0051)
    assert p0["HEIGHT_M"] == pytest.approx(1.3125, abs=0.00051) and p0["UPDATES"] == 97
    assert p1["PITCH_SIGMA_DEG"] == pytest.approx(0.0371, abs=0.00051)
    assert p1["YAW_SIGMA_DEG"] == pytest.approx(0.0402, abs=0.00051)
    assert p1["HEIGHT_SIGMA_M"] == pytest.approx(0.0051, abs=0.00006)


@pytest.mark.parametrize("state, raw", [("off", 0), ("learning", 1), ("converged", 2), ("at_limit", 3)])
def test_every_state_of_the_estimator_has_its_value(state, raw):
    frames = _send_and_receive([_result(0, dict(CAL, state=state))], f"cal-state-{state}")
    assert [v["STATE"] for _t, v in frames] == [raw, raw]


def test_out_of_range_values_saturate_and_are_flagged_never_wrapped():
    wild = dict(CAL, pitch_deg=25.0, yaw_deg=-30.0, height_m=1.2, pitch_sigma_deg=7.5, updates=100000)
    (_, p0), (_, p1) = _send_and_receive([_result(0, wild)], "cal-saturate")
    assert p0["PITCH_DEG"] == pytest.approx(20.47) and p0["YAW_DEG"] == pytest.approx(-20.47)
    assert p0["HEIGHT_M"] == pytest.approx(1.2) and p0["UPDATES"] == 255 and p0["SATURATED"] == 1
    assert p1["PITCH_SIGMA_DEG"] == pytest.approx(4.094) and p1["SATURATED"] == 1
    # within range on one page, out on the other: only that page says so
    (_, q0), (_, q1) = _send_and_receive([_result(0, dict(CAL, height_sigma_m=0.9))], "cal-saturate-2")
    assert q0["SATURATED"] == 0 and q1["SATURATED"] == 1 and q1["HEIGHT_SIGMA_M"] == pytest.approx(0.4094)
    (_, u0), _ = _send_and_receive([_result(0, dict(CAL, updates=255))], "cal-saturate-3")
    assert u0["UPDATES"] == 255 and u0["SATURATED"] == 0


def test_nothing_is_sent_without_a_current_estimate():
    # single-image stages report no calibration: no frame; results that stop: no old estimate as current
    assert _send_and_receive([_result(k, None) for k in range(60)], "cal-none") == []
    frames = _send_and_receive([_result(k, CAL) if k < 3 else None for k in range(90)], "cal-stale")
    assert [t for t, _v in frames] == [0.0, 0.0]
    assert _send_and_receive([_result(k, CAL) for k in range(60)], "cal-off", calibration_rate_hz=0.0) == []


def test_a_replay_sends_the_estimate_the_tracks_file_records(tmp_path):
    from app.can import CanLogReader, CanParser
    from app.replay import replay_scenario

    # plain drawn vehicles, as the convergence below was measured (docs/sim.md, "Real-looking vehicles"): with the
    # real look self-calibration takes fewer updates on steady_following (90 against 136) and converges later
    replay_scenario("steady_following", tracks_path=str(tmp_path / "t.jsonl"), can_out=str(tmp_path / "out.log"),
                    progress=False, vehicle_look="plain")
    recs = {r["frame"]: r for r in map(json.loads, (tmp_path / "t.jsonl").read_text().splitlines())}
    parser = CanParser(headway_database())
    pages = [(t, parser.update(msg)[1]) for t, msg in CanLogReader(tmp_path / "out.log")
             if msg.arbitration_id == 0x606]
    assert parser.accepted >= len(pages) > 10 and not parser.drops
    t0 = pages[0][0]
    fps = 1.0 / min(b["t"] - a["t"] for a, b in zip(recs.values(), list(recs.values())[1:]))
    states = []
    for t, v in pages:
        cal = recs[round((t - t0) * fps)]["calibration"]
        states.append(CALIBRATION_STATES[v["STATE"]])
        if v["CAL_PAGE"] == 0:
            assert v["PITCH_DEG"] == pytest.approx(cal["pitch_deg"], abs=0.0051)
            assert v["YAW_DEG"] == pytest.approx(cal["yaw_deg"], abs=0.0051)
            assert v["HEIGHT_M"] == pytest.approx(cal["height_m"], abs=0.00051)
        else:
            assert v["PITCH_SIGMA_DEG"] == pytest.approx(cal["pitch_sigma_deg"], abs=0.00051)
            assert v["HEIGHT_SIGMA_M"] == pytest.approx(cal["height_sigma_m"], abs=0.0001)
        assert states[-1] == cal["state"]
    # the scenario's camera is exact and the lanes are painted: learning at the first frame, converged after
    assert states[0] == "learning" and all(s == "converged" for s in states[4:])


def test_state_names_are_the_core_enum_and_the_dbc_value_table():
    from app.core import CALIB_STATES

    table = headway_database().get_message_by_name("HW_CALIBRATION").get_signal_by_name("STATE").choices
    assert list(CALIBRATION_STATES) == [str(table[i]) for i in range(len(table))] == \
        [CALIB_STATES[i] for i in sorted(CALIB_STATES)]
