"""How much wider than the vehicle its box is: the box's width minus the span between the vehicle's sides.

The sides are the strongest mirror-symmetric pair of vertical-edge columns over the lower 60 % of the box (a car's
rear is symmetric; its wheels, lamps and body edges give the strongest vertical edges), centred within 10 % of the
box's width of the box's centre and 0.5-1.3 box widths apart, searched in the box widened by 40 % each side.
Only boxes with no other box beside them (the box widened by half its width each side) are measured, so that a
neighbour's edge is not taken for a side.

Run on TuSimple's annotated boxes it measures the margin the annotators drew around each car; `--detector` shows
how the default preset's detections (at their operating point, on the recordings' camera) sit on those boxes. Run
on the synthetic world's truth boxes, which are the drawn rear faces exactly (docs/sim.md), it measures the method's
own bias. The scale TTC takes the margin off the width (`kinematics.scale_margin_px`, docs/tracking.md).

    python -m app.eval.box_margin --images ~/.cache/headway/tusimple-train --every 10 --from 1 [--detector]
    python -m app.eval.box_margin --scenarios steady_following,dense_traffic,lead_braking_0p3g
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Iterable, Optional, Sequence

import cv2
import numpy as np

from app import config as configuration
from app.detect_images import operating_point
from app.eval.detector_points import scored_images
from app.eval.matching import match
from app.eval.tusimple_boxes import entry_boxes, load_entries, tusimple_config
from app.sim import load_scenario, render

BANDS = ((10, 15), (15, 20), (20, 30), (30, 40), (40, 60), (60, 100))  # box heights, px


def side_span(gray: np.ndarray, box: Sequence[float]) -> Optional[int]:
    """Columns between the vehicle's two sides in the box (left, top, right, bottom), or None when the box is too
    small or too near the border to search."""
    left, top, right, bottom = box
    w, h = right - left, bottom - top
    x0, x1 = int(max(0, left - 0.4 * w)), int(min(gray.shape[1], right + 0.4 * w))
    y0, y1 = int(max(0, top + 0.4 * h)), int(min(gray.shape[0], bottom + 1))
    if x1 - x0 < 8 or y1 - y0 < 3:
        return None
    gx = np.abs(cv2.Sobel(gray[y0:y1, x0:x1].astype(np.float32), cv2.CV_32F, 1, 0, ksize=3)).mean(axis=0)
    gx[0], gx[-1] = gx[1], gx[-2]  # the Sobel response is 0 on the border: a side there takes its neighbour's
    centre, n = 0.5 * (left + right) - x0, len(gx)
    best = None
    for c2 in range(int(2 * (centre - 0.1 * w)), int(2 * (centre + 0.1 * w)) + 1):  # twice the centre: half columns
        for s2 in range(int(0.5 * w), int(1.3 * w) + 1):
            a, b = c2 - s2, c2 + s2
            if a % 2 or a < 0 or b > 2 * (n - 1):
                continue
            score = gx[a // 2] + gx[b // 2]
            if best is None or score > best[0]:
                best = (score, a // 2, b // 2)
    return None if best is None else best[2] - best[1]


def _alone(boxes: list[Sequence[float]], i: int) -> bool:
    left, top, right, bottom = boxes[i]
    half = 0.5 * (right - left)
    return not any(j != i and o[0] < right + half and o[2] > left - half and o[1] < bottom and o[3] > top
                   for j, o in enumerate(boxes))


def margins(images: Iterable[tuple[np.ndarray, list[Sequence[float]], list[bool]]]) -> list[tuple[float, float]]:
    """(box height, box width - side span) of every box measured (its flag set) and alone in its image; every box
    of the image counts as a neighbour."""
    out = []
    for gray, boxes, measured in images:
        for i, box in enumerate(boxes):
            h = box[3] - box[1]
            if not measured[i] or not BANDS[0][0] <= h < BANDS[-1][1] or not _alone(boxes, i):
                continue
            span = side_span(gray, box)
            if span is not None:
                out.append((h, (box[2] - box[0]) - span))
    return out


def by_band(rows: list[tuple[float, float]]) -> list[dict]:
    """Per height band: boxes measured, median and quartiles of the margin (px)."""
    r = np.asarray(rows, float).reshape(-1, 2)
    out = []
    for lo, hi in BANDS:
        m = r[(r[:, 0] >= lo) & (r[:, 0] < hi), 1]
        if len(m):
            q25, med, q75 = np.percentile(m, [25, 50, 75])
            out.append({"band": f"{lo}-{hi}", "n": int(len(m)), "median_px": float(med), "q25_px": float(q25),
                        "q75_px": float(q75)})
    return out


def tusimple_images(folder: str, entries: list[dict]):
    """(gray image, annotated boxes, all measured) of each of the TuSimple-format folder's `entries`."""
    for e in entries:
        gray = cv2.imread(str(Path(folder) / e["file_name"]), cv2.IMREAD_GRAYSCALE)
        if gray is None:
            raise FileNotFoundError(f"{Path(folder) / e['file_name']}: not readable as an image")
        boxes = entry_boxes(e)
        yield gray, boxes, [True] * len(boxes)


