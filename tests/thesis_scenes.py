"""Shared by the thesis detector and tracker tests: rendered scenarios, runs through the core, and
the rules that match reported boxes with the ground truth."""
from __future__ import annotations

import dataclasses
import functools
import json

from app.core import Pipeline
from app.sim import load_scenario, render
from app.sim.frames import scenario_camera

LEAD_RANGE_M = 60.0  # the lead must be found wherever it is fully visible up to this range


@functools.lru_cache(maxsize=None)
def frames(name: str, camera_json: str = "{}") -> tuple:
    """Every frame of a shipped scenario, drawn with plain rear faces (whose dark gap and outline are the shadow
    method's cues; docs/sim.md, "Real-looking vehicles"); cached: several tests read the same run."""
    scenario = dataclasses.replace(load_scenario(name), vehicle_look="plain")
    return tuple(render(scenario, camera_overrides=json.loads(camera_json)))


def config(name: str, camera_json: str = "{}", **sections) -> dict:
    """Core configuration for the thesis pipeline on the scenario's own camera."""
    cam = {**scenario_camera(load_scenario(name)).to_dict(), **json.loads(camera_json)}
    return {"pipeline": {"preset": "thesis"}, "camera": cam, **sections}


@functools.lru_cache(maxsize=None)
def tracked(name: str, sections_json: str = "{}") -> tuple:
    """(frames, results) of the whole scenario through process()."""
    fr = frames(name)
    with Pipeline(config(name, **json.loads(sections_json))) as p:
        return fr, tuple(p.process(f.image, f.t_s) for f in fr)


@functools.lru_cache(maxsize=None)
def detected(name: str, camera_json: str = "{}", sections_json: str = "{}") -> tuple:
    """(frames, Detections) of Pipeline.detect on every frame alone."""
    fr = frames(name, camera_json)
    with Pipeline(config(name, camera_json, **json.loads(sections_json))) as p:
        return fr, tuple(p.detect(f.image) for f in fr)


def iou(a, b) -> float:
    iw = min(a[2], b[2]) - max(a[0], b[0])
    ih = min(a[3], b[3]) - max(a[1], b[1])
    if iw <= 0 or ih <= 0:
        return 0.0
    inter = iw * ih
    return inter / ((a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - inter)


def on_vehicle(box, truth_box) -> bool:
    """A reported box on a real vehicle: IoU >= 0.3, or standing on its bottom edge (half of the
    narrower width overlapping, bottoms within 15 % of the width + 2 px); the second case covers
    a tall vehicle whose top the detector estimates low."""
    if iou(box, truth_box) >= 0.3:
        return True
    w = truth_box[2] - truth_box[0]
    overlap = min(box[2], truth_box[2]) - max(box[0], truth_box[0])
    return overlap >= 0.5 * min(w, box[2] - box[0]) and abs(box[3] - truth_box[3]) <= 0.15 * w + 2


def false_boxes(boxes, truth) -> list:
    """The boxes that are on no vehicle of the truth."""
    return [b for b in boxes if not any(on_vehicle(b, g["box"]) for g in truth)]


def lead(truth) -> dict | None:
    """The nearest vehicle in the ego lane, if it is fully visible within LEAD_RANGE_M."""
    ego = [g for g in truth if g["lane"] == 0]
    if not ego:
        return None
    g = min(ego, key=lambda v: v["longitudinal_m"])
    return g if g["visible_fraction"] >= 0.999 and g["longitudinal_m"] <= LEAD_RANGE_M else None


def best_match(boxes, truth_box):
    """(index, IoU) of the box overlapping truth_box most; (None, 0) without boxes."""
    scored = [(iou(b, truth_box), i) for i, b in enumerate(boxes)]
    if not scored:
        return None, 0.0
    v, i = max(scored)
    return i, v


def edge_errors(box, truth_box) -> tuple[float, float, float]:
    """|left|, |right|, |bottom| errors in px: the edges the method measures (the top is derived)."""
    return abs(box[0] - truth_box[0]), abs(box[2] - truth_box[2]), abs(box[3] - truth_box[3])
