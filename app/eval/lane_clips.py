"""Lanes on TuSimple's 20-frame clips: each clip through the whole pipeline, scored on its frame 20.

Two ways: ``evaluate`` feeds the frames to a Pipeline with TuSimple's lane camera (pitch given);
``evaluate_replay`` replays each clip folder as ``headway replay CLIP --fps 20 --config F`` does (the frames in
the folder's natural order, the configuration's own camera and preset), e.g. with only what TuSimple's
calibration.txt holds (``write_camera_config``: intrinsics, 1.80 m height, the hood line; no pitch).

The folder holds ``label.json`` (TuSimple's format, one JSON object per line; ``raw_file`` is frame 20
of a clip, relative to the folder) and the clips' frames ``1.jpg`` .. ``20.jpg`` beside it. Every clip
starts from a fresh pipeline (no lane history) and runs its 20 frames at 20 fps through
``Pipeline.process`` (lane tracking, detection, tracking: what a user gets); the lanes reported for
frame 20 are scored with the TuSimple metric (:mod:`app.eval.tusimple_lanes`) and written as
TuSimple predictions (``{"raw_file", "lanes", "h_samples", "run_time"}`` per line).
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Callable, Optional

import cv2
import yaml

from app import config as configuration
from app.core import Pipeline
from app.eval.tusimple_boxes import TUSIMPLE_CAMERA, TUSIMPLE_LANE_PITCH_DEG, tusimple_config
from app.eval.tusimple_lanes import evaluate_lanes, segments_to_tusimple, write_predictions
from app.replay import replay_recording

FPS = 20.0           # TuSimple clips: 20 frames in one second
FRAMES_PER_CLIP = 20


def load_labels(label_file: Path) -> list[dict]:
    labels = [json.loads(x) for x in label_file.read_text().splitlines() if x.strip()]
    if not labels:
        raise ValueError(f"{label_file}: no labels")
    return labels


def clip_frames(labelled: Path) -> list[Path]:
    """Frames 1..20 of the clip whose frame 20 is `labelled`, in order."""
    frames = [labelled.parent / f"{i}.jpg" for i in range(1, FRAMES_PER_CLIP + 1)]
    missing = [f for f in frames if not f.exists()]
    if missing:
        raise FileNotFoundError(f"{missing[0]}: frame of the clip missing (expected 1.jpg .. 20.jpg beside "
                                f"{labelled.name})")
    return frames


def lane_config(config_path: Optional[str], preset: str, width: int, height: int) -> dict:
    """The core configuration for TuSimple's lane camera at width x height (the camera config must match the
    frame size: TuSimple's 1280x720 camera scaled)."""
    cfg = tusimple_config(configuration.load(config_path, {"pipeline": {"preset": preset}}), TUSIMPLE_LANE_PITCH_DEG)
    cfg["camera"] = configuration.scaled_camera(cfg["camera"], width, height)
    return configuration.core_sections(cfg)


def evaluate(clips_dir: str, config_path: Optional[str] = None, preset: str = "thesis",
             predictions_out: Optional[str] = None, on_clip: Optional[Callable] = None) -> dict:
    """TuSimple accuracy / FP / FN of frame 20 of every clip of `clips_dir` (per clip in ``per_image``).

    on_clip(label, gray_frame20, result20) is called for each clip (annotated examples)."""
    root = Path(clips_dir)
    label_file = root / "label.json"
    if not label_file.exists():
        raise FileNotFoundError(f"{label_file}: not found (expected TuSimple's label.json in the clips folder)")
    labels = load_labels(label_file)
    preds: dict[str, list] = {}
    run_ms: dict[str, float] = {}
    width = None
    for lab in labels:
        frames = clip_frames(root / lab["raw_file"])
        first = cv2.imread(str(frames[0]), cv2.IMREAD_GRAYSCALE)
        if first is None:
            raise FileNotFoundError(f"{frames[0]}: cannot be read")
        h, w = first.shape
        width = w
        with Pipeline(lane_config(config_path, preset, w, h)) as pipe:
            r = gray = None
            for i, f in enumerate(frames):
                gray = first if i == 0 else cv2.imread(str(f), cv2.IMREAD_GRAYSCALE)
                if gray is None:
                    raise FileNotFoundError(f"{f}: cannot be read")
                r = pipe.process(gray, i / FPS)
        preds[lab["raw_file"]] = segments_to_tusimple(r.lanes, lab["h_samples"], w)
        run_ms[lab["raw_file"]] = r.stages.get("lanes", r.total_ms)
        if on_clip:
            on_clip(lab, gray, r)
    if predictions_out:
        write_predictions(predictions_out, labels, preds, run_ms)
    m = evaluate_lanes(preds, label_file, image_width=width)
    return {"clips": len(labels), "accuracy": m["accuracy"], "fp": m["fp"], "fn": m["fn"],
            "per_image": m["per_image"]}


def write_camera_config(path: str, pitch_deg: Optional[float] = None) -> str:
    """A configuration file with TuSimple's camera as calibration.txt gives it (intrinsics, 1.80 m height) and the
    bonnet's 8 % hood line; the pitch only if given (without it the camera is calibrated from scratch). Returns
    `path`."""
    cam = {k: v for k, v in TUSIMPLE_CAMERA.items() if k != "pitch_deg"}
    cam["hood_frac"] = 0.08
    if pitch_deg is not None:
        cam["pitch_deg"] = pitch_deg
    cfg: dict = {"camera": cam}
    Path(path).write_text(yaml.safe_dump(cfg, sort_keys=False))
    return path


def clip_folders(clips_dir: str) -> list[tuple[dict, Path]]:
    """(label, folder of the clip's frames) for every labelled clip of `clips_dir`."""
    root = Path(clips_dir)
    label_file = root / "label.json"
    if not label_file.exists():
        raise FileNotFoundError(f"{label_file}: not found (expected TuSimple's label.json in the clips folder)")
    return [(lab, (root / lab["raw_file"]).parent) for lab in load_labels(label_file)]


def evaluate_replay(clips_dir: str, config_path: Optional[str] = None, on_frame: Optional[Callable] = None) -> dict:
    """TuSimple accuracy / FP / FN of the last frame of every clip replayed as `headway replay CLIP --fps 20`.

    on_frame(label, result) is called for every frame of every clip (the calibration's course)."""
    preds: dict[str, list] = {}
    last: dict = {}
    width = None
    clips = clip_folders(clips_dir)
    for lab, folder in clips:
        def keep(r, _decision, _truth, lab=lab):
            last["r"] = r
            if on_frame:
                on_frame(lab, r)

        replay_recording(str(folder), config_path=config_path, fps=FPS, on_result=keep, progress=False)
        width = last["r"].width
        preds[lab["raw_file"]] = segments_to_tusimple(last["r"].lanes, lab["h_samples"], width)
    m = evaluate_lanes(preds, Path(clips_dir) / "label.json", image_width=width)
    return {"clips": len(clips), "accuracy": m["accuracy"], "fp": m["fp"], "fn": m["fn"],
            "per_image": m["per_image"]}
