"""One frame's work in the supervisor: vehicle inputs -> ego motion to the core -> FCW -> health ->
CAN frames (and the warning to the cabin MCU). The same object serves replay, `headway run` and the
service, so a replay does exactly what the car did.
"""
from __future__ import annotations

from typing import Any, Optional

from app.core import FrameResult
from app.fcw import EgoState, FcwOutput, FcwParams, FcwStateMachine, Lead


def ego_from(can_state: Any, mcu_signals: Any) -> EgoState:
    """The car's own state, input by input: the CAN bus's value when it has a fresh one, else the cabin
    MCU's (a car whose speed reaches Headway only through the MCU, or a CAN input gone stale while the
    MCU still reads it). Neither fresh: None, never a guess."""
    mcu = mcu_signals if mcu_signals is not None and not mcu_signals.stale else None

    def pick(name: str):
        v = getattr(can_state, name, None) if can_state is not None else None
        return v if v is not None or mcu is None else getattr(mcu, name)

    return EgoState(speed_mps=pick("speed_mps"), brake=pick("brake"), turn_left=pick("turn_left"),
                    turn_right=pick("turn_right"))


def lead_of(r: FrameResult) -> Optional[Lead]:
    t = r.lead
    if t is None:
        return None
    return Lead(id=t.id, range_m=t.range_m, range_rate_mps=t.range_rate_mps, ttc_s=t.ttc_s,
                ttc_scale_s=t.ttc_scale_s, range_accel_mps2=t.range_accel_mps2)


class Stack:
    def __init__(self, cfg: dict, can_session: Any = None, bridge: Any = None):
        self.fcw = FcwStateMachine(FcwParams.from_config(cfg["fcw"]), ego_front_m=cfg["kinematics"]["ego_front_m"])
        self.can = can_session
        self.bridge = bridge
        self.decisions: list[tuple[float, FcwOutput]] = []  # every level change, for summaries and tests

    def vehicle_state(self, now_s: float):
        return self.can.vehicle_state(now_s) if self.can is not None else None

    def step(self, r: FrameResult, now_s: float, pipe: Any = None, status: Optional[dict] = None,
             state: Any = None) -> FcwOutput:
        """`now_s`: the clock of the vehicle inputs (the frame time in replay, the bus clock live)."""
        if state is None:
            state = self.vehicle_state(now_s)
        ego = ego_from(state, self.bridge.vehicle_signals() if self.bridge is not None else None)
        if pipe is not None:  # for the ego path when the lanes are missing (next frame on)
            pipe.set_ego_motion(ego.speed_mps, getattr(state, "yaw_rate_rps", None))
        decision = self.fcw.step(r.t_s, lead_of(r), ego)
        if decision.changed:
            self.decisions.append((r.t_s, decision))
        if self.can is not None:
            self.can.publish(now_s, r, fcw=decision, status=status)
        if self.bridge is not None:
            self.bridge.send_warning(decision.level, decision.ttc_used_s, decision.lead_range_m)
        return decision
