"""`headway fleet`: a manifest of drives replayed on Dask (a local cluster, or a scheduler and a worker
started as separate processes), byte-identical outputs whatever the number of workers and equal to
`headway replay` alone, failed drives reported, a killed worker's drive re-run, resume by key, and the
comparison of two runs."""
from __future__ import annotations

import filecmp
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
import yaml

from app.cli import main as cli_main
from app.fleet import compare
from app.fleet.drive import partial_prefix
from app.fleet.manifest import ManifestError, load_manifest
from app.fleet.run import run_fleet
from tests.conftest import DATA, data_path

# Two short scenarios rendered at test time: a stopped car ahead that gives a warning, and steady following.
STOP = {"name": "short_stop", "description": "stopped car ahead, warned", "duration_s": 3.0, "fps": 30, "seed": 7,
        "ego": {"speed_kmh": 72}, "vehicles": [{"id": 1, "kind": "car", "lane": 0, "z_m": 70, "speed_kmh": 0}]}
FOLLOW = {"name": "short_follow", "description": "steady following", "duration_s": 1.5, "fps": 30, "seed": 8,
          "ego": {"speed_kmh": 90}, "vehicles": [{"id": 1, "kind": "car", "lane": 0, "z_m": 30, "speed_kmh": 90},
                                                 {"id": 2, "kind": "truck", "lane": 1, "z_m": 45, "speed_kmh": 95}]}
REAL = ("tme", "tme08")  # 50 real motorway frames at 20 fps


def _files(out: Path, name: str) -> dict[str, bytes]:
    """A drive's deterministic outputs (every file but run.json, which holds the wall time)."""
    d = out / "drives" / name
    return {p.name: p.read_bytes() for p in sorted(d.iterdir()) if p.name != "run.json"}


def _manifest(folder: Path, entries: list[dict], name: str = "drives.yaml") -> Path:
    p = folder / name
    p.write_text(yaml.safe_dump({"drives": entries}))
    return p


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    """The scenarios, the manifest (with the real clip when ../shared/data has it), and a 1-worker run."""
    root = tmp_path_factory.mktemp("fleet")
    (root / "stop.yaml").write_text(yaml.safe_dump(STOP))
    (root / "follow.yaml").write_text(yaml.safe_dump(FOLLOW))
    entries = [{"source": "stop.yaml"}, {"source": "follow.yaml"}]
    real = DATA.joinpath(*REAL)
    if real.exists():
        entries.append({"source": str(real), "fps": 20})
    manifest = _manifest(root, entries)
    one = root / "one"
    rep = run_fleet(str(manifest), str(one), workers=1, progress=False)
    return {"root": root, "manifest": manifest, "one": one, "report_one": rep,
            "names": [d.name for d in load_manifest(str(manifest))]}


def test_two_workers_identical_to_one_and_to_replay_alone(world, tmp_path):
    two = tmp_path / "two"
    rep = run_fleet(str(world["manifest"]), str(two), workers=2, progress=False)
    assert rep["failed"] == [] and rep["totals"]["ok"] == len(world["names"])
    assert "2 worker" in rep["meta"]["where"]
    for name in world["names"]:
        assert _files(two, name) == _files(world["one"], name), name
        assert set(_files(two, name)) >= {"tracks.jsonl", "can.log", "summary.json", "metrics.json", "config.yaml", "key"} \
            or name == "tme08"
    # each drive alone through `headway replay`, with the drive's effective configuration
    for name in world["names"]:
        d = two / "drives" / name
        src = json.loads((d / "summary.json").read_text())["source"]
        args = ["replay", src, "--config", str(d / "config.yaml"), "--tracks", str(tmp_path / f"{name}.jsonl"),
                "--can-out", str(tmp_path / f"{name}.log")]
        if name == "tme08":
            args += ["--fps", "20"]
        assert cli_main(args) == 0
        assert (tmp_path / f"{name}.jsonl").read_bytes() == (d / "tracks.jsonl").read_bytes(), name
        assert (tmp_path / f"{name}.log").read_bytes() == (d / "can.log").read_bytes(), name
    # the report: a row per drive with numbers, the totals
    stop = next(r for r in rep["drives"] if r["name"] == "stop")
    assert stop["frames"] == 90 and stop["vehicles_confirmed"] >= 1 and stop["warnings"] >= 1
    assert stop["metrics"]["recall"] > 0.5 and stop["can_frames"] > 0
    assert rep["totals"]["frames"] == sum(r["frames"] for r in rep["drives"])
    md = (two / "report.md").read_text()
    assert "| stop | 90 |" in md and "**total**" in md


def test_real_clip_is_replayed(world):
    data_path(*REAL)
    row = next(r for r in world["report_one"]["drives"] if r["name"] == "tme08")
    assert row["frames"] == 50 and row["metrics"] is None
    assert (world["one"] / "drives" / "tme08" / "tracks.jsonl").read_text().count("\n") == 50


