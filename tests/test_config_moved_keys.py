"""Keys that moved (to one shared definition: the hood line in the camera section, lane widths in the road
section, the vehicles' width, height and aspects in the vehicle_shape section, the shadow edge's thresholds in the
shadow_edge section; or renamed: fuse.cue_weight) and presets that were removed: an old key or preset is refused with an
error naming what replaces it, by the configuration loader and by the core alike; the one key reaches the stages
that read it. Keys and sections that were removed without a replacement are unknown keys."""
from __future__ import annotations

import re

import pytest
import yaml

from app import config as configuration
from app.core import ConfigError, Pipeline, core_moved_keys, core_removed_presets

# Old key -> the key that replaced it.
MOVED = {
    "lanes.hood_frac": "camera.hood_frac",
    "parallax.hood_frac": "camera.hood_frac",
    "shadow.bottom_ignore_frac": "camera.hood_frac",
    "cascade.bottom_ignore_frac": "camera.hood_frac",
    "lanes.lane_width_m": "road.lane_width_m",
    "shadow.lane_width_m": "road.lane_width_m",
    "cascade.lane_width_m": "road.lane_width_m",
    "lead.lane_width_m": "road.lane_width_m",
    "self_calibration.lane_width_m": "road.lane_width_m",
    "lead.min_lane_width_m": "road.min_lane_width_m",
    "lead.max_lane_width_m": "road.max_lane_width_m",
    "shadow.vehicle_width_m": "vehicle_shape.width_m",
    "cascade.vehicle_width_m": "vehicle_shape.width_m",
    "parallax.vehicle_width_m": "vehicle_shape.width_m",
    "road.vehicle_width_m": "vehicle_shape.width_m",
    "cascade.max_vehicle_height_m": "vehicle_shape.max_height_m",
    "parallax.top_max_height_m": "vehicle_shape.max_height_m",
    "verify.aspect_ratio": "vehicle_shape.aspect",
    "verify.top_min_aspect": "vehicle_shape.top_min_aspect",
    "parallax.top_min_aspect": "vehicle_shape.top_min_aspect",
    "verify.top_max_aspect": "vehicle_shape.max_aspect",
    "parallax.max_aspect": "vehicle_shape.max_aspect",
    "fuse.thesis_weight": "fuse.cue_weight",
    "shadow.grad_rel": "shadow_edge.grad_rel",
    "shadow.min_step_gray": "shadow_edge.min_step_gray",
    "shadow.dark_rel": "shadow_edge.dark_rel",
}

# Removed preset -> what to use instead (a preset, or the composition as configuration YAML).
REMOVED_PRESETS = {
    "fused": "preset default",
    "cascade_shadow_phd": "preset default",
    "cascade": "preset paper004",
    "phd": "pipeline: {detectors: [shadow], tracker: phd}",
    "parallax_kalman": "pipeline: {detectors: [parallax], tracker: kalman}",
    "shadow_particles": "pipeline: {detectors: [shadow], tracker: particles}",
}


def test_the_core_lists_every_moved_key_and_each_new_key_exists():
    assert core_moved_keys() == MOVED
    schema = configuration.schema()
    for new in MOVED.values():
        section, key = new.split(".")
        assert key in schema[section], new
    for old in MOVED:
        section, key = old.split(".")
        assert key not in schema[section], old


@pytest.mark.parametrize("old, new", sorted(MOVED.items()))
def test_an_old_key_in_a_file_names_the_new_key(tmp_path, old, new):
    section, key = old.split(".")
    path = tmp_path / "config.yaml"
    path.write_text(f"{section}:\n  {key}: 0.1\n")
    with pytest.raises(configuration.ConfigFileError) as e:
        configuration.load(path)
    assert f"{path}: {old}: moved to {new}" in str(e.value)
    assert f"set {new} instead" in str(e.value)


@pytest.mark.parametrize("old, new", sorted(MOVED.items()))
def test_an_old_key_given_to_the_core_names_the_new_key(old, new):
    section, key = old.split(".")
    with pytest.raises(ConfigError, match=rf"{old}: moved to {new}"):
        Pipeline({section: {key: 0.1}})


def test_the_core_lists_every_removed_preset_and_none_is_a_preset():
    assert core_removed_presets() == REMOVED_PRESETS
    assert set(configuration.presets()) == {"default", "thesis", "parallax", "paper004", "none"}


