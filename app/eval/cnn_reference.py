"""A CNN detector on the TuSimple vehicle images, scored exactly like Headway's own detectors: what the
issue's bar means against what a user could pick instead of a classical method.

The model is NanoDet-m 416 (COCO), read from `../shared/baselines/cnn/nanodet_m_416.onnx` through
OpenCV's dnn module. It comes without a licence: it is run here for comparison only, never shipped
nor used by any pipeline. Its classes car, bus and truck count as vehicles.

    python -m app.eval.cnn_reference [--model PATH] [--supp DIR] [--limit N] [--json FILE]

prints a markdown table (docs/RESULTS.md); --json writes the whole result with the score curve.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Optional

import cv2
import numpy as np

from app.eval.tusimple_boxes import band_counts, load_entries, operating_curve, recall_at_precision

INPUT = 416
STRIDES = (8, 16, 32)
REG_BINS = 8                     # NanoDet's distance distribution: 8 bins per box side, in strides
VEHICLE_CLASSES = (2, 5, 7)      # COCO car, bus, truck
MEAN_BGR = np.array([103.53, 116.28, 123.675], np.float32)
STD_BGR = np.array([57.375, 57.12, 58.395], np.float32)
MIN_SCORE = 0.05
NMS_IOU = 0.6
OPERATING_SCORE = 0.35           # the score threshold of NanoDet's own demo: the point reported as its result


class NanoDet:
    def __init__(self, model: Path):
        if not model.exists():
            raise FileNotFoundError(f"{model}: NanoDet-m ONNX model not found (it sits in ../shared/baselines/cnn)")
        self.net = cv2.dnn.readNetFromONNX(str(model))
        self.outputs = self.net.getUnconnectedOutLayersNames()
        if len(self.outputs) != 2 * len(STRIDES):
            raise ValueError(f"{model}: expected {2 * len(STRIDES)} outputs (scores and box distances per stride), "
                             f"found {len(self.outputs)}")

    def detect(self, bgr: np.ndarray) -> list[tuple[float, float, float, float, float]]:
        """Vehicle boxes (left, top, right, bottom, score) in the image's pixels, after NMS."""
        h, w = bgr.shape[:2]
        x = (cv2.resize(bgr, (INPUT, INPUT)).astype(np.float32) - MEAN_BGR) / STD_BGR
        self.net.setInput(x.transpose(2, 0, 1)[None])
        outs = self.net.forward(self.outputs)
        boxes, scores = [], []
        for k, stride in enumerate(STRIDES):
            cls, reg = outs[2 * k][0], outs[2 * k + 1][0]
            score = cls[:, VEHICLE_CLASSES].max(axis=1)
            keep = np.flatnonzero(score > MIN_SCORE)
            if keep.size == 0:
                continue
            d = reg[keep].reshape(-1, 4, REG_BINS)
            d = np.exp(d - d.max(axis=2, keepdims=True))
            dist = (d / d.sum(axis=2, keepdims=True) * np.arange(REG_BINS)).sum(axis=2) * stride
            cols = INPUT // stride
            cx, cy = (keep % cols + 0.5) * stride, (keep // cols + 0.5) * stride  # cell centres
            sx, sy = w / INPUT, h / INPUT
            for (l, t, r, b), s, x0, y0 in zip(dist, score[keep], cx, cy):
                boxes.append([(x0 - l) * sx, (y0 - t) * sy, (x0 + r) * sx, (y0 + b) * sy])
                scores.append(float(s))
        if not boxes:
            return []
        keep = cv2.dnn.NMSBoxes([(b[0], b[1], b[2] - b[0], b[3] - b[1]) for b in boxes], scores, MIN_SCORE, NMS_IOU)
        return [(*boxes[i], scores[i]) for i in np.ravel(keep)]


def evaluate(supp_dir: str, model: str, limit: Optional[int] = None) -> dict:
    net = NanoDet(Path(model))
    root = Path(supp_dir)
    entries = load_entries(supp_dir, limit)
    scored = []
    for e in entries:
        bgr = cv2.imread(str(root / e["file_name"]), cv2.IMREAD_COLOR)
        if bgr is None:
            raise FileNotFoundError(f"{root / e['file_name']}: cannot be read")
        scored.append(net.detect(bgr))
    curve = operating_curve(entries, scored, [i / 20 for i in range(2, 16)])
    at = [[d[:4] for d in det if d[4] >= OPERATING_SCORE] for det in scored]
    return {"model": Path(model).name, "images": len(entries), "operating_score": OPERATING_SCORE,
            "bands": band_counts(entries, at), "curve_ge40": curve,
            "best_at_precision_0.8": recall_at_precision(curve, 0.8)}


def markdown(r: dict) -> str:
    out = [f"### Reference: {r['model']} (COCO car/bus/truck, score >= {r['operating_score']}) on the same "
           f"{r['images']} images", "", "| box height | ground truth | detected | false positives | recall | precision |",
           "| --- | ---: | ---: | ---: | ---: | ---: |"]
    for band, b in r["bands"].items():
        label = "all" if band == "overall" else f"{band} px"
        out.append(f"| {label} | {b['gt']} | {b['tp']} | {b['fp']} | {b['recall']:.3f} | "
                   f"{'n/a' if b['precision'] is None else format(b['precision'], '.3f')} |")
    best = r["best_at_precision_0.8"]
    if best:
        out += ["", f"Best recall at precision >= 0.8 (boxes >= 40 px): {best['recall']:.3f} at score "
                    f">= {best['threshold']:.2f} (precision {best['precision']:.3f})."]
    return "\n".join(out)


def main(argv: Optional[list[str]] = None) -> int:
    here = Path(__file__).resolve().parents[2]
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--model", default=str(here.parent / "shared" / "baselines" / "cnn" / "nanodet_m_416.onnx"))
    p.add_argument("--supp", default=str(here.parent / "shared" / "data" / "tusimple" / "supp"))
    p.add_argument("--limit", type=int)
    p.add_argument("--json", help="write the whole result here")
    a = p.parse_args(argv)
    try:
        r = evaluate(a.supp, a.model, a.limit)
    except (FileNotFoundError, ValueError) as e:
        print(f"cnn_reference: {e}", file=sys.stderr)
        return 2
    if a.json:
        Path(a.json).write_text(json.dumps(r, indent=1))
    print(markdown(r))
    return 0


if __name__ == "__main__":
    sys.exit(main())
