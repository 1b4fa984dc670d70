"""The parallax preset end to end on synthetic scenarios with camera shake: entries confirmed early,
transient differences and guardrails never confirmed, exits removed (paper 000, section III-B)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml

from app.core import Pipeline
from app.eval.matching import iou_matrix
from app.sim import load_scenario, render

SCENARIOS = Path(__file__).resolve().parent.parent / "app" / "sim" / "scenarios"


def scenario_file(tmp_path: Path, doc: dict, name: str):
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump(doc))
    return load_scenario(path)


def run(scenario, frames=None, edit=None):
    """Yields (frame, result) with the ego speed given, as the car's CAN would."""
    with Pipeline({"pipeline": {"preset": "parallax"}}) as p:
        for f in render(scenario, frames=frames):
            image = edit(f) if edit else f.image
            p.set_ego_motion(f.ego_speed_mps, 0.0)
            yield f, p.process(image, f.t_s)


def confirmed_on(result, box, min_iou=0.3):
    tracks = [t for t in result.tracks if t.confirmed]
    if not tracks:
        return []
    m = iou_matrix([t.box for t in tracks], [box])[:, 0]
    return [t for t, i in zip(tracks, m) if i >= min_iou]


def test_vehicle_entering_from_the_side_is_confirmed_within_10_frames_of_half_visible():
    """overtaking_from_side, car 1 overtakes on the left at +30 km/h. Measured: confirmed 4 frames after
    it is half visible (IoU 0.3; 2-6 over particle seeds 1-5; the thesis preset: 9)."""
    half_visible = confirmed = None
    for f, r in run(load_scenario("overtaking_from_side"), frames=range(0, 90)):
        car = next((v for v in f.truth if v["id"] == 1), None)
        if car and half_visible is None and car["visible_fraction"] >= 0.5:
            half_visible = f.index
        if car and half_visible is not None and confirmed_on(r, car["box_clipped"]):
            confirmed = f.index
            break
    assert half_visible is not None
    assert confirmed is not None and confirmed - half_visible <= 10, (half_visible, confirmed)


def test_slowly_overtaking_truck_is_confirmed_before_the_thesis_preset_would():
    """overtaking_from_side, truck 2 overtakes on the left at +15 km/h: confirmed at IoU >= 0.5 (the eval's
    confirm_delay_frames) fewer than 20 frames after it is half visible, the thesis preset's 20. Its flat back
    shows no parallax and its roof stands above the road band, so the box's top comes from the truck's side
    edge in the current frame. Measured: 3 with the default seed (3-4 over particle seeds 1-10 with per-vehicle
    resampling, 3-30 with the paper's joint resampling); 41 with the box height from the difference alone, whose boxes were half as tall as the truck (IoU 0.35)."""
    half_visible = confirmed = None
    for f, r in run(load_scenario("overtaking_from_side"), frames=range(0, 250)):
        truck = next((v for v in f.truth if v["id"] == 2), None)
        if truck and half_visible is None and truck["visible_fraction"] >= 0.5:
            half_visible = f.index
        if truck and half_visible is not None and confirmed_on(r, truck["box_clipped"], min_iou=0.5):
            confirmed = f.index
            break
    assert half_visible is not None
    assert confirmed is not None and confirmed - half_visible < 20, (half_visible, confirmed)


