"""The presets (csrc/core/parts.cpp): `default` and the three seed papers' methods, each a composition of parts;
a removed preset is refused with its replacement named, in the YAML loader and in the core alone."""
from __future__ import annotations

import cv2
import numpy as np
import pytest
import yaml

from app import config as configuration
from app.config import SHIPPED_CASCADE, SHIPPED_VERIFIER
from app import cli, detect_images, replay
from app.core import ConfigError, Pipeline, core_default_preset
from app.eval.lane_clips import lane_config
from app.supervisor import service


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
    assert configuration.default_preset() == core_default_preset() == "default"
    assert configuration.load(None)["pipeline"]["preset"] == "default"
    f = tmp_path / "c.yaml"
    f.write_text("pipeline: {preset: thesis}\n")
    assert configuration.load(f)["pipeline"]["preset"] == "thesis"


class _Started(Exception):
    """Raised by _RecordingPipeline once the pipeline a command builds exists: the test has what it asks."""


def _recording_pipeline(ran: list):
    """A Pipeline that notes the preset the core runs (its effective configuration), then stops the command."""
    class _RecordingPipeline(Pipeline):
        def __init__(self, config=None):
            super().__init__(config)
            ran.append(self.config["pipeline"]["preset"])
            self.close()
            raise _Started
    return _RecordingPipeline


def test_every_command_runs_the_one_default_preset(tmp_path, monkeypatch, capsys):
    """The core's preset table names the default once: `headway config default` writes it, and `headway detect`,
    replay and the service, given a configuration file that names no preset, build a core running it."""
    name = core_default_preset()
    assert cli.main(["config", "default"]) == 0
    assert yaml.safe_load(capsys.readouterr().out)["pipeline"]["preset"] == name

    f = tmp_path / "c.yaml"
    f.write_text("fcw: {ttc_warning_s: 1.5}\n")  # a file that names no preset
    image = tmp_path / "road.png"
    cv2.imwrite(str(image), np.full((720, 1280), 90, np.uint8))
    ran: list = []
    for module in (detect_images, replay, service):
        monkeypatch.setattr(module, "Pipeline", _recording_pipeline(ran))
    with pytest.raises(_Started):
        detect_images.detect_images([str(image)], str(f))
    with pytest.raises(_Started):
        replay.replay_scenario("empty_road", str(f), progress=False)
    with pytest.raises(_Started):
        service.Service(configuration.load(f)).run()
    assert ran == [name, name, name]


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
