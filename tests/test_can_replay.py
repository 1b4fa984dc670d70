"""CAN replay: an input log on the frame clock in, every frame Headway sends out to a log. Same
input, same output, byte for byte; output already written survives a failure; FCW goes out on every
change; bad logs are counted, never a crash. Over vcan0 where SocketCAN exists."""
from __future__ import annotations

import math
import socket
import subprocess
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import can
import cantools
import pytest

from app.can import CanLogError, CanLogReader, CanOutput, CanParser, CanSession, headway_database
from app.bench.can_output import fake_result
from app.can.config_schema import defaults
from tests.conftest import REPO

EGO_DBC = REPO / "app" / "sim" / "ego_speed_placeholder.dbc"  # the scenarios' ego-speed message
FPS = 30.0
T0 = 1600000000.0


def config(**can_keys) -> dict:
    cfg = defaults()
    cfg["vehicle"].update(dbc=str(EGO_DBC), speed_message="EGO_SPEED", speed_signals="SPEED_MPS")
    cfg["can"].update(can_keys)
    cfg["camera"] = {"fx": 700.0, "cx": 320.0}
    return cfg


def ego_messages(duration_s=6.0, stop_at_s=None):
    db = cantools.database.load_file(str(EGO_DBC))
    m = db.get_message_by_name("EGO_SPEED")
    out = []
    for k in range(int(duration_s * 50)):
        t = k / 50
        if stop_at_s is not None and t >= stop_at_s:
            break
        out.append(can.Message(timestamp=T0 + t, arbitration_id=m.frame_id, is_extended_id=False, channel="can0",
                               data=m.encode({"SPEED_MPS": 20.0 + 0.5 * t, "COUNTER": k % 16})))
    return out


def write_log(path: Path, messages) -> Path:
    writer = {".log": lambda: can.CanutilsLogWriter(str(path)), ".asc": lambda: can.ASCWriter(str(path)),
              ".blf": lambda: can.BLFWriter(str(path))}[path.suffix]()
    for msg in messages:
        writer.on_message_received(msg)
    writer.stop()
    return path


def fcw_level_at(k: int) -> int:
    """A drive whose warning rises and falls: 0, then 1 from 2.0 s, 2 from 2.5 s, 0 again from 3.5 s."""
    t = k / FPS
    return 2 if 2.5 <= t < 3.5 else 1 if 2.0 <= t < 3.5 else 0


def run(cfg, can_in, can_out, seconds=5.0, fail_at_s=None, via_bus=False) -> CanSession:
    with CanSession.for_replay(cfg, can_in, can_out, via_bus=via_bus) as s:
        for k in range(int(seconds * FPS)):
            t = k / FPS
            if fail_at_s is not None and t >= fail_at_s:
                raise RuntimeError("the core failed")
            state = s.vehicle_state(t)
            s.publish(t, fake_result(k, 5),
                      fcw={"level": fcw_level_at(k), "available": state.speed_mps is not None,
                           "ttc_s": 1.9, "ttc_source": "range"})
    return s


def decode(path):
    """[(replay t, message name, values)] of a Headway output log, asserting it is clean; t to 10 us
    (epoch seconds in a double carry about 0.2 us of noise)."""
    parser = CanParser(headway_database())
    out = [(round(t, 5), *parser.update(msg)) for t, msg in CanLogReader(path)]
    assert parser.accepted == len(out) and not parser.drops, parser.stats()
    return out


@pytest.fixture
def ego_log(tmp_path):
    return write_log(tmp_path / "ego.log", ego_messages())


@pytest.mark.parametrize("suffix", [".log", ".asc", ".blf"])
def test_two_replays_write_identical_output_logs(tmp_path, ego_log, suffix):
    a, b = tmp_path / f"a{suffix}", tmp_path / f"b{suffix}"
    run(config(), ego_log, a)
    run(config(), ego_log, b)
    assert a.read_bytes() == b.read_bytes() and a.stat().st_size > 1000


def test_every_sent_frame_is_in_the_output_log_with_the_input_clock(tmp_path, ego_log):
    s = run(config(), ego_log, tmp_path / "out.log")
    frames = decode(tmp_path / "out.log")
    assert len(frames) == s.output.sent == s.output.logged
    first = next(iter(CanLogReader(tmp_path / "out.log")))[1]
    assert first.timestamp == pytest.approx(T0)  # frame 0 at the input log's first timestamp
    header = [v for _t, name, v in frames if name == "HW_OBJECT_HEADER"]
    objects = [v for _t, name, v in frames if name == "HW_OBJECT"]
    assert all(h["OBJECT_COUNT"] == 5 for h in header) and len(objects) == 10 * len(header)
    assert [o["RANGE_M"] for o in objects[:10:2]] == pytest.approx([10.0, 17.5, 25.0, 32.5, 40.0])


