"""Thesis detector on single images (Pipeline.detect: shadow hypotheses + vertical-edge
verification): rendered scenarios with exact ground truth, and the real TuSimple images.

TuSimple matching rule (explicit, as the issue asks): a detection and an annotated box match at
IoU >= 0.5, greedily from the highest IoU, each at most once. Recall of a height band = matched
annotated boxes of that band / annotated boxes of that band. Precision counts the detections that
are >= 40 px high or matched to an annotated box >= 40 px high (a small detection of a big car is
wrong, a big detection of a 35 px car is right): matched ones / all of those.
"""
from __future__ import annotations

import json
import math

import cv2
import pytest

from app.core import Pipeline
from app.sim import load_scenario
from app.sim.frames import scenario_camera
from tests.conftest import data_path
from tests.thesis_scenes import best_match, config, detected, edge_errors, false_boxes, iou, lead

EDGE_TOL_PX = 3.0

# What shadow + vertical edges measured on the 600 supp images (see tusimple_scores): floors that
# catch a regression; the issue's bar (recall 0.70 at precision 0.80) is tested separately.
TUSIMPLE_FLOOR_40 = {"recall": 0.29, "precision": 0.68}


def _boxes(result):
    return [tuple(b[:4]) for b in result.rows()]


@pytest.mark.parametrize("name", ["steady_following", "dense_traffic", "cut_in", "lane_change"])
def test_lead_detected_in_every_single_image_within_60m(name):
    fr, results = detected(name)
    checked = 0
    for f, r in zip(fr, results):
        g = lead(f.truth)
        if g is None:
            continue
        checked += 1
        i, v = best_match(_boxes(r), g["box"])
        assert v >= 0.5, f"{name} frame {f.index}: lead at {g['longitudinal_m']:.1f} m missed (IoU {v:.2f})"
        if name != "lane_change":  # while it changes lanes a lane marking can stand next to its side
            errors = edge_errors(_boxes(r)[i], g["box"])
            assert max(errors) <= EDGE_TOL_PX, f"{name} frame {f.index}: left/right/bottom errors {errors}"
    assert checked > 100


def test_adjacent_lane_vehicles_detected():
    seen = found = 0
    for name in ("steady_following", "dense_traffic", "adjacent_passing"):
        fr, results = detected(name)
        for f, r in zip(fr, results):
            for g in f.truth:
                if abs(g["lane"]) == 1 and g["visible_fraction"] >= 0.999 and g["longitudinal_m"] <= 40.0:
                    seen += 1
                    found += best_match(_boxes(r), g["box"])[1] >= 0.5
    assert seen > 300 and found >= 0.95 * seen, f"{found}/{seen}"


def test_empty_road_gives_no_detection():
    fr, results = detected("empty_road")
    assert sum(len(r.boxes) for r in results) == 0


def test_overpass_shadow_band_is_not_a_vehicle():
    # The band across the road is as dark as a vehicle shadow and as wide as the road: no detection
    # may stand on it in the ego lane or the right lane (where the car drives through it).
    fr, results = detected("overpass_shadow")
    cam = scenario_camera(load_scenario("overpass_shadow"))
    horizon = cam.cy - cam.fy * math.tan(math.radians(cam.pitch_deg))
    lane_m = load_scenario("overpass_shadow").road.lane_width_m

    def lateral_m(b):  # flat road: X = (x - cx) h / (y - y_h) for fx = fy
        return (0.5 * (b[0] + b[2]) - cam.cx) * cam.height_m / max(1e-3, b[3] - horizon)

    false = [(f.index, b) for f, r in zip(fr, results) for b in false_boxes(_boxes(r), f.truth)]
    in_lanes = [(k, b) for k, b in false if -0.5 * lane_m < lateral_m(b) < 1.5 * lane_m]
    assert not in_lanes, in_lanes
    assert len(false) <= 0.02 * len(fr)  # rare pieces beyond the road edges (guardrail base, posts)


