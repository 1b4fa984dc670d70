"""The supervisor's vehicle inputs: CAN first, the cabin MCU's signals where CAN has none."""
from __future__ import annotations

from app.can.vehicle_input import InputValue, VehicleState
from app.core import FrameResult, Track
from app.fcw import WARNING
from app.supervisor.stack import Stack, ego_from
from firmware_bridge.link import SignalsReading

CFG = {"fcw": {}, "kinematics": {"ego_front_m": 2.0}}


def mcu(speed=20.0, brake=False, stale=False, left=False):
    return SignalsReading(speed, brake, left, False, received_at=0.0, age_s=2.0 if stale else 0.05, stale=stale)


def can(**values):
    names = ("speed", "yaw_rate", "brake", "turn_left", "turn_right")
    inputs = {n: InputValue(values.get(n), 0.0 if n in values else None, False, n in values) for n in names}
    return VehicleState(0.0, inputs)


def test_can_values_win_and_the_mcu_fills_what_can_lacks():
    e = ego_from(can(speed=25.0), mcu(speed=20.0, brake=True, left=True))
    assert e.speed_mps == 25.0 and e.brake is True and e.turn_left is True and e.turn_right is False


def test_stale_mcu_signals_are_not_used():
    e = ego_from(can(), mcu(stale=True))
    assert e.speed_mps is None and e.brake is None
    assert ego_from(None, None).speed_mps is None


class FakeBridge:
    def __init__(self, reading):
        self.reading, self.sent = reading, []

    def vehicle_signals(self, now=None):
        return self.reading

    def send_warning(self, level, ttc_s=None, lead_range_m=None):
        self.sent.append(level)


class FakePipe:
    def __init__(self):
        self.ego = []

    def set_ego_motion(self, speed, yaw_rate):
        self.ego.append((speed, yaw_rate))


def closing_lead(frame: int, gap_m: float) -> FrameResult:
    lead = Track(id=3, confirmed=True, age_frames=frame + 60, box=(300, 250, 340, 280), confidence=0.9,
                 vx_px_s=0.0, vy_px_s=0.0, range_m=gap_m + 2.0, range_sigma_m=0.5, lateral_m=0.0,
                 range_rate_mps=-20.0, range_accel_mps2=0.0, ttc_s=gap_m / 20.0, ttc_scale_s=gap_m / 20.0,
                 lane_index=0, in_path=True)
    return FrameResult(frame=frame, t_s=frame / 30, t_done_s=frame / 30, width=640, height=480, events=[],
                       full_detection=True, tracks=[lead], lanes=[], vanishing_point=None, horizon_row=240.0,
                       lead=lead)


def drive(reading) -> tuple[list[int], FakePipe]:
    bridge, pipe = FakeBridge(reading), FakePipe()
    sup = Stack(CFG, can_session=None, bridge=bridge)
    for k in range(150):  # a stopped car from 100 m at 72 km/h, 5 s
        sup.step(closing_lead(k, 100.0 - 20.0 * k / 30), k / 30, pipe=pipe)
    return bridge.sent, pipe


def test_fcw_warns_on_the_mcu_speed_when_there_is_no_can():
    sent, pipe = drive(mcu(speed=20.0))
    assert WARNING in sent
    assert pipe.ego[0] == (20.0, None)  # the core's ego path gets that speed too


def test_no_warning_without_any_fresh_ego_speed():
    sent, _ = drive(mcu(stale=True))
    assert WARNING not in sent
