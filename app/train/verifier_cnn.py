"""The convolutional verifier: a small CNN on each cascade detection's crop, trained here with JAX (CPU) and
written as ONNX for cv::dnn in the core (`headway train verifier --out X.onnx`).

Samples are the HOG verifier's (verifier.cascade_detections): the core's own cascade detections on the
training images, every group kept (min_neighbors 1, no suppression). A detection with IoU >= 0.5 with an
annotated box is a vehicle; unlike the HOG verifier's samples (IoU 0.3-0.5 left out), every other detection
is not: the verifier learns to tell a well placed box (what the scoring counts) from one beside the vehicle,
which would otherwise win the suppression of overlapping detections. Each is cropped as the core crops it
(verifier_onnx.crop_boxes) and mirrored at random while training.

Box output: for every detection with IoU >= REGRESS_IOU (0.3) with an annotated box, the
target is that box (the one it overlaps most) as verifier_onnx.offsets of the detection's box; with
`near="ignore"` the detections at IoU 0.3-0.5 are left out of the classification (they are neither: once
refined they may be well placed) but still teach the box output. Samples come from the core without the
ABI's cap of 64 tracks (Pipeline.detect): every group of every image.

Fit: Adam (beta 0.9, 0.999; the learning rate falls linearly to 0) on the class-balanced cross-entropy and
the smooth-L1 loss of the box output,
    L = sum_i s_i softplus(-y_i f(x_i)) / sum_i s_i + BOX_WEIGHT mean_{i: IoU_i >= 0.3} mean_k huber((d_ik - t_ik) / BOX_SIGMA)
        + decay |W|^2 / 2,   s_i = 1 / n_class(y_i) (0 for a detection left out),  huber(u) = u^2/2 if |u| < 1 else |u| - 1/2,
batches of `batch`, weights He-initialised from the seed: the same command on the same samples gives the same
file (tests/test_cascade_verifier_cnn.py); the shipped file's own fit is in its model card (docs/detection.md).
The images the HOG verifier held out (every 15th from the 13th of the training folders: the 5th of each
five of its every-3rd images) are held out here too, and the share of other boxes passed at the
thresholds keeping 0.8 / 0.9 / 0.95 of their vehicles is logged, for both verifiers on the same boxes.
"""
from __future__ import annotations

import hashlib
import json
import os
import sys
import time
from pathlib import Path
from typing import Callable

import cv2
import numpy as np
from tqdm import tqdm

from app.output_files import written_whole
from app.train import verifier_onnx as vo
from app.train.cascade.samples import load_folders, read_gray
from app.train.verifier import box_features, cascade_detections, fit_mlp, geometry_features, hog, iou

HELD_OUT = (15, 12)   # image i (in the training folders' order) is held out when i % 15 == 12
KEEP = (0.8, 0.9, 0.95)   # shares of held-out vehicles at which the others passed are reported
REGRESS_IOU = 0.3     # detections overlapping an annotated box at least this much teach the box output
BOX_SIGMA = 0.1       # of the box's width / height: the offset error at which smooth-L1 turns linear
BOX_WEIGHT = 1.0      # of the box loss against the cross-entropy
NEAR = ("negative", "ignore")   # how the detections at IoU 0.3-0.5 count for the classification


def require_train_extra():
    """jax and onnx, or a clear error naming the extra that brings them."""
    try:
        import jax  # noqa: F401
        import onnx  # noqa: F401
    except ImportError as e:
        raise SystemExit(f"headway train verifier --out X.onnx (the CNN) needs the training packages ({e.name} is missing): "
                         "pip install '.[train]' (jax[cpu] and onnx)") from None