def test_entries_do_not_hang_on_the_particle_seed(tmp_path):
    """overtaking_from_side, the eval's confirm_delay_frames (half visible to the first confirmed track at IoU
    0.5) for particle seeds 3, 4 and 8. With the paper's joint resampling the truck took 17, 30 and 22 frames and
    car 3 5, 24 and 11: each particle was kept for how well the vehicles already held fitted, and the new vehicle's
    particles collapsed away from its measurement. Resampled per vehicle (the default): truck 4, 3, 4, car 3 4, 4,
    3, car 1 2, 2, 2."""
    from app.eval.synthetic import evaluate_scenario

    for seed in (3, 4, 8):
        path = tmp_path / f"seed{seed}.yaml"
        path.write_text(yaml.safe_dump({"particles": {"seed": seed}}))
        # the figures above were measured on the plain drawn faces (docs/sim.md, "Real-looking vehicles"); with
        # the real look car 1 takes 13 frames with seed 3
        delay = evaluate_scenario("overtaking_from_side", "parallax", str(path),
                                  vehicle_look="plain")["confirm_delay_frames"]
        assert delay.get(2, 99) <= 8 and delay.get(3, 99) <= 15 and delay.get(1, 99) <= 10, (seed, delay)


BLOB = (290, 330, 350, 356)  # l, t, r, b: a dark vehicle-sized patch on the road, ~1.8 m wide at ~17 m


def pasted(first: int, last: int):
    """Frames first..last get the dark patch (fixed in the image, like a car keeping the ego's speed)."""
    def edit(f):
        if not first <= f.index <= last:
            return f.image
        img = f.image.copy()
        img[BLOB[1]:BLOB[3], BLOB[0]:BLOB[2]] = 35
        return img
    return edit


def test_difference_seen_in_one_frame_only_never_becomes_a_vehicle():
    """The patch in frame 40 only: the aligned difference sees it when it appears and when it vanishes,
    but it is never confirmed."""
    for f, r in run(load_scenario("empty_road"), frames=range(20, 80), edit=pasted(40, 40)):
        assert not confirmed_on(r, BLOB, min_iou=0.1), (f.index, [t.box for t in r.tracks if t.confirmed])


def test_the_same_patch_persisting_is_confirmed():
    """Control for the test above: kept from frame 40 on, the patch is a vehicle within 10 frames."""
    confirmed = None
    for f, r in run(load_scenario("empty_road"), frames=range(20, 60), edit=pasted(40, 60)):
        if confirmed_on(r, BLOB):
            confirmed = f.index
            break
    assert confirmed is not None and confirmed <= 50, confirmed


def test_vehicle_leaving_the_image_is_removed(tmp_path):
    """The ego passes a slower car in the left lane; once it has left the image no track stays."""
    doc = yaml.safe_load((SCENARIOS / "empty_road.yaml").read_text())
    doc.update(name="passing_one_car", duration_s=5.0, road={"lanes": 2, "ego_lane": 1},
               ego={"speed_kmh": 100},
               vehicles=[{"id": 1, "kind": "car", "lane": -1, "z_m": 25, "speed_kmh": 60, "shade": "dark"}])
    tracked = False
    gone_since = None
    for f, r in run(scenario_file(tmp_path, doc, "passing")):
        car = next((v for v in f.truth if v["id"] == 1 and v["visible_fraction"] > 0), None)
        if car is not None:
            tracked = tracked or bool(confirmed_on(r, car["box_clipped"]))
            continue
        gone_since = f.index if gone_since is None else gone_since
        if f.index - gone_since >= 10:
            assert not [t for t in r.tracks if t.confirmed], (f.index, [t.box for t in r.tracks])
    assert tracked, "the car was never tracked, the exit test would prove nothing"
    assert gone_since is not None


def test_guardrail_close_to_the_road_under_strong_shake_gives_no_vehicle(tmp_path):
    """Empty two-lane road, guardrail 0.3 m beyond the edge line, shake 0.4 deg: the guardrail's parallax
    (it stands above the road plane) shows in the difference every frame, but is no vehicle."""
    doc = yaml.safe_load((SCENARIOS / "empty_road.yaml").read_text())
    doc["road"]["shoulder_m"] = 0.3
    doc["shake"] = {"pitch_deg": 0.4, "yaw_deg": 0.13}
    doc["duration_s"] = 4.0
    for f, r in run(scenario_file(tmp_path, doc, "guardrail")):
        assert not [t for t in r.tracks if t.confirmed], (f.index, [t.box for t in r.tracks if t.confirmed])
