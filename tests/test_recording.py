"""The one recording reader (app.recording) that replay and evaluation share: frame rates checked, a
video's own rate used, truncated and corrupt media reported frame by frame, never taken as frames."""
from __future__ import annotations

import re

import cv2
import numpy as np
import pytest

from app import recording
from app.eval import road_motion
from app.recording import RecordingError, open_recording
from app.replay import ReplayError, replay
from tests.conftest import REPO, data_path, write_video


def folder(tmp_path, n=4, size=(64, 48), ext=".jpg"):
    d = tmp_path / "frames"
    d.mkdir()
    for i in range(n):
        img = np.full((size[1], size[0]), 30 + 40 * i, np.uint8)
        cv2.imwrite(str(d / f"{i:03d}{ext}"), img)
    return d


def test_image_extensions_are_one_list_that_the_cpp_capture_agrees_with():
    cpp = next(p for p in (REPO / "csrc").rglob("*.cpp") if "bool is_image_file_name" in p.read_text())
    body = cpp.read_text().split("bool is_image_file_name", 1)[1].split("}", 2)[:2]
    listed = tuple(re.findall(r'"(\.[a-z]+)"', "".join(body)))
    assert listed == recording.IMAGE_EXTS, f"{cpp}: {listed} != app.recording.IMAGE_EXTS"


@pytest.mark.parametrize("fps", [0.0, -5.0, float("nan"), float("inf"), 1001.0])
def test_bad_fps_is_rejected_with_the_range(tmp_path, fps):
    video = write_video(tmp_path / "clip.mp4", n=5, fps=25.0)
    for source in (video, folder(tmp_path)):
        with pytest.raises(RecordingError, match="between 0.1 and 1000"):
            open_recording(source, fps)
        with pytest.raises(ReplayError, match="between 0.1 and 1000"):
            replay(str(source), fps=fps, progress=False)


def test_video_uses_its_own_rate_unless_a_valid_fps_is_given(tmp_path):
    video = write_video(tmp_path / "clip.mp4", n=5, fps=25.0)
    assert open_recording(video).fps == 25.0
    rec = open_recording(video, 1000)  # a valid rate given is used, not replaced by a default
    assert rec.fps == 1000.0
    assert [t for _i, t, _g in rec.frames()] == pytest.approx([0.0, 0.001, 0.002, 0.003, 0.004])
    f = open_recording(folder(tmp_path), 20)
    assert [t for _i, t, _g in f.frames()] == pytest.approx([0.0, 0.05, 0.1, 0.15])


def test_truncated_video_reports_frames_decoded_against_the_container(tmp_path):
    video = write_video(tmp_path / "clip.avi", n=38, fps=25.0, fourcc="MJPG")
    cut = tmp_path / "cut.avi"
    cut.write_bytes(video.read_bytes()[: video.stat().st_size // 2])
    rec = open_recording(cut)
    n = len(rec.read_all())
    assert rec.expected == 38 and 0 < n < 38 and rec.decoded == n
    # the last frame read is cut inside: FFmpeg conceals it, and it is counted as damaged
    assert rec.account().startswith(f"{n} of 38 frames decoded, 1 of them with decoder errors") and rec.damaged == [n - 1]
    assert rec.skipped == [f"frames {n}-37: not decoded: the file is truncated or corrupt ({n} of 38 frames decoded)"]
    s = replay(str(cut), progress=False)
    assert s.frames == n and f"{n} of 38 frames decoded" in s.text() and f"frames {n}-37" in s.text()


def test_truncated_real_clip_says_how_many_frames_were_lost(tmp_path):
    src = data_path("udacity", "test_video.mp4")
    cut = tmp_path / "cut.mp4"
    cut.write_bytes(src.read_bytes()[: src.stat().st_size // 2])
    rec = open_recording(cut)
    n = len(rec.read_all())
    assert n < 38 and rec.expected == 38 and f"{n} of 38 frames decoded" in rec.skipped[-1]


def test_truncated_and_corrupt_images_are_skipped_by_name(tmp_path):
    d = folder(tmp_path, n=4, size=(320, 240))
    good = (d / "001.jpg").read_bytes()
    (d / "001.jpg").write_bytes(good[: len(good) // 3])      # cut to a third: libjpeg would grey-fill it
    (d / "003.jpg").write_bytes(b"\xff\xd8 not a jpeg \xff\xd9")
    png = tmp_path / "x.png"
    cv2.imwrite(str(png), np.zeros((48, 64), np.uint8))
    (d / "004.png").write_bytes(png.read_bytes()[:40])
    rec = open_recording(d, 10)
    got = [i for i, _t, _g in rec.frames()]
    assert got == [0, 2]
    assert rec.skipped == ["001.jpg: truncated JPEG (no end-of-image marker)",
                           "003.jpg: cannot be decoded as an image", "004.png: truncated PNG (no IEND chunk)"]
    assert rec.account() == "2 of 5 frames decoded"
    s = replay(str(d), fps=10, progress=False)
    assert s.frames == 2 and "001.jpg: truncated JPEG" in s.text()


def test_evaluation_reads_recordings_through_the_same_reader(tmp_path, monkeypatch):
    calls = []
    real = recording.open_recording

    def spy(source, fps=None):
        calls.append(str(source))
        return real(source, fps)

    monkeypatch.setattr(road_motion, "open_recording", spy)
    d = folder(tmp_path, n=3)
    (d / "001.jpg").write_bytes((d / "001.jpg").read_bytes()[:50])  # truncated: left out, not a grey frame
    frames, fps = road_motion.read_tme(d)
    assert len(frames) == 2 and fps == 20.0 and calls == [str(d)]
    video = write_video(tmp_path / "v.mp4", n=6, fps=25.0)
    frames, fps = road_motion.read_video(video, max_frames=4)
    assert len(frames) == 4 and fps == 25.0 and calls[-1] == str(video)


def tusimple_named_folder(tmp_path, n=20):
    """Frames named as TuSimple's clips (1.jpg .. 20.jpg), frame i a flat image of gray 10 i."""
    d = tmp_path / "clip"
    d.mkdir()
    for i in range(1, n + 1):
        cv2.imwrite(str(d / f"{i}.jpg"), np.full((48, 64), 10 * i, np.uint8))
    return d


def test_a_folder_named_1_to_20_plays_in_numeric_order(tmp_path):
    """By plain name 10.jpg .. 19.jpg would play between 1.jpg and 2.jpg: the drive would jump back in time."""
    d = tusimple_named_folder(tmp_path)
    assert [p.name for p in recording.folder_images(d)] == [f"{i}.jpg" for i in range(1, 21)]
    levels = [int(round(float(g.mean()))) for _i, _t, g in open_recording(d, 20).frames()]
    assert levels == [10 * i for i in range(1, 21)]


def test_natural_order_compares_digit_runs_as_numbers():
    names = ["img10b.png", "img2.png", "img10a.png", "img1.png", "01.jpg", "1.jpg", "a.jpg", "10.jpg", "9.jpg"]
    assert sorted(names, key=recording.natural_key) == ["01.jpg", "1.jpg", "9.jpg", "10.jpg", "a.jpg", "img1.png",
                                                        "img2.png", "img10a.png", "img10b.png"]
