"""The phd tracker (paper 004: feature points of each vehicle by a GM-PHD filter, its range by a UKF) after the
shadow detector (pipeline: {detectors: [shadow], tracker: phd}), and the default preset (the cascade with the shadow
detector's cues, tracked by phd), on rendered scenarios with exact ground truth: the lead is followed under one id
with metre-level range, the range rate of a steadily followed lead is steadier than the Kalman box tracker's, the
leads of the FCW scenarios get a better range and range rate than from the box tracker, and every FCW case of the
suite passes through it with its margin (warnings in time, none where none is due)."""
from __future__ import annotations

import functools
import json

import numpy as np
import pytest
import yaml

from app import config as configuration
from app.core import Pipeline
from app.eval.fcw_scenarios import NO_WARNING, REQUIRED_TTC_S, evaluate
from tests.thesis_scenes import best_match, frames, lead
from app.sim import load_scenario
from app.sim.frames import scenario_camera


# The compositions compared, by name: the shadow detector tracked by phd, or by the Kalman box tracker (preset
# thesis), and the default preset.
PIPELINES = {"shadow_phd": {"detectors": ["shadow"], "tracker": "phd"}, "thesis": {"preset": "thesis"},
             "default": {"preset": "default"}, "paper004": {"preset": "paper004"}}


@functools.lru_cache(maxsize=None)
def _run(name: str, pipeline: str, sections_json: str = "{}") -> tuple:
    values = {"pipeline": PIPELINES[pipeline], "camera": scenario_camera(load_scenario(name)).to_dict(),
              **json.loads(sections_json)}
    fr = frames(name)
    # through the configuration: a preset's own keys and the shipped models (the cascade's) filled in
    with Pipeline(configuration.core_sections(configuration.load(None, values))) as p:
        return fr, tuple(p.process(f.image, f.t_s) for f in fr)


def _lead_errors(name: str, pipeline: str, sections_json: str = "{}"):
    """Per frame with the lead within 60 m and tracked (confirmed, IoU >= 0.5): range error, range-rate
    error (NaN while the tracker gives none), and the track id; plus the frames the lead was visible."""
    fr, results = _run(name, pipeline, sections_json)
    rows, visible = [], 0
    for f, r in zip(fr, results):
        g = lead(f.truth)
        if g is None or f.index < 10:
            continue
        visible += 1
        conf = [t for t in r.tracks if t.confirmed]
        i, v = best_match([t.box for t in conf], g["box"])
        if v < 0.5:
            continue
        t = conf[i]
        rate = np.nan if t.range_rate_mps is None else t.range_rate_mps - g["relative_speed_mps"]
        rows.append((t.range_m - g["longitudinal_m"], rate, t.id))
    return rows, visible


@pytest.mark.parametrize("name", ["steady_following", "stopped_lead_72kmh", "lead_braking_0p3g"])
def test_lead_followed_with_metre_level_range(name):
    rows, visible = _lead_errors(name, "shadow_phd")
    assert len(rows) >= 0.9 * visible, f"{name}: lead tracked in {len(rows)} of {visible} frames"
    err = np.abs([r[0] for r in rows])
    # measured: 1.88 / 0.99 / 0.58 m (thesis preset 1.91 / 1.21 / 0.63 m); docs/tracking.md
    assert err.mean() <= 2.5, f"{name}: mean absolute range error {err.mean():.2f} m"
    assert len({r[2] for r in rows}) == 1, f"{name}: the lead changed id"


@pytest.mark.parametrize("name", ["steady_following"])
def test_range_rate_steadier_than_the_box_tracker(name):
    # measured: 0.13 m/s against 0.85 m/s (the approaching leads: test_lead_range_and_rate_beat_the_box_tracker)
    def rate_error(pipeline):
        rows, _ = _lead_errors(name, pipeline)
        e = np.array([r[1] for r in rows])
        return float(np.mean(np.abs(e[np.isfinite(e)])))

    phd, thesis = rate_error("shadow_phd"), rate_error("thesis")
    assert phd < thesis, f"{name}: mean range-rate error phd {phd:.2f} m/s, thesis {thesis:.2f} m/s"


