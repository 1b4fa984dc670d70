"""The rendered pictures carry the cues the detectors rely on, and nothing moves that should not."""
import dataclasses

import cv2
import numpy as np
import pytest

from app.sim import load_scenario, render
from app.sim.frames import scenario_camera
from app.sim.scenario import parse_scenario
from app.sim.world import World


def _quiet(scenario, seed=None):
    """The scenario without sensor noise (to look at the rendering itself)."""
    lighting = dataclasses.replace(scenario.lighting, noise_sigma=0.0)
    return dataclasses.replace(scenario, lighting=lighting, seed=scenario.seed if seed is None else seed)


def _plain(name):
    """A shipped scenario drawn with plain rear faces: the cues of the shadow method are drawn there on purpose."""
    return dataclasses.replace(load_scenario(name), vehicle_look="plain")


def _camera(scenario, frame):
    base = scenario_camera(scenario)
    return base.shaken(frame.pitch_deg - base.pitch_deg, frame.yaw_deg - base.yaw_deg)


def _lead_frame():
    frame = next(render(_plain("steady_following"), frames=[0]))
    lead = next(v for v in frame.truth if v["id"] == 1)
    return frame.image.astype(np.float64), lead


def test_shadow_under_the_lead_is_much_darker_than_the_road():
    image, lead = _lead_frame()
    l, t, r, b = lead["box"]
    height, inset = b - t, 0.15 * (r - l)
    cols = slice(int(np.ceil(l + inset)), int(np.floor(r - inset)) + 1)
    shadow = image[int(np.ceil(b - 0.15 * height)):int(np.floor(b)) + 1, cols].mean()  # just above the bottom edge
    road = image[int(np.ceil(b)) + 3:int(np.ceil(b)) + 3 + int(height), cols].mean()  # the road in front of it
    assert road - shadow >= 30.0, (road, shadow)
    assert shadow < 60.0


def test_lead_sides_are_the_strongest_vertical_edges():
    image, lead = _lead_frame()
    l, t, r, b = lead["box"]
    gx = np.abs(cv2.Sobel(image, cv2.CV_64F, 1, 0, ksize=3))
    rows = slice(int(np.ceil(t + 0.2 * (b - t))), int(np.floor(b - 0.2 * (b - t))) + 1)
    mid = 0.5 * (l + r)
    left_cols = np.arange(int(l) - 6, int(mid))
    right_cols = np.arange(int(mid) + 1, int(r) + 7)
    profile = gx[rows].mean(axis=0)
    assert abs(left_cols[np.argmax(profile[left_cols])] - l) <= 3.0
    assert abs(right_cols[np.argmax(profile[right_cols])] - r) <= 3.0
    assert profile[left_cols].max() > 3.0 * np.median(profile[left_cols])


def test_same_seed_gives_identical_bytes():
    scenario = load_scenario("dense_traffic")
    first = [f.image.tobytes() for f in render(scenario, frames=[0, 7, 150])]
    second = [f.image.tobytes() for f in render(load_scenario("dense_traffic"), frames=[0, 7, 150])]
    assert first == second


def test_different_seed_gives_a_different_road_texture():
    scenario = _quiet(load_scenario("empty_road"))
    a = next(render(scenario, frames=[0])).image.astype(np.float64)
    b = next(render(_quiet(scenario, seed=scenario.seed + 1), frames=[0])).image.astype(np.float64)
    near_road = (slice(400, 480), slice(200, 440))  # a few metres ahead, inside the ego lane
    assert np.abs(a[near_road] - b[near_road]).mean() > 4.0
    assert abs(a[near_road].mean() - b[near_road].mean()) < 10.0  # same lighting, other texture


