"""The presets (csrc/core/parts.cpp): `default` and the three seed papers' methods, each a composition of parts;
a removed preset is refused with its replacement named, in the YAML loader and in the core alone."""
from __future__ import annotations

import pytest

from app import config as configuration
from app.config import SHIPPED_CASCADE, SHIPPED_VERIFIER
from app.core import ConfigError, Pipeline
from app.eval.lane_clips import lane_config


def _core(values: dict) -> dict:
    """The core's effective configuration for a partial one given to the core directly (no YAML loader)."""
    cfg = {**values, "cascade": {"model": str(SHIPPED_CASCADE), "verifier": str(SHIPPED_VERIFIER),
                                 **values.get("cascade", {})}}
    with Pipeline(cfg) as p:
        return p.config


def test_the_shipped_presets_and_their_parts():
    p = configuration.presets()
    assert {name: (v["detectors"], v["tracker"]) for name, v in p.items()} == {
        "default": (["cascade", "shadow"], "phd"),
        "thesis": (["shadow"], "kalman"),
        "parallax": (["parallax"], "particles"),
        "paper004": (["cascade"], "phd"),
        "none": ([], ""),
    }


def test_headway_runs_the_default_preset_unless_told_otherwise(tmp_path):
    assert configuration.DEFAULT_PRESET == "default"
    assert configuration.load(None)["pipeline"]["preset"] == "default"
    f = tmp_path / "c.yaml"
    f.write_text("pipeline: {preset: thesis}\n")
    assert configuration.load(f)["pipeline"]["preset"] == "thesis"


@pytest.mark.parametrize("removed, replacement", [
    ("fused", "preset default"), ("cascade_shadow_phd", "preset default"), ("cascade", "preset paper004"),
    ("phd", "pipeline: {detectors: [shadow], tracker: phd}"),
    ("parallax_kalman", "pipeline: {detectors: [parallax], tracker: kalman}"),
    ("shadow_particles", "pipeline: {detectors: [shadow], tracker: particles}"),
])
def test_a_removed_preset_is_refused_naming_its_replacement(tmp_path, removed, replacement):
    message = f"pipeline.preset: preset '{removed}' was removed; use {replacement}"
    f = tmp_path / "c.yaml"
    f.write_text(f"pipeline: {{preset: {removed}}}\n")
    with pytest.raises(configuration.ConfigFileError) as e:
        configuration.load(f)
    assert message in str(e.value)
    with pytest.raises(ConfigError) as e:
        _core({"pipeline": {"preset": removed}})
    assert message in str(e.value)


def test_an_unknown_preset_lists_the_shipped_ones():
    with pytest.raises(configuration.ConfigFileError, match=r"pipeline\.preset"):
        configuration.validate({"pipeline": {"preset": "fast"}})
    with pytest.raises(ConfigError, match="default"):
        _core({"pipeline": {"preset": "fast"}})


def test_the_loaders_configuration_reaches_the_core_unchanged():
    for preset in ("default", "paper004"):
        cfg = configuration.core_sections(configuration.load(None, {"pipeline": {"preset": preset}}))
        with Pipeline(cfg) as p:
            assert p.config == cfg
    assert lane_config(None, "paper004", 1280, 720)["pipeline"]["preset"] == "paper004"


def test_config_doc_lists_the_presets():
    doc = configuration.markdown()
    assert "## Presets" in doc
    assert "| `default` | cascade, shadow | phd |" in doc
    assert "| `paper004` | cascade | phd |" in doc
