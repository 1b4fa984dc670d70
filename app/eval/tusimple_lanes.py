"""TuSimple lane-detection metric: accuracy, false-positive and false-negative rates.

Follows the official benchmark script (TuSimple ``lane/evaluate/lane.py``, ``LaneEval.bench``):

- every lane is a list of x, one per ``h_samples`` row, ``-2`` (any negative) where it has no point;
- for a ground-truth lane, a predicted x on a row is correct if ``|x_pred - x_gt| < t / cos(a)``,
  where ``t`` is 20 px at 1280 px image width (scaled here to the actual width) and ``a`` the angle
  of the ground-truth lane (slope of a least-squares fit of x against y); rows where both are absent
  count as correct, and the fraction is over all ``h_samples`` rows;
- each ground-truth lane takes its best predicted lane; it is matched if that fraction is >= 0.85,
  otherwise it is a false negative; predicted lanes beyond the matched count are false positives;
- per image: accuracy = sum of best fractions / min(4, n_gt), FP = unmatched predictions / n_pred,
  FN = misses / min(4, n_gt) (with more than 4 ground-truth lanes the worst one is forgiven);
  an image with more than n_gt + 2 predictions scores 0 accuracy and FN 1 as in the official script;
- the result is the mean over all ground-truth images (an image without predictions counts).

One deliberate difference: a ground-truth lane with no point at all (padding in some converted
label files) is not a lane and is ignored, instead of being an unmatchable false negative.

Predictions come from Headway's lane model, whose boundaries bend with the road (image points, straight
between them; a boundary given only by its bottom and top point is a straight segment);
:func:`segments_to_tusimple` samples them at the ``h_samples`` rows within their vertical extent and
:func:`write_predictions` writes them as a TuSimple submission.
"""
from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

PIXEL_THRESH_AT_1280 = 20.0  # px, official threshold for 1280-wide images
POINT_THRESH = 0.85          # fraction of rows that must be correct for a lane to match
REFERENCE_WIDTH = 1280


def _polyline(lane: Any) -> list[tuple[float, float]]:
    """The lane's image points (x, y), bottom first: its ``points`` when it has two or more (a lane model
    that bends with the road), else its straight segment (x_bottom, y_bottom) - (x_top, y_top). The lane is
    an object with those attributes or a mapping with those keys."""
    get = (lambda k, d=None: lane.get(k, d)) if isinstance(lane, Mapping) else (lambda k, d=None: getattr(lane, k, d))
    pts = get("points") or []
    if len(pts) >= 2:
        return [(float(x), float(y)) for x, y in pts]
    return [(float(get("x_bottom")), float(get("y_bottom"))), (float(get("x_top")), float(get("y_top")))]


def polyline_x(pts: Sequence[tuple[float, float]], y: float) -> float:
    """x of the polyline at row y (straight between its points), NaN outside its rows."""
    for (x0, y0), (x1, y1) in zip(pts, pts[1:]):
        if min(y0, y1) <= y <= max(y0, y1) and y0 != y1:
            return x0 + (x1 - x0) * (y - y0) / (y1 - y0)
    return math.nan


def segments_to_tusimple(lanes: Iterable[Any], h_samples: Sequence[int], width: int) -> list[list[float]]:
    """Lane boundaries (image polylines or straight segments, :func:`_polyline`) -> TuSimple x lists.

    Each boundary is sampled at the h_samples rows between its top and bottom point; rows outside
    that extent, or where the line is outside the image (0 <= x < width), get -2. Boundaries with no
    point inside the image are dropped (they would only count as false positives).
    """
    out = []
    for lane in lanes:
        pts = _polyline(lane)
        if not all(math.isfinite(v) for p in pts for v in p) or pts[0][1] == pts[-1][1]:
            continue
        xs: list[float] = []
        for h in h_samples:
            x = polyline_x(pts, h)
            xs.append(x if math.isfinite(x) and 0 <= x < width else -2)
        if any(x >= 0 for x in xs):
            out.append(xs)
    return out


def _lane_angle(xs: Sequence[float], ys: Sequence[float]) -> float:
    """Angle of the least-squares fit x = k y + c through the lane's points (official get_angle)."""
    pts = [(y, x) for x, y in zip(xs, ys) if x >= 0]
    if len(pts) < 2:
        return 0.0
    n = len(pts)
    my = sum(p[0] for p in pts) / n
    mx = sum(p[1] for p in pts) / n
    syy = sum((p[0] - my) ** 2 for p in pts)
    if syy == 0:
        return 0.0
    k = sum((p[0] - my) * (p[1] - mx) for p in pts) / syy
    return math.atan(k)


def lane_threshold(gt_xs: Sequence[float], h_samples: Sequence[int], pixel_thresh: float) -> float:
    """The official per-lane threshold: pixel_thresh / cos(angle of the ground-truth lane)."""
    return pixel_thresh / math.cos(_lane_angle(gt_xs, h_samples))


def _line_accuracy(pred: Sequence[float], gt: Sequence[float], thresh: float) -> float:
    """Fraction of rows where pred and gt agree within thresh (absent = -100 on both sides)."""
    hits = 0
    for p, g in zip(pred, gt):
        p = p if p >= 0 else -100.0
        g = g if g >= 0 else -100.0
        hits += abs(p - g) < thresh
    return hits / len(gt)


