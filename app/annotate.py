"""Draws what the pipeline saw onto a frame: lanes, each track's box with id, range and TTC, the lead, and a
heads-up bar (ego speed, the lead's range and TTC, the FCW state as a coloured banner, the calibration state, the
core's ms per frame). docs/annotated_video.md shows the layout.

Drawing runs in Python after the core has handed over the frame's result, never in the real-time loop; the ms per
frame shown is the core's own time for the frame, drawing not included. Every size is in units of the frame's
height / 720, so the text is as readable at 960x540 as at 1280x720.
"""
from __future__ import annotations

from typing import Optional

import cv2
import numpy as np

from app.core import FrameResult, Track
from app.fcw import FcwOutput
from app.contracts.fcw_level import FcwLevel

# BGR
_LANE = (0, 200, 255)
_TRACK = (0, 220, 0)
_TENTATIVE = (170, 170, 170)
_LEAD = (0, 0, 255)
_TRUTH = (255, 160, 0)
_WHITE = (255, 255, 255)
_BAR = (30, 30, 30)
_GREEN, _AMBER, _RED, _GREY = (0, 170, 0), (0, 170, 255), (0, 0, 230), (110, 110, 110)

# the FCW banner: (text, colour) per level
FCW_BANNER = {FcwLevel.NONE: ("FCW clear", _GREEN), FcwLevel.PREWARNING: ("CAUTION", _AMBER),
              FcwLevel.WARNING: ("BRAKE!", _RED)}
CALIBRATION_COLOUR = {"converged": _GREEN, "learning": _AMBER, "at_limit": _RED, "off": _GREY}
BAR_HEIGHT_PX = 56       # at 720 rows
FONT = cv2.FONT_HERSHEY_SIMPLEX
LABEL_SCALE = 0.75       # at 720 rows: text 17 px tall (cv2.getTextSize)
BAR_SCALE = 0.7


def bar_height(frame_height: int) -> int:
    """Rows of the heads-up bar at the top of a frame `frame_height` rows tall."""
    return int(round(BAR_HEIGHT_PX * frame_height / 720))