def samples(folders: list[str], cascade_xml: str, every: int, cfg: dict, cache: str | None = None,
            progress=None, margin: float = vo.MARGIN) -> dict:
    """Crops (n, H, W) uint8, extra features (n, 2), labels (n,) +1/-1, image index in the folders (n,),
    boxes (n, 4), largest IoU with an annotated box (n,) and that annotated box (n, 4) of the cascade's
    detections (every group: no cap); read from / written to `cache` (.npz) when given and made from the same
    cascade, images and crop geometry."""
    key = hashlib.sha256(json.dumps(["labels: IoU >= 0.5 vs the rest, every group, matched box; crops: area_cells",
                                     hashlib.sha256(Path(cascade_xml).read_bytes()).hexdigest(),
                                     [str(Path(f).resolve()) for f in folders], every, vo.CROP_W, vo.CROP_H,
                                     margin, cfg["camera"], cfg["cascade"]], default=str).encode()).hexdigest()[:16]
    if cache and Path(cache).is_file():
        d = dict(np.load(cache))
        if str(d.get("key")) == key:
            return d
    cfg["cascade"]["nms_iou"] = 1.0   # every group: the verifier judges them all before suppression
    cam_h = cfg["camera"]["height_m"]
    items = load_folders(folders)[::every]
    crops, extra, label, image, boxes, overlap, matched = [], [], [], [], [], [], []
    for k, g, det, n, lab, horizon, m in cascade_detections(folders, cascade_xml, every, cfg, progress):
        crops.append(vo.crop_boxes(g, det, margin))
        extra.append(geometry_features(det, n, horizon, cam_h))
        label.append(np.where(m >= 0.5, 1, -1).astype(np.int8))
        image.append(np.full(len(det), k * every, np.int32))
        boxes.append(det.astype(np.float32))
        overlap.append(m.astype(np.float32))
        gt = np.asarray(items[k].boxes, float).reshape(-1, 4)
        matched.append((gt[iou(det, gt).argmax(1)] if len(gt) else np.full((len(det), 4), np.nan)).astype(np.float32))
    d = dict(crops=np.concatenate(crops), extra=np.concatenate(extra), label=np.concatenate(label),
             image=np.concatenate(image), boxes=np.concatenate(boxes), iou=np.concatenate(overlap),
             matched=np.concatenate(matched), key=np.array(key))
    if cache:
        Path(cache).parent.mkdir(parents=True, exist_ok=True)
        # whole or not at all: the next run would read a cache cut short; to a file, NumPy adds no .npz to the name
        with written_whole(cache) as tmp, open(tmp, "wb") as f:
            np.savez(f, **d)
    return d


def passed_at(p: np.ndarray, y: np.ndarray, keep=KEEP) -> list[float]:
    """Share of others (y < 0) scoring at least the threshold that keeps `keep` of the vehicles (y > 0)."""
    pos = np.sort(p[y > 0])[::-1]
    return [float((p[y < 0] >= pos[max(0, int(np.ceil(k * len(pos))) - 1)]).mean()) for k in keep]


