"""`headway config check` opens what the service opens, so "ok" means the service starts: output folders,
paths the OS cannot take, model files under their own key, the source and its frame size; every error is
exit 2 and one line of at most 200 characters with the key and its YAML line; YAML 1.2 numbers and
booleans."""
from __future__ import annotations

import pytest

from app import cli
from app import config as configuration
from tests.conftest import write_video


def check(capsys, tmp_path, text: str, *flags: str) -> tuple[int, str]:
    f = tmp_path / "c.yaml"
    f.write_text(text)
    rc = cli.main(["config", "check", str(f), *flags])
    out = capsys.readouterr()
    return rc, out.err if rc else out.out


def one_line(err: str) -> str:
    assert err.count("\n") == 1 and len(err.rstrip("\n")) <= 200 and "Traceback" not in err, err
    return err


@pytest.mark.parametrize("text, key, line, why", [
    ("camera: {fx: 700}\nservice:\n  tracks_file: /nonexistent/dir/t.jsonl\n", "service.tracks_file", 3,
     "its folder /nonexistent/dir does not exist: create it"),
    ('service:\n  status_file: "/tmp/a\\0b.json"\n', "service.status_file", 2, "contains a NUL byte"),
    ("service: {tracks_file: /tmp/" + "A" * 5000 + "}\n", "service.tracks_file", 1, "a path has at most 4095"),
    ("service: {tracks_file: /tmp/" + "A" * 300 + "}\n", "service.tracks_file", 1, "a file name has at most 255"),
    ("service: {tracks_file: /tmp}\n", "service.tracks_file", 1, "is a folder; give a file's path"),
    ("pipeline: {preset: paper004}\ncascade:\n  verifier: /nonexistent/x.onnx\n", "cascade.verifier",
     3, "no such model file"),
    ("cascade:\n\n  verifier: /tmp\n", "cascade.verifier", 3, "is a folder, not a model file"),
    ("health:\n  camera_timeout_s: 12:30:00\n", "health.camera_timeout_s", 2, "expected a number, got '12:30:00'"),
    ("source:\n  wait_for_device: yes\n", "source.wait_for_device", 2, "expected true or false, got 'yes'"),
    ("vehicle: {dbc: /tmp}\n", "vehicle.dbc", 1, "is a folder, not a DBC file"),
])
def test_what_would_stop_the_service_is_exit_2_one_line_with_key_and_line(capsys, tmp_path, text, key, line, why):
    rc, err = check(capsys, tmp_path, text)
    assert rc == 2, err
    one_line(err)
    assert f"c.yaml: line {line}: {key}" in err and why in err


def test_a_corrupt_model_is_named_by_its_own_key_in_one_line(capsys, tmp_path):
    bad = tmp_path / "bad.onnx"
    bad.write_bytes(bytes(range(256)) * 12)
    rc, err = check(capsys, tmp_path, f"pipeline: {{preset: paper004}}\ncascade: {{verifier: {bad}}}\n")
    assert rc == 2 and "line 2: cascade.verifier: " in one_line(err) and "persistence.cpp" not in err
    xml = tmp_path / "bad.xml"
    xml.write_text('<?xml version="1.0"?>\n<opencv_storage><cascade>x</cascade></opencv_storage>\n')
    rc, err = check(capsys, tmp_path, f"pipeline: {{preset: paper004}}\ncascade: {{model: {xml}}}\n")
    assert rc == 2 and "line 2: cascade.model: " in one_line(err) and "persistence.cpp" not in err