def test_fcw_goes_out_at_once_on_every_change_and_periodically(tmp_path, ego_log):
    run(config(fcw_rate_hz=2.0), ego_log, tmp_path / "out.log")
    fcw = [(t, v["FCW_LEVEL"], v["FCW_AVAILABLE"]) for t, name, v in decode(tmp_path / "out.log") if name == "HW_FCW"]
    frame_of = {round(t * FPS) for t, _l, _a in fcw}
    for k in range(1, int(5 * FPS)):  # every change of level is sent at the frame where it happens
        if fcw_level_at(k) != fcw_level_at(k - 1):
            assert k in frame_of, f"level change at frame {k} not sent at once"
    # periodic: at most 0.5 s between HW_FCW frames
    times = [t for t, _l, _a in fcw]
    assert max(b - a for a, b in zip(times, times[1:])) <= 0.5 + 1e-6
    assert [lvl for _t, lvl, _a in fcw if 2.55 < _t < 3.45] and \
        all(lvl == 2 for t, lvl, _a in fcw if 2.5 <= t < 3.5)
    assert all(a == 1 for t, _l, a in fcw if t > 0.1)


def test_rates_are_configurable_per_group(tmp_path, ego_log):
    run(config(fcw_rate_hz=5.0, lead_rate_hz=4.0, objects_rate_hz=2.0, status_rate_hz=1.0, max_objects=3),
        ego_log, tmp_path / "out.log", seconds=10.0)
    frames = decode(tmp_path / "out.log")
    names = [name for _t, name, _v in frames]
    assert names.count("HW_LEAD") == names.count("HW_LEAD_TTC") == 40
    assert names.count("HW_OBJECT_HEADER") == 20 and names.count("HW_OBJECT") == 20 * 3 * 2
    assert names.count("HW_STATUS") == 10
    # 5 Hz; a change of level goes out at once and restarts the period, so the count depends on where
    # the three changes fall: 50 to 53 frames, and never more than 0.2 s apart
    fcw_times = [t for t, name, _v in frames if name == "HW_FCW"]
    assert 50 <= len(fcw_times) <= 53
    assert max(b - a for a, b in zip(fcw_times, fcw_times[1:])) <= 0.2 + 1e-6


def test_old_results_are_never_sent_as_current(tmp_path, ego_log):
    with CanSession.for_replay(config(), ego_log, tmp_path / "out.log") as s:
        for k in range(int(3 * FPS)):
            t = k / FPS
            s.vehicle_state(t)
            s.publish(t, fake_result(k, 4) if t < 1.0 else None, fcw={"level": 1, "available": True})
    frames = decode(tmp_path / "out.log")
    late = [(name, v) for t, name, v in frames if t > 1.0 - 1 / FPS + 0.5 + 1e-6]  # data_timeout_s = 0.5
    assert late
    for name, v in late:
        if name == "HW_FCW":
            assert v["FCW_AVAILABLE"] == 0 and v["FCW_LEVEL"] == 0 and v["TTC_USED_S"] is None
        elif name in ("HW_LEAD", "HW_LEAD_TTC"):
            assert v["LEAD_ID"] == 0
        elif name == "HW_OBJECT_HEADER":
            assert v["OBJECT_COUNT"] == 0
        else:
            assert name == "HW_STATUS"


def test_a_speed_that_stops_suppresses_fcw_and_sets_the_fault_bit(tmp_path):
    cut = write_log(tmp_path / "ego.log", ego_messages(stop_at_s=2.0))
    run(config(), cut, tmp_path / "out.log")
    frames = decode(tmp_path / "out.log")
    stale_after = defaults()["vehicle"]["speed_stale_after_s"]
    for t, name, v in frames:
        late = t - 1.98 > stale_after + 1e-5  # the last frame came at 1.98 s; a frame later it is stale
        if name == "HW_STATUS" and t > 0.5:
            assert v["FAULT_EGO_SPEED_STALE"] == int(late) and v["STATE"] == (2 if late else 1), t
        if name == "HW_FCW" and late:
            assert v["FCW_AVAILABLE"] == 0 and v["FCW_LEVEL"] == 0  # the 2.5 s warning is suppressed


