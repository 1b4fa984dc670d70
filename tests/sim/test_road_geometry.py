"""Curves, hills and the ego's own lane changes (app/sim/road_shape.py): the road's reference line is the
circle its curvature says, the picture puts the markings where the analytic projection does (within 1 px),
and the truth (ranges, boxes, the camera's pose against the local road) stays exact."""
from __future__ import annotations

import math

import numpy as np
import pytest

from app.sim import Camera, list_scenarios, load_scenario, render
from app.sim.road_shape import RoadShape, Segment
from app.sim.scenario import ScenarioError, list_road_geometry_scenarios, parse_scenario

R_CURVE, R_CREST = 600.0, -1500.0


def _scenario(road: dict, ego: dict | None = None, vehicles: list | None = None):
    data = {"name": "bent", "duration_s": 1.0, "fps": 30, "seed": 5, "shake": {"pitch_deg": 0, "yaw_deg": 0},
            "lighting": {"noise_sigma": 0, "texture_contrast": 0},
            "road": road, "ego": ego or {"speed_kmh": 72}, "vehicles": vehicles or []}
    return parse_scenario(data, "test")


def _on_circle(radius: float, arc: np.ndarray, offset: np.ndarray | float) -> np.ndarray:
    """Local (x right, y up, z forward) of a point `offset` m right of a reference line that starts at the
    ego and bends with this radius (> 0 right) in plan, from the circle's equation: no road_shape code."""
    phi = arc / radius
    r = radius - offset  # distance from the centre (right of the start for a right-hand bend)
    return np.stack([radius - r * np.cos(phi), np.zeros_like(phi), r * np.sin(phi)], -1)


def test_reference_line_of_constant_curvature_is_a_circle():
    s = np.linspace(0.0, 280.0, 57)
    curve = RoadShape((Segment(0.0, 300.0, 1.0 / 500.0),), (), 400.0)
    c, n, _u, t = curve.frame(s)
    assert np.abs(c - _on_circle(500.0, s, 0.0)).max() < 2e-4
    assert np.allclose(t[:, [0, 2]], np.stack([np.sin(s / 500.0), np.cos(s / 500.0)], 1), atol=1e-9)
    crest = RoadShape((), (Segment(0.0, 300.0, -1.0 / 2000.0),), 400.0)
    c, _n, u, _t = crest.frame(s)
    drop = 2000.0 * (1.0 - np.cos(s / 2000.0))
    assert np.abs(c - np.stack([0 * s, -drop, 2000.0 * np.sin(s / 2000.0)], 1)).max() < 2e-4
    assert np.all(u[:, 1] > 0.99) and np.allclose(u[:, 2], np.sin(s / 2000.0), atol=1e-9)  # the surface tilts down


def test_bend_is_the_flat_world_before_the_road_bends():
    shape = RoadShape((Segment(900.0, 100.0, 1.0 / 400.0),), (Segment(950.0, 50.0, 1.0 / 3000.0),), 1500.0)
    pts = np.array([[x, y, z] for x in (-5.0, 0.0, 3.6) for y in (0.0, 1.5) for z in (-20.0, 2.0, 60.0, 500.0)])
    assert np.allclose(shape.bend_at(100.0).apply(pts), pts, atol=1e-9)


def test_bend_inside_a_curve_follows_the_circle():
    shape = RoadShape((Segment(0.0, 600.0, 1.0 / R_CURVE),), (), 900.0)
    arc = np.linspace(1.0, 150.0, 30)
    for offset in (-5.4, 0.0, 1.8):
        local = shape.bend_at(200.0).apply(np.stack([np.full_like(arc, offset), 0 * arc, arc], 1))
        assert np.abs(local - _on_circle(R_CURVE, arc, offset)).max() < 5e-4


def _marking_columns(image: np.ndarray, rows: np.ndarray, expected_u: np.ndarray, floor: float) -> np.ndarray:
    """Brightness-weighted column of the marking in each row, within +-12 px of where it is expected (a line
    slanted by 4 px a row spans ~10 px of a row, and its anti-aliased ramps more)."""
    out = []
    for v, u0 in zip(rows, expected_u):
        lo, hi = int(round(u0)) - 12, int(round(u0)) + 13
        seg = image[int(v), lo:hi].astype(float) - floor
        seg[seg < 0] = 0.0
        out.append(np.nan if seg.sum() == 0 else lo + float((seg * np.arange(len(seg))).sum() / seg.sum()))
    return np.array(out)


