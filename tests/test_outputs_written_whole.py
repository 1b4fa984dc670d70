"""An output is replaced only by a whole one: every command writes its files (and a folder of frames or
examples) beside their place and renames them into it when the work completed, so that a command that fails
midway, or whose disk fills while it writes, leaves each output it had before byte for byte and no partial
file; a run that completes replaces them. `headway replay`'s outputs: test_outputs_keep_inputs.py."""
from __future__ import annotations

import errno
import gzip
import json
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from app import cli
from app.annotate import VideoOut
from app.fleet import report as fleet_report
from app.output_files import folder_written_whole, partial_path, written_whole
from app.supervisor.install import install
from app.train import proposals, verifier
from app.train.cascade import FeatureSet, TrainParams, train
from app.train.cascade.model import Cascade
from tests.test_cascade_train import _dataset

SCENARIO = "name: tiny\nduration_s: {d}\nfps: 10\nego: {{speed_kmh: 72}}\nvehicles: []\n"


def run(capsys, *args) -> tuple[int, str]:
    rc = cli.main(list(args))
    return rc, capsys.readouterr().err


def snapshot(folder: Path) -> dict[str, bytes | None]:
    """Every file (its bytes) and folder (None) under `folder`, hidden ones included."""
    return {str(p.relative_to(folder)): p.read_bytes() if p.is_file() else None for p in sorted(folder.rglob("*"))}


def previous(folder: Path, *names: str) -> None:
    """Files standing for an earlier run's outputs."""
    for name in names:
        (folder / name).parent.mkdir(parents=True, exist_ok=True)
        (folder / name).write_text(f"the previous {name}\n")


def refused_on_a_full_disk_then_written(capsys, folder: Path, full_disk, suffix: str, *args: str) -> None:
    """`headway ARGS` while files ending in `suffix` cannot be written whole: exit 1 naming the full disk, and
    `folder` as it was; then with room: exit 0."""
    before = snapshot(folder)
    full_disk(suffix)
    rc, err = run(capsys, *args)
    assert rc == 1 and "No space left on device" in err, err
    assert snapshot(folder) == before
    full_disk(None)
    rc, err = run(capsys, *args)
    assert rc == 0, err


