"""Range on a real clip: TuSimple train_clip1 (20 fps, annotated last frame with range-sensor positions)."""
from __future__ import annotations

import json
from pathlib import Path
from typing import Optional

import cv2

from app import config as configuration
from app.core import Pipeline
from app.eval.matching import match
from app.eval.tusimple_boxes import tusimple_config
from app.recording import folder_images


def evaluate(clip_dir: str, config_path: Optional[str] = None, preset: str = "thesis", fps: float = 20.0) -> dict:
    root = Path(clip_dir)
    frames = folder_images(root / "imgs")
    ann = json.loads((root / "annotation.json").read_text())
    cfg = tusimple_config(configuration.load(config_path, {"pipeline": {"preset": preset}}))
    with Pipeline(configuration.core_sections(cfg)) as pipe:
        for i, path in enumerate(frames):
            r = pipe.process(cv2.imread(str(path), cv2.IMREAD_GRAYSCALE), i / fps)
    gt = [(a["bbox"]["left"], a["bbox"]["top"], a["bbox"]["right"], a["bbox"]["bottom"]) for a in ann]
    tracks = [t for t in r.tracks if t.range_m is not None]
    pairs = {i: j for i, j, _ in match(gt, [t.box for t in tracks], 0.3)}
    vehicles = []
    for i, a in enumerate(ann):
        true = float(a["position"][0])
        entry = {"true_range_m": true, "true_lateral_m": float(a["position"][1]), "found": i in pairs}
        if i in pairs:
            t = tracks[pairs[i]]
            entry.update(range_m=t.range_m, error_m=t.range_m - true, rel_error=(t.range_m - true) / true,
                         lateral_m=t.lateral_m, range_rate_mps=t.range_rate_mps,
                         true_range_rate_mps=float(a["velocity"][0]), confirmed=t.confirmed)
        vehicles.append(entry)
    return {"frames": len(frames), "vehicles": vehicles}