def fit(crops, extra, y, channels=(8, 16, 32), hidden=64, epochs=6, lr=2e-3, decay=1e-4, seed=0, batch=128,
        on_epoch: Callable[[int, dict, float], None] | None = None, target=None, neg_share: float = 1.0) -> dict:
    """Parameters (numpy, verifier_onnx.forward's names) fitted by Adam on the class-balanced cross-entropy
    (y: +1 vehicle, -1 other, 0 left out) and, with `target` (n, 4) offsets (NaN rows = none), the box
    output's smooth-L1 loss (module docstring).

    `neg_share` < 1: each epoch sees only that share, drawn afresh, of the others that teach nothing but the
    class (no box target: IoU < REGRESS_IOU), weighted 1 / neg_share so that the loss estimated is the same
    one; every vehicle and every sample with a box target is seen every epoch. These plain background crops
    are ~90 % of the samples and most are easy, so an epoch costs about neg_share of a full one."""
    if not 0 < neg_share <= 1:
        raise ValueError(f"neg_share={neg_share}: a share in (0, 1]")
    # JAX is optional (pip install '.[train]'): imported only where a network is fitted, written or read
    import jax
    import jax.numpy as jnp
    from jax import lax

    rng = np.random.default_rng(seed)
    c_in = (1, *channels)
    p: dict = {}
    for k in range(3):   # He-normal weights, zero biases
        p[f"conv{k}_w"] = rng.normal(0, np.sqrt(2 / (9 * c_in[k])), (c_in[k + 1], c_in[k], 3, 3))
        p[f"conv{k}_b"] = np.zeros(c_in[k + 1])
    nflat = channels[2] * (vo.CROP_H // 8) * (vo.CROP_W // 8)
    p["dense_w"] = rng.normal(0, np.sqrt(2 / (nflat + 2)), (nflat + 2, hidden))
    p["dense_b"] = np.zeros(hidden)
    p["out_w"] = rng.normal(0, np.sqrt(1 / hidden), hidden)
    p["out_b"] = np.zeros(1)
    if target is not None:   # the box output starts near 0: the detection's own box
        p["box_w"] = rng.normal(0, 0.01 / np.sqrt(hidden), (hidden, 4))
        p["box_b"] = np.zeros(4)
    p = {k: jnp.asarray(v, jnp.float32) for k, v in p.items()}
    e_mean = extra.mean(0).astype(np.float32)
    e_scale = (1 / (extra.std(0) + 1e-3)).astype(np.float32)
    decayed = [k for k in p if k.endswith("_w")]

    def hidden_layer(p, z, e):
        a = z
        for k in range(3):
            a = lax.conv_general_dilated(a, p[f"conv{k}_w"], (1, 1), ((1, 1), (1, 1)),
                                         dimension_numbers=("NCHW", "OIHW", "NCHW")) + p[f"conv{k}_b"][None, :, None, None]
            a = lax.reduce_window(jnp.maximum(a, 0), -jnp.inf, lax.max, (1, 1, 2, 2), (1, 1, 2, 2), "VALID")
        return jnp.maximum(jnp.concatenate([a.reshape(a.shape[0], -1), e], 1) @ p["dense_w"] + p["dense_b"], 0)

    def loss(p, z, e, yy, s, tt, r):
        h = hidden_layer(p, z, e)
        data = jnp.sum(s * jax.nn.softplus(-yy * (h @ p["out_w"] + p["out_b"][0]))) / jnp.maximum(jnp.sum(s), 1e-12)
        if "box_w" in p:   # smooth L1 over the detections with a target (r = 1)
            u = jnp.abs((h @ p["box_w"] + p["box_b"] - tt) / BOX_SIGMA)
            hub = jnp.where(u < 1, 0.5 * u * u, u - 0.5).mean(1)
            data = data + BOX_WEIGHT * jnp.sum(r * hub) / jnp.maximum(jnp.sum(r), 1.0)
        return data + 0.5 * decay * sum(jnp.sum(p[k] ** 2) for k in decayed)

    @jax.jit
    def step(p, m, v, t, z, e, yy, s, tt, r, rate):
        val, g = jax.value_and_grad(loss)(p, z, e, yy, s, tt, r)
        m = jax.tree_util.tree_map(lambda a, b: 0.9 * a + 0.1 * b, m, g)
        v = jax.tree_util.tree_map(lambda a, b: 0.999 * a + 0.001 * b * b, v, g)
        p = jax.tree_util.tree_map(lambda q, a, b: q - rate * (a / (1 - 0.9 ** t)) / (jnp.sqrt(b / (1 - 0.999 ** t)) + 1e-8),
                                   p, m, v)
        return p, m, v, val

    m = jax.tree_util.tree_map(jnp.zeros_like, p)
    v = jax.tree_util.tree_map(jnp.zeros_like, p)
    yf = np.where(y > 0, 1.0, -1.0).astype(np.float32)
    sw = np.where(y > 0, 1 / max(1, (y > 0).sum()), np.where(y < 0, 1 / max(1, (y < 0).sum()), 0.0)).astype(np.float32)
    en = ((extra - e_mean) * e_scale).astype(np.float32)
    has_t = np.zeros(len(y), bool) if target is None else np.isfinite(target).all(1)
    tg = np.zeros((len(y), 4), np.float32) if target is None else np.where(has_t[:, None], target, 0).astype(np.float32)
    rw = has_t.astype(np.float32)
    plain = (y < 0) & ~has_t          # thinned each epoch when neg_share < 1
    always = np.flatnonzero(~plain)
    plain = np.flatnonzero(plain)
    n_plain = int(round(neg_share * len(plain)))
    sw[plain] /= neg_share
    per_epoch = (len(always) + n_plain) // batch
    steps, t = epochs * per_epoch, 0
    with tqdm(total=steps, desc="cnn", unit="batch", file=sys.stderr, disable=not sys.stderr.isatty(),
              leave=False) as bar:
        for ep in range(epochs):
            t0, total = time.perf_counter(), 0.0
            # every sample (drawn as before neg_share existed: the same seed gives the same file), or a fresh share
            seen = (np.arange(len(y)) if n_plain == len(plain)
                    else np.r_[always, rng.choice(plain, n_plain, replace=False)])
            order = seen[rng.permutation(len(seen))]
            flips = rng.random(len(y)) < 0.5
            for b in range(per_epoch):
                idx = np.sort(order[b * batch:(b + 1) * batch])
                c = crops[idx]
                f = flips[idx]
                c = np.where(f[:, None, None], c[:, :, ::-1], c)
                tb = tg[idx]   # mirrored: left and right swap and change sign, (dl, dt, dr, db) -> (-dr, dt, -dl, db)
                tb = np.where(f[:, None], tb[:, [2, 1, 0, 3]] * np.float32([-1, 1, -1, 1]), tb)
                t += 1
                p, m, v, val = step(p, m, v, t, vo.standardise(c), en[idx], yf[idx], sw[idx], tb, rw[idx],
                                    np.float32(lr * (1 - (t - 1) / steps)))
                total += float(val)
                bar.update(1)
            out = finish(p, e_mean, e_scale)
            if on_epoch:
                on_epoch(ep, out, total / per_epoch, time.perf_counter() - t0)
    return finish(p, e_mean, e_scale)


def finish(p, e_mean, e_scale) -> dict:
    out = {k: np.asarray(v, np.float32) for k, v in p.items()}
    out.update(extra_mean=e_mean, extra_scale=e_scale)
    return out


def predict(params: dict, crops: np.ndarray, extra: np.ndarray, chunk: int = 2048, box: bool = False):
    """verifier_onnx.forward in chunks: probabilities (n,), and with `box` the box output (n, 4) too."""
    if not len(crops):
        return (np.zeros(0), np.zeros((0, 4))) if box else np.zeros(0)
    out = [vo.forward(params, vo.standardise(crops[i:i + chunk]), extra[i:i + chunk], box=True)
           for i in range(0, len(crops), chunk)]
    p = np.concatenate([o[0] for o in out])
    return (p, np.concatenate([o[1] for o in out])) if box else p


def predict_onnx(path: str, crops: np.ndarray, extra: np.ndarray, chunk: int = 1024):
    """predict's probabilities and box output from the written ONNX by cv2.dnn (as the core runs it; ~9x faster
    than the numpy forward pass, which took ~1 min an epoch for the held-out crops). Without a box output, zeros."""
    net = cv2.dnn.readNetFromONNX(path)
    has_box = "box" in net.getUnconnectedOutLayersNames()
    p, box = [np.zeros(0, np.float32)], [np.zeros((0, 4), np.float32)]
    for i in range(0, len(crops), chunk):
        net.setInput(vo.standardise(crops[i:i + chunk]), "crop")
        net.setInput(np.ascontiguousarray(extra[i:i + chunk], np.float32), "extra")
        out = net.forward(["p", "box"] if has_box else ["p"])
        p.append(out[0].ravel())
        box.append(out[1] if has_box else np.zeros((len(out[0]), 4), np.float32))
    return np.concatenate(p), np.concatenate(box)


def paired_iou(a, b) -> np.ndarray:
    """(n,) IoU of a[i] with b[i], boxes (n, 4) left, top, right, bottom."""
    a, b = np.asarray(a, float).reshape(-1, 4), np.asarray(b, float).reshape(-1, 4)
    w = np.clip(np.minimum(a[:, 2], b[:, 2]) - np.maximum(a[:, 0], b[:, 0]), 0, None)
    h = np.clip(np.minimum(a[:, 3], b[:, 3]) - np.maximum(a[:, 1], b[:, 1]), 0, None)
    area = lambda x: (x[:, 2] - x[:, 0]) * (x[:, 3] - x[:, 1])
    return w * h / np.maximum(area(a) + area(b) - w * h, 1e-9)


def box_summary(d_out: np.ndarray, boxes, matched, overlap) -> str:
    """How the box output moves the detections with a target: median IoU with their annotated box before /
    after, and the share of those at IoU 0.3-0.5 it brings to >= 0.5 (and of those >= 0.5 it keeps there)."""
    after = paired_iou(vo.refine(boxes, d_out), matched)
    near, good = (overlap >= REGRESS_IOU) & (overlap < 0.5), overlap >= 0.5
    sel = overlap >= REGRESS_IOU
    return (f"box output on {int(sel.sum())} detections with IoU >= {REGRESS_IOU}: median IoU {np.median(overlap[sel]):.3f} -> "
            f"{np.median(after[sel]):.3f}; of IoU 0.3-0.5 now >= 0.5: {(after[near] >= 0.5).mean():.3f}, of >= 0.5 still: "
            f"{(after[good] >= 0.5).mean():.3f}")


def train(folders: list[str], cascade_xml: str, out: str, cfg: dict, every: int = 1, channels=(8, 16, 32),
          hidden: int = 64, epochs: int = 6, decay: float = 1e-4, seed: int = 0, cache: str | None = None,
          compare_hog: bool = False, log: Callable[[str], None] = print, box: bool = True,
          near: str = "negative", margin: float = vo.MARGIN, neg_share: float = 1.0) -> dict:
    """Fit on the training images less the held-out ones, log the held-out shares, write the ONNX to `out`.
    `compare_hog`: also fit the HOG verifier on the same images and log it on the same held-out boxes.
    `box`: with the box output; `near`: the detections at IoU 0.3-0.5 are others ("negative") or left out of
    the classification ("ignore"); `neg_share`: the share of the plain others each epoch sees (fit)."""
    if near not in NEAR:
        raise ValueError(f"near={near!r}: one of {', '.join(NEAR)}")
    require_train_extra()
    # one thread (the machine is shared); must be set before jax is first imported
    os.environ.setdefault("XLA_FLAGS", "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1")
    cv2.setNumThreads(1)   # the held-out crops judged by cv2.dnn after every epoch, on the same one core
    t0 = time.perf_counter()
    n_items = len(load_folders(folders)[::every])
    with tqdm(total=n_items, desc="cascade detections", unit="img", file=sys.stderr,
              disable=not sys.stderr.isatty(), leave=False) as bar:
        d = samples(folders, cascade_xml, every, cfg, cache, progress=bar.update, margin=margin)
    held = d["image"] % HELD_OUT[0] == HELD_OUT[1]
    y = d["label"]
    ov = d["iou"]
    fit_y = np.where((near == "ignore") & (ov >= REGRESS_IOU) & (ov < 0.5), 0, y)
    target = np.where((ov >= REGRESS_IOU)[:, None], vo.offsets(d["boxes"], d["matched"]), np.nan) if box else None
    clear = (d["iou"][held] >= 0.5) | (d["iou"][held] < 0.3)   # the HOG verifier's samples
    log(f"verifier (cnn): {n_items} images (every {every}), {int((y > 0).sum())} vehicle and {int((y < 0).sum())} "
        f"other boxes (before mirroring), {int(held.sum())} of them on {len(np.unique(d['image'][held]))} held-out "
        f"images; crop {vo.CROP_W}x{vo.CROP_H} gray, margin {margin:g}; conv {'/'.join(map(str, channels))}, "
        f"{hidden} hidden, {epochs} epochs, decay {decay:g}, seed {seed}; box output {'on' if box else 'off'}, IoU 0.3-0.5 "
        f"{near} ({int(((ov >= REGRESS_IOU) & (ov < 0.5)).sum())} of them); plain others an epoch sees {neg_share:g}; samples {(time.perf_counter() - t0) / 60:.1f} min")
    if compare_hog:
        t1 = time.perf_counter()
        ph = hog_baseline(folders, d, held, seed)
        log(f"HOG verifier (verifier.py's recipe) fitted on the same images, held-out others with IoU < 0.3 passed at "
            f"{'/'.join(map(str, KEEP))} of vehicles: " + " / ".join(f"{v:.3f}" for v in passed_at(ph, y[held][clear]))
            + f"; {(time.perf_counter() - t1) / 60:.1f} min")
    t1 = time.perf_counter()

    def on_epoch(ep, params, loss, secs):   # the ONNX after every epoch: a stopped run leaves the last one
        if box:
            params["crop_margin"] = np.float32([margin])
        with written_whole(out) as tmp:   # renamed over `out` once whole: a stopped write leaves the last epoch's
            vo.save_onnx(params, tmp, doc=f"headway train verifier --out {Path(out).name}, seed {seed}, epoch {ep + 1}")
        ph, dh = predict_onnx(out, d["crops"][held], d["extra"][held])
        log(f"epoch {ep + 1}/{epochs}: loss {loss:.4f}, held-out others passed at {'/'.join(map(str, KEEP))} of "
            f"vehicles: " + " / ".join(f"{v:.3f}" for v in passed_at(ph, y[held])) + "; of those with IoU < 0.3 "
            "(the HOG verifier's others): " + " / ".join(f"{v:.3f}" for v in passed_at(ph[clear], y[held][clear]))
            + f", {secs:.0f} s" + ("; " + box_summary(dh, d["boxes"][held], d["matched"][held], ov[held]) if box else ""))

    params = fit(d["crops"][~held], d["extra"][~held], fit_y[~held], channels, hidden, epochs, decay=decay, seed=seed,
                 on_epoch=on_epoch, target=None if target is None else target[~held], neg_share=neg_share)
    if box:
        params["crop_margin"] = np.float32([margin])
    log(f"fit {(time.perf_counter() - t1) / 60:.1f} min, total {(time.perf_counter() - t0) / 60:.1f} min -> {out} "
        f"({Path(out).stat().st_size / 1024:.0f} KiB)")
    return params


def hog_baseline(folders: list[str], d: dict, held: np.ndarray, seed: int) -> np.ndarray:
    """The HOG verifier (verifier.py, its shipped recipe: IoU 0.3-0.5 left out, 64 hidden units, 12 epochs,
    decay 1e-4, mirrors) fitted on the same images less the held-out ones; its probabilities for the held-out
    samples with IoU >= 0.5 or < 0.3."""
    h, items = hog(), load_folders(folders)
    x = np.zeros((len(d["label"]), h.getDescriptorSize()), np.float32)
    xm = np.zeros_like(x)
    for i in tqdm(np.unique(d["image"]), desc="HOG", unit="img", file=sys.stderr, disable=not sys.stderr.isatty(),
                  leave=False):
        j = np.flatnonzero(d["image"] == i)
        g = read_gray(items[i].path)
        b = d["boxes"][j]
        x[j] = box_features(h, g, b)
        xm[j] = box_features(h, g[:, ::-1].copy(), np.c_[g.shape[1] - b[:, 2], b[:, 1], g.shape[1] - b[:, 0], b[:, 3]])
    x, xm = np.c_[x, d["extra"]], np.c_[xm, d["extra"]]
    y = np.where(d["label"] > 0, 1.0, -1.0)
    clear = (d["iou"] >= 0.5) | (d["iou"] < 0.3)
    fit_on = ~held & clear
    m = fit_mlp(np.r_[x[fit_on], xm[fit_on]], np.r_[y[fit_on], y[fit_on]], 64, 12, 1e-4, seed)
    return m.probability(x[held & clear])
