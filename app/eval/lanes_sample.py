"""Lane detection on the TuSimple lane sample: the TuSimple metric and the ego-lane hit rate."""
from __future__ import annotations

import json
from pathlib import Path
from typing import Callable, Optional

import cv2

from app import config as configuration
from app.core import Pipeline
from app.eval.tusimple_boxes import TUSIMPLE_CAMERA
from app.eval.tusimple_lanes import evaluate_lanes, segments_to_tusimple

EGO_POINT_SHARE = 0.85  # share of a ground-truth lane's rows within the threshold for a boundary to count


def _ego_found(lanes, label: dict, width: int) -> bool:
    """Both ego boundaries of the model lie on ground-truth lanes (TuSimple point criterion)."""
    ego = [l for l in lanes if l.position in (-1, 1)]
    if len(ego) != 2:
        return False
    thresh = 20.0 * width / 1280
    h = label["h_samples"]
    for pred in segments_to_tusimple(ego, h, width):
        best = 0.0
        for gt in label["lanes"]:
            rows = [(p, g) for p, g in zip(pred, gt) if g >= 0]
            if rows:
                best = max(best, sum(1 for p, g in rows if p >= 0 and abs(p - g) < thresh) / len(rows))
        if best < EGO_POINT_SHARE:
            return False
    return True


def evaluate(sample_dir: str, config_path: Optional[str] = None, on_image: Optional[Callable] = None) -> dict:
    root = Path(sample_dir)
    label_file = next(root.rglob("label_data.json"))
    labels = [json.loads(x) for x in label_file.read_text().splitlines() if x.strip()]
    preds, ego_hits = {}, 0
    pipes: dict[tuple[int, int], Pipeline] = {}
    try:
        for lab in labels:
            gray = cv2.imread(str(label_file.parent / lab["raw_file"]), cv2.IMREAD_GRAYSCALE)
            if gray is None:
                raise FileNotFoundError(f"{label_file.parent / lab['raw_file']}: cannot be read")
            size = (gray.shape[1], gray.shape[0])
            if size not in pipes:  # the sample is TuSimple's camera scaled down
                cfg = configuration.load(config_path)
                cfg["camera"] = configuration.scaled_camera({**cfg["camera"], **TUSIMPLE_CAMERA}, *size)
                pipes[size] = Pipeline(configuration.core_sections(cfg))
            r = pipes[size].run_stage("lanes", gray)
            preds[lab["raw_file"]] = r.lanes
            ego_hits += _ego_found(r.lanes, lab, size[0])
            if on_image:
                on_image(lab, gray, r)
    finally:
        for p in pipes.values():
            p.close()
    m = evaluate_lanes(preds, label_file)
    return {"images": len(labels), "accuracy": m["accuracy"], "fp": m["fp"], "fn": m["fn"],
            "ego_lane_found": ego_hits}
