"""`headway status` never reads "ok" for a service that is not running: a clean stop reads "stopped", a
killed service, a stale, future or non-finite time stamp and any malformed field read "unknown" (exit 3),
and no status file, however broken, gives a traceback."""
from __future__ import annotations

import json
import math
import random
import signal
import time

import pytest

from app import cli
from app.supervisor.status_file import write_status
from tests.test_service import FrameWriter, frames, service  # noqa: F401  (the fixture)


def status(capsys, path) -> tuple[int, str]:
    rc = cli.main(["status", "--file", str(path)])
    out = capsys.readouterr()
    return rc, out.out + out.err


def good_status(path) -> dict:
    write_status(str(path), {"state": "ok", "faults": [], "bits": 0, "fps": 20.0, "latency_median_ms": 3.0,
                             "latency_p99_ms": 9.0, "frames": 100, "queue_drops": 0, "camera": "ok",
                             "source_state": "running", "frames_captured": 100, "fcw": None,
                             "can_input": {"read": 10, "used": 10, "dropped": {}},
                             "calibration": {"pitch_deg": 1.0, "yaw_deg": 0.0, "height_m": 1.3, "active": False}})
    return json.loads(path.read_text())


def test_a_fresh_status_of_a_running_writer_is_its_state(tmp_path, capsys):
    good_status(tmp_path / "s.json")
    rc, out = status(capsys, tmp_path / "s.json")
    assert rc == 0 and "state: ok" in out


@pytest.mark.parametrize("change, why", [
    ({"written_unix_s": time.time() + 3600}, "in the future"),
    ({"written_unix_s": time.time() - 60}, "s old"),
    ({"pid": 2 ** 22 + 12345}, "is gone without stopping"),
    ({"boot_id": "another-boot"}, "before this host last booted"),
])
def test_future_stale_dead_or_other_boot_status_is_unknown_exit_3(tmp_path, capsys, change, why):
    st = good_status(tmp_path / "s.json")
    (tmp_path / "s.json").write_text(json.dumps({**st, **change}))
    rc, out = status(capsys, tmp_path / "s.json")
    assert rc == 3 and "state: unknown" in out and why in out and "state: ok" not in out


@pytest.mark.parametrize("stamp", ["NaN", "Infinity", "-Infinity", '"12:00"', "null", "true", "1e400"])
def test_a_non_finite_or_non_numeric_time_stamp_is_unknown_exit_3(tmp_path, capsys, stamp):
    st = good_status(tmp_path / "s.json")
    text = json.dumps({**st, "written_unix_s": 0}).replace('"written_unix_s": 0', f'"written_unix_s": {stamp}')
    (tmp_path / "s.json").write_text(text)
    rc, out = status(capsys, tmp_path / "s.json")
    assert rc == 3 and "state: unknown" in out and "written_unix_s" in out


@pytest.mark.parametrize("field, value", [
    ("calibration", {"active": False}), ("calibration", {"pitch_deg": "x", "yaw_deg": 0, "height_m": 1}),
    ("calibration", {"active": True, "pitch_deg": 1, "yaw_deg": 0, "height_m": 1}), ("calibration", [1, 2]),
    ("state", "fine"), ("state", 1), ("faults", "camera_lost"), ("faults", [1]), ("fps", -1), ("fps", "20"),
    ("frames", 1.5), ("queue_drops", -3), ("pid", 0), ("pid", "123"), ("can_input", {"read": "x"}),
    ("boot_id", None), ("camera", 3)])
def test_every_malformed_field_is_unknown_exit_3_named_without_a_traceback(tmp_path, capsys, field, value):
    st = good_status(tmp_path / "s.json")
    (tmp_path / "s.json").write_text(json.dumps({**st, field: value}))
    rc, out = status(capsys, tmp_path / "s.json")
    assert rc == 3 and "state: unknown" in out and field in out and "Traceback" not in out


def _mutate(rng: random.Random, value):
    pool = [None, True, -1, 0, 2 ** 70, 1.5, math.nan, math.inf, "", "x" * 500, [], {}, [1, "a"], {"a": {"b": None}}]
    r = rng.random()
    if isinstance(value, dict) and r < 0.5 and value:
        key = rng.choice(list(value))
        if rng.random() < 0.2:
            return {k: v for k, v in value.items() if k != key}
        return {**value, key: _mutate(rng, value[key])}
    return rng.choice(pool)


def test_1000_fuzzed_status_files_give_no_traceback_and_never_ok_unless_valid(tmp_path, capsys):
    rng = random.Random(40)
    base = good_status(tmp_path / "base.json")
    path = tmp_path / "s.json"
    codes = {0: 0, 1: 0, 3: 0}
    for i in range(1000):
        st = base
        for _ in range(rng.randint(1, 3)):
            st = _mutate(rng, st)
        text = json.dumps(st)
        if rng.random() < 0.2:  # bytes cut or flipped
            cut = rng.randrange(len(text) + 1)
            text = text[:cut] + rng.choice(["", "\x00", "\ufffd", "}", "NaN"]) + text[cut + 1:]
        path.write_text(text)
        rc, out = status(capsys, path)
        assert rc in (0, 3) and "Traceback" not in out, (i, text[:200])
        codes[rc] += 1
        if rc == 0:  # only a status whose every field is valid and whose writer (this process) is alive
            assert isinstance(st, dict) and st.get("state") in ("ok", "starting", "degraded", "fault")
    assert codes[3] > 800, codes


def test_clean_stop_reads_stopped_and_kill_9_reads_unknown(service, tmp_path, capsys):  # noqa: F811
    path = tmp_path / "status.json"
    for how in ("SIGTERM", "SIGKILL"):
        p, _notify = service()
        writer = FrameWriter(tmp_path / "frames.fifo", frames(10))
        writer.thread.start()
        end = time.monotonic() + 30
        while time.monotonic() < end and not (path.exists() and '"frames": 0' not in path.read_text()):
            time.sleep(0.2)
        rc, out = status(capsys, path)
        assert rc == 0 and "state: unknown" not in out and "state: stopped" not in out, out
        p.send_signal(signal.SIGTERM if how == "SIGTERM" else signal.SIGKILL)
        p.wait(timeout=10)
        writer.stop.set()
        rc, out = status(capsys, path)   # at once, not after the 5 s staleness
        if how == "SIGTERM":
            assert rc == 3 and "state: stopped" in out, out
        else:
            assert rc == 3 and "state: unknown" in out and "gone without stopping" in out, out
        path.unlink()
        (tmp_path / "notify.sock").unlink()

