"""Thesis tracker (one Kalman filter per vehicle on its bottom corners, ROI search between full
detections, correlation check before dropping): on rendered scenarios with exact ground truth."""
from __future__ import annotations

import json

import numpy as np
import pytest

from app.core import Pipeline
from tests.thesis_scenes import best_match, config, edge_errors, false_boxes, frames, lead, tracked

CONFIRM_FRAMES = 2  # default confirm_hits = 3: a vehicle seen from frame 0 is confirmed at frame 2
EDGE_TOL_PX = 3.0   # left, right and bottom of the lead box; 5 % of the width for a near vehicle


def _confirmed(result):
    return [t for t in result.tracks if t.confirmed]


def _track_ids_of(name: str, vehicle_id: int, sections: dict | None = None) -> tuple[list, int, int]:
    """Ids of the confirmed tracks matching (IoU >= 0.5) the vehicle, frames matched, frames visible."""
    fr, results = tracked(name, json.dumps(sections or {}))
    ids, matched, visible = [], 0, 0
    for f, r in zip(fr, results):
        g = next((g for g in f.truth if g["id"] == vehicle_id), None)
        if g is None or g["visible_fraction"] < 0.999 or f.index < CONFIRM_FRAMES:
            continue
        visible += 1
        conf = _confirmed(r)
        i, v = best_match([t.box for t in conf], g["box"])
        if v >= 0.5:
            matched += 1
            ids.append(conf[i].id)
    return ids, matched, visible


@pytest.mark.parametrize("name", ["steady_following", "lane_change", "cut_in", "dense_traffic",
                                  "stopped_lead_72kmh", "lead_braking_0p3g", "slower_lead"])
def test_lead_tracked_in_every_frame_within_60m_with_tight_edges(name):
    fr, results = tracked(name)
    checked = 0
    for f, r in zip(fr, results):
        g = lead(f.truth)
        if g is None or f.index < CONFIRM_FRAMES:
            continue
        checked += 1
        conf = _confirmed(r)
        i, v = best_match([t.box for t in conf], g["box"])
        assert v >= 0.5, f"{name} frame {f.index}: lead at {g['longitudinal_m']:.1f} m not tracked (IoU {v:.2f})"
        tol = max(EDGE_TOL_PX, 0.05 * (g["box"][2] - g["box"][0]))
        errors = edge_errors(conf[i].box, g["box"])
        assert max(errors) <= tol, f"{name} frame {f.index}: left/right/bottom errors {errors} > {tol:.1f} px"
    assert checked > 50


def test_steady_following_keeps_every_id():
    for vehicle in (1, 2):  # the lead and the van in the right lane
        ids, matched, visible = _track_ids_of("steady_following", vehicle)
        assert matched == visible and len(set(ids)) == 1, f"vehicle {vehicle}: ids {sorted(set(ids))}"


@pytest.mark.parametrize("name, vehicle", [("lane_change", 1), ("cut_in", 1)])
def test_vehicle_changing_lanes_keeps_its_id(name, vehicle):
    ids, matched, visible = _track_ids_of(name, vehicle)
    assert matched >= 0.98 * visible
    assert len(set(ids)) == 1, f"{name}: vehicle {vehicle} had ids {sorted(set(ids))}"


def test_empty_road_never_confirms_a_track():
    fr, results = tracked("empty_road")
    assert all(not _confirmed(r) for r in results)


def test_overpass_shadow_gives_no_false_confirmed_track():
    fr, results = tracked("overpass_shadow")
    for f, r in zip(fr, results):
        assert not false_boxes([t.box for t in _confirmed(r)], f.truth), f"frame {f.index}"
    # ... and the car in the right lane is followed through the shadow band, with one id.
    ids, matched, visible = _track_ids_of("overpass_shadow", 1)
    assert matched >= 0.98 * visible and len(set(ids)) == 1


