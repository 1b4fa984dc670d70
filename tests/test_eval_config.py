"""`headway eval --config F` reaches every part: the real-drive parts (road motion, real-video false warnings)
run the user's configuration under each recording's own camera, and a bad key in it fails naming the key."""
from __future__ import annotations

import pytest

from app.config import ConfigFileError
from app.eval import real_video_fcw, road_motion


def test_the_real_drive_parts_take_the_users_configuration(tmp_path):
    f = tmp_path / "c.yaml"
    f.write_text("phd:\n  birth_min_appearance: 0.5\ncamera:\n  height_m: 9.9\n")
    cfg = road_motion.core_config({"camera": {"height_m": 1.2}, "pipeline": {"preset": "paper004"}}, str(f))
    assert cfg["phd"]["birth_min_appearance"] == 0.5
    assert cfg["camera"]["height_m"] == 1.2  # the recording's camera wins
    cfg = real_video_fcw.recording_config({"height_m": 1.2}, "paper004", str(f))
    assert cfg["phd"]["birth_min_appearance"] == 0.5 and cfg["camera"]["height_m"] == 1.2
    assert cfg["pipeline"]["preset"] == "paper004"


def test_a_bad_key_in_the_users_configuration_is_named(tmp_path):
    f = tmp_path / "c.yaml"
    f.write_text("phd:\n  birth_min_apearance: 0.5\n")
    with pytest.raises(ConfigFileError, match="birth_min_apearance"):
        real_video_fcw.recording_config({"height_m": 1.2}, "paper004", str(f))
