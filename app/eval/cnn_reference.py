"""A CNN detector on the TuSimple vehicle images, scored exactly like Headway's own detectors: what the
issue's bar means against what a user could pick instead of a classical method.

The models are NanoDet-m 416 (COCO), `../shared/baselines/cnn/nanodet_m_416.onnx`, and Yolo-FastestV2 352 (COCO),
`../shared/baselines/cnn/yolo_fastestv2_352.onnx` (`YoloFastestV2`), read through OpenCV's dnn module. They come
without a licence: they are run here for comparison only, never shipped nor used by any pipeline. Their classes car,
bus and truck count as vehicles.

    python -m app.eval.cnn_reference [--model PATH] [--supp DIR] [--limit N] [--runtime opencv|onnxruntime] [--json FILE]

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
from app.output_files import write_whole

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


class YoloFastestV2:
    """Yolo-FastestV2 352 as its authors' demo decodes it. The export's one output (605, 95) holds the 22x22 cells
    of stride 16, then the 11x11 of stride 32; per cell 3 anchors' boxes (4 each, after a sigmoid), their 3
    objectness values and the 80 class probabilities (softmax). Input: the BGR image resized to 352 x 352, / 255.
    Run by OpenCV's dnn module, or with runtime "onnxruntime" by ONNX Runtime on one thread (pip install onnxruntime;
    not a dependency of Headway: a reference only)."""
    INPUT = 352
    ANCHORS = ((12.64, 19.39), (37.88, 51.48), (55.71, 138.31), (126.91, 78.23), (131.57, 214.55), (279.92, 258.87))
    NMS_IOU = 0.45

    def __init__(self, model: Path, runtime: str = "opencv"):
        if not model.exists():
            raise FileNotFoundError(f"{model}: Yolo-FastestV2 ONNX model not found (it sits in ../shared/baselines/cnn)")
        if runtime == "onnxruntime":
            try:
                import onnxruntime as ort
            except ImportError:
                raise ValueError("--runtime onnxruntime: ONNX Runtime is not installed (pip install onnxruntime)") from None
            opts = ort.SessionOptions()
            opts.intra_op_num_threads = opts.inter_op_num_threads = 1
            sess = ort.InferenceSession(str(model), opts, providers=["CPUExecutionProvider"])
            name = sess.get_inputs()[0].name
            self.run = lambda x: sess.run(None, {name: x})[0]
        elif runtime == "opencv":
            net = cv2.dnn.readNetFromONNX(str(model))

            def run(x):
                net.setInput(x)
                return net.forward()
            self.run = run
        else:
            raise ValueError(f"--runtime {runtime!r}: opencv or onnxruntime")

    def detect(self, bgr: np.ndarray) -> list[tuple[float, float, float, float, float]]:
        """Vehicle boxes (left, top, right, bottom, score) in the image's pixels, after NMS; score =
        objectness^0.4 class^0.6 (the demo's)."""
        h, w = bgr.shape[:2]
        x = cv2.resize(bgr, (self.INPUT, self.INPUT)).astype(np.float32) / 255.0
        out = np.asarray(self.run(np.ascontiguousarray(x.transpose(2, 0, 1)[None]))).reshape(-1, 95)
        if out.shape != (605, 95):
            raise ValueError(f"Yolo-FastestV2: expected an output of (605, 95), found {out.shape}")
        boxes, scores = [], []
        start = 0
        for level, stride in enumerate((16, 32)):
            n = self.INPUT // stride
            cells = out[start:start + n * n]
            start += n * n
            cls = cells[:, 15:][:, list(VEHICLE_CLASSES)].max(axis=1)
            gy, gx = np.divmod(np.arange(n * n), n)
            for a in range(3):
                score = cells[:, 12 + a] ** 0.4 * cls ** 0.6
                keep = np.flatnonzero(score > MIN_SCORE)
                reg = cells[keep, 4 * a:4 * a + 4]
                aw, ah = self.ANCHORS[3 * level + a]
                cx = (reg[:, 0] * 2 - 0.5 + gx[keep]) * stride
                cy = (reg[:, 1] * 2 - 0.5 + gy[keep]) * stride
                bw, bh = (reg[:, 2] * 2) ** 2 * aw, (reg[:, 3] * 2) ** 2 * ah
                sx, sy = w / self.INPUT, h / self.INPUT
                for x0, y0, ww, hh, s in zip(cx, cy, bw, bh, score[keep]):
                    boxes.append([(x0 - ww / 2) * sx, (y0 - hh / 2) * sy, (x0 + ww / 2) * sx, (y0 + hh / 2) * sy])
                    scores.append(float(s))
        if not boxes:
            return []
        keep = cv2.dnn.NMSBoxes([(b[0], b[1], b[2] - b[0], b[3] - b[1]) for b in boxes], scores, MIN_SCORE,
                                self.NMS_IOU)
        return [(*boxes[i], scores[i]) for i in np.ravel(keep)]


def reference(model: str, runtime: str = "opencv"):
    """The detector the model file holds: Yolo-FastestV2 when its name says so, else NanoDet-m (OpenCV only)."""
    if "yolo" in Path(model).name.lower():
        return YoloFastestV2(Path(model), runtime)
    if runtime != "opencv":
        raise ValueError(f"--runtime {runtime}: NanoDet-m is run by OpenCV's dnn module only")
    return NanoDet(Path(model))


def evaluate(supp_dir: str, model: str, limit: Optional[int] = None, runtime: str = "opencv") -> dict:
    net = reference(model, runtime)
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
            "best_at_precision_0.8": recall_at_precision(curve, 0.8),
            "best_at_precision_0.85": recall_at_precision(curve, 0.85)}


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
    p.add_argument("--runtime", choices=("opencv", "onnxruntime"), default="opencv",
                   help="Yolo-FastestV2: OpenCV's dnn module (default) or ONNX Runtime on one thread")
    p.add_argument("--json", help="write the whole result here")
    a = p.parse_args(argv)
    try:
        r = evaluate(a.supp, a.model, a.limit, a.runtime)
    except (FileNotFoundError, ValueError) as e:
        print(f"cnn_reference: {e}", file=sys.stderr)
        return 2
    if a.json:
        write_whole(a.json, json.dumps(r, indent=1))
    print(markdown(r))
    return 0


if __name__ == "__main__":
    sys.exit(main())
