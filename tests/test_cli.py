"""The `headway` command line end to end: demo, sim, replay (real recordings too), detect, bench, errors."""
from __future__ import annotations

import json
import subprocess
import sys

import cv2
import numpy as np
import pytest

from tests.conftest import REPO, data_path


def headway(*args: str, cwd=REPO, timeout=600) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "app.cli", *args], cwd=cwd, capture_output=True, text=True,
                          timeout=timeout)


def lines(path) -> list[dict]:
    return [json.loads(x) for x in path.read_text().splitlines()]


def test_demo_writes_annotated_video_tracks_and_summary(tmp_path):
    r = headway("demo", "--out", str(tmp_path / "demo"))
    assert r.returncode == 0, r.stderr
    out = tmp_path / "demo"
    cap = cv2.VideoCapture(str(out / "annotated.mp4"))
    n_video = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
    ok, frame = cap.read()
    assert ok and frame.shape == (480, 640, 3)
    tracks = lines(out / "tracks.jsonl")
    assert len(tracks) == n_video > 100
    assert {"frame", "t", "tracks", "lead_id", "fcw"} <= set(tracks[0])
    confirmed = [t for rec in tracks for t in rec["tracks"]]
    assert confirmed and {"id", "box", "range_m", "lateral_m", "range_rate_mps", "ttc_s", "ttc_scale_s",
                          "in_path"} <= set(confirmed[0])
    assert "Demo written to" in r.stdout and (out / "summary.txt").exists()
    assert (out / "can_out.log").stat().st_size > 0


def test_sim_writes_frames_truth_and_ego_speed_log(tmp_path):
    r = headway("sim", "empty_road", "--out", str(tmp_path / "s"))
    assert r.returncode == 0, r.stderr
    frames = sorted((tmp_path / "s" / "frames").glob("*.png"))
    truth = lines(tmp_path / "s" / "truth.jsonl")
    assert len(frames) == len(truth) == 180
    assert cv2.imread(str(frames[0]), cv2.IMREAD_GRAYSCALE).shape == (480, 640)
    assert (tmp_path / "s" / "ego_speed.log").read_text().count("#") == 299  # 50 Hz from 0 to the last frame (5.967 s)


def test_replay_of_rendered_folder_matches_scenario_replay(tmp_path):
    """A scenario written to disk and replayed as an image folder gives the same tracks as replaying the
    scenario directly (same per-frame code, same timestamps)."""
    assert headway("sim", "steady_following", "--out", str(tmp_path / "s")).returncode == 0
    a = headway("replay", str(tmp_path / "s" / "frames"), "--fps", "30", "--tracks", str(tmp_path / "a.jsonl"))
    b = headway("replay", "steady_following", "--tracks", str(tmp_path / "b.jsonl"))
    assert a.returncode == 0 and b.returncode == 0, a.stderr + b.stderr
    ta, tb = lines(tmp_path / "a.jsonl"), lines(tmp_path / "b.jsonl")
    assert len(ta) == len(tb) == 300
    assert [[t["id"] for t in x["tracks"]] for x in ta] == [[t["id"] for t in x["tracks"]] for x in tb]


def test_replay_udacity_video_one_line_per_frame(tmp_path):
    video = data_path("udacity", "test_video.mp4")
    r = headway("replay", str(video), "--tracks", str(tmp_path / "t.jsonl"), "--out-video", str(tmp_path / "v.mp4"))
    assert r.returncode == 0, r.stderr
    cap = cv2.VideoCapture(str(video))
    n = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
    recs = lines(tmp_path / "t.jsonl")
    assert len(recs) == n == 38
    assert [x["frame"] for x in recs] == list(range(n))
    assert cv2.VideoCapture(str(tmp_path / "v.mp4")).read()[0]


def test_replay_tme_image_folder(tmp_path):
    folder = data_path("tme", "tme08")
    n = len([p for p in folder.iterdir() if p.suffix.lower() in (".png", ".jpg", ".jpeg", ".bmp")])
    r = headway("replay", str(folder), "--fps", "20", "--tracks", str(tmp_path / "t.jsonl"))
    assert r.returncode == 0, r.stderr
    recs = lines(tmp_path / "t.jsonl")
    assert len(recs) == n >= 50
    assert recs[1]["t"] == pytest.approx(0.05)


def test_detect_writes_one_entry_per_image(tmp_path):
    images = sorted(data_path("tusimple", "supp", "images").glob("*.jpg"))[:3]
    out = tmp_path / "det.json"
    r = headway("detect", *map(str, images), "--out", str(out))
    assert r.returncode == 0, r.stderr
    res = json.loads(out.read_text())
    assert [e["file_name"] for e in res] == [p.name for p in images]
    for e in res:
        for b in e["bbox"]:
            assert set(b) == {"left", "top", "right", "bottom", "score"} and b["left"] < b["right"]


def test_bench_reports_median_and_p99_per_stage():
    r = headway("bench", "--scenario", "steady_following", "--repeats", "1", "--json")
    assert r.returncode == 0, r.stderr
    rep = json.loads(r.stdout)
    stages = rep["stages"]["all"]
    assert {"lanes", "total"} <= set(stages) and rep["frame_size"] == "640x480"
    assert all(s["p99_ms"] >= s["median_ms"] > 0 for s in stages.values())
    # at the configuration's camera rate (30 fps) too: a detection every 3rd frame, 10 a second
    paced = rep["at_camera_rate"]
    assert paced["fps"] == 30.0 and {"lanes", "total"} <= set(paced["stages"]["all"])
    assert paced["detections_per_s"] == pytest.approx(10.0, abs=0.5)
    assert paced["detection_age"]["median_ms"] > 0


