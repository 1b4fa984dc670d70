"""Configuration mistakes are caught before the car drives: duplicate keys, rules between keys, files the
keys point to, YAML alias bombs and deep nesting; every error one short line naming what to change."""
from __future__ import annotations

import resource
import subprocess
import sys

import pytest

from app import config as configuration
from app.config import ConfigFileError
from tests.conftest import REPO


def check(tmp_path, text: str) -> subprocess.CompletedProcess:
    f = tmp_path / "c.yaml"
    f.write_text(text)
    return subprocess.run([sys.executable, "-m", "app.cli", "config", "check", str(f)], cwd=REPO,
                          capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize("text, lines", [
    ("camera:\n  fx: 700\nfcw: {}\ncamera:\n  fy: 700\n", "lines 1 and 4"),
    ("camera:\n  fx: 700\n  fy: 700\n  fx: 800\n", "lines 2 and 4"),
])
def test_duplicate_keys_at_any_level_name_the_key_and_both_lines(tmp_path, text, lines):
    f = tmp_path / "c.yaml"
    f.write_text(text)
    with pytest.raises(ConfigFileError) as e:
        configuration.load(f)
    assert "duplicate key" in str(e.value) and lines in str(e.value)


def test_fcw_thresholds_in_the_wrong_order_are_an_error_that_says_what_to_change(tmp_path):
    f = tmp_path / "c.yaml"
    f.write_text("fcw: {ttc_warning_s: 5.0, ttc_prewarning_s: 4.0}\n")
    with pytest.raises(ConfigFileError, match="fcw.ttc_warning_s .5. must be below fcw.ttc_prewarning_s .4."):
        configuration.load(f)


def test_config_check_finds_what_would_stop_the_service(tmp_path):
    r = check(tmp_path, f"vehicle: {{dbc: {tmp_path / 'missing.dbc'}}}\n")
    assert r.returncode == 2 and "vehicle.dbc" in r.stderr and "no such DBC file" in r.stderr
    (tmp_path / "frames.raw").write_bytes(b"\0" * 100)
    r = check(tmp_path, f"source: {{kind: fifo, path: {tmp_path / 'frames.raw'}}}\n")
    assert r.returncode == 2 and "exists and is not a FIFO" in r.stderr
    r = check(tmp_path, "source: {kind: video, path: /nonexistent/drive.mp4}\n")
    assert r.returncode == 2 and "source.path" in r.stderr and "no such video file" in r.stderr
    r = check(tmp_path, f"can: {{output_log: {tmp_path / 'frames.raw' / 'out.log'}}}\n")  # under a file
    assert r.returncode == 2 and "can.output_log" in r.stderr
    r = check(tmp_path, "can: {interface: socketcan, channel: nosuchcan9}\n")
    assert r.returncode == 2 and "nosuchcan9" in r.stderr
    for result in (r,):
        assert "Traceback" not in result.stderr
    r = check(tmp_path, "camera: {fx: 700}\n")
    assert r.returncode == 0, r.stderr


BOMB = ("camera:\n  fx: &a [x,x,x,x,x,x,x,x,x]\n  fy: &b [*a,*a,*a,*a,*a,*a,*a,*a,*a]\n"
        "  cx: &c [*b,*b,*b,*b,*b,*b,*b,*b,*b]\n  cy: &d [*c,*c,*c,*c,*c,*c,*c,*c,*c]\n"
        "  height_m: &e [*d,*d,*d,*d,*d,*d,*d,*d,*d]\n  pitch_deg: &f [*e,*e,*e,*e,*e,*e,*e,*e,*e]\n"
        "  width: [*f,*f,*f,*f,*f,*f,*f,*f,*f]\n")


def test_alias_bomb_is_one_short_line_in_little_memory(tmp_path):
    assert len(BOMB) < 420
    f = tmp_path / "bomb.yaml"
    f.write_text(BOMB)
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    with pytest.raises(ConfigFileError) as e:
        configuration.load(f)
    grown_kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before
    assert len(str(e.value)) < 300 and "\n" not in str(e.value) and grown_kb < 50_000
    r = check(tmp_path, BOMB)
    assert r.returncode == 2 and len(r.stderr) < 400 and "Traceback" not in r.stderr


def test_few_aliases_still_work_but_a_huge_value_is_quoted_briefly(tmp_path):
    f = tmp_path / "c.yaml"
    f.write_text("camera: {fx: &f 700.0, fy: *f}\n")
    assert configuration.load(f)["camera"]["fy"] == 700.0
    f.write_text("camera: {fx: &a [1, 2, 3, 4, 5, 6, 7, 8], fy: [*a, *a, *a, *a, *a, *a, *a, *a]}\n")
    with pytest.raises(ConfigFileError) as e:
        configuration.load(f)
    assert "camera.fx: expected a number" in str(e.value) and len(str(e.value)) < 200
    f.write_text("camera:\n  fx: " + "[" * 200 + "]" * 200 + "\n")
    with pytest.raises(ConfigFileError, match="nested more than 20 levels"):
        configuration.load(f)
