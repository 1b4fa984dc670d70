"""Every shipped scenario: ground truth agrees with the camera model and with the world."""
import numpy as np
import pytest

from app.sim import Camera, list_scenarios, load_scenario, render
from app.sim.frames import scenario_camera

REQUIRED_SCENARIOS = {
    "stopped_lead_72kmh", "stopped_lead_50kmh", "stopped_lead_100kmh", "lead_braking_0p3g", "slower_lead",
    "steady_following", "cut_in", "cut_out_stopped_car", "overtaking_from_side", "adjacent_passing",
    "overpass_shadow", "dense_traffic", "empty_road", "lane_change",
}


def test_the_scenario_set_is_complete():
    assert REQUIRED_SCENARIOS <= set(list_scenarios())


def _frame_camera(scenario, frame, overrides=None) -> Camera:
    """The camera of this frame: the scenario's camera (with overrides) turned by the frame's shake."""
    base = scenario_camera(scenario, overrides)
    return base.shaken(frame.pitch_deg - base.pitch_deg, frame.yaw_deg - base.yaw_deg)


def test_frames_are_vga_gray(scenario_name, sampled_frames):
    for frame in sampled_frames(scenario_name):
        assert frame.image.shape == (480, 640) and frame.image.dtype == np.uint8
        assert abs(frame.pitch_deg - 1.0) < 1.0 and abs(frame.yaw_deg) < 1.0


def test_box_bottom_is_the_flat_road_row_of_the_range(scenario_name, sampled_frames):
    scenario = load_scenario(scenario_name)
    checked = 0
    for frame in sampled_frames(scenario_name):
        camera = _frame_camera(scenario, frame)
        for v in frame.truth:
            x_world = v["lateral_m"] + camera.lateral_m
            assert abs(v["box"][3] - camera.row_of_range(v["longitudinal_m"], x_world)) <= 1.0
            assert abs(v["box"][3] - camera.row_of_range(v["longitudinal_m"])) <= 1.0  # shake yaw is tiny
            # ... and the range read back from the bottom row (what a flat-road estimator does).
            z_back = camera.range_of_row(v["box"][3], x_world)
            assert abs(z_back - v["longitudinal_m"]) <= 0.02 * v["longitudinal_m"] + 1e-6
            checked += 1
    if scenario.vehicles:
        assert checked > 0


def test_box_width_and_height_follow_the_pinhole_model(scenario_name, sampled_frames):
    scenario = load_scenario(scenario_name)
    for frame in sampled_frames(scenario_name):
        camera = _frame_camera(scenario, frame)
        for v in frame.truth:
            z, w, h = v["longitudinal_m"], v["width_m"], v["height_m"]
            width_px, height_px = v["box"][2] - v["box"][0], v["box"][3] - v["box"][1]
            x_world = v["lateral_m"] + camera.lateral_m
            # The box is the bounding box of the projected rear face (pitch makes it a slight
            # keystone, wider at the top, so plain fx * w / Z only holds at a distance).
            corners = np.array([[x_world + dx * w, y, z] for dx in (-0.5, 0.5) for y in (0.0, h)])
            u, v_rows = camera.project(corners)
            assert np.allclose(v["box"], [u.min(), v_rows.min(), u.max(), v_rows.max()], atol=1e-6)
            if z >= 20.0:  # the keystone is below a pixel from here on: plain fx * w / Z holds
                assert abs(width_px - camera.fx * w / z) <= 1.0
                assert abs(height_px - camera.fy * h / z) <= 1.0


def test_lane_lateral_and_ttc_agree_with_the_scenario(scenario_name, sampled_frames):
    scenario = load_scenario(scenario_name)
    specs = {s.id: s for s in scenario.vehicles}
    lane_width = scenario.road.lane_width_m
    for frame in sampled_frames(scenario_name):
        camera = _frame_camera(scenario, frame)
        for v in frame.truth:
            spec = specs[v["id"]]
            x_world = v["lateral_m"] + camera.lateral_m
            assert v["lane"] == round(x_world / lane_width)
            assert -scenario.road.ego_lane <= v["lane"] <= scenario.road.lanes - 1 - scenario.road.ego_lane
            if not spec.lane_changes:
                assert abs(x_world - (spec.lane * lane_width + spec.lateral_offset_m)) < 1e-9
                assert v["lane"] == spec.lane
            assert v["kind"] == spec.kind
            assert abs(v["relative_speed_mps"] - (v["speed_mps"] - frame.ego_speed_mps)) < 1e-9
            if v["relative_speed_mps"] < 0:
                expected = (v["longitudinal_m"] - scenario.ego.front_m) / -v["relative_speed_mps"]
                assert abs(v["ttc_s"] - expected) < 1e-9
            else:
                assert v["ttc_s"] is None
            assert v["longitudinal_m"] > 0.5
            l, t, r, b = v["box_clipped"]
            assert 0 <= l < r <= 639 and 0 <= t < b <= 479
            assert 0.0 <= v["visible_fraction"] <= 1.0


def test_unoccluded_vehicles_inside_the_image_are_fully_visible(sampled_frames):
    frame = sampled_frames("steady_following")[0]
    lead = next(v for v in frame.truth if v["id"] == 1)
    assert lead["visible_fraction"] == pytest.approx(1.0, abs=0.02)


def test_occluded_and_clipped_vehicles_report_partial_visibility(sampled_frames):
    fractions = [v["visible_fraction"] for f in sampled_frames("dense_traffic") for v in f.truth]
    assert min(fractions) < 0.5 and max(fractions) > 0.95
    # A vehicle entering from the bottom-left edge is clipped by the image border.
    clipped = [v for f in sampled_frames("overtaking_from_side") for v in f.truth if v["box"][0] < 0]
    assert clipped and all(v["visible_fraction"] < 1.0 for v in clipped)


def test_other_cameras_keep_truth_and_pixels_consistent():
    scenario = load_scenario("lane_change")
    overrides = {"width": 1280, "height": 720, "fx": 1000.0, "height_m": 1.5, "pitch_deg": 3.0,
                 "yaw_deg": 2.0, "lateral_m": 0.5}
    frames = list(render(scenario, camera_overrides=overrides, frames=[0, 120]))
    for frame in frames:
        assert frame.image.shape == (720, 1280)
        camera = _frame_camera(scenario, frame, overrides)
        assert abs(frame.pitch_deg - 3.0) < 0.5 and abs(frame.yaw_deg - 2.0) < 0.5
        for v in frame.truth:
            x_world = v["lateral_m"] + 0.5
            assert abs(v["box"][3] - camera.row_of_range(v["longitudinal_m"], x_world)) <= 1.0
        # The lead's bottom edge is where the picture turns dark (the gap under the body).
        lead = next(v for v in frame.truth if v["id"] == 1)
        l, t, r, b = lead["box"]
        column = frame.image[:, int(round(0.5 * (l + r)))].astype(float)
        row = int(round(b))
        assert column[row + 3:row + 8].mean() - column[row - 4:row - 1].mean() > 30.0
