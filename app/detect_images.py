"""`headway detect`: single-image vehicle detection, one JSON entry per image.

Output: [{"file_name", "bbox": [{"left","top","right","bottom","score"}]}]. Each image goes alone through the
pipeline's detection stage (the configuration's preset, default `default`: the learned detector with the shadow
detector's cues; Pipeline.detect, the stage a tracked pipeline asks for its detections), with the
camera fitted to the image's size. An image that cannot be used (unreadable, truncated, too small) is left out of
the output and listed with the reason; the others are written.

Only detections scoring at least the preset's operating point are written (OPERATING_POINT, or --min-score; 0
writes every detection, for a score curve of one's own).
"""
from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Iterable, Optional

from app import config as configuration
from app.core import Pipeline
from app.output_files import check_outputs, numbered, write_whole
from app.recording import read_image


class DetectError(RuntimeError):
    pass


# The score a detection must reach to be written, per preset: the lowest threshold (0.01 apart) at which precision
# (boxes >= 40 px, IoU >= 0.5) reaches 0.85 on 800 training images the verifier never saw (TuSimple 0602, 0612, ...
# and 0606, 0616, ...; docs/detection.md, "Operating points of `headway detect`"), not on the validation split. The
# thesis detector reaches no such precision at any score: every detection is written; so for a composition of
# one's own (pipeline.detectors).
OPERATING_POINT = {"default": 0.73, "paper004": 0.69}


def operating_point(cfg: dict) -> float:
    """The score `headway detect` writes from with this configuration (its preset's, unless its detectors are
    the configuration's own)."""
    if cfg["pipeline"].get("detectors"):
        return 0.0
    return OPERATING_POINT.get(cfg["pipeline"]["preset"], 0.0)


def detector_config(config_path: Optional[str], preset: Optional[str] = None) -> dict:
    """The configuration a detection runs with: the file's (or the defaults), with `preset` when given."""
    return configuration.load(config_path, {"pipeline": {"preset": preset}} if preset else None)


def read_usable(path: str) -> tuple:
    """(gray, "") or (None, why): the image read whole and decoded, at a size a camera may have."""
    gray, why = read_image(path)
    if gray is None:
        return None, f"cannot be read as an image ({why})"
    why = configuration.frame_size_problem(gray.shape[1], gray.shape[0])
    return (None, why) if why else (gray, "")


def scaled_camera_note(base: dict, size: tuple[int, int], configured: bool) -> Optional[str]:
    """What a user is told when images of `size` get the configuration's camera scaled to them (None: its own size):
    the detections depend on the camera (which rows can hold a vehicle of each size)."""
    cam = (base["camera"]["width"], base["camera"]["height"])
    if size == cam:
        return None
    return (f"{size[0]}x{size[1]} images: the {'configured' if configured else 'default'} camera ({cam[0]}x{cam[1]}) "
            f"scaled to them; for the figures of docs/detection.md give --config with the images' own camera "
            f"(TuSimple's: app/eval/data/tusimple_camera.yaml)")


def image_pipeline(base: dict, width: int, height: int) -> Pipeline:
    """The pipeline that detects in images of this size: the configuration with its camera scaled to them."""
    cfg = dict(base)
    cfg["camera"] = configuration.scaled_camera(base["camera"], width, height)
    return Pipeline(configuration.core_sections(cfg))


def image_entry(path: str, detections, min_score: float) -> dict:
    """The output's entry of one image: its detections (Detections.rows()) scoring at least `min_score`."""
    return {"file_name": Path(path).name, "bbox": [
        {"left": round(l, 1), "top": round(t, 1), "right": round(r, 1), "bottom": round(b, 1), "score": round(s, 4)}
        for l, t, r, b, s in detections if s >= min_score]}


def detect_images(paths: Iterable[str], config_path: Optional[str] = None, progress: bool = False,
                  bad: Optional[list[str]] = None, preset: Optional[str] = None,
                  min_score: Optional[float] = None, notes: Optional[list[str]] = None) -> list[dict]:
    """One entry per usable image, with the detections scoring at least `min_score` (None: the preset's
    OPERATING_POINT). Images that cannot be used go to ``bad`` ("path: why") when it is given; without it
    the first one raises DetectError. Each image size the configured camera is scaled to gives a line in ``notes``
    (the detections depend on the camera: which rows can hold a vehicle of each size)."""
    base = detector_config(config_path, preset)
    if min_score is None:
        min_score = operating_point(base)
    if not 0.0 <= min_score <= 1.0:
        raise DetectError(f"--min-score {min_score}: scores lie in [0, 1]; give a value in that range "
                          f"(0 writes every detection)")
    pipes: dict[tuple[int, int], Pipeline] = {}
    out = []
    try:
        for path in paths:
            gray, why = read_usable(path)
            if why:
                if bad is None:
                    raise DetectError(f"{path}: {why}")
                bad.append(f"{path}: {why}")
                continue
            size = (gray.shape[1], gray.shape[0])
            if size not in pipes:  # one pipeline per image size, camera scaled to it
                pipes[size] = image_pipeline(base, *size)
                note = scaled_camera_note(base, size, config_path is not None)
                if note and notes is not None:
                    notes.append(note)
            out.append(image_entry(path, pipes[size].detect(gray).rows(), min_score))
    finally:
        for p in pipes.values():
            p.close()
    return out


def add_parser(subparsers) -> None:
    s = subparsers.add_parser("detect", help="single-image vehicle detection to JSON")
    s.add_argument("images", nargs="+", help="image files")
    s.add_argument("--out", required=True, help="output JSON file")
    s.add_argument("--config", help="configuration YAML; its camera should be the images' (default: Headway's "
                                    "640x480 camera, scaled to the images' size)")
    s.add_argument("--preset", choices=configuration.single_image_presets(),
                   help=f"the preset whose detection stage runs (default: the configuration's, `{configuration.default_preset()}`)")
    s.add_argument("--min-score", type=float, default=None,
                   help="write only detections scoring at least this (0-1); default: the preset's operating point "
                        "(precision 0.85 on held-out training images: docs/detection.md; thesis: every detection); 0 "
                        "writes every detection")
    s.set_defaults(run=run)


def run(args) -> int:
    check_outputs({"--out": args.out}, {**numbered("input", args.images), "--config": args.config})
    bad: list[str] = []
    notes: list[str] = []
    result = detect_images(args.images, args.config, bad=bad, preset=args.preset, min_score=args.min_score,
                           notes=notes)
    if not result and bad:
        raise DetectError(bad[0] if len(bad) == 1 else f"none of the {len(bad)} images can be used: " + "; ".join(bad[:5]))
    write_whole(args.out, json.dumps(result, indent=1))
    print(f"{len(result)} images, {sum(len(e['bbox']) for e in result)} vehicles -> {args.out}")
    for line in notes:
        print(f"headway: note: {line}", file=sys.stderr)
    for line in bad:
        print(f"headway: skipped {line}", file=sys.stderr)
    return 1 if bad else 0
