"""The annotated video (`--out-video`, `headway demo`): the colour frame where the source has colour, each track's
box labelled readably, and a heads-up bar whose FCW banner takes the warning's colour."""
from __future__ import annotations

import cv2
import numpy as np

from app import annotate
from app.contracts.fcw_level import FcwLevel
from app.replay import replay_recording, replay_scenario


def read_video(path) -> list[np.ndarray]:
    cap = cv2.VideoCapture(str(path))
    frames = []
    while True:
        ok, img = cap.read()
        if not ok:
            return frames
        frames.append(img)


def bar_pixels(img: np.ndarray, colour: tuple[int, int, int]) -> int:
    """The largest connected patch of the heads-up bar within 60 levels of `colour` (BGR) on every channel, in
    pixels: a filled banner, not the letters of a text drawn in that colour (the calibration state's)."""
    bar = img[:annotate.bar_height(img.shape[0])].astype(int)
    mask = np.all(np.abs(bar - np.array(colour)) < 60, axis=2).astype(np.uint8)
    n, _labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    return int(stats[1:, cv2.CC_STAT_AREA].max()) if n > 1 else 0


def test_the_banner_turns_red_while_the_fcw_warns(tmp_path):
    """stopped_lead_50kmh: the FCW warns before the stopped car; in every frame of the warning the bar holds the
    red BRAKE! banner, and in the frames before any threat the green one."""
    levels = []
    replay_scenario("stopped_lead_50kmh", out_video=str(tmp_path / "v.mp4"), progress=False,
                    on_result=lambda r, d, t: levels.append(d.level))
    frames = read_video(tmp_path / "v.mp4")
    assert len(frames) == len(levels)
    warning = [i for i, lv in enumerate(levels) if lv == FcwLevel.WARNING]
    clear = [i for i, lv in enumerate(levels[:warning[0] if warning else None]) if lv == FcwLevel.NONE]
    assert len(warning) >= 10 and len(clear) >= 30, levels
    red, green = annotate.FCW_BANNER[FcwLevel.WARNING][1], annotate.FCW_BANNER[FcwLevel.NONE][1]
    # the banner at 480 rows is about 30 px tall and 90 px wide, its white text inside
    for i in warning:
        assert bar_pixels(frames[i], red) > 1200 and bar_pixels(frames[i], green) < 300, i
    for i in clear:
        assert bar_pixels(frames[i], green) > 1200 and bar_pixels(frames[i], red) < 300, i


def test_a_colour_recording_gives_a_colour_video(tmp_path):
    """A blue-tinted colour clip: below the bar the annotated frames keep its colour (the core sees the gray)."""
    src = tmp_path / "blue.mp4"
    w = cv2.VideoWriter(str(src), cv2.VideoWriter_fourcc(*"mp4v"), 20.0, (640, 360))
    for i in range(20):
        img = np.full((360, 640, 3), (200, 90, 40), np.uint8)
        cv2.rectangle(img, (10 * i, 200), (10 * i + 60, 260), (40, 40, 40), -1)
        w.write(img)
    w.release()
    replay_recording(str(src), out_video=str(tmp_path / "v.mp4"), progress=False)
    frames = read_video(tmp_path / "v.mp4")
    assert len(frames) == 20
    for img in frames:
        below = img[annotate.bar_height(360):].reshape(-1, 3).astype(float).mean(axis=0)
        assert below[0] - below[2] > 100, below  # blue well above red: the colour frame, not the gray one


def test_a_track_label_is_readable_at_1280x720():
    """A track's label at least 14 px tall at 720 rows (cv2.getTextSize: 17 px; at font scale 0.4 with 1-px strokes,
    9 px)."""
    (_w, h), _ = cv2.getTextSize("#12 23 m 2.1 s", annotate.FONT, annotate.LABEL_SCALE, 2)
    assert h >= 14