@pytest.mark.parametrize("suffix", [".log", ".asc"])
def test_output_already_written_is_kept_when_the_run_fails(tmp_path, ego_log, suffix):
    out = tmp_path / f"out{suffix}"
    with pytest.raises(RuntimeError, match="the core failed"):
        run(config(), ego_log, out, fail_at_s=2.0)
    run(config(), ego_log, tmp_path / f"full{suffix}")
    before_failure = [f for f in decode(tmp_path / f"full{suffix}") if f[0] < 2.0 - 1e-5]
    assert decode(out) == before_failure and len(before_failure) >= 300


def test_output_log_is_on_disk_even_after_a_hard_kill(tmp_path):
    out = tmp_path / "killed.log"
    code = f"""
import os, can
from app.can import CanOutput, CanPacker, headway_database
packer = CanPacker(headway_database())
output = CanOutput(None, {str(out)!r})
for k in range(50):
    output.send([packer.pack("HW_STATUS", {{"STATE": 1}}, timestamp=k * 0.1)])
os._exit(3)  # no close, no flush at exit: what send() flushed must be there
"""
    r = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True)
    assert r.returncode == 3, r.stderr
    assert len(decode(out)) == 50


@pytest.mark.parametrize("suffix", [".asc", ".blf"])
def test_input_logs_in_other_formats_give_the_same_replay(tmp_path, ego_log, suffix):
    other = write_log(tmp_path / f"ego{suffix}", ego_messages())
    run(config(), ego_log, tmp_path / "a.log")
    run(config(), other, tmp_path / "b.log")
    # the same frames at the same replay times (an .asc log's timestamps count from its start)
    assert decode(tmp_path / "a.log") == decode(tmp_path / "b.log")