def synthetic_images(scenarios: Sequence[str], every: int = 5):
    """(frame, truth boxes, measured) of every `every`-th frame of each scenario: the cars and vans wholly visible and
    inside the image are measured; every vehicle is a neighbour."""
    for name in scenarios:
        for f in render(load_scenario(name)):
            if f.index % every:
                continue
            yield f.image, [v["box"] for v in f.truth], [
                v["kind"] != "truck" and v.get("visible_fraction", 1.0) >= 0.95 and v["box"][0] >= 0
                and v["box"][2] <= f.image.shape[1] for v in f.truth]


def detector_offsets(folder: str, entries: list[dict], min_iou: float = 0.3) -> list[tuple[float, float]]:
    """(annotated box height, detected width - annotated width) of each annotated box the default preset's detection
    stage matches (IoU >= min_iou) at its operating point, on the recordings' camera (as `headway eval` scores)."""
    cfg = tusimple_config(configuration.load(None, {"pipeline": {"preset": configuration.default_preset()}}))
    at = operating_point(cfg)
    out = []
    for e, found in zip(entries, scored_images(folder, entries, cfg)):
        gt = entry_boxes(e)
        det = [d[:4] for d in found if d[4] >= at]
        for i, j, _ in match(gt, det, min_iou):
            out.append((gt[i][3] - gt[i][1], (det[j][2] - det[j][0]) - (gt[i][2] - gt[i][0])))
    return out


def main(argv: Optional[list[str]] = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--images", help="folder with annotation.json (TuSimple format)")
    src.add_argument("--scenarios", help="synthetic scenarios, comma-separated: their exact truth boxes")
    p.add_argument("--every", type=int, default=1, help="with --images: only images k with k %% EVERY == FROM")
    p.add_argument("--from", dest="start", type=int, default=0)
    p.add_argument("--detector", action="store_true",
                   help="with --images: the default preset's detected width minus the annotated width instead")
    a = p.parse_args(argv)
    if a.every < 1 or not 0 <= a.start < a.every:
        print(f"box_margin: --every {a.every} --from {a.start}: give EVERY >= 1 and 0 <= FROM < EVERY", file=sys.stderr)
        return 2
    if a.images:
        if not (Path(a.images) / "annotation.json").is_file():
            print(f"box_margin: {a.images} holds no annotation.json (TuSimple format); give the folder "
                  f"`../shared/tools/tusimple-train` wrote, or ../shared/data/tusimple/supp", file=sys.stderr)
            return 2
        entries = [e for k, e in enumerate(load_entries(a.images)) if k % a.every == a.start]
        rows = detector_offsets(a.images, entries) if a.detector else margins(tusimple_images(a.images, entries))
    else:
        rows = margins(synthetic_images([s.strip() for s in a.scenarios.split(",") if s.strip()]))
    what = "detected - annotated width px" if a.detector else "margin px"
    print(f"| box height px | boxes | {what}: median | q25 | q75 |")
    print("| --- | ---: | ---: | ---: | ---: |")
    for b in by_band(rows):
        print(f"| {b['band']} | {b['n']} | {b['median_px']:+.1f} | {b['q25_px']:+.1f} | {b['q75_px']:+.1f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