def test_the_source_opens_and_its_frame_size_must_match_the_camera(capsys, tmp_path):
    video = write_video(tmp_path / "v.mp4", n=5, size=(320, 240))
    rc, err = check(capsys, tmp_path, f"source: {{kind: video, path: {video}}}\ncamera: {{width: 640, height: 480}}\n")
    assert rc == 2 and "source.path: " in one_line(err) and "frames are 320x240 but camera.width/camera.height say 640x480" in err
    rc, out = check(capsys, tmp_path, f"source: {{kind: video, path: {video}}}\n"
                                      f"camera: {{width: 320, height: 240, fx: 300, fy: 300, cx: 160, cy: 120}}\n")
    assert rc == 0 and out.endswith(": ok\n"), out
    (tmp_path / "text.mp4").write_text("not a video\n")
    rc, err = check(capsys, tmp_path, f"source: {{kind: video, path: {tmp_path / 'text.mp4'}}}\n")
    assert rc == 2 and "source.path: " in one_line(err) and "cannot be opened as a video" in err


def test_an_absent_camera_fails_only_when_the_service_would_not_wait_for_it(capsys, tmp_path):
    absent = "source: {kind: v4l2, device: /dev/video97, wait_for_device: false}\n"
    rc, err = check(capsys, tmp_path, absent)
    assert rc == 2 and "source.device: /dev/video97: not on this machine" in one_line(err)
    rc, _ = check(capsys, tmp_path, absent, "--skip-absent-devices")
    assert rc == 0
    rc, _ = check(capsys, tmp_path, "source: {kind: v4l2, device: /dev/video97, wait_for_device: true}\n")
    assert rc == 0


def test_an_output_naming_an_input_is_refused(capsys, tmp_path):
    video = write_video(tmp_path / "v.mp4", n=3, size=(320, 240))
    rc, err = check(capsys, tmp_path, f"source: {{kind: video, path: {video}}}\nservice: {{tracks_file: {video}}}\n")
    assert rc == 2 and "service.tracks_file" in one_line(err) and "is source.path" in err


def test_yaml_1_2_numbers_and_booleans(tmp_path):
    f = tmp_path / "c.yaml"
    f.write_text("camera: {fx: 0700, fy: 1e3, cx: 0x140}\nsource: {wait_for_device: false, fps: .5}\n")
    cfg = configuration.load(f)
    assert cfg["camera"]["fx"] == 700.0 and cfg["camera"]["fy"] == 1000.0 and cfg["camera"]["cx"] == 320.0
    assert cfg["source"]["wait_for_device"] is False and cfg["source"]["fps"] == 0.5
    for text, got in (("source: {wait_for_device: off}", "'off'"), ("health: {camera_timeout_s: 1:30}", "'1:30'"),
                      ("source: {device: 2001-01-01}", None)):
        f.write_text(text + "\n")
        if got is None:
            assert configuration.load(f)["source"]["device"] == "2001-01-01"   # a string, not a date
            continue
        with pytest.raises(configuration.ConfigFileError, match=f"got {got}"):
            configuration.load(f)


def test_limits_name_their_line(tmp_path, capsys):
    rc, err = check(capsys, tmp_path, "camera:\n  fx: 700\n  fy: " + "[" * 30 + "]" * 30 + "\n")
    assert rc == 2 and "line 3: brackets nested more than 20 levels" in one_line(err)
    rc, err = check(capsys, tmp_path, "a: &x 1\nb:\n" + "".join(f"  - *x\n" for _ in range(120)))
    assert rc == 2 and "line 103: more than 100 aliases" in one_line(err)
    rc, err = check(capsys, tmp_path, "camera:\n  fx: 700\n  cy: !!float 'x'\n")
    assert rc == 2 and "line 3: a value cannot be read" in one_line(err)
    rc, err = check(capsys, tmp_path, "camera:\n  fx: 700\n" + "x" * 300 + ":\n")
    assert rc == 2 and "c.yaml: line 3: xxxx" in one_line(err) and "unknown section" in err
    rc, err = check(capsys, tmp_path, "camera:\n  fx: 700\n:can:\n  interface: virtual\n")  # a colon in the name
    assert rc == 2 and "c.yaml: line 3: :can: unknown section" in one_line(err)
    (tmp_path / "folder.yaml").mkdir()
    rc = cli.main(["config", "check", str(tmp_path / "folder.yaml")])
    assert rc == 2 and "is a folder, not a configuration file" in one_line(capsys.readouterr().err)