def test_lead_tracked_without_a_lane_model():
    # No lane markings found (contrast threshold out of reach): the detector falls back to the
    # flat-road camera model for the scan area and the expected vehicle width.
    sections = {"lanes": {"min_edge_contrast": 255.0, "min_bar_contrast": 255.0}}
    fr, results = tracked("steady_following", json.dumps(sections))
    assert all(not r.lanes for r in results)
    ids, matched, visible = _track_ids_of("steady_following", 1, sections)
    assert matched == visible and len(set(ids)) == 1


def test_image_velocity_follows_the_vehicle():
    # The lead's bottom centre in the lane change moves sideways; compare the tracker's image velocity
    # with the truth box's central difference (px/s).
    fr, results = tracked("lane_change")
    errors, speeds = [], []
    for k in range(CONFIRM_FRAMES + 5, len(fr) - 1):
        g0, g1 = (next(g for g in fr[j].truth if g["id"] == 1) for j in (k - 1, k + 1))
        g = next(g for g in fr[k].truth if g["id"] == 1)
        dt = fr[k + 1].t_s - fr[k - 1].t_s
        vx = ((g1["box"][0] + g1["box"][2]) - (g0["box"][0] + g0["box"][2])) / (2 * dt)
        conf = _confirmed(results[k])
        i, v = best_match([t.box for t in conf], g["box"])
        if v >= 0.5:
            errors.append(conf[i].vx_px_s - vx)
            speeds.append(abs(vx))
    assert max(speeds) > 20.0  # the lane change really moves it
    assert np.median(np.abs(errors)) < 3.0 and np.percentile(np.abs(errors), 90) < 8.0


def test_full_detection_runs_every_n_frames():
    fr = frames("steady_following")[:13]
    with Pipeline(config("steady_following", kalman={"detect_every_n": 4})) as p:
        full = [p.process(f.image, f.t_s).full_detection for f in fr]
    assert [i for i, v in enumerate(full) if v] == [0, 4, 8, 12]


def test_stage_times_name_the_sub_stages():
    fr = frames("steady_following")[:3]
    with Pipeline(config("steady_following")) as p:
        r0, r1 = (p.process(f.image, f.t_s) for f in fr[:2])
    assert r0.full_detection and {"hypotheses", "verify", "track"} <= set(r0.stages)
    assert not r1.full_detection and "track" in r1.stages and "hypotheses" not in r1.stages


def test_track_confirmed_after_m_hits():
    fr = frames("steady_following")[:6]
    with Pipeline(config("steady_following", kalman={"confirm_hits": 5})) as p:
        results = [p.process(f.image, f.t_s) for f in fr]
    lead_box = next(g for g in fr[0].truth if g["id"] == 1)["box"]
    states = []
    for r in results:
        i, v = best_match([t.box for t in r.tracks], lead_box)
        assert v >= 0.5
        states.append(r.tracks[i].confirmed)
    assert states == [False, False, False, False, True, True]


def _follow_then(frames_after, sections: dict, n_before: int = 30):
    """Tracks the steady_following lead for n_before frames, then feeds other images; returns the
    lead's track id and, per later frame, the ids of all tracks."""
    fr = frames("steady_following")[:n_before]
    with Pipeline(config("steady_following", **sections)) as p:
        for f in fr:
            r = p.process(f.image, f.t_s)
        g = next(g for g in fr[-1].truth if g["id"] == 1)
        i, v = best_match([t.box for t in r.tracks], g["box"])
        assert v >= 0.5 and r.tracks[i].confirmed
        lead_id = r.tracks[i].id
        t = fr[-1].t_s
        later = []
        for image in frames_after:
            t += 1 / 30
            later.append({tr.id for tr in p.process(image, t).tracks})
    return lead_id, later


def test_vehicle_deleted_after_k_missed_frames():
    # The road empties at once (frames of the empty-road run): neither the edges nor the correlation
    # find the vehicles any more, and each track goes after max_misses frames.
    empty = [f.image for f in frames("empty_road")[:6]]
    lead_id, later = _follow_then(empty, {"kalman": {"max_misses": 4}})
    assert all(lead_id in ids for ids in later[:3])
    assert all(lead_id not in ids for ids in later[3:])