def test_lead_range_and_rate_beat_the_box_tracker():
    # The feature cloud's purpose: its features' tags (offsets in units of the contact's depth below
    # the horizon) carry the contact row without the box width, and its expansion observes the range rate
    # without the bottom edge's pixel offset (docs/tracking.md). Measured on the leads (phd against thesis):
    # range 0.99/1.21, 0.58/0.63, 1.00/1.11, 0.73/1.15, 0.97/1.21, 1.88/1.91 m; range rate 0.98/0.92,
    # 0.61/0.85, 0.38/0.77, 0.52/1.24, 1.05/0.78, 0.13/0.85 m/s (worse on stopped_lead_72kmh and slower_lead).
    names = ("stopped_lead_72kmh", "lead_braking_0p3g", "stopped_lead_50kmh", "stopped_lead_100kmh", "slower_lead",
             "steady_following")

    def errors(pipeline):
        rng, rate = [], []
        for name in names:
            rows, _ = _lead_errors(name, pipeline)
            e = np.array([r[1] for r in rows])
            rng.append(float(np.mean(np.abs([r[0] for r in rows]))))
            rate.append(float(np.mean(np.abs(e[np.isfinite(e)]))))
        return np.array(rng), np.array(rate)

    (phd_range, phd_rate), (box_range, box_rate) = errors("shadow_phd"), errors("thesis")
    msg = (f"phd range {phd_range.round(2)} rate {phd_rate.round(2)}; "
           f"thesis range {box_range.round(2)} rate {box_rate.round(2)}")
    assert phd_range.mean() < box_range.mean(), msg
    assert np.sum(phd_range <= box_range) >= 5, msg
    assert phd_rate.mean() <= 0.8 * box_rate.mean(), msg
    assert np.sum(phd_rate < box_rate) >= 4, msg


@pytest.fixture(scope="module")
def phd_config(tmp_path_factory):
    path = tmp_path_factory.mktemp("phd") / "phd.yaml"
    path.write_text(yaml.safe_dump({"pipeline": PIPELINES["shadow_phd"]}))
    return str(path)


# The phd preset's detector is the shadow detector: its FCW cases run on the plain drawn faces, whose dark gap is
# its cue (docs/sim.md, "Real-looking vehicles"; with the real look stopped_lead_100kmh warns at true TTC 1.99 s).
@pytest.mark.parametrize("scenario", sorted(REQUIRED_TTC_S))
def test_ncap_scenario_warns_in_time_through_phd(scenario, phd_config):
    r = evaluate(scenario, phd_config, vehicle_look="plain")
    assert r["warnings"] >= 1, f"{scenario}: no warning at all"
    assert r["true_ttc_s"] is not None and r["margin_s"] >= 0, (
        f"{scenario}: warned at true TTC {r['true_ttc_s']}, required >= {r['required_ttc_s']} s")
    assert r["ttc_used_s"] is not None and 0 < r["ttc_used_s"] <= 3.5


@pytest.mark.parametrize("scenario", NO_WARNING)
def test_no_false_warning_through_phd(scenario, phd_config):
    r = evaluate(scenario, phd_config, vehicle_look="plain")
    assert r["warnings"] == 0, f"{scenario}: false warning at t={r['first_warning_t_s']} s"



def _ids_following(name: str, pipeline: str, vehicle: int, sections_json: str = "{}") -> tuple[list, int]:
    """The confirmed track id matched (IoU >= 0.5) to one truth vehicle on each frame it is fully visible within
    60 m (None where nothing matches), and the number of those frames."""
    fr, results = _run(name, pipeline, sections_json)
    ids = []
    for f, r in zip(fr, results):
        g = next((g for g in f.truth if g["id"] == vehicle), None)
        if g is None or g["visible_fraction"] < 0.999 or g["longitudinal_m"] > 60.0:
            continue
        conf = [t for t in r.tracks if t.confirmed]
        i, v = best_match([t.box for t in conf], g["box"])
        ids.append(conf[i].id if v >= 0.5 else None)
    return ids, len(ids)


def test_a_car_keeps_its_identity_through_a_bridges_shadow():
    """overpass_shadow, preset default: the car in the next lane (36 m) drives into a bridge's shadow at frame 96,
    where every LK feature fails its forward-backward check at once. The learned detector finds it in the shadow
    too, so it keeps one id and is followed (IoU >= 0.5) on 183 of its 210 visible frames (measured)."""
    ids, visible = _ids_following("overpass_shadow", "default", 1)
    followed = [i for i in ids if i is not None]
    assert visible >= 150 and len(set(followed)) == 1 and len(followed) >= 0.86 * visible, (set(followed), len(followed), visible)


def test_a_truck_keeps_its_measured_height_against_car_shaped_guesses():
    """cut_in, the shadow detector tracked by phd: the truck 20-37 m ahead in the left lane (about 60 x 90 px, height 1.5
    widths). On many detection runs the verification finds no top on its side and guesses a car's height
    (vehicle_shape.aspect 0.8); averaged into the vehicle's box, those guesses halved it (IoU under 0.5 with the truck,
    and from frame 255 a second, car-shaped track). A vehicle whose measured tops said taller than
    vehicle_height.tall_aspect twice in a row keeps its height against guessed ones, and is matched to them as if
    they were as tall (track/vehicle_height.hpp; the Kalman tracker shares the rule)."""
    ids, visible = _ids_following("cut_in", "shadow_phd", 3)
    followed = [i for i in ids if i is not None]
    assert visible >= 250 and len(set(followed)) == 1 and len(followed) >= 0.98 * visible, (set(followed), len(followed), visible)
    ids0, _ = _ids_following("cut_in", "shadow_phd", 3, json.dumps({"vehicle_height": {"tall_aspect": 10}}))
    assert sum(i is not None for i in ids0) < 0.95 * visible, "the truck was followed without the rule: the test no longer tests it"
