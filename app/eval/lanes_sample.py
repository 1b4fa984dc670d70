"""Lane detection on the TuSimple lane sample: the TuSimple metric and the ego-lane hit rate."""
from __future__ import annotations

import json
from pathlib import Path
from typing import Callable, Optional

import cv2
import numpy as np

from app import config as configuration
from app.core import Pipeline
from app.eval.tusimple_boxes import TUSIMPLE_LANE_PITCH_DEG, tusimple_config
from app.eval.tusimple_lanes import evaluate_lanes, lane_threshold, segments_to_tusimple, write_predictions

def boundary_on_gt_lane(lane, label: dict, width: int) -> bool:
    """The boundary lies on one ground-truth lane: over the rows both have, on average within that
    lane's TuSimple threshold (20 px at 1280 wide, divided by the cosine of the lane's angle), and
    those rows cover at least half of the lane."""
    pred = segments_to_tusimple([lane], label["h_samples"], width)
    if not pred:
        return False
    for gt in label["lanes"]:
        gt_rows = [i for i, g in enumerate(gt) if g >= 0]
        both = [i for i in gt_rows if pred[0][i] >= 0]
        thresh = lane_threshold(gt, label["h_samples"], 20.0 * width / 1280)
        if gt_rows and len(both) >= 0.5 * len(gt_rows) and \
                float(np.mean([abs(pred[0][i] - gt[i]) for i in both])) < thresh:
            return True
    return False


def ego_lane_found(lanes, label: dict, width: int) -> bool:
    """Both ego boundaries of the model found, each on a ground-truth lane."""
    ego = [l for l in lanes if l.position in (-1, 1)]
    return len({l.position for l in ego}) == 2 and all(boundary_on_gt_lane(l, label, width) for l in ego)


def evaluate(sample_dir: str, config_path: Optional[str] = None, on_image: Optional[Callable] = None,
             predictions_out: Optional[str] = None) -> dict:
    """Each image alone (Pipeline.image_lanes, no history), scored with the TuSimple metric; the predictions
    are written in TuSimple's format to `predictions_out` when given."""
    root = Path(sample_dir)
    label_file = next(root.rglob("label_data.json"))
    labels = [json.loads(x) for x in label_file.read_text().splitlines() if x.strip()]
    preds, ego_hits, run_ms = {}, 0, {}
    pipes: dict[tuple[int, int], Pipeline] = {}
    try:
        for lab in labels:
            gray = cv2.imread(str(label_file.parent / lab["raw_file"]), cv2.IMREAD_GRAYSCALE)
            if gray is None:
                raise FileNotFoundError(f"{label_file.parent / lab['raw_file']}: cannot be read")
            size = (gray.shape[1], gray.shape[0])
            if size not in pipes:  # the sample is TuSimple's camera scaled down
                cfg = tusimple_config(configuration.load(config_path), TUSIMPLE_LANE_PITCH_DEG)
                cfg["camera"] = configuration.scaled_camera(cfg["camera"], *size)
                cfg["pipeline"] = {**cfg.get("pipeline", {}), "preset": "none"}  # lanes alone
                pipes[size] = Pipeline(configuration.core_sections(cfg))
            r = pipes[size].image_lanes(gray)
            preds[lab["raw_file"]] = segments_to_tusimple(r.lanes, lab["h_samples"], size[0])
            run_ms[lab["raw_file"]] = r.stages.get("lanes", r.total_ms)
            ego_hits += ego_lane_found(r.lanes, lab, size[0])
            if on_image:
                on_image(lab, gray, r)
    finally:
        for p in pipes.values():
            p.close()
    if predictions_out:
        write_predictions(predictions_out, labels, preds, run_ms)
    m = evaluate_lanes(preds, label_file)
    return {"images": len(labels), "accuracy": m["accuracy"], "fp": m["fp"], "fn": m["fn"],
            "ego_lane_found": ego_hits}
