"""`headway detect`: single-image vehicle detection, one JSON entry per image.

Output: [{"file_name", "bbox": [{"left","top","right","bottom","score"}]}]. Each image is detected
alone (by default the "detect" stage: lanes, shadow hypotheses, vertical-edge verification; with
detector "cascade" the trained Haar cascade, with "fused" both merged), with the camera fitted to the image's size.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Iterable, Optional

import cv2

from app import config as configuration
from app.core import Pipeline


class DetectError(RuntimeError):
    pass


STAGES = {"thesis": "detect", "cascade": "cascade", "fused": "fused"}  # --detector -> the core's single-image stage


def detect_images(paths: Iterable[str], config_path: Optional[str] = None, progress: bool = False,
                  detector: str = "thesis") -> list[dict]:
    stage = STAGES[detector]
    base = configuration.load(config_path)
    pipes: dict[tuple[int, int], Pipeline] = {}
    out = []
    try:
        for path in paths:
            gray = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
            if gray is None:
                raise DetectError(f"{path}: cannot be read as an image")
            size = (gray.shape[1], gray.shape[0])
            if size not in pipes:  # one pipeline per image size, camera scaled to it
                cfg = dict(base)
                cfg["camera"] = configuration.scaled_camera(base["camera"], *size)
                pipes[size] = Pipeline(configuration.core_sections(cfg))
            r = pipes[size].run_stage(stage, gray)
            out.append({"file_name": Path(path).name, "bbox": [
                {"left": round(t.box[0], 1), "top": round(t.box[1], 1), "right": round(t.box[2], 1),
                 "bottom": round(t.box[3], 1), "score": round(t.confidence, 4)} for t in r.tracks]})
    finally:
        for p in pipes.values():
            p.close()
    return out


def main(args) -> int:
    result = detect_images(args.images, args.config, detector=args.detector)
    Path(args.out).write_text(json.dumps(result, indent=1))
    print(f"{len(result)} images, {sum(len(e['bbox']) for e in result)} vehicles -> {args.out}")
    return 0
