"""Shared test helpers: where the real driving data is, and small recordings made on the spot."""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

REPO = Path(__file__).resolve().parent.parent
DATA = REPO.parent / "shared" / "data"


def data_path(*parts: str) -> Path:
    """A path inside ../shared/data; the test is skipped with the reason when it is absent."""
    p = DATA.joinpath(*parts)
    if not p.exists():
        pytest.skip(f"real driving data not found at {p} (../shared/data is absent on this machine)")
    return p


def cascade_alone(**sections) -> dict:
    """Configuration values whose detection stage (Pipeline.detect) is the trained cascade
    with its verifier alone: pipeline.detectors [cascade] (tracked by kalman), with the other `sections` given (a
    `pipeline` among them adds to those keys)."""
    return {**sections, "pipeline": {"detectors": ["cascade"], "tracker": "kalman", **sections.get("pipeline", {})}}


def tme08_sequence(preset: str) -> tuple[list, float, dict]:
    """TME's tme08 (50 real motorway frames; skipped when absent): the frames, their rate, and the configuration
    values `headway eval` runs it with (camera pitch and yaw fitted to the lanes, the hood line, the preset)."""
    from app.eval import road_motion

    frames, fps = road_motion.read_tme(data_path("tme", "tme08"))
    cam = road_motion.fit_horizon(road_motion.tme_camera(data_path("tme", "calibration.ini")), frames)
    return frames, fps, {"camera": {**cam, "hood_frac": road_motion.HOOD["tme08"]}, "pipeline": {"preset": preset}}


def write_video(path: Path, n: int = 30, size=(640, 480), fps: float = 30.0, fourcc: str = "mp4v") -> Path:
    """A short video whose frame i has a bright square at x = 10 * i (so frames are distinguishable)."""
    w = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*fourcc), fps, size)
    assert w.isOpened(), f"cannot write {path}"
    for i in range(n):
        img = np.full((size[1], size[0], 3), 40, np.uint8)
        cv2.rectangle(img, (10 * i, 100), (10 * i + 40, 140), (230, 230, 230), -1)
        w.write(img)
    w.release()
    return path


@pytest.fixture
def make_video(tmp_path):
    def make(name="clip.mp4", **kw):
        return write_video(tmp_path / name, **kw)

    return make