def test_bench_at_the_camera_rate_reports_the_lagged_detections_age(tmp_path):
    """With the detection on its worker thread, taken 2 frames after its frame (phd.detect_lag 2), the bench at 30 fps
    reports the frame thread's wait for it, and its age when taken: at least the 2 frame periods of the lag."""
    cfg = tmp_path / "lag.yaml"
    cfg.write_text("phd: {detect_lag: 2}\n")
    r = headway("bench", "--scenario", "steady_following", "--repeats", "1", "--fps", "30", "--config", str(cfg),
                "--json")
    assert r.returncode == 0, r.stderr
    paced = json.loads(r.stdout)["at_camera_rate"]
    assert {"detect_wait", "bg_detect", "bg_detect_cpu"} <= set(paced["stages"]["full_detection"])
    assert paced["detection_age"]["median_ms"] >= 2000.0 / 30.0
    assert paced["detections_per_s"] == pytest.approx(10.0, abs=0.5)


def test_image_bench_times_headway_detect_part_by_part(tmp_path):
    """`bench --images` times what `headway detect` spends on each image: reading, the core's parts of the preset's
    detection stage (the default preset: the cascade's scan and its verifier apart, the shadow detector's hypotheses
    and their verification, their fusion), the core's whole stage and the total; the parts add up within each.
    --preset paper004 times the cascade alone."""
    images = data_path("tusimple", "supp", "images")
    r = headway("bench", "--images", str(images), "--limit", "3", "--repeats", "2", "--json")
    assert r.returncode == 0, r.stderr
    rep = json.loads(r.stdout)
    assert rep["preset"] == "default" and rep["images"] == 6 and rep["frame_sizes"] == ["1280x720"]
    # the default camera scaled to the images is said, as `headway detect` says it
    assert len(rep["notes"]) == 1 and "default camera (640x480) scaled" in rep["notes"][0]
    parts = rep["stages"]["image"]
    detection = ["lanes", "cascade", "verifier", "hypotheses", "verify", "fuse"]
    assert list(parts) == ["read", *detection, "core", "total"]
    assert all(s["n"] == 6 and s["p99_ms"] >= s["median_ms"] > 0 for s in parts.values())
    mean = {k: s["mean_ms"] for k, s in parts.items()}
    assert mean["core"] >= sum(mean[k] for k in detection) - 1e-3
    assert mean["total"] >= mean["read"] + mean["core"] - 1e-3
    # the network's looks are timed as the verifier's, not the scan's: without a verifier that part is empty
    (tmp_path / "off.yaml").write_text("cascade: {verifier: \"off\"}\n")
    r = headway("bench", "--images", str(images), "--limit", "2", "--repeats", "1", "--preset", "paper004",
                "--config", str(tmp_path / "off.yaml"), "--json")
    assert r.returncode == 0, r.stderr
    rep = json.loads(r.stdout)
    parts = rep["stages"]["image"]
    assert rep["preset"] == "paper004" and list(parts) == ["read", "lanes", "cascade", "verifier", "core", "total"]
    assert parts["verifier"]["p99_ms"] < 0.05 < parts["cascade"]["median_ms"]


def test_latency_bench_runs_the_preset_asked_for():
    """`bench --latency --preset P` measures P's real-time loop (not the configuration's default) and says which
    preset it measured."""
    r = headway("bench", "--latency", "--seconds", "1", "--preset", "thesis", "--json")
    assert r.returncode == 0, r.stderr
    rep = json.loads(r.stdout)
    assert rep["preset"] == "thesis" and rep["frames"] >= 20 and rep["dropped"] == 0
    c = rep["capture_to_can"]
    assert c["p99_ms"] >= c["median_ms"] > 0


@pytest.mark.parametrize("args, message", [
    (["replay", "/nonexistent/drive.mp4"], "no such file or folder"),
    (["replay", "FOLDER"], "needs its frame rate"),
    (["replay", "NOTVIDEO"], "cannot be read as a video"),
    (["replay", "no_such_scenario.yaml"], "no_such_scenario.yaml"),
    (["sim", "BADSCENARIO", "--out", "OUT"], "vehicles[0].speed_kmh"),
    (["detect", "NOTVIDEO", "--out", "OUT"], "cannot be read as an image"),
    (["replay", "steady_following", "--config", "BADCONFIG"], "camera.fx"),
    (["bench", "--images", "/nonexistent/images"], "no such file or folder"),
    (["bench", "--images", "NOTVIDEO"], "cannot be read as an image"),
    (["bench", "--images", "EMPTY"], "holds no image"),
])
def test_bad_input_is_one_clear_line(tmp_path, args, message):
    (tmp_path / "frames").mkdir()
    (tmp_path / "empty").mkdir()
    cv2.imwrite(str(tmp_path / "frames" / "0.png"), np.zeros((48, 64), np.uint8))
    (tmp_path / "notvideo.mp4").write_text("not a video")
    (tmp_path / "bad.yaml").write_text("name: bad\nduration_s: 2\nvehicles:\n  - {id: 1, lane: 0, z_m: 30, "
                                       "speed_kmh: fast}\n")
    (tmp_path / "bad_config.yaml").write_text("camera: {fx: wide}\n")
    subst = {"FOLDER": str(tmp_path / "frames"), "NOTVIDEO": str(tmp_path / "notvideo.mp4"),
             "BADSCENARIO": str(tmp_path / "bad.yaml"), "OUT": str(tmp_path / "out"),
             "BADCONFIG": str(tmp_path / "bad_config.yaml"), "EMPTY": str(tmp_path / "empty")}
    r = headway(*[subst.get(a, a) for a in args])
    assert r.returncode in (1, 2)
    assert message in r.stderr, r.stderr
    assert "Traceback" not in r.stderr and len(r.stderr.strip().splitlines()) == 1