def test_resume_skips_done_drives_and_compare_finds_moved_warning(world, tmp_path):
    # everything done: nothing runs (no cluster is even started), every row is marked resumed
    again = tmp_path / "again"
    shutil.copytree(world["one"], again)
    stamp = {n: (again / "drives" / n / "run.json").read_bytes() for n in world["names"]}
    rep = run_fleet(str(world["manifest"]), str(again), workers=1, progress=False)
    assert rep["totals"]["resumed"] == len(world["names"]) and rep["totals"]["failed"] == 0
    assert {n: (again / "drives" / n / "run.json").read_bytes() for n in world["names"]} == stamp
    # an interrupted run: one drive missing, a partial folder left behind; a later warning threshold on
    # the stopped-car drive changes its key: those two run, the other is skipped
    shutil.rmtree(again / "drives" / "follow")
    (again / "drives" / (partial_prefix("follow") + "host-1")).mkdir()
    entries = yaml.safe_load(world["manifest"].read_text())["drives"]
    entries[0]["config"] = {"fcw": {"ttc_warning_s": 1.8}}
    later = _manifest(world["root"], entries, "later.yaml")
    rep = run_fleet(str(later), str(again), workers=1, progress=False)
    resumed = {r["name"] for r in rep["drives"] if r.get("resumed")}
    assert resumed == set(world["names"]) - {"stop", "follow"}
    assert not list((again / "drives").glob(".*"))
    assert _files(again, "follow") == _files(world["one"], "follow")
    # the comparison: the stopped car's warning moved later (lower TTC), the CAN logs differ; the rest identical
    c = compare.compare(str(world["one"]), str(again))
    d = c["drives"]["stop"]
    (old,), (new,) = [e for e in d["fcw_disappeared"] if e[0] == "warning"], \
        [e for e in d["fcw_appeared"] if e[0] == "warning"]
    assert new[1] > old[1] and new[2] < old[2]
    assert "can" in d and set(c["identical"]) == set(world["names"]) - {"stop"}
    assert "FCW appeared: warning at t=" in compare.markdown(c)
    assert cli_main(["fleet", "--compare", str(world["one"]), str(again)]) == 0


def test_failed_drives_reported_and_the_rest_complete(world, tmp_path, capsys):
    (tmp_path / "corrupt.mp4").write_bytes(os.urandom(4000))
    (tmp_path / "bad.blf").write_bytes(os.urandom(3000))
    shutil.copy(world["root"] / "follow.yaml", tmp_path / "follow.yaml")
    manifest = _manifest(tmp_path, [{"source": "corrupt.mp4"}, {"source": "follow.yaml"},
                                    {"source": "follow.yaml", "name": "follow_bad_can", "can_in": "bad.blf"}])
    out = tmp_path / "out"
    assert cli_main(["fleet", str(manifest), "--out", str(out), "--workers", "1"]) == 1
    assert "2 of 3 drives failed" in capsys.readouterr().err
    rep = json.loads((out / "report.json").read_text())
    failed = {f["name"]: f["error"] for f in rep["failed"]}
    assert set(failed) == {"corrupt", "follow_bad_can"}
    assert "cannot be read as a video" in failed["corrupt"] and "bad.blf: cannot be read as a CAN log" in failed["follow_bad_can"]
    assert [r["name"] for r in rep["drives"]] == ["follow"]
    for f in ("tracks.jsonl", "can.log", "metrics.json"):   # the same scenario, from another folder
        assert (out / "drives" / "follow" / f).read_bytes() == (world["one"] / "drives" / "follow" / f).read_bytes()
    md = (out / "report.md").read_text()
    assert "## Failed drives" in md and "**corrupt**" in md
    assert not (out / "drives" / "corrupt").exists()