@pytest.fixture
def full_disk(monkeypatch):
    """`fill(suffix)`: from then on a text written to a file whose name ends in `suffix` stops half-way
    with "No space left on device", as on a full disk; `fill(None)` frees the disk."""
    real = Path.write_text

    def fill(suffix: str | None) -> None:
        if suffix is None:
            monkeypatch.setattr(Path, "write_text", real)
            return

        def half(self, data, *args, **kwargs):
            if not self.name.endswith(suffix):
                return real(self, data, *args, **kwargs)
            real(self, data[:len(data) // 2], *args, **kwargs)
            raise OSError(errno.ENOSPC, "No space left on device", str(self))

        monkeypatch.setattr(Path, "write_text", half)
    return fill


def test_the_temporary_file_keeps_every_suffix_so_writers_choose_the_same_format(tmp_path):
    assert partial_path(str(tmp_path / "v.yml.gz")).name.endswith(".yml.gz")
    assert partial_path(str(tmp_path / "tracks.jsonl")).name.startswith(".tracks.partial-")
    with pytest.raises(RuntimeError):
        with written_whole(str(tmp_path / "x.json")) as tmp:
            Path(tmp).write_text("half")
            raise RuntimeError("stopped")
    assert list(tmp_path.iterdir()) == []


def test_a_folder_is_replaced_whole_or_not_at_all(tmp_path):
    frames = tmp_path / "frames"
    previous(frames, "000000.png", "000099.png")
    before = snapshot(tmp_path)
    with pytest.raises(RuntimeError):
        with folder_written_whole(frames) as tmp:
            (Path(tmp) / "000000.png").write_bytes(b"new")
            raise RuntimeError("stopped")
    assert snapshot(tmp_path) == before
    with folder_written_whole(frames) as tmp:
        (Path(tmp) / "000000.png").write_bytes(b"new")
    assert snapshot(tmp_path) == {"frames": None, "frames/000000.png": b"new"}   # the stale frame went with its folder


def test_detect_out(capsys, tmp_path, full_disk):
    images = []
    for i in range(2):
        images.append(str(tmp_path / f"{i}.png"))
        cv2.imwrite(images[-1], np.full((120, 160), 100, np.uint8))
    out = tmp_path / "detections.json"
    previous(tmp_path, "detections.json")
    refused_on_a_full_disk_then_written(capsys, tmp_path, full_disk, ".json", "detect", *images, "--out", str(out))
    assert [e["file_name"] for e in json.loads(out.read_text())] == ["0.png", "1.png"]


def chessboards(folder: Path, n: int = 5) -> list[str]:
    """Views of a 9x6-corner board, each a perspective of the flat board."""
    sq = 40
    board = np.kron((np.indices((7, 10)).sum(0) % 2) * 255, np.ones((sq, sq))).astype(np.uint8)
    board = cv2.copyMakeBorder(board, sq, sq, sq, sq, cv2.BORDER_CONSTANT, value=255)
    h, w = board.shape
    paths = []
    for i in range(n):
        d = 30 + 12 * i
        corners = np.float32([[60 + d, 40], [580 - d / 2, 60 + d / 3], [600, 440 - d / 2], [40, 420]])
        warp = cv2.getPerspectiveTransform(np.float32([[0, 0], [w, 0], [w, h], [0, h]]), corners)
        paths.append(str(folder / f"board{i}.png"))
        cv2.imwrite(paths[-1], cv2.warpPerspective(board, warp, (640, 480), borderValue=128))
    return paths


def test_calibrate_out(capsys, tmp_path, full_disk):
    views = chessboards(tmp_path)
    out = tmp_path / "camera.yaml"
    previous(tmp_path, "camera.yaml")
    refused_on_a_full_disk_then_written(capsys, tmp_path, full_disk, ".yaml", "calibrate", *views, "--out", str(out))
    assert yaml.safe_load(out.read_text())["camera"]["width"] == 640


@pytest.mark.parametrize("video", [False, True])
def test_sim_out_folder(capsys, tmp_path, monkeypatch, video):
    scenario = tmp_path / "tiny.yaml"
    scenario.write_text(SCENARIO.format(d=0.3))
    out = tmp_path / "render"
    previous(out, "scenario.yaml", "camera.json", "truth.jsonl", "ego_speed.log", "video.mp4", "frames/000000.png",
             "frames/000099.png")
    before = snapshot(tmp_path)
    from app.sim import writer

    real = writer.render

    def stops_at_frame_2(*args, **kwargs):
        for frame in real(*args, **kwargs):
            if frame.index == 2:
                raise RuntimeError("the renderer stopped")
            yield frame

    monkeypatch.setattr(writer, "render", stops_at_frame_2)
    video_flag = ["--video"] if video else []
    rc, err = run(capsys, "sim", str(scenario), "--out", str(out), *video_flag)
    assert rc == 1 and "the renderer stopped" in err, err
    assert snapshot(tmp_path) == before
    monkeypatch.setattr(writer, "render", real)
    rc, err = run(capsys, "sim", str(scenario), "--out", str(out), *video_flag)
    assert rc == 0, err
    assert len((out / "truth.jsonl").read_text().splitlines()) == 3
    assert yaml.safe_load((out / "scenario.yaml").read_text())["name"] == "tiny"
    if video:
        assert cv2.VideoCapture(str(out / "video.mp4")).get(cv2.CAP_PROP_FRAME_COUNT) == 3
    else:   # the frames folder is this run's: the earlier run's 100th frame is gone
        assert sorted(p.name for p in (out / "frames").iterdir()) == ["000000.png", "000001.png", "000002.png"]
    assert not [p for p in out.rglob(".*")]


def test_demo_out_folder(capsys, tmp_path, monkeypatch):
    scenario = tmp_path / "tiny.yaml"
    scenario.write_text(SCENARIO.format(d=0.3))
    out = tmp_path / "demo"
    previous(out, "annotated.mp4", "tracks.jsonl", "truth.jsonl", "can_out.log", "summary.txt")
    before = snapshot(tmp_path)
    real = VideoOut.write

    def fails_at_frame_2(self, bgr):
        self.frames = getattr(self, "frames", 0) + 1
        if self.frames == 3:
            raise OSError(errno.ENOSPC, "No space left on device", self.path)
        real(self, bgr)

    monkeypatch.setattr(VideoOut, "write", fails_at_frame_2)
    rc, err = run(capsys, "demo", "--scenario", str(scenario), "--out", str(out))
    assert rc == 1 and "No space left on device" in err, err
    assert snapshot(tmp_path) == before
    monkeypatch.setattr(VideoOut, "write", real)
    rc, err = run(capsys, "demo", "--scenario", str(scenario), "--out", str(out))
    assert rc == 0, err
    for name in ("tracks.jsonl", "truth.jsonl"):
        assert len((out / name).read_text().splitlines()) == 3
    assert "vehicles within 60 m tracked" in (out / "summary.txt").read_text()
    assert (out / "annotated.mp4").read_bytes() != before["demo/annotated.mp4"]
    assert sorted(p.name for p in out.iterdir()) == sorted(["annotated.mp4", "tracks.jsonl", "truth.jsonl",
                                                            "can_out.log", "summary.txt"])


def test_eval_out_folder(capsys, tmp_path, full_disk):
    scenario = tmp_path / "tiny.yaml"
    scenario.write_text(SCENARIO.format(d=0.3))
    data, out = tmp_path / "data", tmp_path / "report"
    data.mkdir()
    previous(out, "report.json", "report.md", "examples/old.jpg")
    # report.json is written first: it must not be renamed into place without report.md
    refused_on_a_full_disk_then_written(capsys, tmp_path, full_disk, ".md", "eval", "--parts", "synthetic",
                                        "--scenarios", str(scenario), "--data", str(data), "--out", str(out))
    assert "synthetic" in json.loads((out / "report.json").read_text())
    assert "Synthetic suite" in (out / "report.md").read_text()
    assert sorted(p.name for p in out.iterdir()) == ["examples", "report.json", "report.md"]
    assert list((out / "examples").iterdir()) == []   # this run's examples (none for the synthetic suite)


def test_fleet_report(tmp_path, full_disk):
    previous(tmp_path, "report.json", "report.md")
    before = snapshot(tmp_path)
    rep = fleet_report.build([], {"manifest": "drives.yaml"})
    full_disk(".md")
    with pytest.raises(OSError, match="No space left"):
        fleet_report.write(rep, tmp_path)
    assert snapshot(tmp_path)["report.md"] == before["report.md"]
    assert sorted(snapshot(tmp_path)) == ["report.json", "report.md"]
    full_disk(None)
    fleet_report.write(rep, tmp_path)
    assert fleet_report.read(tmp_path)["totals"]["drives"] == 0
    assert "# Fleet replay: drives.yaml" in (tmp_path / "report.md").read_text()


@pytest.fixture(scope="module")
def tiny_data(tmp_path_factory):
    return _dataset(tmp_path_factory.mktemp("tiny") / "data", 20, 1)


CASCADE_ARGS = ("--window", "12x8", "--stages", "2", "--num-pos", "100", "--num-neg", "100", "--features", "200")


def test_train_cascade_out_and_log(capsys, tmp_path, monkeypatch, tiny_data):
    out, log = tmp_path / "cascade.xml", tmp_path / "train.log"
    previous(tmp_path, "cascade.xml", "train.log")
    before = snapshot(tmp_path)
    real = Cascade.save
    saved = []

    def second_stage_cut_short(self, fs, path):
        if Path(path).parent != tmp_path:   # the trainer's own copy it mines negatives with
            return real(self, fs, path)
        saved.append(path)
        if len(saved) == 2:
            Path(path).write_text(self.to_xml(fs)[:200])
            raise OSError(errno.ENOSPC, "No space left on device", path)
        return real(self, fs, path)

    monkeypatch.setattr(Cascade, "save", second_stage_cut_short)
    rc, err = run(capsys, "train", "cascade", "--data", str(tiny_data), "--out", str(out), "--log", str(log),
                  *CASCADE_ARGS)
    assert rc == 1 and "No space left on device" in err, err
    # the first stage's cascade, whole, replaced the previous one; the log of a training that failed is not kept
    assert len(Cascade.from_xml(FeatureSet(12, 8), str(out)).stages) == 1
    assert log.read_bytes() == before["train.log"] and sorted(snapshot(tmp_path)) == ["cascade.xml", "train.log"]
    monkeypatch.setattr(Cascade, "save", real)
    rc, err = run(capsys, "train", "cascade", "--data", str(tiny_data), "--out", str(out), "--log", str(log),
                  *CASCADE_ARGS)
    assert rc == 0, err
    assert len(Cascade.from_xml(FeatureSet(12, 8), str(out)).stages) == 2 and not cv2.CascadeClassifier(str(out)).empty()
    assert log.read_text().splitlines()[-1].startswith("done: 2 stages")
    assert sorted(snapshot(tmp_path)) == ["cascade.xml", "train.log"]


def test_train_verifier_out_keeps_its_gzipped_yaml(capsys, tmp_path, monkeypatch, tiny_data):
    cascade = tmp_path / "cascade.xml"
    train([str(tiny_data)], str(cascade), TrainParams(width=12, height=8, stages=2, num_pos=100, num_neg=100,
                                                      features=200), log=lambda line: None)
    camera = tmp_path / "camera.yaml"
    camera.write_text("camera: {width: 160, height: 120, fx: 150.0, fy: 150.0, cx: 80.0, cy: 60.0}\n")
    out = tmp_path / "verifier.yml.gz"
    previous(tmp_path, "verifier.yml.gz")
    before = snapshot(tmp_path)
    args = ("train", "verifier", "--data", str(tiny_data), "--cascade", str(cascade), "--out", str(out), "--every", "1",
            "--epochs", "2", "--config", str(camera))
    real = verifier.Mlp.save

    def cut_short(self, path):
        Path(path).write_bytes(b"%YAML:1.0\n")
        raise OSError(errno.ENOSPC, "No space left on device", path)

    monkeypatch.setattr(verifier.Mlp, "save", cut_short)
    rc, err = run(capsys, *args)
    assert rc == 1 and "No space left on device" in err, err
    assert snapshot(tmp_path) == before
    monkeypatch.setattr(verifier.Mlp, "save", real)
    rc, err = run(capsys, *args)
    assert rc == 0, err
    assert gzip.decompress(out.read_bytes()).startswith(b"%YAML")   # OpenCV chose the format by the suffixes
    assert verifier.Mlp.load(str(out)).w1.shape[1] == 64   # the default hidden units


def test_a_training_cache_is_written_whole_under_its_own_name(tmp_path, monkeypatch, tiny_data):
    cache = tmp_path / "images.cache"
    with open(cache, "wb") as f:   # another set's cache: read, found to be of other images, replaced
        np.savez(f, key=np.array("other images"))
    before = snapshot(tmp_path)
    real = np.savez

    def cut_short(file, **arrays):
        file.write(b"PK\x03\x04")
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(np, "savez", cut_short)
    with pytest.raises(OSError, match="No space left"):
        proposals.load_images([str(tiny_data)], 32, cache=str(cache))
    assert snapshot(tmp_path) == before
    monkeypatch.setattr(np, "savez", real)
    images, boxes, scale = proposals.load_images([str(tiny_data)], 32, cache=str(cache))
    assert sorted(snapshot(tmp_path)) == ["images.cache"]   # no .npz added to the name
    again = proposals.load_images([str(tiny_data)], 32, cache=str(cache))
    assert np.array_equal(again[0], images) and again[2] == scale


def test_install_service_config_and_units(tmp_path, full_disk):
    unit = tmp_path / "etc" / "systemd" / "system" / "headway.service"
    previous(unit.parent, unit.name)
    before = snapshot(tmp_path)
    full_disk(".service")
    with pytest.raises(OSError, match="No space left"):
        install(tmp_path, enable=False)
    assert snapshot(tmp_path) == before
    full_disk(".yaml")   # a configuration cut short would be kept by every later install
    with pytest.raises(OSError, match="No space left"):
        install(tmp_path, enable=False)
    config = tmp_path / "etc" / "headway" / "config.yaml"
    assert not config.parent.exists() or list(config.parent.iterdir()) == []
    full_disk(None)
    done = install(tmp_path, enable=False)
    assert f"wrote {config} (edit the camera: and can: sections for your car)" in done
    assert yaml.safe_load(config.read_text())["can"]["channel"] == "can0"
    assert "ExecStart" in unit.read_text()
