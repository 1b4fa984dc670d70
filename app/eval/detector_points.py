"""A composition of detector parts on annotated TuSimple images, as `headway detect --config
app/eval/data/tusimple_camera.yaml` runs it: the configuration's pipeline `{detectors: [...], tracker: kalman}` on the
recordings' camera, one pipeline per image size with the camera scaled to it (detect_images.image_pipeline), each
image through the core's single-image stage "detect"; scored as `headway eval` scores the TuSimple validation split
(boxes >= 40 px, IoU 0.5; app/eval/tusimple_boxes.py).

The operating point is chosen on held-out training images, never on the validation split: `--choose` gives the
lowest score (0.01 apart) whose precision reaches the asked one there; `--at` reports the validation split at a
threshold chosen so.

    python -m app.eval.detector_points --detectors proposals --images DIR [--every 10 --from 9] [--set KEY=VALUE ...]
        [--limit N] [--choose 0.87 | --at 0.42] [--json FILE]
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Optional

import yaml

from app import config as configuration
from app.detect_images import image_pipeline, read_usable
from app.eval.tusimple_boxes import band_counts, load_entries, operating_curve, recall_at_precision, tusimple_config
from app.output_files import write_whole

THRESHOLDS = [i / 100 for i in range(100)]


def composition_config(detectors: list[str], sets: Optional[list[str]] = None) -> dict:
    """The default configuration on the TuSimple recordings' camera (app/eval/data/tusimple_camera.yaml, as `headway
    eval` scores them) with pipeline {detectors, tracker: kalman} and each `section.key=value` of `sets` (value read
    as YAML, a string key's as it is: "off" stays "off")."""
    over: dict = {"pipeline": {"detectors": detectors, "tracker": "kalman"}}
    for s in sets or []:
        key, sep, value = s.partition("=")
        section, dot, name = key.partition(".")
        if not sep or not dot:
            raise ValueError(f"--set {s!r}: give SECTION.KEY=VALUE, e.g. proposals.verifier=off")
        typed = configuration.schema().get(section, {}).get(name, {}).get("type") != "str"
        over.setdefault(section, {})[name] = yaml.safe_load(value) if typed else value
    return tusimple_config(configuration.load(None, over))


def scored_images(folder: str, entries: list[dict], cfg: dict, progress=None) -> list[list[tuple]]:
    """(left, top, right, bottom, score) of every detection of each entry's image."""
    pipes = {}
    out = []
    try:
        for e in entries:
            path = str(Path(folder) / e["file_name"])
            gray, why = read_usable(path)
            if why:
                raise FileNotFoundError(f"{path}: {why}")
            size = (gray.shape[1], gray.shape[0])
            if size not in pipes:
                pipes[size] = image_pipeline(cfg, *size)
            out.append(pipes[size].detect(gray).rows())
            if progress:
                progress(1)
    finally:
        for p in pipes.values():
            p.close()
    return out


def lowest_at_precision(curve: list[dict], min_precision: float) -> Optional[dict]:
    """The curve point of the lowest threshold whose precision reaches `min_precision` (None if none)."""
    ok = [c for c in curve if c["precision"] is not None and c["precision"] >= min_precision]
    return min(ok, key=lambda c: c["threshold"]) if ok else None


def summary(entries: list[dict], scored: list[list[tuple]], at: Optional[float] = None) -> dict:
    curve = operating_curve(entries, scored, THRESHOLDS)
    out = {"images": len(entries), "every_detection": band_counts(entries, [[d[:4] for d in det] for det in scored])[">=40"],
           "best_at_precision_0.85": recall_at_precision(curve, 0.85),
           "best_at_precision_0.87": recall_at_precision(curve, 0.87), "curve_ge40": curve,
           "detections_per_image": sum(len(d) for d in scored) / max(1, len(scored))}
    if at is not None:
        out["at"] = operating_curve(entries, scored, [at])[0]
    return out


def main(argv: Optional[list[str]] = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--detectors", required=True, help="detector parts, comma-separated (e.g. proposals,cascade)")
    p.add_argument("--images", required=True, help="folder with annotation.json (TuSimple format)")
    p.add_argument("--every", type=int, default=1, help="only images k with k %% EVERY == FROM (default: all)")
    p.add_argument("--from", dest="start", type=int, default=0)
    p.add_argument("--limit", type=int, default=0, help="only the first N images chosen (0 = all)")
    p.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE")
    p.add_argument("--choose", type=float, help="report the lowest score reaching this precision (held-out images)")
    p.add_argument("--at", type=float, help="report recall and precision at this score threshold")
    p.add_argument("--json", help="write the whole result here")
    a = p.parse_args(argv)
    if a.every < 1 or not 0 <= a.start < a.every:
        print(f"detector_points: --every {a.every} --from {a.start}: give EVERY >= 1 and 0 <= FROM < EVERY",
              file=sys.stderr)
        return 2
    entries = load_entries(a.images)
    entries = [e for k, e in enumerate(entries) if k % a.every == a.start][:a.limit or None]
    cfg = composition_config([d.strip() for d in a.detectors.split(",") if d.strip()], a.set)
    r = summary(entries, scored_images(a.images, entries, cfg), a.at)
    if a.choose is not None:
        r["chosen"] = lowest_at_precision(r["curve_ge40"], a.choose)
    r.update(detectors=a.detectors, sets=a.set, folder=a.images, every=a.every, start=a.start)
    if a.json:
        write_whole(a.json, json.dumps(r, indent=1))
    print(json.dumps({k: v for k, v in r.items() if k != "curve_ge40"}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
