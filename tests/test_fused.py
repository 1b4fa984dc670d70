"""The `cascade` detector part and the `fused` and `cascade` presets (issue 12 point 4, issue 15 point 5):
the part gives the trained Haar cascade's detections as hypotheses on a real highway image, several
detectors' hypotheses are merged and verified once, the `cascade` preset (cascade + phd) tracks a vehicle,
and `fused` (cascade + shadow + parallax -> one verification -> kalman) warns in time in the FCW cases."""
from __future__ import annotations

import json

import cv2
import pytest

from app import config as configuration
from app.core import Pipeline
from app.eval.fcw_scenarios import REQUIRED_TTC_S, evaluate
from app.eval.matching import iou_matrix
from tests.conftest import DATA, data_path
from tests.thesis_scenes import config, frames


def _iou(a, b) -> float:
    ix = max(0.0, min(a[2], b[2]) - max(a[0], b[0]))
    iy = max(0.0, min(a[3], b[3]) - max(a[1], b[1]))
    inter = ix * iy
    return inter / ((a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - inter)


def _validation_image(name: str):
    supp = data_path("tusimple", "supp")
    entry = next(e for e in json.loads((supp / "annotation.json").read_text()) if e["file_name"] == name)
    truth = [(b["left"], b["top"], b["right"], b["bottom"]) for b in entry["bbox"]]
    return cv2.imread(str(supp / name), cv2.IMREAD_GRAYSCALE), truth


def _tusimple_pipeline(pipeline: dict) -> Pipeline:
    from app.eval.tusimple_boxes import tusimple_config

    return Pipeline(configuration.core_sections(tusimple_config(configuration.load(None, {"pipeline": pipeline}))))


def test_the_cascade_part_finds_the_car_in_a_validation_image():
    """TuSimple validation image 0001 (three cars 25-79 px wide ahead): the `cascade` preset's detector part,
    run alone on the image, gives hypotheses scored in [0, 1], exactly the cascade's detections (the core's
    `cascade` stage), and one of them boxes the nearest car (79 x 46 px) at IoU >= 0.5."""
    gray, truth = _validation_image("images/0001.jpg")
    with _tusimple_pipeline({"preset": "cascade"}) as pipe:
        part = pipe.run_stage("detect", gray)
        stage = pipe.run_stage("cascade", gray)
    hyps = [(t.box, t.confidence) for t in part.tracks]
    assert hyps and all(0.0 <= c <= 1.0 for _, c in hyps)
    assert hyps == [(t.box, t.confidence) for t in stage.tracks]
    assert "cascade" in part.stages
    assert max(_iou(b, truth[0]) for b, _ in hyps) >= 0.5


def test_several_detectors_are_merged_and_verified_once():
    """cascade + shadow on image 0001, merged and verified once by the shadow detector's verification. By
    default (merge.min_appearance 1) a vehicle the cascade alone found is not kept: the vehicles are the shadow
    detector's own detections, box for box, each scored at least as high, and higher where the cascade found it
    too (the nearest car). Admitting the cascade's own vehicles (min_appearance 0) adds vehicles, each through
    the same verification, so far fewer than the cascade's hypotheses."""
    gray, truth = _validation_image("images/0001.jpg")
    both = {"preset": "thesis", "detectors": ["cascade", "shadow"]}
    with _tusimple_pipeline(both) as pipe:
        merged = pipe.run_stage("detect", gray)
    with _tusimple_pipeline({"preset": "thesis"}) as pipe:
        shadow = pipe.run_stage("detect", gray)
    with _tusimple_pipeline({"preset": "cascade"}) as pipe:
        cascade = pipe.run_stage("detect", gray)
    assert "merge" in merged.stages
    by_box = {t.box: t.confidence for t in shadow.tracks}
    assert sorted(t.box for t in merged.tracks) == sorted(by_box)
    assert all(t.confidence >= by_box[t.box] for t in merged.tracks)
    nearest = max(merged.tracks, key=lambda t: _iou(t.box, truth[0]))
    assert _iou(nearest.box, truth[0]) >= 0.5 and nearest.confidence > by_box[nearest.box]

    from app.eval.tusimple_boxes import tusimple_config

    cfg = tusimple_config(configuration.load(None, {"pipeline": both, "merge": {"min_appearance": 0.0}}))
    with Pipeline(configuration.core_sections(cfg)) as pipe:
        admitted = pipe.run_stage("detect", gray)
    assert len(shadow.tracks) < len(admitted.tracks) < len(cascade.tracks)


def _on(track, truth_box) -> bool:
    """The track is on the vehicle: IoU >= 0.3 with its visible box, as the real-video evaluation matches (a box
    three times the vehicle's width around it is another, false, track, not this vehicle's)."""
    return iou_matrix([track.box], [truth_box])[0, 0] >= 0.3


def test_the_cascade_preset_tracks_the_lead():
    """steady_following (a car 25-30 m ahead all along): the `cascade` preset (the cascade's detections,
    features by the GM-PHD filter, range by the UKF) confirms a track on the lead within 1 s and keeps one on it
    over the next two seconds, its range there within 15 % of the truth."""
    name = "steady_following"
    cfg = config(name)
    cfg["pipeline"] = {"preset": "cascade"}
    cfg["cascade"] = {"model": str(configuration.SHIPPED_CASCADE)}
    fr = frames(name)[:90]
    with Pipeline(cfg) as p:
        results = [p.process(f.image, f.t_s) for f in fr]
    on_lead, rel = [], []
    for i, (f, r) in enumerate(zip(fr, results)):
        lead = next(v for v in f.truth if v["id"] == 1)
        on = [t for t in r.tracks if t.confirmed and _on(t, lead["box_clipped"])]
        on_lead.append(bool(on))
        if i >= 30:
            rel += [abs(t.range_m - lead["longitudinal_m"]) / lead["longitudinal_m"] for t in on if t.range_m is not None]
    assert any(on_lead[:30]), on_lead
    assert sum(on_lead[30:90]) >= 54, on_lead
    assert rel and max(rel) <= 0.15, max(rel)


@pytest.mark.parametrize("scenario", sorted(REQUIRED_TTC_S))
def test_fused_warns_before_the_required_ttc(scenario):
    r = evaluate(scenario, preset="fused")
    assert r["warnings"] >= 1, f"{scenario}: no warning at all"
    assert r["true_ttc_s"] is not None and r["true_ttc_s"] >= r["required_ttc_s"], (
        f"{scenario}: warned at true TTC {r['true_ttc_s']:.2f} s, required >= {r['required_ttc_s']} s")


# The white car ahead in the ego lane of Udacity's solidWhiteRight.mp4 (960x540), 54 m at frame 20 and 45 m at frame
# 170: boxes read off the fused preset's track and checked by eye on each frame (docs/PERFORMANCE.md, session 19).
WHITE_CAR_AHEAD = {20: (410, 302, 439, 325), 50: (412, 303, 437, 322), 80: (410, 302, 435, 322),
                   110: (416, 302, 442, 322), 140: (420, 302, 444, 321), 170: (420, 304, 445, 324)}


def _frames_on_the_white_car(preset: str, **sections) -> int:
    from app.eval.real_video_fcw import recordings
    from app.eval.road_motion import read_video

    data_path("udacity", "clips", "solidWhiteRight.mp4")
    source, camera, fps, _ = recordings(DATA, "solidWhiteRight.mp4")[0]
    cfg = configuration.load(None, {"camera": camera, "pipeline": {"preset": preset}, **sections})
    n = 0
    with Pipeline(configuration.core_sections(cfg)) as p:
        for i, f in enumerate(read_video(source, max(WHITE_CAR_AHEAD) + 1)[0]):
            r = p.process(f, i / fps)
            if i in WHITE_CAR_AHEAD:
                n += any(t.confirmed and _iou(t.box, WHITE_CAR_AHEAD[i]) >= 0.3 for t in r.tracks)
    return n


def test_fused_tracks_the_far_car_ahead_that_shadows_alone_miss():
    """solidWhiteRight's white car ahead, 45-54 m away: the tracked `fused` preset has a confirmed track on it on
    the six labelled frames (measured 6 of 6), thesis (shadows and edges) on none. The preset spreads the cascade's
    scan of the nearer sizes over 4 full detections but scans a car's sizes beyond 35 m every time
    (cascade.tracked_far_m); with every size spread (tracked_far_m 0) the car is lost, with the whole scan on every
    detection (tracked_slices 1) it is kept too."""
    assert _frames_on_the_white_car("fused") >= 5
    assert _frames_on_the_white_car("fused", cascade={"tracked_slices": 1}) >= 5
    assert _frames_on_the_white_car("thesis") == 0
    assert _frames_on_the_white_car("fused", cascade={"tracked_far_m": 0.0}) <= 1


def test_fused_starts_no_second_track_beside_a_tracked_car(tmp_path):
    """overpass_shadow: a cascade group half on the dark car ahead and a parallax region agreeing with it started a
    second track beside the car, in the ego lane at ~37 m, confirmed for 30 frames (the suite's precision 0.874
    against thesis's 1.000). Two vehicles at one range stand side by side and cannot overlap in the image, so a
    detection on a tracked vehicle's bottom row overlapping its columns starts no track (kalman.beside_overlap).
    Measured on the plain drawn faces (docs/sim.md, "Real-looking vehicles"), where that cascade group arose."""
    from app.eval.synthetic import evaluate_scenario

    shipped = evaluate_scenario("overpass_shadow", "fused", vehicle_look="plain")
    assert shipped["fp"] == 0 and shipped["tp"] >= 205
    off = tmp_path / "off.yaml"
    off.write_text("kalman: {beside_overlap: 1.0}\n")
    assert evaluate_scenario("overpass_shadow", "fused", config_path=str(off), vehicle_look="plain")["fp"] >= 20
