"""An output never destroys an input: `headway replay` refuses --tracks, --out-video and --can-out naming
one of its inputs (or a link to it) with one line and the input unchanged, and writes each output beside
its place, renamed into it only when the run completed. detect, calibrate, sim, demo, eval, fleet and train
refuse an output (a file, or a folder and the files they write into it) that is one of their inputs."""
from __future__ import annotations

import os

import cv2
import numpy as np
import pytest

from app import cli
from app.safe_yaml import short_path
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


def test_sim_refuses_an_out_folder_where_it_would_write_over_its_scenario(capsys, tmp_path):
    out = tmp_path / "render"
    out.mkdir()
    scenario = out / "scenario.yaml"   # a scenario kept in the folder its render is written to
    scenario.write_text("name: kept\nduration_s: 1.0\nfps: 10\nego: {speed_kmh: 72}\nvehicles: []\n")
    before = scenario.read_bytes()
    rc, err = run(capsys, "sim", str(scenario), "--out", str(out))
    assert rc == 1 and err.count("\n") == 1, err
    assert f"--out's scenario.yaml {short_path(scenario)}: is the scenario" in err
    assert scenario.read_bytes() == before and sorted(p.name for p in out.iterdir()) == ["scenario.yaml"]


def test_demo_refuses_an_out_folder_holding_its_configuration_under_a_written_name(capsys, tmp_path):
    config = tmp_path / "summary.txt"   # YAML under the name of the demo's summary
    config.write_text("fcw:\n  ttc_warning_s: 2.0\n")
    before = config.read_bytes()
    rc, err = run(capsys, "demo", "--out", str(tmp_path), "--config", str(config))
    assert rc == 1 and f"--out's summary.txt {short_path(config)}: is --config" in err and err.count("\n") == 1, err
    assert config.read_bytes() == before and sorted(p.name for p in tmp_path.iterdir()) == ["summary.txt"]


@pytest.mark.parametrize("case", ["config_as_report", "out_is_data"])
def test_eval_refuses_an_out_that_names_its_configuration_or_its_data(capsys, tmp_path, case):
    data = tmp_path / "data"
    data.mkdir()
    config = tmp_path / "report.json"   # JSON is YAML: a configuration may carry the report's name
    config.write_text('{"fcw": {"ttc_warning_s": 2.0}}\n')
    before = config.read_bytes()
    out = tmp_path if case == "config_as_report" else data
    rc, err = run(capsys, "eval", "--parts", "cost", "--config", str(config), "--data", str(data), "--out", str(out))
    expected = f"--out's report.json {short_path(config)}: is --config" if case == "config_as_report" else \
        f"--out {short_path(data)}: is --data"
    assert rc == 1 and expected in err and err.count("\n") == 1, err
    assert config.read_bytes() == before and list(data.iterdir()) == []
    assert sorted(p.name for p in tmp_path.iterdir()) == ["data", "report.json"]


@pytest.mark.parametrize("case", ["out_is_manifest", "out_is_a_drive"])
def test_fleet_refuses_an_out_that_is_its_manifest_or_a_drive(capsys, tmp_path, case):
    frames = tmp_path / "frames"
    frames.mkdir()
    for i in range(3):
        cv2.imwrite(str(frames / f"{i:03d}.png"), np.full((120, 160), 60 + 30 * i, np.uint8))
    manifest = tmp_path / "drives.yaml"
    manifest.write_text(f"drives:\n  - source: {frames}\n    fps: 10\n")
    before = manifest.read_bytes(), sorted(p.name for p in frames.iterdir())
    out = manifest if case == "out_is_manifest" else frames
    rc, err = run(capsys, "fleet", str(manifest), "--out", str(out))
    expected = "is the manifest" if case == "out_is_manifest" else "is drive frames's source"
    assert rc == 1 and f"--out {short_path(out)}: {expected}" in err and err.count("\n") == 1, err
    assert (manifest.read_bytes(), sorted(p.name for p in frames.iterdir())) == before


@pytest.mark.parametrize("model", ["cascade", "proposals", "verifier"])
def test_train_refuses_an_out_over_the_annotations_it_learns_from(capsys, tmp_path, model):
    data = tmp_path / "train"
    data.mkdir()
    ann = data / "annotation.json"
    ann.write_text('[{"file_name": "images/0001.jpg", "bbox": []}]\n')
    before = ann.read_bytes()
    extra = ["--cascade", str(tmp_path / "c.xml")] if model == "verifier" else []
    rc, err = run(capsys, "train", model, "--data", str(data), "--out", str(ann), *extra)
    assert rc == 1 and err.count("\n") == 1, err
    assert f"--out {short_path(ann)}: is --data folder 1's annotation.json" in err
    assert ann.read_bytes() == before and sorted(p.name for p in tmp_path.iterdir()) == ["train"]


def test_train_cascade_refuses_an_out_that_is_the_cascade_it_resumes_or_its_own_log(capsys, tmp_path):
    data = tmp_path / "train"
    data.mkdir()
    resume = tmp_path / "cascade.xml"
    resume.write_text("<opencv_storage/>\n")
    before = resume.read_bytes()
    rc, err = run(capsys, "train", "cascade", "--data", str(data), "--out", str(resume), "--resume", str(resume))
    assert rc == 1 and f"--out {short_path(resume)}: is --resume" in err and err.count("\n") == 1, err
    log = tmp_path / "new.xml"
    rc, err = run(capsys, "train", "cascade", "--data", str(data), "--out", str(log), "--log", str(log))
    assert rc == 1 and f"--log {short_path(log)}: is --out" in err and "an output" in err, err
    assert resume.read_bytes() == before and sorted(p.name for p in tmp_path.iterdir()) == ["cascade.xml", "train"]