def test_bad_input_logs_give_clear_errors_or_counts(tmp_path, ego_log):
    with pytest.raises(CanLogError, match="no such CAN log"):
        CanLogReader(tmp_path / "absent.log")
    (tmp_path / "x.xyz").write_text("hello")
    with pytest.raises(CanLogError, match="cannot be read as a CAN log"):
        CanLogReader(tmp_path / "x.xyz")
    blf = write_log(tmp_path / "ego.blf", ego_messages())
    cut = tmp_path / "cut.blf"
    cut.write_bytes(blf.read_bytes()[: blf.stat().st_size // 2] + b"\x00garbage")
    reader = CanLogReader(cut)
    got = list(reader)
    assert len(got) < 300 and (reader.read_error is not None or len(got) >= 0)
    text = tmp_path / "mixed.log"
    good = ego_log.read_text().splitlines()
    text.write_text("\n".join(["junk line", *good[:100], "(1.0) can0 3E9#0", "(2.0) can0 3E9#001122334455667788",
                               "(3) vcan0 12345#00", *good[100:]]) + "\n")
    reader = CanLogReader(text)
    assert sum(1 for _ in reader) == len(good) and reader.bad_lines == 4
    assert "4 malformed lines skipped, first at line 1: 'junk line'" in reader.summary()


def test_bad_frames_of_headway_messages_in_a_log_are_counted_drops(tmp_path, ego_log):
    run(config(), ego_log, tmp_path / "out.log", seconds=1.0)
    lines = (tmp_path / "out.log").read_text().splitlines()
    n = len(lines)
    ts, ch, frame, d = lines[0].split()
    fid, data = frame.split("#")
    bad = [f"{ts} {ch} {fid}#{data[:-2]} {d}",                                   # wrong length
           f"{ts} {ch} {fid}#{data[:-2]}{(int(data[-2:], 16) ^ 0x01):02X} {d}",   # wrong checksum
           f"{ts} {ch} 7A0#{data} {d}",                                           # unknown id
           "not a frame at all"]                                                  # garbage
    tampered = tmp_path / "tampered.log"
    tampered.write_text("\n".join(lines[:5] + bad + lines[5:]) + "\n")
    parser = CanParser(headway_database())
    reader = CanLogReader(tampered)
    for _t, msg in reader:
        parser.update(msg)
    assert reader.bad_lines == 1
    assert parser.drops == {"wrong_length": 1, "bad_checksum": 1, "unknown_id": 1}
    assert parser.accepted == n


def test_out_of_order_frames_come_out_in_time_order(tmp_path):
    msgs = ego_messages(duration_s=1.0)
    msgs[10], msgs[11] = msgs[11], msgs[10]
    reader = CanLogReader(write_log(tmp_path / "swapped.log", msgs))
    times = [t for t, _m in reader]
    assert times == sorted(times) and len(times) == 50 and reader.out_of_order == 0


def test_messages_until_feeds_the_frame_clock(ego_log):
    reader = CanLogReader(ego_log, offset_s=1.0)  # the log starts 1 s into the video
    assert [round(t, 3) for t, _m in reader.messages_until(1.05)] == [1.0, 1.02, 1.04]
    assert list(reader.messages_until(1.05)) == []
    assert round(next(iter(reader.messages_until(9.0)))[0], 3) == 1.06


def test_replay_through_a_virtual_bus_gives_the_same_frames(tmp_path, ego_log):
    cfg = config(interface="virtual", channel="replay-test")
    run(cfg, ego_log, tmp_path / "file.log")
    run(cfg, ego_log, tmp_path / "bus.log", via_bus=True)
    assert (tmp_path / "bus.log").read_bytes() == (tmp_path / "file.log").read_bytes()


def vcan0_available() -> bool:
    try:
        s = socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW)
        try:
            s.bind(("vcan0",))
        finally:
            s.close()
        return True
    except (OSError, AttributeError):
        return False


@pytest.mark.skipif(not vcan0_available(), reason="SocketCAN vcan0 not available on this machine")
def test_replay_over_vcan0_gives_the_same_frames(tmp_path, ego_log):
    run(config(channel="vcan0"), ego_log, tmp_path / "file.log")  # file only, frames named vcan0 as below
    with can.Bus(interface="socketcan", channel="vcan0") as listener:
        run(config(interface="socketcan", channel="vcan0"), ego_log, tmp_path / "vcan.log", via_bus=True)
        seen = []
        while (msg := listener.recv(timeout=0.2)) is not None:
            seen.append(msg)
    assert (tmp_path / "vcan.log").read_bytes() == (tmp_path / "file.log").read_bytes()
    own = {m.frame_id for m in headway_database().messages}
    assert sum(m.arbitration_id in own for m in seen) == len(decode(tmp_path / "file.log"))
    played = [m for m in ego_messages() if m.timestamp - T0 <= (5 * FPS - 1) / FPS + 1e-6]  # up to the last frame
    assert sum(m.arbitration_id == 1001 for m in seen) == len(played)


@pytest.mark.skipif(not vcan0_available(), reason="SocketCAN vcan0 not available on this machine")
def test_live_session_on_vcan0_sends_every_group(tmp_path):
    cfg = config(interface="socketcan", channel="vcan0")
    with can.Bus(interface="socketcan", channel="vcan0") as listener, CanSession.for_live(cfg) as s:
        sent = s.publish(time.time())
        got = [listener.recv(timeout=1.0) for _ in sent]
    assert [m.arbitration_id for m in got if m is not None] == [0x600, 0x601, 0x602, 0x603, 0x605]


def test_send_failures_are_counted_reported_and_not_logged(tmp_path):
    class BrokenBus(can.BusABC):
        def __init__(self):
            super().__init__(channel="broken")

        def send(self, msg, timeout=None):
            raise can.CanOperationError("Transmit buffer full")

        def _recv_internal(self, timeout):
            return None, False

    out = CanOutput(BrokenBus(), tmp_path / "out.log")
    s = CanSession(config(), out, deterministic=True)
    assert len(s.publish(0.0)) == 5 and out.send_errors == 5 and out.sent == 0  # fallbacks + status
    assert "Transmit buffer full" in out.last_error
    assert s.faults(0.5) == {"can_error"} and s.faults(1.01) == set()
    assert s.health_inputs(0.5) == {"can_ok": False, "ego_speed_fresh": None}
    s.close()
    assert (tmp_path / "out.log").read_text() == ""


def test_on_result_takes_the_fcw_state_machine_output(tmp_path, ego_log):
    """The replay hook: results on their own clock, FCW as app.fcw.FcwOutput gives it."""
    with CanSession.for_replay(config(), ego_log, tmp_path / "out.log") as s:
        for k in range(int(1 * FPS)):
            r = fake_result(k, 3)
            decision = SimpleNamespace(level=2 if k >= 15 else 0, ttc_used_s=1.5, ttc_source="scale", changed=k == 15)
            state = s.on_result(r, "scenario frame", fcw=decision)
            newest_can_t = math.floor(k / FPS * 50 + 1e-9) / 50  # the 50 Hz frame the speed comes from
            assert state.speed_mps == pytest.approx(20.0 + 0.5 * newest_can_t, abs=0.006)
    fcw = [(t, v) for t, name, v in decode(tmp_path / "out.log") if name == "HW_FCW"]
    assert fcw[-1][1]["FCW_LEVEL"] == 2 and fcw[-1][1]["TTC_SOURCE"] == 2 and fcw[-1][1]["TTC_USED_S"] == 1.5
    assert fcw[-1][1]["FCW_AVAILABLE"] == 1 and 0.5 in [t for t, _v in fcw]  # the change at frame 15 at once
