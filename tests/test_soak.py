"""The soak (`python -m app.bench.soak`) runs the service as systemd does, from the checkout, and accounts for its
run: a few seconds on a small rendered clip end with the service stopped cleanly and its CAN log parsing whole."""
from __future__ import annotations

import cv2
import numpy as np

from app.bench.soak import soak


def test_a_short_soak_runs_the_service_and_reads_back_its_whole_can_log(tmp_path):
    clip = tmp_path / "clip.avi"
    w = cv2.VideoWriter(str(clip), cv2.VideoWriter_fourcc(*"MJPG"), 20.0, (320, 240))
    rng = np.random.default_rng(3)
    for _ in range(20):
        w.write(rng.integers(0, 255, (240, 320, 3), np.uint8))
    w.release()
    work = tmp_path / "work"
    work.mkdir()
    rep = soak(str(clip), minutes=0.15, every_s=2.0, workdir=work, fps=20.0)
    assert rep["exit_code"] == 0 and not rep["traceback"], rep
    assert rep["state_after_stop"] == "stopped", rep
    assert rep["frames_fed"] >= 100 and rep["frames_processed"] >= 0.5 * rep["frames_fed"], rep
    assert rep["can_log_lines"] > 0 and rep["can_log_parsed"] == rep["can_log_lines"], rep
