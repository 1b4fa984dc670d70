"""An output never destroys an input: `headway replay` refuses --tracks, --out-video and --can-out naming
one of its inputs (or a link to it) with one line and the input unchanged, and writes each output beside
its place, renamed into it only when the run completed."""
from __future__ import annotations

import os

import cv2
import numpy as np
import pytest

from app import cli
from tests.conftest import write_video


def run(capsys, *args) -> tuple[int, str]:
    rc = cli.main(list(args))
    out = capsys.readouterr()
    return rc, out.err


@pytest.fixture
def inputs(tmp_path):
    video = write_video(tmp_path / "v1.mp4", n=8, size=(320, 240))
    log = tmp_path / "in.log"
    log.write_text("".join(f"({1000 + i * 0.01:.6f}) can0 3E9#{i % 256:02X}00000000000000\n" for i in range(3000)))
    return video, log


@pytest.mark.parametrize("option", ["--tracks", "--out-video"])
def test_an_output_naming_the_source_video_is_refused_and_the_video_kept(capsys, inputs, option):
    video, _log = inputs
    before = video.read_bytes()
    rc, err = run(capsys, "replay", str(video), option, str(video))
    assert rc == 1 and err.count("\n") == 1, err
    assert f"{option} {video}: is the source" in err and "would destroy it" in err
    assert video.read_bytes() == before


def test_can_out_naming_can_in_is_refused_and_the_log_kept(capsys, inputs):
    video, log = inputs
    before = log.read_bytes()
    rc, err = run(capsys, "replay", str(video), "--can-in", str(log), "--can-out", str(log))
    assert rc == 1 and "--can-out" in err and "is --can-in" in err and err.count("\n") == 1, err
    assert log.read_bytes() == before and len(before.splitlines()) == 3000


def test_a_link_to_an_input_is_the_input(capsys, inputs, tmp_path):
    video, log = inputs
    (tmp_path / "soft.mp4").symlink_to(video)
    os.link(log, tmp_path / "hard.log")
    before_v, before_l = video.read_bytes(), log.read_bytes()
    rc, err = run(capsys, "replay", str(video), "--tracks", str(tmp_path / "soft.mp4"))
    assert rc == 1 and "is the source" in err
    rc, err = run(capsys, "replay", str(video), "--can-in", str(log), "--can-out", str(tmp_path / "hard.log"))
    assert rc == 1 and "is --can-in" in err
    rc, err = run(capsys, "replay", str(video), "--tracks", str(tmp_path / "t.jsonl"), "--can-out",
                  str(tmp_path / "t.jsonl"))
    assert rc == 1 and "is --tracks" in err and "an output" in err
    assert video.read_bytes() == before_v and log.read_bytes() == before_l


def test_outputs_appear_whole_and_a_failed_run_leaves_the_previous_ones(capsys, tmp_path):
    folder = tmp_path / "frames"
    folder.mkdir()
    for i in range(5):
        cv2.imwrite(str(folder / f"{i:03d}.png"), np.full((120, 160), 30 + 20 * i, np.uint8))
    tracks = tmp_path / "tracks.jsonl"
    rc, err = run(capsys, "replay", str(folder), "--fps", "10", "--tracks", str(tracks))
    assert rc == 0, err
    assert len(tracks.read_text().splitlines()) == 5
    tracks.write_text("the previous run\n")
    rc, err = run(capsys, "replay", str(folder), "--fps", "10", "--tracks", str(tracks), "--can-in",
                  str(tmp_path / "missing.log"))
    assert rc == 1 and "missing.log" in err
    assert tracks.read_text() == "the previous run\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["frames", "tracks.jsonl"]  # no partial file left


@pytest.mark.parametrize("command", ["detect", "calibrate"])
def test_detect_and_calibrate_refuse_an_out_that_is_one_of_their_images(capsys, tmp_path, command):
    images = []
    for i in range(2):
        p = tmp_path / f"{i}.png"
        cv2.imwrite(str(p), np.full((120, 160), 100, np.uint8))
        images.append(str(p))
    before = (tmp_path / "1.png").read_bytes()
    rc, err = run(capsys, command, *images, "--out", images[1])
    assert rc == 1 and f"--out {images[1]}: is input 2" in err and err.count("\n") == 1, err
    assert (tmp_path / "1.png").read_bytes() == before
