"""The YAML configuration: partial files over documented defaults, every bad key named."""
from __future__ import annotations

import subprocess
import sys

import pytest
import yaml

from app import config as configuration
from app.core import Pipeline
from tests.conftest import REPO


def write(tmp_path, text: str):
    p = tmp_path / "config.yaml"
    p.write_text(text)
    return p


def test_defaults_are_complete_and_accepted_by_the_core():
    cfg = configuration.load(None)
    with Pipeline(configuration.core_sections(cfg)) as p:
        effective = p.config
    assert effective == configuration.core_sections(cfg)
    assert set(cfg["camera"]) >= {"fx", "fy", "cx", "cy", "height_m", "pitch_deg", "width", "height"}
    assert cfg["source"]["kind"] == "v4l2"


def test_partial_file_changes_only_its_keys(tmp_path):
    cfg = configuration.load(write(tmp_path, "camera:\n  fx: 1000\n  height_m: 1.45\n"))
    d = configuration.defaults()
    assert cfg["camera"]["fx"] == 1000.0 and cfg["camera"]["height_m"] == 1.45
    assert cfg["camera"]["fy"] == d["camera"]["fy"] and cfg["pipeline"] == d["pipeline"]


@pytest.mark.parametrize(
    "text, message",
    [
        ("camera:\n  fxx: 700\n", "camera.fxx: unknown key"),
        ("camra:\n  fx: 700\n", "camra: unknown section"),
        ("camera:\n  fx: wide\n", "camera.fx: expected a number, got 'wide'"),
        ("camera:\n  fx: -1\n", "camera.fx: -1.0 is outside"),
        ("camera:\n  width: 640.5\n", "camera.width: expected an integer"),
        ("pipeline:\n  preset: magic\n", "pipeline.preset: 'magic' is not one of"),
        ("source:\n  wait_for_device: maybe\n", "source.wait_for_device: expected true or false"),
        ("camera: [1, 2]\n", "camera: expected a mapping"),
        ("- just\n- a list\n", "expected a mapping of sections"),
        ("camera:\n  fx: [700\n", "not valid YAML"),
    ],
)
def test_bad_files_name_file_and_key(tmp_path, text, message):
    path = write(tmp_path, text)
    with pytest.raises(configuration.ConfigFileError) as e:
        configuration.load(path)
    assert message in str(e.value)
    assert str(path) in str(e.value)


def test_missing_file(tmp_path):
    with pytest.raises(configuration.ConfigFileError, match="no such file"):
        configuration.load(tmp_path / "nope.yaml")


def test_device_index_or_path():
    cfg = configuration.validate({"source": {"device": 2}})
    assert configuration.source_spec(cfg)["device"] == 2
    cfg = configuration.validate({"source": {"device": "/dev/video4", "pixel_format": "MJPG"}})
    spec = configuration.source_spec(cfg)
    assert spec["device"] == "/dev/video4" and spec["pixel_format"] == "MJPG" and spec["kind"] == "v4l2"


def test_default_yaml_documents_every_key_and_loads_back(tmp_path):
    """Every key documented with its default; the keys the default preset sets, commented out with the preset's value
    (written out they would stay set under another preset); loaded back, the defaults."""
    text = configuration.default_yaml()
    preset = configuration.defaults()["pipeline"]["preset"]
    by_preset = configuration.presets()[preset]["keys"]
    for sec, keys in configuration.schema().items():
        for key in keys:
            if key in by_preset.get(sec, {}):
                assert f"  # {key}: " in text and f"(set by the preset {preset};" in text, f"{sec}.{key}"
            else:
                assert f"  {key}:" in text, f"{sec}.{key} missing from the documented default"
    assert configuration.load(write(tmp_path, text)) == configuration.defaults()
    assert yaml.safe_load(text)["camera"]["fx"] == configuration.defaults()["camera"]["fx"]


def test_scaled_camera_keeps_field_of_view():
    cam = configuration.defaults()["camera"]
    s = configuration.scaled_camera(cam, 1280, 960)
    assert s["fx"] == 2 * cam["fx"] and s["cx"] == 2 * cam["cx"] and s["width"] == 1280


def test_config_check_command(tmp_path):
    good = write(tmp_path, "camera:\n  fx: 900\n")
    r = subprocess.run([sys.executable, "-m", "app.cli", "config", "check", str(good)], cwd=REPO,
                       capture_output=True, text=True)
    assert r.returncode == 0 and "ok" in r.stdout
    bad = tmp_path / "bad.yaml"
    bad.write_text("pipeline:\n  queue_capacity: -4\n")
    r = subprocess.run([sys.executable, "-m", "app.cli", "config", "check", str(bad)], cwd=REPO,
                       capture_output=True, text=True)
    assert r.returncode == 2
    assert "pipeline.queue_capacity" in r.stderr and "Traceback" not in r.stderr


def test_docs_config_reference_is_current():
    doc = REPO / "docs" / "CONFIG.md"
    assert doc.read_text().strip() == configuration.markdown().strip(), (
        "docs/CONFIG.md is out of date: run `headway config doc > docs/CONFIG.md`")
