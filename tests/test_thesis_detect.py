"""Thesis detector on single images (run_stage 'detect': shadow hypotheses + vertical-edge
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

from app.sim import load_scenario
from app.sim.frames import scenario_camera
from tests.conftest import data_path
from tests.thesis_scenes import best_match, detected, edge_errors, false_boxes, iou, lead

EDGE_TOL_PX = 3.0
BANDS = ((0, 20), (20, 40), (40, 80), (80, math.inf))

# TuSimple's camera: K and height from train_clip1/calibration.txt (same rig); the pitch puts the
# horizon at row 344, where the annotated vehicles' bottom rows extrapolate to zero width (least
# squares over all supp boxes), i.e. atan((376.26 - 344) / 710.37) = 2.6 deg down.
TUSIMPLE_CAMERA = {"width": 1280, "height": 720, "fx": 714.1526, "fy": 710.3725, "cx": 675.5754,
                   "cy": 376.2563, "height_m": 1.80, "pitch_deg": 2.6}
# What shadow + vertical edges measured on the 600 supp images (see tusimple_scores): floors that
# catch a regression; the issue's bar (recall 0.70 at precision 0.80) is tested separately.
TUSIMPLE_FLOOR_40 = {"recall": 0.29, "precision": 0.68}


def _boxes(result):
    return [t.box for t in result.tracks]


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
            errors = edge_errors(r.tracks[i].box, g["box"])
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
    assert sum(len(r.tracks) for r in results) == 0


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


def test_detection_without_a_lane_model():
    sections = json.dumps({"lanes": {"min_edge_contrast": 255.0, "min_bar_contrast": 255.0}})
    fr, results = detected("steady_following", "{}", sections)
    assert all(not r.lanes for r in results)
    for f, r in zip(fr, results):
        i, v = best_match(_boxes(r), lead(f.truth)["box"])
        assert v >= 0.5 and max(edge_errors(r.tracks[i].box, lead(f.truth)["box"])) <= EDGE_TOL_PX


def test_detection_on_a_larger_image_with_the_camera_scaled():
    camera = json.dumps({"width": 1280, "height": 960, "fx": 1400.0, "fy": 1400.0, "cx": 640.0, "cy": 480.0})
    fr, results = detected("steady_following", camera)
    hits = sum(best_match(_boxes(r), lead(f.truth)["box"])[1] >= 0.5 for f, r in zip(fr, results))
    assert hits >= 0.98 * len(fr)


# --- TuSimple -------------------------------------------------------------------------------------

def _match(dets, gts):
    """Greedy one-to-one matching at IoU >= 0.5: {detection index: annotation index}."""
    pairs = sorted(((iou(d, g), i, j) for i, d in enumerate(dets) for j, g in enumerate(gts)), reverse=True)
    by_det, used = {}, set()
    for v, i, j in pairs:
        if v < 0.5:
            break
        if i not in by_det and j not in used:
            by_det[i] = j
            used.add(j)
    return by_det


def _band(h):
    return next(b for b in BANDS if b[0] <= h < b[1])


@pytest.fixture(scope="module")
def tusimple_scores():
    from app.core import Pipeline
    root = data_path("tusimple", "supp")
    annotations = json.loads((root / "annotation.json").read_text())
    gt_n = {b: 0 for b in BANDS}; gt_hit = {b: 0 for b in BANDS}
    det_n = {b: 0 for b in BANDS}; det_hit = {b: 0 for b in BANDS}
    rel_n = rel_hit = big_n = big_hit = 0
    with Pipeline({"pipeline": {"preset": "thesis"}, "camera": TUSIMPLE_CAMERA}) as p:
        for e in annotations:
            gray = cv2.imread(str(root / e["file_name"]), cv2.IMREAD_GRAYSCALE)
            dets = _boxes(p.run_stage("detect", gray))
            gts = [(b["left"], b["top"], b["right"], b["bottom"]) for b in e["bbox"]]
            m = _match(dets, gts)
            matched_gt = set(m.values())
            for j, g in enumerate(gts):
                b = _band(g[3] - g[1])
                gt_n[b] += 1; gt_hit[b] += j in matched_gt
                if g[3] - g[1] >= 40:
                    big_n += 1; big_hit += j in matched_gt
            for i, d in enumerate(dets):
                h = gts[m[i]][3] - gts[m[i]][1] if i in m else d[3] - d[1]
                b = _band(h)
                det_n[b] += 1; det_hit[b] += i in m
                if d[3] - d[1] >= 40 or h >= 40:
                    rel_n += 1; rel_hit += i in m
    scores = {"bands": {f"{b[0]}-{b[1]}": {"recall": gt_hit[b] / max(1, gt_n[b]), "n_gt": gt_n[b],
                                            "precision": det_hit[b] / max(1, det_n[b]), "n_det": det_n[b]}
                        for b in BANDS},
              "recall_40": big_hit / max(1, big_n), "precision_40": rel_hit / max(1, rel_n)}
    print("TuSimple supp detection:", json.dumps(scores, indent=1))
    return scores


def test_tusimple_detection_by_height_band(tusimple_scores):
    assert tusimple_scores["recall_40"] >= TUSIMPLE_FLOOR_40["recall"]
    assert tusimple_scores["precision_40"] >= TUSIMPLE_FLOOR_40["precision"]
    # Every band is measured (the small ones are reported, not held to a bar).
    assert all(s["n_gt"] > 0 for s in tusimple_scores["bands"].values())


@pytest.mark.xfail(strict=True, reason=(
    "not reached by shadow + vertical edges: recall 0.32 at precision 0.72 for boxes >= 40 px (no score "
    "threshold gives recall above 0.09 at precision 0.8); the annotations box whole vehicles (flank "
    "included, oncoming lanes, shoulders) while the method finds rear faces standing on a shadow in the "
    "road area. A COCO CNN (NanoDet-m, app/eval/cnn_reference.py) clears the bar on the same images: "
    "0.77 at 0.91"))
def test_tusimple_meets_the_issue_bar(tusimple_scores):
    assert tusimple_scores["recall_40"] >= 0.70 and tusimple_scores["precision_40"] >= 0.80
