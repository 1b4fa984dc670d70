"""Pipelines composed of named parts (csrc/core/parts.cpp, docs/ARCHITECTURE.md): the presets are
compositions, any detector can feed any tracker, and a composition that cannot run is refused with the
key named."""
from __future__ import annotations

import argparse

import pytest

from app import config as configuration, detect_images
from app.config import SHIPPED_CASCADE
from app.core import ConfigError, Pipeline, core_detectors, core_schema
from tests.thesis_scenes import config, frames


def _run(name: str, pipeline: dict, n: int, keys: dict | None = None) -> list:
    """The first n frames of the scenario through the composition, `keys` ({section: {key: value}}) set."""
    cfg = config(name)
    cfg["pipeline"] = pipeline
    for section, values in (keys or {}).items():
        cfg[section] = {**cfg.get(section, {}), **values}
    # the core alone has no default model (app/config.py fills it)
    cfg["cascade"] = {**cfg.get("cascade", {}), "model": str(SHIPPED_CASCADE)}
    with Pipeline(cfg) as p:
        return [p.process(f.image, f.t_s) for f in frames(name)[:n]]


def _boxes(results) -> list:
    return [[(t.id, t.confirmed, tuple(round(x, 3) for x in t.box)) for t in r.tracks] for r in results]


def test_the_registries_are_in_the_configuration_schema():
    pipe = core_schema()["pipeline"]
    assert set(pipe["preset"]["choices"].split("|")) == {"default", "thesis", "parallax", "paper004", "none"}
    assert set(pipe["detectors"]["choices"].split("|")) == {"shadow", "parallax", "cascade", "proposals"}
    assert {"kalman", "particles", "none"} <= set(pipe["tracker"]["choices"].split("|"))


def test_single_image_choices_come_from_the_detectors_registrations():
    """`headway detect --preset` and the TuSimple box evaluation offer what the core's registrations say works on
    one image: every detector but parallax, which compares two frames."""
    assert {d: v["single_image"] for d, v in core_detectors().items()} == {
        "shadow": True, "cascade": True, "proposals": True, "parallax": False}
    assert configuration.single_image_presets() == ["default", "paper004", "thesis"]
    assert not configuration.works_on_one_image([])
    assert not configuration.works_on_one_image(["shadow", "parallax"])
    parser = argparse.ArgumentParser()
    detect_images.add_parser(parser.add_subparsers())
    assert parser.parse_args(["detect", "a.png", "--out", "o.json", "--preset", "paper004"]).preset == "paper004"
    with pytest.raises(SystemExit):
        parser.parse_args(["detect", "a.png", "--out", "o.json", "--preset", "parallax"])


@pytest.mark.parametrize("preset,detectors,tracker", [("default", ["cascade", "shadow"], "phd"),
                                                       ("thesis", ["shadow"], "kalman"),
                                                       ("parallax", ["parallax"], "particles"),
                                                       ("paper004", ["cascade"], "phd")])
def test_a_preset_is_its_composition(preset, detectors, tracker):
    """A preset is its parts and the keys it sets."""
    by_name = _run("steady_following", {"preset": preset}, 40)
    keys = configuration.presets()[preset]["keys"]
    assert set(keys) <= {"cascade", "phd", "fuse", "kinematics"}
    by_parts = _run("steady_following", {"preset": "none", "detectors": detectors, "tracker": tracker}, 40, keys)
    assert _boxes(by_name) == _boxes(by_parts)
    assert [r.stages.keys() for r in by_name] == [r.stages.keys() for r in by_parts]


def _on(track, truth_box) -> bool:
    """A track stands on the vehicle: its bottom centre inside the vehicle's columns and its bottom row within
    a fifth of the vehicle's width of the true one (the row the range is read from)."""
    l, _, r, b = truth_box
    x = 0.5 * (track.box[0] + track.box[2])
    return l <= x <= r and abs(track.box[3] - b) <= 0.2 * (r - l)


@pytest.mark.parametrize("detectors,tracker", [(["parallax"], "kalman"), (["shadow"], "particles")])
def test_crossed_compositions_track_the_lead(detectors, tracker):
    """steady_following: a car 25-30 m ahead in the ego lane all along; both crossed compositions confirm
    a track standing on it within the first 60 frames (2 s) and keep one on it over the next second."""
    fr = frames("steady_following")
    preset = f"{detectors[0]}+{tracker}"
    results = _run("steady_following", {"preset": "none", "detectors": detectors, "tracker": tracker}, 90)
    on_lead = []
    for f, r in zip(fr, results):
        lead = next(v for v in f.truth if v["id"] == 1)
        on_lead.append(any(t.confirmed and _on(t, lead["box_clipped"]) for t in r.tracks))
    assert any(on_lead[:60]), preset
    assert sum(on_lead[60:90]) >= 24, (preset, on_lead)


def test_the_phd_tracker_takes_its_vehicles_from_both_detectors():
    """The phd tracker (paper 004) asks the composition's detectors, whichever they are: fed by shadow and
    parallax together it confirms a track standing on the steady_following lead within 2 s and keeps one on
    it over the next second, asking the detectors only every phd.detect_every_n = 3 frames."""
    fr = frames("steady_following")
    results = _run("steady_following", {"preset": "none", "detectors": ["shadow", "parallax"], "tracker": "phd"}, 90)
    on_lead = []
    for f, r in zip(fr, results):
        lead = next(v for v in f.truth if v["id"] == 1)
        on_lead.append(any(t.confirmed and _on(t, lead["box_clipped"]) for t in r.tracks))
    assert any(on_lead[:60]), on_lead
    assert sum(on_lead[60:90]) >= 24, on_lead
    assert [r.full_detection for r in results].count(True) <= 30
    assert any(r.road_motion == "accepted" for r in results[2:])


def test_the_crossed_kalman_tracker_runs_the_parallax_detector_only_every_n_frames():
    results = _run("steady_following", {"preset": "none", "detectors": ["parallax"], "tracker": "kalman"}, 30)
    ran = [r.full_detection for r in results]
    assert ran.count(True) <= 11  # at most every third frame (kalman.detect_every_n = 3)
    assert all(r.road_motion is None for r in results[:1])
    assert any(r.road_motion == "accepted" for r in results[2:])


@pytest.mark.parametrize("pipeline,message", [
    ({"preset": "none", "tracker": "kalman"}, "pipeline.tracker: tracker 'kalman' has no detector"),
    ({"preset": "none", "detectors": ["shadow"]}, "pipeline.detectors: detectors need a tracker"),
    ({"detectors": ["shadow", "shadow"]}, "pipeline.detectors: 'shadow' is listed twice"),
    ({"detectors": ["radar"]}, "pipeline.detectors: 'radar' is not one of"),
    ({"tracker": "no_such_tracker"}, "pipeline.tracker: 'no_such_tracker' is not one of"),
])
def test_a_composition_that_cannot_run_is_refused_naming_the_key(pipeline, message):
    with pytest.raises(ConfigError, match=message):
        Pipeline({"pipeline": pipeline})
