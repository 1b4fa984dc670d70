"""Frame sources: recordings play completely and in order; bad sources give clear errors, never crashes."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from app.core import EndOfStream, Pipeline, SourceError


def drain(p: Pipeline, timeout_s: float = 5.0):
    out = []
    while True:
        try:
            r = p.pop(timeout_s)
        except EndOfStream:
            return out
        assert r is not None, f"no result within {timeout_s} s: {p.health()}"
        out.append(r)


def play(spec, config=None):
    with Pipeline(config or {"pipeline": {"preset": "none"}}) as p:
        p.start(spec)
        results = drain(p)
        return results, p.health()


def test_video_file_plays_every_frame_with_media_time(make_video):
    path = make_video(n=45, fps=15.0)
    results, health = play({"kind": "video", "path": str(path)})
    assert [r.frame for r in results] == list(range(45))
    assert results[1].t_s == pytest.approx(1 / 15) and results[-1].t_s == pytest.approx(44 / 15)
    assert health["source_state"] == "ended" and health["decode_errors"] == 0 and health["results_dropped"] == 0


def test_recording_is_not_dropped_when_consumer_is_slow(make_video):
    """Behind a recording the loop waits for the consumer, so a replay is complete."""
    path = make_video(n=40)
    with Pipeline({"pipeline": {"preset": "none", "queue_capacity": 2}}) as p:
        p.start({"kind": "video", "path": str(path)})
        import time

        time.sleep(0.5)  # the loop fills the queue and must wait, not drop
        results = drain(p)
        assert len(results) == 40 and p.health()["results_dropped"] == 0


def test_image_folder_sorted_names_given_fps(tmp_path):
    for name in ["b.png", "a.png", "c.jpg", "notes.txt"]:
        if name.endswith("txt"):
            (tmp_path / name).write_text("not an image")
        else:
            cv2.imwrite(str(tmp_path / name), np.full((480, 640), ord(name[0]), np.uint8))
    results, health = play({"kind": "folder", "path": str(tmp_path), "fps": 20.0})
    assert [r.frame for r in results] == [0, 1, 2]
    assert [r.t_s for r in results] == pytest.approx([0.0, 0.05, 0.10])


def test_image_folder_named_like_tusimple_clips_plays_in_numeric_order(tmp_path):
    """1.jpg .. 20.jpg: the C++ folder source plays 2.jpg second, not 10.jpg (natural_name_less)."""
    for i in range(1, 21):
        cv2.imwrite(str(tmp_path / f"{i}.jpg"), np.full((480, 640), 10 * i, np.uint8))
    results, _ = play({"kind": "folder", "path": str(tmp_path), "fps": 20.0})
    assert [int(round(r.image_mean)) for r in results] == [10 * i for i in range(1, 21)]


def test_folder_of_mixed_sizes_skips_and_counts_the_odd_frames(tmp_path):
    for i in range(5):
        shape = (240, 320) if i == 2 else (480, 640)
        cv2.imwrite(str(tmp_path / f"{i:03d}.png"), np.zeros(shape, np.uint8))
    results, health = play({"kind": "folder", "path": str(tmp_path), "fps": 10.0})
    assert [r.frame for r in results] == [0, 1, 3, 4]
    assert "size_changed" in results[2].events  # reported with the next frame
    assert health["decode_errors"] == 1


def test_corrupt_image_in_folder_is_a_decode_event(tmp_path):
    cv2.imwrite(str(tmp_path / "000.png"), np.zeros((480, 640), np.uint8))
    (tmp_path / "001.png").write_bytes(b"\x89PNG garbage")
    cv2.imwrite(str(tmp_path / "002.png"), np.zeros((480, 640), np.uint8))
    results, health = play({"kind": "folder", "path": str(tmp_path), "fps": 10.0})
    assert [r.frame for r in results] == [0, 2] and "decode_error" in results[1].events


def test_a_folders_decode_event_is_reported_with_the_next_frame_only(tmp_path):
    for i in range(6):
        cv2.imwrite(str(tmp_path / f"{i:03d}.png"), np.zeros((480, 640), np.uint8))
    (tmp_path / "001.png").write_bytes(b"\x89PNG garbage")
    results, health = play({"kind": "folder", "path": str(tmp_path), "fps": 10.0})
    assert [r.frame for r in results] == [0, 2, 3, 4, 5]
    assert [sorted(r.events) for r in results] == [[], ["decode_error"], [], [], []]
    assert health["decode_errors"] == 1


def test_truncated_jpeg_in_folder_is_a_decode_event_not_a_grey_frame(tmp_path):
    """libjpeg decodes a cut file into a half-grey image and reports success; the folder source must not."""
    rng = np.random.default_rng(14)
    img = rng.integers(0, 255, (480, 640), np.uint8)
    for i in range(3):
        cv2.imwrite(str(tmp_path / f"{i:03d}.jpg"), img)
    whole = (tmp_path / "001.jpg").read_bytes()
    (tmp_path / "001.jpg").write_bytes(whole[: len(whole) // 2])
    assert cv2.imread(str(tmp_path / "001.jpg"), cv2.IMREAD_GRAYSCALE) is not None  # OpenCV alone accepts it
    results, health = play({"kind": "folder", "path": str(tmp_path), "fps": 10.0})
    assert [r.frame for r in results] == [0, 2] and "decode_error" in results[1].events
    assert health["decode_errors"] == 1


@pytest.mark.parametrize(
    "spec_of, match",
    [
        (lambda d: {"kind": "video", "path": str(d / "missing.mp4")}, "no such file"),
        (lambda d: {"kind": "folder", "path": str(d / "nope"), "fps": 10}, "no such folder"),
        (lambda d: {"kind": "folder", "path": str(d), "fps": 10}, "contains no images"),
        (lambda d: {"kind": "video", "path": str(d)}, "is a folder"),
        (lambda d: {"kind": "v4l2", "device": "/dev/video-missing"}, "/dev/video-missing: cannot open"),
        (lambda d: {"kind": "v4l2", "device": 57}, "V4L2 camera 57: cannot open"),
        (lambda d: {"kind": "firewire", "index": 3}, "FireWire camera 3: cannot open"),
    ],
)
def test_unopenable_sources_are_clear_errors(tmp_path, spec_of, match):
    with Pipeline() as p:
        with pytest.raises(SourceError, match=match):
            p.start(spec_of(tmp_path))
        assert p.health()["running"] is False


def test_file_that_is_not_a_video(tmp_path):
    bad = tmp_path / "drive.mp4"
    bad.write_text("this is a text file, not a video\n" * 100)
    with Pipeline() as p, pytest.raises(SourceError, match="cannot be opened as a video"):
        p.start({"kind": "video", "path": str(bad)})


def test_single_still_image_is_not_taken_for_a_video(tmp_path):
    img = tmp_path / "frame.png"
    cv2.imwrite(str(img), np.zeros((480, 640), np.uint8))
    with Pipeline() as p, pytest.raises(SourceError, match="video"):
        p.start({"kind": "video", "path": str(img)})


def test_truncated_mp4_is_a_clear_error(make_video, tmp_path):
    data = make_video(n=60).read_bytes()
    cut = tmp_path / "cut.mp4"
    cut.write_bytes(data[: len(data) // 2])  # the index (moov atom) is at the end: lost
    with Pipeline() as p, pytest.raises(SourceError, match="cut.mp4"):
        p.start({"kind": "video", "path": str(cut)})


def test_truncated_avi_plays_what_survives_then_ends(make_video, tmp_path):
    data = make_video(name="full.avi", n=60, fourcc="MJPG").read_bytes()
    cut = tmp_path / "cut.avi"
    cut.write_bytes(data[: len(data) // 2])
    results, health = play({"kind": "video", "path": str(cut)})
    assert 10 <= len(results) < 60
    assert health["source_state"] == "ended"
    frames = [r.frame for r in results]
    assert frames == sorted(frames)


def test_video_of_other_size_than_camera(make_video):
    path = make_video(size=(320, 240))
    with Pipeline() as p, pytest.raises(SourceError, match="320x240 but camera.width/camera.height say 640x480"):
        p.start({"kind": "video", "path": str(path)})


def test_missing_camera_with_wait_for_device_reconnects_with_backoff():
    cfg = {"pipeline": {"preset": "none", "reconnect_initial_s": 0.02, "reconnect_max_s": 0.05}}
    with Pipeline(cfg) as p:
        p.start({"kind": "v4l2", "device": "/dev/video-missing", "wait_for_device": True})
        assert p.pop(0.3) is None  # nothing comes, nothing crashes
        h = p.health()
        assert h["running"] and h["source_state"] == "reconnecting" and h["source_losses"] == 1
        p.stop()
        assert p.health()["running"] is False


@pytest.mark.parametrize(
    "spec, match",
    [
        ({"kind": "webcam"}, "source.kind"),
        ({"path": "x.mp4"}, "source.kind"),
        ({"kind": "v4l2", "pixel_format": "YUV"}, "source.pixel_format"),
        ({"kind": "firewire", "guid": "zz-top"}, "source.guid"),
        ({"kind": "video"}, "source.path"),
    ],
)
def test_malformed_source_descriptions(spec, match):
    from app.core import ConfigError

    with Pipeline() as p, pytest.raises(ConfigError, match=match):
        p.start(spec)