def bench_image(pred: Sequence[Sequence[float]], gt: Sequence[Sequence[float]], h_samples: Sequence[int],
                pixel_thresh: float) -> tuple[float, float, float]:
    """(accuracy, fp rate, fn rate) of one image, as the official LaneEval.bench."""
    if any(len(p) != len(h_samples) for p in pred):
        raise ValueError("every predicted lane needs one x per h_samples row")
    gt = [g for g in gt if any(x >= 0 for x in g)]
    if not gt:  # as the official script: nothing to find scores 0, any prediction is false
        return 0.0, (1.0 if pred else 0.0), 0.0
    if len(gt) + 2 < len(pred):
        return 0.0, 0.0, 1.0
    threshs = [lane_threshold(g, h_samples, pixel_thresh) for g in gt]
    line_accs = []
    fn = 0.0
    matched = 0.0
    for g, t in zip(gt, threshs):
        best = max((_line_accuracy(p, g, t) for p in pred), default=0.0)
        if best < POINT_THRESH:
            fn += 1
        else:
            matched += 1
        line_accs.append(best)
    fp = len(pred) - matched
    if len(gt) > 4 and fn > 0:
        fn -= 1
    s = sum(line_accs)
    if len(gt) > 4:
        s -= min(line_accs)
    denom = max(min(4.0, len(gt)), 1.0)
    return s / denom, (fp / len(pred) if pred else 0.0), fn / denom


def _image_width(gt_dir: Path, raw_file: str) -> int:
    try:
        import cv2  # lazy: only needed when the caller does not give the width
    except ImportError as exc:
        raise ValueError("image_width not given and OpenCV is not available to read it") from exc
    img = cv2.imread(str(gt_dir / raw_file), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise ValueError(f"image_width not given and {gt_dir / raw_file} cannot be read")
    return int(img.shape[1])


def evaluate_lanes(pred_lanes_per_image: Mapping[str, Sequence[Any]], gt_json_path: str | Path,
                   image_width: int | None = None) -> dict:
    """TuSimple accuracy / FP / FN of predictions against a TuSimple label file (JSON lines).

    pred_lanes_per_image: raw_file (as written in the label file) -> lanes of that image, each either
    a TuSimple x list (one x per h_samples row, negative = no point) or a straight segment (an object
    with x_bottom, y_bottom, x_top, y_top attributes, or a mapping with those keys, e.g. the Lane
    records of app.core results). Images of the label file missing from the mapping count as images
    with no lanes found.
    image_width: width of the labelled images in px (threshold scaling); read from the first image
    when not given.
    """
    gt_path = Path(gt_json_path)
    labels = [json.loads(line) for line in gt_path.read_text().splitlines() if line.strip()]
    if not labels:
        raise ValueError(f"{gt_path}: no labels")
    unknown = set(pred_lanes_per_image) - {lab["raw_file"] for lab in labels}
    if unknown:
        raise ValueError(f"predictions for images not in {gt_path}: {sorted(unknown)[:3]}")
    width = image_width if image_width is not None else _image_width(gt_path.parent, labels[0]["raw_file"])
    pixel_thresh = PIXEL_THRESH_AT_1280 * width / REFERENCE_WIDTH

    per_image = []
    acc_sum = fp_sum = fn_sum = 0.0
    for lab in labels:
        h_samples = lab["h_samples"]
        lanes = pred_lanes_per_image.get(lab["raw_file"], [])
        xs_lanes = [list(map(float, ln)) for ln in lanes if _is_x_list(ln, h_samples)]
        segs = [ln for ln in lanes if not _is_x_list(ln, h_samples)]
        pred = xs_lanes + segments_to_tusimple(segs, h_samples, width)
        a, p, n = bench_image(pred, lab["lanes"], h_samples, pixel_thresh)
        acc_sum += a
        fp_sum += p
        fn_sum += n
        per_image.append({"raw_file": lab["raw_file"], "accuracy": a, "fp": p, "fn": n,
                          "n_pred": len(pred), "n_gt": sum(1 for g in lab["lanes"] if any(x >= 0 for x in g))})
    num = len(labels)
    return {"accuracy": acc_sum / num, "fp": fp_sum / num, "fn": fn_sum / num, "n_images": num,
            "pixel_thresh": pixel_thresh, "image_width": width, "per_image": per_image}


def _is_x_list(lane: Any, h_samples: Sequence[int]) -> bool:
    return (isinstance(lane, Sequence) and not isinstance(lane, (str, bytes, Mapping))
            and len(lane) == len(h_samples) and all(isinstance(v, (int, float)) for v in lane))


def write_predictions(path: str | Path, labels: Sequence[Mapping], preds: Mapping[str, Sequence[Sequence[float]]],
                      run_ms: Mapping[str, float]) -> None:
    """A TuSimple submission: one JSON line per labelled image, {"raw_file", "lanes" (x lists, -2 = none),
    "h_samples", "run_time" (ms)}, as the official LaneEval.bench_one_submit reads it."""
    with open(path, "w") as f:
        for lab in labels:
            lanes = [[round(x, 1) if x >= 0 else -2 for x in ln] for ln in preds.get(lab["raw_file"], [])]
            f.write(json.dumps({"raw_file": lab["raw_file"], "lanes": lanes, "h_samples": lab["h_samples"],
                                "run_time": round(float(run_ms.get(lab["raw_file"], 0.0)), 3)}) + "\n")
