"""The service's CAN record survives restarts: a run killed with SIGKILL keeps its log (rotated, never
overwritten, whole lines), the next run writes its own; SIGHUP takes the stop path; a source path that
is a regular file is refused before anything starts."""
from __future__ import annotations

import json
import signal
import subprocess
import sys
import time

import can
import pytest

from app.can import CanOutput, CanPacker, headway_database
from app.can.bus import rotate_log
from tests.conftest import REPO
from tests.test_service import FrameWriter, frames, service  # noqa: F401  (service is a fixture)


def whole_candump(path) -> int:
    """Lines of a candump log, asserting every one is a whole frame that python-can parses."""
    lines = path.read_text().splitlines()
    for line in lines:
        assert line.startswith("(") and "#" in line and len(line.split()) in (3, 4), line
    assert sum(1 for _ in can.LogReader(str(path))) == len(lines)
    return len(lines)


def wait_for_lines(path, n: int = 20, timeout_s: float = 60.0) -> None:
    """Until the running service has written n lines to its CAN log (start-up is slow on a loaded machine)."""
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if path.exists() and path.read_text().count("\n") >= n:
            return
        time.sleep(0.1)
    raise AssertionError(f"{path}: fewer than {n} lines after {timeout_s} s")


def test_sigkill_then_restart_keeps_both_runs_can_records(service, tmp_path):
    images = frames()
    p, _ = service()
    writer = FrameWriter(tmp_path / "frames.fifo", images)
    writer.thread.start()
    wait_for_lines(tmp_path / "out.log")
    p.kill()  # SIGKILL: no stop path, no flush at exit
    p.wait(timeout=5)
    writer.stop.set()
    first_run = whole_candump(tmp_path / "out.log")
    assert first_run > 10
    (tmp_path / "notify.sock").unlink()  # the fixture binds it again
    p, _ = service()
    writer = FrameWriter(tmp_path / "frames.fifo", images)
    writer.thread.start()
    end = time.monotonic() + 60
    while not (tmp_path / "out.1.log").exists() and time.monotonic() < end:  # rotated at start
        time.sleep(0.1)
    wait_for_lines(tmp_path / "out.log")
    p.send_signal(signal.SIGTERM)
    assert p.wait(timeout=5) == 0
    writer.stop.set()
    assert whole_candump(tmp_path / "out.1.log") == first_run  # the killed run's record, intact
    assert whole_candump(tmp_path / "out.log") > 10            # and this run's own
    _, err = p.communicate()
    assert "previous run's is kept as" in err and "out.1.log" in err


def test_rotation_keeps_the_configured_count_and_trims_a_cut_last_line(tmp_path):
    packer = CanPacker(headway_database())
    out = tmp_path / "out.log"
    for run in range(4):
        with CanOutput(None, out, keep=2) as o:
            o.send([packer.pack("HW_STATUS", {"STATE": 1}, timestamp=run + k * 0.1) for k in range(run + 1)])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.1.log", "out.2.log", "out.log"]
    assert [whole_candump(tmp_path / n) for n in ("out.log", "out.1.log", "out.2.log")] == [4, 3, 2]
    with out.open("a") as f:
        f.write("(1600000000.100000) can0 601#0")  # a power cut in the middle of a line
    assert rotate_log(out, 2) == tmp_path / "out.1.log"
    assert whole_candump(tmp_path / "out.1.log") == 4 and not out.exists()


def test_sighup_takes_the_stop_path_and_asks_systemd_for_a_restart(service, tmp_path):
    from app.supervisor.service import RESTART_EXIT

    p, _ = service()
    writer = FrameWriter(tmp_path / "frames.fifo", frames())
    writer.thread.start()
    wait_for_lines(tmp_path / "out.log")
    p.send_signal(signal.SIGHUP)
    assert p.wait(timeout=5) == RESTART_EXIT != 0  # Restart=on-failure starts it again, config read anew
    writer.stop.set()
    _, err = p.communicate()
    assert "stopping" in err and "configuration read anew" in err and "Traceback" not in err
    # the vehicle-bus input account is in the status (nothing on this virtual bus but Headway's own frames)
    status = json.loads((tmp_path / "status.json").read_text())
    assert status["can_input"] == {"read": 0, "used": 0, "dropped": {}}
    assert whole_candump(tmp_path / "out.log") > 10


def test_source_path_that_is_a_regular_file_is_refused(tmp_path):
    raw = tmp_path / "frames.raw"
    raw.write_bytes(bytes(640 * 480) * 3)
    cfg = tmp_path / "c.yaml"
    cfg.write_text(f"source: {{kind: fifo, path: {raw}}}\nservice: {{status_file: {tmp_path / 'status.json'}}}\n"
                   f"can: {{interface: virtual, output_log: {tmp_path / 'out.log'}}}\n")
    r = subprocess.run([sys.executable, "-m", "app.cli", "service", "--config", str(cfg)], cwd=REPO,
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "is not a FIFO" in r.stderr and "Traceback" not in r.stderr
    assert not (tmp_path / "status.json").exists() and not (tmp_path / "out.log").exists()


@pytest.mark.parametrize("suffix", [".asc"])
def test_text_logs_other_than_candump_rotate_too(tmp_path, suffix):
    packer = CanPacker(headway_database())
    out = tmp_path / f"out{suffix}"
    for run in range(2):
        with CanOutput(None, out, keep=3) as o:
            o.send([packer.pack("HW_STATUS", {"STATE": 1}, timestamp=1.0 + run)])
    assert len(list(can.LogReader(str(tmp_path / f"out.1{suffix}")))) == 1
