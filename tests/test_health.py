"""The health monitor: one overall state and fault bits from made-up inputs, second by second."""
from __future__ import annotations

from app.contracts.faults import FAULTS, fault_bits, fault_names
from app.supervisor.health import HealthMonitor, HealthParams


def feed(h: HealthMonitor, t0: float, seconds: float, fps: float = 30.0, stddev: float = 40.0, change: float = 3.0,
         latency_ms: float = 5.0) -> float:
    t = t0
    while t < t0 + seconds:
        h.on_result(t, latency_ms, stddev, change)
        t += 1 / fps
    return t


def evaluate(h, t, **kw):
    return h.evaluate(t, loop_alive_s=t - 0.01, loop_running=True, queue_drops=kw.pop("drops", 0), **kw)


def test_starting_then_ok_with_frame_rate_and_latency():
    h = HealthMonitor()
    h.start(0.0)
    assert evaluate(h, 0.1).state == "starting"
    t = feed(h, 0.2, 3.0)
    r = evaluate(h, t)
    assert r.state == "ok" and r.faults == [] and r.bits == 0
    assert abs(r.fps - 30.0) < 0.5 and r.latency_p99_ms == 5.0


def test_no_frames_at_all_after_timeout_is_camera_lost():
    h = HealthMonitor(HealthParams(camera_timeout_s=0.5))
    h.start(10.0)
    assert evaluate(h, 10.4).faults == []
    assert evaluate(h, 10.6).faults == ["camera_lost"]


def test_camera_loss_and_recovery():
    h = HealthMonitor(HealthParams(camera_timeout_s=0.5))
    h.start(0.0)
    t = feed(h, 0.0, 2.0)
    assert evaluate(h, t + 0.45).state == "ok"
    r = evaluate(h, t + 0.55)
    assert r.state == "fault" and "camera_lost" in r.faults
    t = feed(h, t + 2.0, 0.5)
    assert evaluate(h, t).state == "ok"


def test_blinded_and_frozen_are_degraded():
    h = HealthMonitor(HealthParams(blinded_frames=15, frozen_frames=30))
    h.start(0.0)
    t = feed(h, 0.0, 0.4, stddev=1.0)  # 12 blinded frames: not yet
    assert "camera_blinded" not in evaluate(h, t).faults
    t = feed(h, t, 0.2, stddev=1.0)
    r = evaluate(h, t)
    assert r.state == "degraded" and r.faults == ["camera_blinded"]
    t = feed(h, t, 1.2, change=0.0)  # contrast back, but frozen
    r = evaluate(h, t)
    assert r.faults == ["camera_frozen"]
    t = feed(h, t, 0.1)
    assert evaluate(h, t).state == "ok"


def test_stalled_core_is_a_fault():
    h = HealthMonitor(HealthParams(stall_timeout_s=2.0))
    h.start(0.0)
    t = feed(h, 0.0, 1.0)
    r = h.evaluate(t + 2.5, loop_alive_s=t, loop_running=True, queue_drops=0)
    assert "core_stalled" in r.faults and r.state == "fault"


def test_overload_from_latency_or_drops():
    h = HealthMonitor(HealthParams(latency_budget_ms=50.0))
    h.start(0.0)
    t = feed(h, 0.0, 1.0, latency_ms=80.0)
    assert "overload" in evaluate(h, t).faults
    h2 = HealthMonitor()
    h2.start(0.0)
    t = feed(h2, 0.0, 1.0)
    assert evaluate(h2, t, drops=0).faults == []
    assert "overload" in evaluate(h2, t + 0.1, drops=3).faults
    assert "overload" in evaluate(h2, t + 4.0, drops=3).faults   # shown a while ...
    assert "overload" not in evaluate(h2, t + 6.0, drops=3).faults  # ... then cleared


def test_bus_inputs_and_mcu():
    h = HealthMonitor()
    h.start(0.0)
    t = feed(h, 0.0, 1.0)
    r = evaluate(h, t, can_ok=False, ego_speed_fresh=False, mcu_up=False)
    assert r.faults == ["can_error", "ego_speed_stale", "mcu_silent"] and r.state == "fault"
    r = evaluate(h, t, ego_speed_fresh=False)
    assert r.state == "degraded"
    assert evaluate(h, t, can_ok=None, ego_speed_fresh=None, mcu_up=None).state == "ok"  # not configured


def test_fault_bits_registry_round_trip_and_unique():
    names = [f.name for f in FAULTS]
    assert len(set(names)) == len(names) and len({f.bit for f in FAULTS}) == len(FAULTS)
    assert fault_names(fault_bits(["camera_lost", "mcu_silent"])) == ["camera_lost", "mcu_silent"]
    assert fault_bits(["camera_lost"]) == 1 and fault_bits(["mcu_silent"]) == 1 << 7