def test_killed_worker_drive_is_rerun(world, tmp_path):
    out = tmp_path / "out"
    killed: list[int] = []

    def killer():
        deadline = time.monotonic() + 120
        while not killed and time.monotonic() < deadline:
            for p in (out / "drives").glob(partial_prefix("stop") + "*") if (out / "drives").exists() else []:
                pid = int(p.name.rsplit("-", 1)[1])
                os.kill(pid, signal.SIGKILL)
                killed.append(pid)
                break
            time.sleep(0.01)

    t = threading.Thread(target=killer, daemon=True)
    t.start()
    rep = run_fleet(str(world["manifest"]), str(out), workers=2, progress=False)
    t.join()
    assert killed, "the stopped-car drive was never seen running"
    assert rep["failed"] == [] and {r["name"] for r in rep["drives"]} == set(world["names"])
    stop = next(r for r in rep["drives"] if r["name"] == "stop")
    assert int(stop["worker"].rsplit(":", 1)[1]) != killed[0]
    assert not list((out / "drives").glob(".*"))
    for name in world["names"]:
        assert _files(out, name) == _files(world["one"], name), name


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_separate_scheduler_and_worker_processes(world, tmp_path):
    port = _free_port()
    dask = str(Path(sys.executable).parent / "dask")
    env = {**os.environ, "OPENCV_LOG_LEVEL": "ERROR"}
    procs = []
    try:
        procs.append(subprocess.Popen([dask, "scheduler", "--host", "127.0.0.1", "--port", str(port),
                                       "--no-dashboard"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env))
        procs.append(subprocess.Popen([dask, "worker", f"tcp://127.0.0.1:{port}", "--host", "127.0.0.1",
                                       "--nthreads", "1", "--nworkers", "1", "--no-dashboard"],
                                      stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env))
        out = tmp_path / "out"
        assert cli_main(["fleet", str(world["manifest"]), "--out", str(out),
                         "--scheduler", f"tcp://127.0.0.1:{port}"]) == 0
        rep = json.loads((out / "report.json").read_text())
        assert rep["meta"]["where"] == f"the cluster at tcp://127.0.0.1:{port}"
        for name in world["names"]:
            assert _files(out, name) == _files(world["one"], name), name
    finally:
        for p in reversed(procs):
            p.terminate()
        for p in procs:
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()


def test_unreachable_scheduler_is_a_clear_error(world, tmp_path, capsys):
    port = _free_port()
    assert cli_main(["fleet", str(world["manifest"]), "--out", str(tmp_path / "o"),
                     "--scheduler", f"tcp://127.0.0.1:{port}"]) == 1
    assert "cannot reach the Dask scheduler" in capsys.readouterr().err


@pytest.mark.parametrize("entries, message", [
    ([{"source": "stop.yaml", "fsp": 20}], "drives[0]: unknown key(s) fsp"),
    ([{"source": "nowhere.mp4"}], "drives[0]: source:"),
    ([{"source": "stop.yaml"}, {"source": "stop.yaml"}], "two drives are named 'stop'"),
    ([{"source": "stop.yaml", "config": {"fcw": {"ttc_warning_s": "soon"}}}], "fcw.ttc_warning_s"),
    ([{"suite": ["no_such_scenario"]}], "no scenario 'no_such_scenario'"),
    ([{"source": "stop.yaml", "truth": "x.jsonl"}], "a scenario's truth is its own"),
])
def test_manifest_errors_name_the_entry(world, entries, message, capsys):
    m = _manifest(world["root"], entries, "bad.yaml")
    with pytest.raises(ManifestError, match=None) as err:
        load_manifest(str(m))
    assert message in str(err.value)
    assert cli_main(["fleet", str(m), "--out", str(world["root"] / "bad-out")]) == 1
    assert message in capsys.readouterr().err


def test_manifest_suite_and_folder(world, tmp_path):
    rec = tmp_path / "recordings"
    (rec / "clip_b").mkdir(parents=True)
    from tests.conftest import write_video

    write_video(rec / "clip_a.mp4", n=5)
    import cv2
    import numpy as np

    cv2.imwrite(str(rec / "clip_b" / "0.png"), np.zeros((48, 64), np.uint8))
    m = _manifest(tmp_path, [{"suite": ["cut_in", "empty_road"]}, {"folder": "recordings", "fps": 10}])
    drives = load_manifest(str(m))
    assert [(d.name, d.kind, d.truth, d.fps) for d in drives] == [
        ("cut_in", "scenario", "scenario", None), ("empty_road", "scenario", "scenario", None),
        ("clip_a", "recording", None, 10.0), ("clip_b", "recording", None, 10.0)]


def test_eval_synthetic_through_the_engine_matches_one_process(world, tmp_path):
    from app.eval import synthetic
    from app.eval.report import evaluate

    scen = [str(world["root"] / "follow.yaml")]
    alone = synthetic.evaluate_suite("thesis", scen)
    rep = evaluate("thesis", str(tmp_path / "eval"), parts=("synthetic",), scenarios=scen, workers=1)
    assert rep["synthetic"]["per_scenario"] == alone["per_scenario"]
    assert rep["synthetic"]["overall"] == alone["overall"]
    assert rep["synthetic"]["per_scenario"][scen[0]]["tp"] > 0


def test_local_cluster_is_pinned_single_threaded_and_local():
    from app.fleet.engine import cluster

    if len(os.sched_getaffinity(0)) < 2:
        pytest.skip("needs two cores to pin two workers to different ones")
    with cluster(None, 2) as client:
        assert client.scheduler.address.startswith("tcp://127.0.0.1:")
        assert all(a.startswith("tcp://127.0.0.1:") for a in client.nthreads())
        assert sorted(client.nthreads().values()) == [1, 1]
        cores = client.run(lambda: sorted(os.sched_getaffinity(0)))
        assert sorted(len(c) for c in cores.values()) == [1, 1]
        assert len({c[0] for c in cores.values()}) == 2