def _text(img: np.ndarray, text: str, org: tuple[int, int], scale: float, color, thick: int,
          background=None) -> int:
    """Draws `text` with its baseline at org (on a filled box when `background` is given); returns its width."""
    (w, h), base = cv2.getTextSize(text, FONT, scale, thick)
    x, y = org
    if background is not None:
        pad = max(2, h // 4)
        cv2.rectangle(img, (x - pad, y - h - pad), (x + w + pad, y + base + pad // 2), background, -1)
    cv2.putText(img, text, (x, y), FONT, scale, color, thick, cv2.LINE_AA)
    return w


def track_label(t: Track) -> str:
    """'#7 23 m 2.1 s': id, range and TTC, each left out when unknown."""
    parts = [f"#{t.id}"] if t.id >= 0 else []
    if t.range_m is not None:
        parts.append(f"{t.range_m:.0f} m")
    if t.ttc_s is not None:
        parts.append(f"{t.ttc_s:.1f} s")
    return " ".join(parts)


def _draw_track(img: np.ndarray, t: Track, lead: bool, s: float, top_limit: int) -> None:
    l, tp, rt, b = (int(round(v)) for v in t.box)
    color = _LEAD if lead else (_TRACK if t.confirmed else _TENTATIVE)
    thick = max(1, round((4 if lead else 2 if t.confirmed else 1) * s))
    cv2.rectangle(img, (l, tp), (rt, b), color, thick, cv2.LINE_AA)
    if lead:  # a filled marker under the box: the lead is seen without reading colours
        h = max(6, round(14 * s))
        cx = (l + rt) // 2
        tri = np.array([[cx, b + 2], [cx - h, b + 2 + h], [cx + h, b + 2 + h]], np.int32)
        cv2.fillPoly(img, [tri], _LEAD, cv2.LINE_AA)
    label = ("LEAD " if lead else "") + track_label(t)
    if not label or not t.confirmed:
        return
    scale, lt = LABEL_SCALE * s, max(1, round(2 * s))
    (_w, h), _base = cv2.getTextSize(label, FONT, scale, lt)
    y = tp - max(4, round(6 * s))
    if y - h < top_limit:  # no room above the box (under the bar): inside it, at its top
        y = tp + h + max(4, round(6 * s))
    _text(img, label, (l, y), scale, _WHITE, lt, background=color)


def _bar_items(r: FrameResult, fcw: Optional[FcwOutput]) -> list[tuple[str, tuple, bool]]:
    """The bar's fields left to right: (text, colour, drawn as a banner)."""
    speed = fcw.ego_speed_mps if fcw is not None else None
    items = [("ego " + ("--" if speed is None else f"{speed * 3.6:.0f}") + " km/h", _WHITE, False)]
    lead = r.lead
    lead_text = "lead --"
    if lead is not None:
        lead_text = "lead " + (f"{lead.range_m:.1f} m" if lead.range_m is not None else "-- m")
        lead_text += "  TTC " + (f"{lead.ttc_s:.1f} s" if lead.ttc_s is not None else "--")
    items.append((lead_text, _WHITE, False))
    text, colour = FCW_BANNER[fcw.level] if fcw is not None else ("FCW --", _GREY)
    items.append((text, colour, True))
    cal = r.calibration or {}
    state = cal.get("state") or "off"
    cal_text = f"cal {state}"
    if cal.get("active") and cal.get("pitch_deg") is not None:
        cal_text += f" {cal['pitch_deg']:.1f}/{cal['yaw_deg']:.1f} deg"
    items.append((cal_text, CALIBRATION_COLOUR.get(state, _WHITE), False))
    items.append((f"{r.total_ms:.1f} ms", _WHITE, False))
    return items


def _heads_up_bar(img: np.ndarray, r: FrameResult, fcw: Optional[FcwOutput], s: float) -> None:
    hgt = bar_height(img.shape[0])
    roi = img[:hgt]
    roi[:] = (0.35 * roi + 0.65 * np.array(_BAR)).astype(np.uint8)  # the road stays faintly visible
    items = _bar_items(r, fcw)
    thick = max(1, round(2 * s))
    margin, gap, pad = round(12 * s), round(28 * s), round(14 * s)

    def widths(scale: float) -> list[int]:
        return [cv2.getTextSize(t, FONT, scale * (1.1 if banner else 1.0), thick + banner)[0][0] + 2 * pad * banner
                for t, _c, banner in items]

    scale = BAR_SCALE * s
    need = sum(widths(scale)) + gap * (len(items) - 1) + 2 * margin
    scale *= min(1.0, img.shape[1] / need)  # a narrow frame: smaller text, every field kept
    y = int(hgt * 0.68)
    x = margin
    for (text, colour, banner), w in zip(items, widths(scale)):
        if banner:  # a filled box the bar's height less a margin, the level's colour, white text
            cv2.rectangle(img, (x, round(6 * s)), (x + w, hgt - round(6 * s)), colour, -1)
            cv2.putText(img, text, (x + pad, y), FONT, scale * 1.1, _WHITE, thick + 1, cv2.LINE_AA)
        else:
            _text(img, text, (x, y), scale, colour, thick)
        x += w + gap


def annotate(frame: np.ndarray, r: FrameResult, truth: Optional[list[dict]] = None,
             fcw: Optional[FcwOutput] = None) -> np.ndarray:
    """A BGR picture of `frame` (the colour frame where the source has colour, else the gray one) with the result
    drawn on it: truth boxes thin, in blue, if given; `fcw`, the FCW state machine's output decided in the
    supervisor, gives the banner and the ego speed."""
    img = cv2.cvtColor(frame, cv2.COLOR_GRAY2BGR) if frame.ndim == 2 else frame.copy()
    s = img.shape[0] / 720
    for lane in r.lanes:
        pts = lane.points or [(lane.x_bottom, lane.y_bottom), (lane.x_top, lane.y_top)]
        cv2.polylines(img, [np.round(np.array(pts)).astype(np.int32)], False, _LANE,
                      max(1, round((3 if lane.observed else 1) * s)), cv2.LINE_AA)
    for t in truth or []:
        l, tp, rt, b = (int(round(v)) for v in t["box"])
        cv2.rectangle(img, (l, tp), (rt, b), _TRUTH, 1)
    # the lead last, on top of the others
    for t in sorted(r.tracks, key=lambda t: t is r.lead):
        _draw_track(img, t, t is r.lead, s, bar_height(img.shape[0]))
    _heads_up_bar(img, r, fcw, s)
    return img


def annotate_detections(frame: np.ndarray, boxes: np.ndarray, truth: Optional[list[dict]] = None) -> np.ndarray:
    """A BGR picture of `frame` with one image's detections (Detections.boxes) drawn as unconfirmed vehicles are,
    and the truth boxes thin, in blue, if given."""
    img = cv2.cvtColor(frame, cv2.COLOR_GRAY2BGR) if frame.ndim == 2 else frame.copy()
    thick = max(1, round(img.shape[0] / 720))
    for t in truth or []:
        l, tp, rt, b = (int(round(v)) for v in t["box"])
        cv2.rectangle(img, (l, tp), (rt, b), _TRUTH, 1)
    for l, tp, rt, b in np.round(boxes[:, :4]).astype(int):
        cv2.rectangle(img, (l, tp), (rt, b), _TENTATIVE, thick, cv2.LINE_AA)
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