@pytest.mark.parametrize("kind", ["curve", "crest"])
def test_markings_are_drawn_where_the_analytic_projection_puts_them(kind):
    bends = {"curves": [{"s_m": 0, "length_m": 400, "radius_m": R_CURVE}]} if kind == "curve" else \
        {"hills": [{"s_m": 0, "length_m": 400, "radius_m": R_CREST}]}
    sc = _scenario({"lanes": 2, "ego_lane": 0, "shoulder_m": 4.0, **bends})  # the guardrail well away from the line
    frame = next(render(sc, frames=[0]))
    camera = Camera.from_dict(dict(sc.camera))
    road = sc.road
    edge = road.right_edge_m - 0.5 * road.marking_width_m  # centre of the solid right edge line
    arc = np.geomspace(6.0, 45.0, 400)
    if kind == "curve":
        local = _on_circle(R_CURVE, arc, edge)
    else:  # a vertical circle below the tangent plane: the road falls away by R (1 - cos)
        r = -R_CREST
        local = np.stack([np.full_like(arc, edge), -r * (1 - np.cos(arc / r)), r * np.sin(arc / r)], -1)
    u, v = camera.project(local)
    flat_u, flat_v = camera.project(np.stack([np.full_like(arc, edge), 0 * arc, arc], 1))
    rows = np.arange(math.ceil(v.min()) + 2, min(479, math.floor(v.max())) - 2)
    expected = np.interp(rows, v[::-1], u[::-1])
    inside = (expected > 14) & (expected < camera.width - 15)
    rows, expected = rows[inside], expected[inside]
    assert len(rows) > 40
    found = _marking_columns(frame.image, rows, expected, road_floor := sc.lighting.asphalt_gray + 20)
    assert np.isfinite(found).mean() > 0.95, (kind, road_floor)
    err = np.abs(found - expected)[np.isfinite(found)]
    assert err.max() <= 1.0, (kind, err.max())
    # ... and the bend shows: a straight, level road's line is elsewhere by several pixels
    assert np.abs(np.interp(rows, flat_v[::-1], flat_u[::-1]) - expected).max() > 3.0


def test_truth_on_a_curve_is_the_circle_and_the_box_its_projection():
    sc = _scenario({"curves": [{"s_m": 0, "length_m": 400, "radius_m": R_CURVE}]},
                   vehicles=[{"id": 1, "kind": "car", "lane": 0, "z_m": 40, "speed_kmh": 72}])
    frame = next(render(sc, frames=[0]))
    (truth,) = frame.truth
    centre = _on_circle(R_CURVE, np.array([40.0]), 0.0)[0]
    assert truth["longitudinal_m"] == pytest.approx(centre[2], abs=1e-3)
    assert truth["lateral_m"] == pytest.approx(centre[0], abs=1e-3)
    assert centre[0] == pytest.approx(40.0 ** 2 / (2 * R_CURVE), rel=0.01)  # 1.33 m: the bend is there
    # rear face: across the road at that arc (turned by phi), standing up
    phi, half, spec = 40.0 / R_CURVE, 0.5 * sc.vehicles[0].width_m, sc.vehicles[0]
    side = np.array([math.cos(phi), 0.0, -math.sin(phi)])
    corners = np.array([centre + dx * half * side + np.array([0, y, 0]) for dx in (-1, 1) for y in (0, spec.height_m)])
    u, v = Camera.from_dict(dict(sc.camera)).project(corners)
    assert np.allclose(truth["box"], [u.min(), v.min(), u.max(), v.max()], atol=1e-3)


def test_ego_lane_change_turns_the_camera_against_the_lane_and_moves_it_across():
    sc = _scenario({"lanes": 3}, ego={"speed_kmh": 72, "lane_changes": [{"t_s": 0.0, "to_lane": 1, "duration_s": 4.0}]},
                   vehicles=[{"id": 1, "kind": "car", "lane": 0, "z_m": 30, "speed_kmh": 72}])
    frame = next(render(sc, frames=[15]))  # t = 0.5 s into the 4-s manoeuvre
    t, v, width = 0.5, 20.0, sc.road.lane_width_m
    e = width * 0.5 * (1 - math.cos(math.pi * t / 4.0))
    de_dt = width * 0.5 * math.pi / 4.0 * math.sin(math.pi * t / 4.0)
    mount = Camera.from_dict(dict(sc.camera))
    assert frame.yaw_deg - mount.yaw_deg == pytest.approx(math.degrees(math.atan2(de_dt, v)), abs=1e-9)
    assert frame.road["ego_lateral_m"] == pytest.approx(e, abs=1e-9)
    assert frame.truth[0]["lateral_m"] == pytest.approx(-e, abs=1e-9)  # the lead stays in the lane the ego leaves
    assert frame.yaw_rate_rps < 0  # turning right (left positive, as the CAN bus has it)


@pytest.mark.parametrize("road, message", [
    ({"curves": [{"s_m": 0, "length_m": 100, "radius_m": 150}]}, "road.curves[0].radius_m: |radius_m| must be >= 200"),
    ({"hills": [{"s_m": 0, "length_m": 100, "radius_m": 3000}, {"s_m": 50, "length_m": 10, "radius_m": -3000}]},
     "road.hills[1].s_m: starts before the previous stretch has ended"),
    ({"curves": [{"s_m": 0, "radius_m": 900}]}, "road.curves[0].length_m: missing required key"),
])
def test_bad_bends_name_the_key(road, message):
    with pytest.raises(ScenarioError, match=message.replace("|", r"\|").replace("[", r"\[").replace("]", r"\]")):
        _scenario(road)


def test_bent_scenarios_are_shipped_apart_and_load_by_name():
    bent = list_road_geometry_scenarios()
    assert {"calibration_curves_hills", "calibration_lane_change"} <= set(bent)
    assert not set(bent) & set(list_scenarios())  # the flat scenarios' contract (tests/sim) stays theirs
    sc = load_scenario("calibration_curves_hills")
    assert sc.road.curves and sc.road.hills
