"""Damaged video frames that the decoder conceals, and JPEGs libjpeg warns about, are counted and named,
never played as if whole: the damage is made by each test itself."""
from __future__ import annotations

import random
import struct

import cv2
import numpy as np
import pytest

from app.recording import open_recording
from app.replay import replay
from tests.conftest import data_path


def noise(i: int, shape=(240, 320)) -> np.ndarray:
    return (np.random.default_rng(i).random(shape) * 255).astype(np.uint8)


def damage(data: bytearray, starts: list[int], rng: random.Random, span: int, n: int, width: int) -> bytearray:
    """``n`` regions of ``width`` random bytes, each within ``span`` bytes after one of ``starts``."""
    for k in range(n):
        at = rng.randrange(starts[k % len(starts)], starts[k % len(starts)] + span)
        data[at:at + width] = bytes(rng.randrange(256) for _ in range(width))
    return data


def test_an_mjpeg_video_with_damaged_frames_reports_them(tmp_path):
    w = cv2.VideoWriter(str(tmp_path / "clean.avi"), cv2.VideoWriter_fourcc(*"MJPG"), 20.0, (320, 240))
    for i in range(30):
        w.write(cv2.cvtColor(noise(i), cv2.COLOR_GRAY2BGR))
    w.release()
    data = bytearray((tmp_path / "clean.avi").read_bytes())
    scans = [i for i in range(len(data) - 1) if data[i] == 0xFF and data[i + 1] == 0xDA]  # each frame's JPEG scan
    assert len(scans) == 30
    (tmp_path / "bad.avi").write_bytes(damage(data, [scans[k] + 30 for k in (5, 9, 17, 21)], random.Random(40),
                                              2000, 12, 16))
    clean = open_recording(tmp_path / "clean.avi")
    assert sum(1 for _ in clean.frames()) == 30 and clean.account() == "30 of 30 frames decoded"
    bad = open_recording(tmp_path / "bad.avi")
    assert sum(1 for _ in bad.frames()) == 30
    assert 3 <= len(bad.damaged) <= 4 and set(bad.damaged) <= {5, 9, 17, 21}, bad.damaged
    assert sum(bad.decode_errors.values()) >= len(bad.damaged)
    assert f"30 of 30 frames decoded, {len(bad.damaged)} of them with decoder errors, concealed by FFmpeg" in bad.account()


def test_the_h264_clip_with_40_regions_overwritten_reports_its_damaged_frames(tmp_path):
    data = bytearray(data_path("udacity", "test_video.mp4").read_bytes())
    at = data.find(b"mdat")
    start, end = at + 4, at - 4 + struct.unpack(">I", data[at - 4:at])[0]
    (tmp_path / "damaged.mp4").write_bytes(damage(data, [start + 64], random.Random(40), end - start - 128, 40, 8))
    rec = open_recording(tmp_path / "damaged.mp4")
    assert sum(1 for _ in rec.frames()) == 38
    assert rec.damaged and rec.decode_errors["error while decoding MB, bytestream"] >= 1
    assert "38 of 38 frames decoded, " in rec.account() and "with decoder errors, concealed by FFmpeg" in rec.account()
    whole = open_recording(data_path("udacity", "test_video.mp4"))
    assert sum(1 for _ in whole.frames()) == 38 and not whole.damaged and whole.account() == "38 of 38 frames decoded"


def bit_flipped_jpeg(path, rng: random.Random) -> None:
    ok, buf = cv2.imencode(".jpg", noise(7))
    data = bytearray(buf.tobytes())
    sos = data.find(b"\xff\xda")
    for _ in range(5):
        at = rng.randrange(sos + 20, len(data) - 10)
        data[at] ^= 1 << rng.randrange(8)
    path.write_bytes(bytes(data))


def test_a_bit_flipped_jpeg_in_a_folder_is_skipped_by_name_and_counted(tmp_path, capfd):
    folder = tmp_path / "frames"
    folder.mkdir()
    for i in range(6):
        cv2.imwrite(str(folder / f"{i:03d}.jpg"), noise(i))
    bit_flipped_jpeg(folder / "003.jpg", random.Random(40))
    rec = open_recording(folder, fps=10)
    assert [i for i, _t, _g in rec.frames()] == [0, 1, 2, 4, 5]
    assert len(rec.skipped) == 1 and rec.skipped[0].startswith("003.jpg: corrupt JPEG data (libjpeg: Corrupt JPEG data")
    assert "Corrupt JPEG" not in capfd.readouterr().err   # counted, not printed past us
    s = replay(str(folder), fps=10, progress=False)
    assert s.frames == 5 and "1 skipped" in s.text() and "003.jpg: corrupt JPEG data" in s.text()


