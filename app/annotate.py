"""Draws what the pipeline saw onto a frame: lanes, boxes with ids and range, lead, FCW, timings."""
from __future__ import annotations

from typing import Optional

import cv2
import numpy as np

from app.core import FrameResult
from app.fcw_level import FcwLevel

_LANE = (0, 200, 255)
_TRACK = (0, 220, 0)
_TENTATIVE = (160, 160, 160)
_LEAD = (0, 0, 255)
_TRUTH = (255, 160, 0)


def annotate(gray: np.ndarray, r: FrameResult, truth: Optional[list[dict]] = None, fcw_level: int = FcwLevel.NONE) -> np.ndarray:
    """A BGR picture of `gray` with the result drawn on it (truth boxes thin, in blue, if given; the FCW
    state machine's level, decided in the supervisor, as a caption)."""
    img = cv2.cvtColor(gray, cv2.COLOR_GRAY2BGR)
    for lane in r.lanes:
        pts = lane.points or [(lane.x_bottom, lane.y_bottom), (lane.x_top, lane.y_top)]
        cv2.polylines(img, [np.round(np.array(pts)).astype(np.int32)], False, _LANE, 2 if lane.observed else 1,
                      cv2.LINE_AA)
    for t in truth or []:
        l, tp, rt, b = (int(round(v)) for v in t["box"])
        cv2.rectangle(img, (l, tp), (rt, b), _TRUTH, 1)
    for t in r.tracks:
        l, tp, rt, b = (int(round(v)) for v in t.box)
        color = _LEAD if t is r.lead else (_TRACK if t.confirmed else _TENTATIVE)
        cv2.rectangle(img, (l, tp), (rt, b), color, 2 if t.confirmed else 1)
        label = f"#{t.id}" if t.id >= 0 else ""
        if t.range_m is not None:
            label += f" {t.range_m:.0f}m"
        if t.ttc_s is not None:
            label += f" ttc {t.ttc_s:.1f}s"
        if label:
            cv2.putText(img, label, (l, max(10, tp - 4)), cv2.FONT_HERSHEY_SIMPLEX, 0.4, color, 1, cv2.LINE_AA)
    status = f"frame {r.frame}  {r.total_ms:.2f} ms" + ("  full detection" if r.full_detection else "")
    cv2.putText(img, status, (6, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (255, 255, 255), 1, cv2.LINE_AA)
    if fcw_level != FcwLevel.NONE:
        text = "BRAKE!" if fcw_level == FcwLevel.WARNING else "caution"
        cv2.putText(img, text, (img.shape[1] // 2 - 60, 40), cv2.FONT_HERSHEY_DUPLEX, 1.0, _LEAD, 2, cv2.LINE_AA)
    return img


class VideoOut:
    """An annotated video file (mp4v); opened on the first frame so its size is the frame's."""

    def __init__(self, path: str, fps: float):
        self.path, self.fps, self._w = path, fps, None

    def write(self, bgr: np.ndarray) -> None:
        if self._w is None:
            self._w = cv2.VideoWriter(self.path, cv2.VideoWriter_fourcc(*"mp4v"), self.fps,
                                      (bgr.shape[1], bgr.shape[0]))
            if not self._w.isOpened():
                raise OSError(f"{self.path}: cannot write a video there")
        self._w.write(bgr)

    def close(self) -> None:
        if self._w is not None:
            self._w.release()