@pytest.mark.parametrize("name,index", [("empty_road", 50), ("steady_following", 100), ("overpass_shadow", 60)])
def test_road_moves_exactly_with_the_road_plane_homography(name, index):
    """Measured (no sensor noise): mean |residual| about 1.0-1.3 gray levels after warping, 4.3-5 without."""
    scenario = _quiet(load_scenario(name))
    world = World(scenario)
    prev, cur = render(scenario, frames=[index - 1, index])
    travelled_m = world.frame_state(index).ego_odometer_m - world.frame_state(index - 1).ego_odometer_m
    # Road point (X, Z) at k-1 is at (X, Z - travelled) at k.
    shift = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, -travelled_m], [0.0, 0.0, 1.0]])
    h = _camera(scenario, cur).ground_to_image() @ shift @ np.linalg.inv(_camera(scenario, prev).ground_to_image())
    warped = cv2.warpPerspective(prev.image, h, (640, 480), flags=cv2.INTER_LINEAR).astype(np.float64)
    v, u = np.mgrid[0:480, 0:640]
    x, z = _camera(scenario, cur).ground_from_pixel(u, v)
    road = np.isfinite(z) & (z > 4.0) & (z < 40.0) & (np.abs(x) < 5.0)
    for vehicle in cur.truth + prev.truth:
        l, t, r, b = vehicle["box"]
        road &= ~((u >= l - 3) & (u <= r + 3) & (v >= t - 3) & (v <= b + 3))
    assert road.sum() > 20000
    residual = np.abs(warped - cur.image)[road].mean()
    unwarped = np.abs(prev.image.astype(np.float64) - cur.image)[road].mean()
    assert residual < 2.0
    assert residual < 0.4 * unwarped


def test_overpass_shadow_is_as_dark_as_a_vehicle_shadow_and_spans_the_road():
    scenario = load_scenario("overpass_shadow")
    world = World(scenario)
    index = 105  # the band lies about 28-42 m ahead
    frame = next(render(scenario, frames=[index]))
    camera = _camera(scenario, frame)
    bridge = scenario.road.overpass
    z0 = bridge.z_m + bridge.shadow_offset_m - world.frame_state(index).ego_odometer_m
    v, u = np.mgrid[0:480, 0:640]
    x, z = camera.ground_from_pixel(u, v)
    on_road = np.isfinite(z) & (x > scenario.road.left_edge_m + 0.3) & (x < scenario.road.right_edge_m - 0.3)
    for vehicle in frame.truth:
        l, t, r, b = vehicle["box"]
        on_road &= ~((u >= l - 3) & (u <= r + 3) & (v >= t - 3) & (v <= b + 3))
    image = frame.image.astype(np.float64)
    shadow = on_road & (z > z0 + 1.0) & (z < z0 + bridge.depth_m - 1.0)
    sunlit = on_road & (z > 6.0) & (z < z0 - 3.0)
    assert shadow.sum() > 300 and sunlit.sum() > 3000
    assert image[sunlit].mean() - image[shadow].mean() >= 30.0
    assert abs(image[shadow].mean() - scenario.lighting.asphalt_gray * scenario.lighting.shadow_factor) < 12.0
    # Full width: every lane has the dark band.
    for lane_centre in np.arange(scenario.road.lanes) * scenario.road.lane_width_m + scenario.road.left_edge_m + 1.8:
        in_lane = shadow & (np.abs(x - lane_centre) < 1.0)
        assert image[in_lane].mean() < image[sunlit].mean() - 30.0


def test_brake_lights_light_up_when_the_lead_brakes():
    before, during = render(_plain("lead_braking_0p3g"), frames=[45, 105])  # braking starts at t = 2 s (frame 60)

    def brightest_in_box(frame):
        lead = next(v for v in frame.truth if v["id"] == 1)
        l, t, r, b = (int(round(c)) for c in lead["box"])
        return frame.image[t:b, l:r].max()

    # Unlit, the brightest part is the number plate (~215); lit brake lights are ~245.
    assert brightest_in_box(before) < 235 <= brightest_in_box(during)


def test_sun_side_shadow_spills_beside_the_vehicle_only_on_that_side():
    data = {"duration_s": 1.0, "seed": 3, "lighting": {"sun_side_m": 0.6, "noise_sigma": 0.0},
            "ego": {"speed_kmh": 50}, "vehicles": [{"id": 1, "lane": 0, "z_m": 15, "speed_kmh": 50, "shade": "light"}]}
    scenario = parse_scenario(data, "scenario sun.yaml")
    frame = next(render(scenario, frames=[0]))
    l, t, r, b = frame.truth[0]["box"]
    image = frame.image.astype(np.float64)
    rows = slice(int(b) - 3, int(b))  # just above the bottom edge: the road beside the tyres
    right = image[rows, int(r) + 3:int(r) + 8].mean()
    left = image[rows, int(l) - 8:int(l) - 3].mean()
    assert left - right >= 30.0  # shadow on the right (sun on the left), sun-lit road on the left
