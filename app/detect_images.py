"""`headway detect`: single-image vehicle detection, one JSON entry per image.

Output: [{"file_name", "bbox": [{"left","top","right","bottom","score"}]}]. Each image is detected
alone (by default the "detect" stage: lanes, shadow hypotheses, vertical-edge verification; with
detector "cascade" the trained Haar cascade, with "fused" both merged), with the camera fitted to the
image's size. An image that cannot be used (unreadable, truncated, too small) is left out of the output
and listed with the reason; the others are written.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Iterable, Optional

from app import config as configuration
from app.core import Pipeline
from app.recording import read_image


class DetectError(RuntimeError):
    pass


STAGES = {"thesis": "detect", "cascade": "cascade", "fused": "fused"}  # --detector -> the core's single-image stage


def detect_images(paths: Iterable[str], config_path: Optional[str] = None, progress: bool = False,
                  bad: Optional[list[str]] = None, detector: str = "thesis") -> list[dict]:
    """One entry per usable image. Images that cannot be used go to ``bad`` ("path: why") when it is
    given; without it the first one raises DetectError."""
    stage = STAGES[detector]
    base = configuration.load(config_path)
    pipes: dict[tuple[int, int], Pipeline] = {}
    out = []
    try:
        for path in paths:
            gray, why = read_image(path)
            if gray is None:
                why = f"cannot be read as an image ({why})"
            else:
                why = configuration.frame_size_problem(gray.shape[1], gray.shape[0]) or ""
            if why:
                if bad is None:
                    raise DetectError(f"{path}: {why}")
                bad.append(f"{path}: {why}")
                continue
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
    bad: list[str] = []
    result = detect_images(args.images, args.config, bad=bad, detector=args.detector)
    if not result and bad:
        raise DetectError(bad[0] if len(bad) == 1 else f"none of the {len(bad)} images can be used: " + "; ".join(bad[:5]))
    Path(args.out).write_text(json.dumps(result, indent=1))
    print(f"{len(result)} images, {sum(len(e['bbox']) for e in result)} vehicles -> {args.out}")
    for line in bad:
        print(f"headway: skipped {line}", file=sys.stderr)
    return 1 if bad else 0