def damaged_mjpeg(tmp_path, frames: int = 60) -> tuple:
    """A clean and a damaged MJPEG video (frames 5, 9, 17, 21 damaged) of 320x240 noise."""
    w = cv2.VideoWriter(str(tmp_path / "clean.avi"), cv2.VideoWriter_fourcc(*"MJPG"), 20.0, (320, 240))
    for i in range(frames):
        w.write(cv2.cvtColor(noise(i), cv2.COLOR_GRAY2BGR))
    w.release()
    data = bytearray((tmp_path / "clean.avi").read_bytes())
    scans = [i for i in range(len(data) - 1) if data[i] == 0xFF and data[i + 1] == 0xDA]
    (tmp_path / "bad.avi").write_bytes(damage(data, [scans[k] + 30 for k in (5, 9, 17, 21)], random.Random(40),
                                              2000, 12, 16))
    return tmp_path / "clean.avi", tmp_path / "bad.avi"


def test_the_services_video_source_marks_concealed_frames_and_the_status_counts_them(tmp_path):
    from app.core import EndOfStream, Pipeline
    from app.supervisor.status_file import read_status
    from tests.test_config_service_fuzz import run_service

    clean, bad = damaged_mjpeg(tmp_path, frames=200)   # more than the service runs: it is stopped, not ended
    cam = {"width": 320, "height": 240, "fx": 300.0, "fy": 300.0, "cx": 160.0, "cy": 120.0}
    concealed = {}
    for name, path in (("clean", clean), ("bad", bad)):
        with Pipeline({"camera": cam, "pipeline": {"preset": "thesis"}}) as pipe:
            pipe.start({"kind": "video", "path": str(path)})
            frames = []
            try:
                while True:
                    r = pipe.pop(timeout_s=10)
                    if r is None:
                        break
                    frames.append(r)
            except EndOfStream:
                pass
        assert len(frames) == 200
        concealed[name] = [r.frame for r in frames if "concealed" in r.events]
    assert concealed["clean"] == []
    # OpenCV 4.6 decodes on several threads: a frame's messages may arrive a read or two after it
    assert 3 <= len(concealed["bad"]) <= 4 and all(any(0 <= f - d <= 2 for d in (5, 9, 17, 21)) for f in concealed["bad"])
    cfg = tmp_path / "service.yaml"
    cfg.write_text(f"camera: {{width: 320, height: 240, fx: 300, fy: 300, cx: 160, cy: 120}}\n"
                   f"source: {{kind: video, path: {bad}}}\ncan: {{interface: virtual, channel: dec-{id(cfg)}}}\n"
                   f"service: {{status_file: {tmp_path / 'status.json'}}}\n")
    frames, why = run_service(cfg)
    assert not why, why
    st = read_status(str(tmp_path / "status.json"))
    assert st["state"] == "stopped" and st["decode_errors"]["concealed"] == len(concealed["bad"])


def test_the_services_folder_source_skips_a_bit_flipped_jpeg_and_the_status_counts_it(tmp_path, capfd):
    from app.core import EndOfStream, Pipeline
    from app.supervisor.status_file import read_status
    from tests.test_config_service_fuzz import run_service

    folder = tmp_path / "frames"
    folder.mkdir()
    for i in range(300):   # more than the service runs: it is stopped, not ended
        cv2.imwrite(str(folder / f"{i:03d}.jpg"), noise(i))
    bit_flipped_jpeg(folder / "003.jpg", random.Random(40))
    python_side = open_recording(folder, fps=10)
    assert sum(1 for _ in python_side.frames()) == 299
    assert [s.split(": ", 1)[0] for s in python_side.skipped] == ["003.jpg"]
    cam = {"width": 320, "height": 240, "fx": 300.0, "fy": 300.0, "cx": 160.0, "cy": 120.0}
    with Pipeline({"camera": cam, "pipeline": {"preset": "thesis"}}) as pipe:
        pipe.start({"kind": "folder", "path": str(folder), "fps": 10.0})
        frames = []
        try:
            while True:
                r = pipe.pop(timeout_s=10)
                assert r is not None, pipe.health()
                frames.append(r)
        except EndOfStream:
            pass
        health = pipe.health()
    # a folder's frame number is the file's place in name order: 003.jpg is the one left out
    assert [r.frame for r in frames] == [i for i in range(300) if i != 3]
    assert [(r.frame, sorted(r.events)) for r in frames if r.events] == [(4, ["decode_error"])]
    assert health["decode_errors"] == 1 and health["source_state"] == "ended"
    assert "Corrupt JPEG" not in capfd.readouterr().err   # counted, not printed past us
    cfg = tmp_path / "service.yaml"
    cfg.write_text(f"camera: {{width: 320, height: 240, fx: 300, fy: 300, cx: 160, cy: 120}}\n"
                   f"source: {{kind: folder, path: {folder}, fps: 10}}\n"
                   f"can: {{interface: virtual, channel: dec-{id(cfg)}}}\n"
                   f"service: {{status_file: {tmp_path / 'status.json'}}}\n")
    served, why = run_service(cfg)
    assert not why, why
    st = read_status(str(tmp_path / "status.json"))
    assert served >= 50 and st["state"] == "stopped" and st["decode_errors"] == {"skipped": 1, "concealed": 0}
