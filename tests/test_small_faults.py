"""Smaller faults: detect writes the good images and lists the bad, a tiny image is said
to be one, `headway status` on a stale or malformed file, --fps on the command line."""
from __future__ import annotations

import json
import re
import time

import cv2
import numpy as np
import pytest

from tests.test_cli import headway


def test_detect_with_one_bad_image_writes_the_good_ones_and_lists_the_bad(tmp_path):
    paths = []
    for i in range(10):
        p = tmp_path / f"{i}.png"
        cv2.imwrite(str(p), np.full((120, 160), 20 * i, np.uint8))
        paths.append(str(p))
    (tmp_path / "4.png").write_bytes(b"not an image")
    r = headway("detect", *paths, "--out", str(tmp_path / "out.json"))
    assert r.returncode == 1 and "Traceback" not in r.stderr
    out = json.loads((tmp_path / "out.json").read_text())
    assert [e["file_name"] for e in out] == [f"{i}.png" for i in range(10) if i != 4]
    assert "4.png" in r.stderr and "cannot be read as an image" in r.stderr


def test_a_1x1_image_is_named_as_too_small_not_as_a_configuration_error(tmp_path):
    p = tmp_path / "dot.png"
    cv2.imwrite(str(p), np.zeros((1, 1), np.uint8))
    r = headway("detect", str(p), "--out", str(tmp_path / "out.json"))
    assert r.returncode == 1 and "configuration" not in r.stderr and "camera.height" not in r.stderr
    assert "dot.png: 1x1 px: frames must be 16x16 to 8192x8192 px" in r.stderr
    d = tmp_path / "dots"
    d.mkdir()
    cv2.imwrite(str(d / "0.png"), np.zeros((1, 1), np.uint8))
    r = headway("replay", str(d), "--fps", "10")
    assert r.returncode == 1 and "1x1 px: frames must be" in r.stderr and "configuration" not in r.stderr


def test_status_of_a_stale_file_is_unknown_with_a_non_zero_exit(tmp_path):
    from app.supervisor.status_file import write_status

    path = tmp_path / "status.json"
    write_status(str(path), {"state": "ok", "faults": []})
    path.write_text(json.dumps({**json.loads(path.read_text()), "written_unix_s": time.time() - 60}))
    r = headway("status", "--file", str(path))
    assert r.returncode != 0 and "state: unknown" in r.stdout and "state: ok" not in r.stdout
    assert re.search(r"status is \d+ s old", r.stdout) and "last report said ok" in r.stdout


@pytest.mark.parametrize("text", ["{", "[]", '"ok"', '{"state": "ok", "written_unix_s": "yesterday"}', ""])
def test_status_of_a_malformed_file_is_one_line_not_a_traceback(tmp_path, text):
    path = tmp_path / "status.json"
    path.write_text(text)
    r = headway("status", "--file", str(path))
    assert r.returncode == 3 and "Traceback" not in r.stderr + r.stdout
    assert "state: unknown" in r.stdout and "not a status file" in r.stdout


@pytest.mark.parametrize("fps", ["0", "inf", "nan", "-5", "1000.5"])
def test_replay_fps_out_of_range_is_one_clear_line(tmp_path, fps):
    d = tmp_path / "frames"
    d.mkdir()
    for i in range(3):
        cv2.imwrite(str(d / f"{i}.png"), np.zeros((48, 64), np.uint8))
    r = headway("replay", str(d), "--fps", fps)
    assert r.returncode == 1 and "Traceback" not in r.stderr
    assert "--fps" in r.stderr and "between 0.1 and 1000 frames/s" in r.stderr
