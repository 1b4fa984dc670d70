"""Kinematics, collisions, camera shake and the ego-speed CAN log."""
import math

import can
import cantools
import numpy as np
import pytest

from app.sim import ScenarioError, load_scenario, render
from app.sim.can_log import DBC_PATH, write_ego_speed_log
from app.sim.frames import scenario_camera
from app.sim.scenario import SpeedStep, parse_scenario
from app.sim.truth import frame_truth
from app.sim.world import Motion1D, World


def _euler(z0, v0, steps, t_end, dt=1e-4):
    """Independent reference: tiny-step integration of the same rules."""
    z, v, a, target = z0, v0, 0.0, None
    pending = list(steps)
    for t in np.arange(0.0, t_end, dt):
        while pending and pending[0].t_s <= t + 1e-12:
            s = pending.pop(0)
            a, target = s.accel_mps2, None if s.until_speed_kmh is None else s.until_speed_kmh / 3.6
        v_next = v + a * dt
        limit = target if target is not None else (0.0 if a < 0 else math.inf)
        if (a < 0 and v_next < max(limit, 0.0)) or (a > 0 and v_next > limit):
            v_next = max(limit, 0.0) if a < 0 else limit
        z += 0.5 * (v + v_next) * dt
        v = v_next
    return z, v


@pytest.mark.parametrize("steps", [
    [],
    [SpeedStep(1.0, -2.94)],  # brake to a stop, then stand still
    [SpeedStep(0.5, -3.0, 50.0), SpeedStep(3.0, 1.5, 70.0), SpeedStep(6.0, -8.0)],
    [SpeedStep(0.0, 2.0), SpeedStep(2.25, 0.0)],
])
def test_piecewise_constant_acceleration_is_integrated_exactly(steps):
    motion = Motion1D(10.0, 20.0, steps)
    for t_end in (0.7, 2.5, 4.0, 9.0):
        z_ref, v_ref = _euler(10.0, 20.0, steps, t_end)
        z, v, _ = motion.at(t_end)
        assert abs(z - z_ref) < 5e-3 and abs(v - v_ref) < 5e-3


def test_speed_never_goes_below_zero():
    motion = Motion1D(0.0, 10.0, [SpeedStep(0.0, -5.0)])
    z, v, a = motion.at(np.array([1.0, 2.0, 3.0, 10.0]))
    assert np.allclose(v, [5.0, 0.0, 0.0, 0.0]) and np.allclose(z, [7.5, 10.0, 10.0, 10.0])
    assert a[-1] == 0.0


def test_stopped_lead_ttc_falls_monotonically_to_zero():
    scenario = load_scenario("stopped_lead_72kmh")
    world = World(scenario)
    assert world.collision_frame is not None and world.n_frames < scenario.n_frames_nominal
    ttc = []
    for k in range(world.n_frames):
        truth = frame_truth(world.frame_state(k), scenario_camera(scenario), scenario.ego.front_m,
                            scenario.road.lane_width_m)
        ttc.append(next(v["ttc_s"] for v in truth if v["id"] == 1))
    assert ttc[0] == pytest.approx((110.0 - 2.0) / 20.0)
    assert all(b < a for a, b in zip(ttc, ttc[1:]))
    assert 0.0 < ttc[-1] <= 1.0 / scenario.fps + 1e-9


@pytest.mark.parametrize("name,speed_kmh", [("stopped_lead_50kmh", 50), ("stopped_lead_100kmh", 100),
                                             ("lead_braking_0p3g", 72), ("slower_lead", 72)])
def test_warning_scenarios_end_at_contact(name, speed_kmh):
    scenario = load_scenario(name)
    frames = list(render(scenario, frames=[World(scenario).n_frames - 1]))
    lead = next(v for v in frames[0].truth if v["id"] == 1)
    assert 0.0 < lead["ttc_s"] <= 1.0 / scenario.fps + 1e-9
    assert scenario.ego.speed_kmh == speed_kmh


def test_ego_speed_log_decodes_to_the_profile(tmp_path):
    scenario = load_scenario("dense_traffic")  # the ego slows down and speeds up again
    world = World(scenario)
    end_s = (world.n_frames - 1) / scenario.fps
    path = tmp_path / "ego_speed.log"
    n = write_ego_speed_log(path, world.ego, end_s)
    message = cantools.database.load_file(str(DBC_PATH)).get_message_by_name("EGO_SPEED")
    records = list(can.CanutilsLogReader(str(path)))
    assert len(records) == n == int(round(end_s * 50)) + 1
    times = np.array([r.timestamp for r in records])
    assert times[0] == 0.0 and np.allclose(np.diff(times), 0.02)
    decoded = [message.decode(r.data) for r in records]
    speeds = np.array([d["SPEED_MPS"] for d in decoded])
    assert np.max(np.abs(speeds - world.ego.at(times)[1])) <= 0.01
    assert speeds.min() < 11.2 and speeds.max() > 16.6  # 40 km/h dip from 60 km/h
    assert [d["COUNTER"] for d in decoded[:18]] == list(range(16)) + [0, 1]
    assert all(r.arbitration_id == 0x3E9 and r.channel == "vcan0" for r in records)


def test_camera_shake_has_the_configured_size_and_is_seeded():
    scenario = load_scenario("steady_following")
    world = World(scenario)
    assert 0.05 < np.abs(world.pitch_shake_deg).max() <= 0.15 * 1.5
    assert 0.01 < np.abs(world.yaw_shake_deg).max() <= 0.05 * 1.5
    assert np.array_equal(World(scenario).pitch_shake_deg, world.pitch_shake_deg)


def _scenario(vehicles, ego=None):
    data = {"duration_s": 6.0, "ego": ego or {"speed_kmh": 72}, "vehicles": vehicles}
    return parse_scenario(data, "scenario test.yaml", source="test.yaml")


def test_vehicles_running_into_each_other_are_rejected():
    scenario = _scenario([{"id": 1, "lane": 1, "z_m": 30, "speed_kmh": 100},
                          {"id": 7, "lane": 1, "z_m": 50, "speed_kmh": 60}])
    with pytest.raises(ScenarioError, match=r"test\.yaml: vehicles\[0\] \(id 1\) and vehicles\[1\] \(id 7\) overlap"):
        World(scenario)


def test_a_vehicle_cutting_into_the_ego_side_is_rejected():
    scenario = _scenario([{"id": 3, "lane": 1, "z_m": -1, "speed_kmh": 72,
                           "lane_changes": [{"t_s": 1.0, "to_lane": 0, "duration_s": 2.0}]}])
    with pytest.raises(ScenarioError, match=r"vehicles\[0\] \(id 3\) overlaps the ego vehicle"):
        World(scenario)


def test_running_into_a_vehicle_ahead_ends_the_run():
    scenario = _scenario([{"id": 1, "lane": 0, "z_m": 42, "speed_kmh": 0}])
    world = World(scenario)
    # Contact when the ego front (2 m ahead of the camera) reaches the rear face: (42 - 2) / 20 = 2 s,
    # frame 60; the run keeps the frames before it.
    assert world.collision_frame == 60 and world.n_frames == 60
