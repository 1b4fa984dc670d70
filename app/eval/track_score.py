"""Scoring confirmed tracks against per-frame truth boxes: detection counts, the MOT accumulator, range
errors and how soon each true vehicle was confirmed. Shared by the synthetic suite (`headway eval`) and
the fleet's drives with truth (`headway fleet`).

Truth: vehicles within `max_range_m` whose box is at least `min_visible` visible (when the truth says;
a boxes-only truth counts every box). Other vehicles are "don't care": a confirmed track that matches no
true vehicle and lies more than half inside a don't-care vehicle's box is neither a hit nor a false
positive (the KITTI tracking benchmark's rule for its DontCare regions: a car 100 m ahead, boxed a few
pixels too wide by a detector whose smallest window is larger than the car, is still that car).

The truth boxes are the vehicles' parts in the image (a vehicle entering or leaving the view is boxed where it is
seen, as KITTI boxes a truncated car); a track's box is scored the same way, cut to the image when its size is
given: a track that carries a vehicle's whole width past the image's side is not thereby a false positive.
"""
from __future__ import annotations

from typing import Optional

import motmetrics as mm
import numpy as np

from app.eval.matching import inside_matrix, iou_matrix, match
from app.sim.truth import clip_to_image


def _box(v: dict) -> list[float]:
    return v.get("box_clipped") or v["box"]


def in_image(box, image_size: Optional[tuple[int, int]]) -> list[float]:
    """`box` cut to an image of `image_size` (width, height) as the truth's boxes are (a box wholly outside: an empty
    box at the image's edge, which overlaps nothing); as it is when None."""
    if image_size is None:
        return list(box)
    w, h = image_size
    cut = clip_to_image(box, w, h)
    if cut is None:
        x, y = min(max(float(box[0]), 0.0), w - 1.0), min(max(float(box[1]), 0.0), h - 1.0)
        return [x, y, x, y]
    return list(cut)


class TrackScorer:
    def __init__(self, max_range_m: float = 60.0, min_visible: float = 0.5):
        self.max_range_m = max_range_m
        self.min_visible = min_visible
        self.acc = mm.MOTAccumulator(auto_id=True)
        self.tp = self.fp = self.fn = 0
        self.range_errors: list[tuple[float, float]] = []   # (true range, relative error)
        self.first_confirmed: dict[int, int] = {}           # truth id -> first frame a track matched it
        self.first_half_visible: dict[int, int] = {}

    def is_truth(self, v: dict) -> bool:
        return (v.get("longitudinal_m", 0.0) <= self.max_range_m
                and v.get("visible_fraction", 1.0) >= self.min_visible)

    def update(self, frame: int, truth_all: list[dict], tracks: list,
               image_size: Optional[tuple[int, int]] = None) -> None:
        """One frame: `truth_all` the true vehicles ({"id", "box" or "box_clipped", ...}), `tracks` the
        confirmed tracks (objects with .id, .box, .range_m), `image_size` the frame's (width, height)."""
        truth = [v for v in truth_all if self.is_truth(v)]
        dont_care = [v for v in truth_all if not self.is_truth(v)]
        boxes = [in_image(t.box, image_size) for t in tracks]
        # drop tracks that sit on a don't-care vehicle and on no real one
        if dont_care and tracks:
            dc = inside_matrix(boxes, [_box(v) for v in dont_care])
            gt = iou_matrix(boxes, [_box(v) for v in truth])
            keep = [i for i in range(len(tracks)) if not (dc[i].max(initial=0) > 0.5 and gt[i].max(initial=0) < 0.5)]
            tracks, boxes = [tracks[i] for i in keep], [boxes[i] for i in keep]
        for v in truth_all:
            if v.get("visible_fraction", 1.0) >= 0.5 and v["id"] not in self.first_half_visible:
                self.first_half_visible[v["id"]] = frame
        pairs = match([_box(v) for v in truth], boxes)
        self.tp += len(pairs)
        self.fn += len(truth) - len(pairs)
        self.fp += len(tracks) - len(pairs)
        for i, j, _ in pairs:
            self.first_confirmed.setdefault(truth[i]["id"], frame)
            rng = tracks[j].range_m
            if rng is not None and "longitudinal_m" in truth[i]:
                true = truth[i]["longitudinal_m"]
                self.range_errors.append((true, (rng - true) / true))
        dist = 1.0 - iou_matrix([_box(v) for v in truth], boxes)
        dist[dist > 0.5] = np.nan
        self.acc.update([v["id"] for v in truth], [t.id for t in tracks], dist)

    def confirm_delay_frames(self) -> dict[int, int]:
        return {tid: self.first_confirmed[tid] - self.first_half_visible.get(tid, self.first_confirmed[tid])
                for tid in self.first_confirmed}

    def metrics(self) -> dict:
        """Precision, recall, MOTA, IDF1, id switches, fragments and the median relative range error of
        this one sequence (None where undefined)."""
        row = mm.metrics.create().compute(self.acc, metrics=["mota", "idf1", "num_switches", "num_fragmentations"],
                                          name="drive")
        rel = [abs(e) for _, e in self.range_errors]

        def num(x) -> Optional[float]:
            x = float(x)
            return None if np.isnan(x) else round(x, 6)

        return detection_metrics(self.tp, self.fp, self.fn) | {
            "mota": num(row["mota"].iloc[0]), "idf1": num(row["idf1"].iloc[0]),
            "id_switches": int(row["num_switches"].iloc[0]), "fragments": int(row["num_fragmentations"].iloc[0]),
            "median_range_rel_error": round(float(np.median(rel)), 6) if rel else None}


def detection_metrics(tp: int, fp: int, fn: int) -> dict:
    return {"tp": tp, "fp": fp, "fn": fn,
            "precision": tp / (tp + fp) if tp + fp else None, "recall": tp / (tp + fn) if tp + fn else None}