def test_correlation_keeps_a_vehicle_whose_edges_fade():
    # The same scene at a fifth of its contrast for 8 frames: the edges fall below the adaptive
    # thresholds but the normalised correlation of the lead's last box still recognises it.
    fr = frames("steady_following")
    faded = []
    for f in fr[30:38]:
        img = f.image.astype(np.float32)
        faded.append(np.clip(0.2 * img + 0.8 * img.mean(), 0, 255).astype(np.uint8))
    kept_id, kept = _follow_then(faded, {})
    assert all(kept_id in ids for ids in kept)
    dropped_id, dropped = _follow_then(faded, {"kalman": {"ncc_min": 1.0}})
    assert dropped_id not in dropped[-1]


def test_reset_starts_ids_again():
    fr = frames("steady_following")[:4]
    with Pipeline(config("steady_following")) as p:
        first = [p.process(f.image, f.t_s) for f in fr]
        p.reset()
        again = [p.process(f.image, f.t_s) for f in fr]
    assert sorted(t.id for t in first[-1].tracks) == sorted(t.id for t in again[-1].tracks)
    assert min(t.id for t in again[0].tracks) == 1


def _frames_on(name: str, vehicle_id: int, sections: dict) -> tuple[int, int]:
    """Frames a confirmed track is on the vehicle (IoU >= 0.5 with its visible box) and frames the evaluation scores
    it (at least half visible, within 60 m)."""
    from app.eval.track_score import _box
    fr, results = tracked(name, json.dumps(sections))
    on = scored = 0
    for f, r in zip(fr, results):
        g = next((g for g in f.truth if g["id"] == vehicle_id), None)
        if g is None or g["visible_fraction"] < 0.5 or g["longitudinal_m"] > 60.0:
            continue
        scored += 1
        on += best_match([t.box for t in _confirmed(r)], _box(g))[1] >= 0.5
    return on, scored


def test_a_truck_keeps_its_measured_height_in_the_box_tracker():
    """dense_traffic: the truck 28-40 m ahead in the left lane (vehicle 5, 1.5 widths tall). The Kalman tracker takes
    each detection's aspect into the box (0.4 of it); detections whose top the verification could not find carry a
    car's guessed 0.8 and pulled the truck's box down to IoU < 0.5 with it. A vehicle measured taller than
    vehicle_height.tall_aspect twice in a row keeps its measured height (track/vehicle_height.hpp, shared with phd).
    Measured: 221 of the 300 scored frames, 196 without the rule."""
    on, scored = _frames_on("dense_traffic", 5, {})
    off, _ = _frames_on("dense_traffic", 5, {"vehicle_height": {"tall_aspect": 10}})
    assert scored == 300 and on >= 215, (on, scored)
    assert off < 205, f"the truck was followed on {off} frames without the rule: the test no longer tests it"


def test_boxes_keep_their_width_per_depth_through_the_calibration_drive(tmp_path):
    """calibration_drive (hills, curves, lane changes): the ROI search let boxes grow onto neighbouring edges and
    templates slide with the road, 235 false and 210 missed vehicle-frames (MOTA 0.72). An ROI or template
    measurement whose width per depth below the horizon breaks the vehicle's (kalman.max_width_depth_change) is not
    taken: measured MOTA 0.95 (kalman.max_width_depth_change 0.3)."""
    from app.eval.synthetic import evaluate_scenario, summarize

    def mota(config_path=None) -> float:
        run = evaluate_scenario("calibration_drive", "thesis", config_path, vehicle_look="plain")
        return summarize([run])["per_scenario"]["calibration_drive"]["mota"]

    off = tmp_path / "off.yaml"
    off.write_text("kalman: {max_width_depth_change: 100}\n")
    on, without = mota(), mota(str(off))
    assert on >= 0.93, on
    assert without <= 0.8, f"MOTA {without} without the check: the test no longer tests it"