@pytest.mark.parametrize("old, use", sorted(REMOVED_PRESETS.items()))
def test_a_removed_preset_in_a_file_names_its_replacement(tmp_path, old, use):
    path = tmp_path / "config.yaml"
    path.write_text(f"pipeline:\n  preset: {old}\n")
    with pytest.raises(configuration.ConfigFileError) as e:
        configuration.load(path)
    assert f"{path}: pipeline.preset: preset '{old}' was removed; use {use}" in str(e.value)


@pytest.mark.parametrize("old, use", sorted(REMOVED_PRESETS.items()))
def test_a_removed_preset_given_to_the_core_names_its_replacement(old, use):
    with pytest.raises(ConfigError, match=re.escape(f"pipeline.preset: preset '{old}' was removed; use {use}")):
        Pipeline({"pipeline": {"preset": old}})


@pytest.mark.parametrize("use", sorted(set(REMOVED_PRESETS.values())))
def test_each_named_replacement_is_a_configuration_that_loads(use):
    values = ({"pipeline": {"preset": use.split()[1]}} if use.startswith("preset ") else yaml.safe_load(use))
    with Pipeline(configuration.core_sections(configuration.load(None, values))) as p:
        assert p.config["pipeline"]["preset"]


@pytest.mark.parametrize("text, key", [
    ("merge:\n  min_appearance: 0.9\n", "merge"),
    ("cascade:\n  tracked_verifier: same\n", "cascade.tracked_verifier"),
    ("cascade:\n  refine_tracked: true\n", "cascade.refine_tracked"),
])
def test_removed_keys_and_sections_are_unknown(tmp_path, text, key):
    path = tmp_path / "config.yaml"
    path.write_text(text)
    with pytest.raises(configuration.ConfigFileError, match=re.escape(key)):
        configuration.load(path)
    section, _, name = key.partition(".")
    with pytest.raises(ConfigError, match=re.escape(key)):
        Pipeline({section: {name: "same"} if name else {}})


def test_the_nominal_lane_width_must_be_a_believed_one():
    with pytest.raises(ConfigError, match=r"road\.lane_width_m: must lie within \[road\.min_lane_width_m"):
        Pipeline({"road": {"lane_width_m": 4.5}})  # max_lane_width_m 4.0
    with Pipeline({"road": {"lane_width_m": 4.5, "max_lane_width_m": 5.0}}) as p:
        assert p.config["road"]["lane_width_m"] == 4.5


def _calibrated_height(road: dict) -> float:
    """Self-calibration's camera height after steady_following (true camera 1.3 m high, lanes 3.6 m)."""
    from tests import thesis_scenes

    frames = thesis_scenes.frames("steady_following")
    with Pipeline(thesis_scenes.config("steady_following", road=road)) as p:
        for f in frames[:150]:
            r = p.process(f.image, f.t_s)
    return r.calibration["height_m"]


def test_road_lane_width_reaches_self_calibration():
    """The camera height follows from the lane width (h = fx W cos(theta) / (fy a)): with the road section's
    lane width 10 % above the scenario's 3.6 m lanes, the estimate is 10 % above the true 1.3 m."""
    assert _calibrated_height({}) == pytest.approx(1.3, rel=0.02)
    assert _calibrated_height({"lane_width_m": 3.96}) == pytest.approx(1.3 * 1.1, rel=0.02)


def test_the_hood_line_of_the_camera_stops_the_lanes_and_the_shadow_scan():
    """steady_following, frame 60 (horizon near row 228 of 480): two vehicles stand with their bottoms on rows
    248 and 263. camera.hood_frac 0.47 hides the rows from 254 down: the nearer vehicle is no longer found, the
    farther one still is. At 0.5 (rows from 240) the road within the lanes' 60 m is all bonnet: no lane
    boundary and no vehicle."""
    import json

    from tests import thesis_scenes

    image = thesis_scenes.frames("steady_following")[60].image

    def detect(hood: float):
        with Pipeline(thesis_scenes.config("steady_following", json.dumps({"hood_frac": hood}))) as p:
            return sorted(round(b[3]) for b in p.detect(image).rows()), p.image_lanes(image).lanes

    bottoms, lanes = detect(0.0)
    assert bottoms == [248, 263] and len(lanes) == 4
    assert detect(0.47)[0] == [248]
    assert detect(0.5) == ([], [])