@pytest.mark.parametrize("sun_side_m, lane", [(0.8, -1), (-0.8, 1)])
def test_a_shadow_cast_past_the_vehicle_up_to_a_lane_marking_is_not_its_width(sun_side_m, lane):
    """A dark car in the lane beside, 20-28 m ahead, in a low sun from the side: its shadow spills 0.8 m past
    its far side, over the road up to the lane marking. The stretch of the shadow edge with lit road above it is
    cut off (`shadow.beside_rel`): measured, a box within IoU 0.8 in 60, 60 (left lane) and 60, 59 (right lane) of
    the 60 frames at 20 and 28 m. Without it the verification took the marking for the car's side: no such box in
    any frame, boxes 87-104 px wide on the 61 px car at 20 m, 62-72 px on the 43 px car at 28 m."""
    from app.sim import render
    from app.sim.scenario import parse_scenario

    def tight(scenario, beside_rel: float) -> int:
        cam = scenario_camera(scenario).to_dict()
        config = {"pipeline": {"preset": "thesis"}, "camera": cam, "shadow": {"beside_rel": beside_rel}}
        with Pipeline(config) as p:
            return sum(best_match(_boxes(p.detect(f.image)), f.truth[0]["box"])[1] >= 0.8
                       for f in fr)

    for z_m in (20.0, 28.0):
        data = {"duration_s": 2.0, "seed": 3, "vehicle_look": "plain", "lighting": {"sun_side_m": sun_side_m},
                "ego": {"speed_kmh": 50},
                "vehicles": [{"id": 1, "lane": lane, "z_m": z_m, "speed_kmh": 50, "shade": "dark"}]}
        scenario = parse_scenario(data, f"scenario low sun, lane {lane}, {z_m:.0f} m")
        fr = list(render(scenario))
        on, off = tight(scenario, 0.25), tight(scenario, 0.0)
        assert on >= 0.9 * len(fr), f"{z_m} m: {on} of {len(fr)} frames with a tight box"
        assert off <= 0.1 * len(fr), f"{z_m} m: {off} tight without the rule: the test no longer tests it"


def test_detection_without_a_lane_model():
    sections = json.dumps({"lanes": {"min_edge_contrast": 255.0, "min_bar_contrast": 255.0}})
    fr, results = detected("steady_following", "{}", sections)
    with Pipeline(config("steady_following", "{}", **json.loads(sections))) as p:
        assert all(not p.image_lanes(f.image).lanes for f in fr)
    for f, r in zip(fr, results):
        i, v = best_match(_boxes(r), lead(f.truth)["box"])
        assert v >= 0.5 and max(edge_errors(_boxes(r)[i], lead(f.truth)["box"])) <= EDGE_TOL_PX


def test_detection_on_a_larger_image_with_the_camera_scaled():
    camera = json.dumps({"width": 1280, "height": 960, "fx": 1400.0, "fy": 1400.0, "cx": 640.0, "cy": 480.0})
    fr, results = detected("steady_following", camera)
    hits = sum(best_match(_boxes(r), lead(f.truth)["box"])[1] >= 0.5 for f, r in zip(fr, results))
    assert hits >= 0.98 * len(fr)


# --- TuSimple -------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def tusimple_scores():
    """The evaluation's own scoring (app/eval/tusimple_boxes.py), as `headway eval` reports it."""
    from app.eval.tusimple_boxes import evaluate

    bands = evaluate(str(data_path("tusimple", "supp")))["bands"]
    print("TuSimple supp detection:", json.dumps(bands, indent=1))
    return {"bands": {name: {"recall": b["recall"], "n_gt": b["gt"], "precision": b["precision"]}
                      for name, b in bands.items() if name not in (">=40", "overall")},
            "recall_40": bands[">=40"]["recall"], "precision_40": bands[">=40"]["precision"]}


def test_tusimple_detection_by_height_band(tusimple_scores):
    assert tusimple_scores["recall_40"] >= TUSIMPLE_FLOOR_40["recall"]
    assert tusimple_scores["precision_40"] >= TUSIMPLE_FLOOR_40["precision"]
    # Every band is measured (the small ones are reported, not held to a bar).
    assert all(s["n_gt"] > 0 for s in tusimple_scores["bands"].values())


@pytest.mark.xfail(strict=True, reason=(
    "not reached by shadow + vertical edges: recall 0.31 at precision 0.70 for boxes >= 40 px (no score "
    "threshold gives recall above 0.01 at precision 0.8); the annotations box whole vehicles (flank "
    "included, oncoming lanes, shoulders) while the method finds rear faces standing on a shadow in the "
    "road area. A COCO CNN (NanoDet-m, app/eval/cnn_reference.py) clears the bar on the same images: "
    "0.77 at 0.91"))
def test_tusimple_meets_the_issue_bar(tusimple_scores):
    assert tusimple_scores["recall_40"] >= 0.70 and tusimple_scores["precision_40"] >= 0.80
