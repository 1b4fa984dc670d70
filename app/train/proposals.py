"""`headway train proposals`: the learned first stage, a small fully convolutional network that finds where the
vehicles are (an objectness heat map with each vehicle's box, CenterNet-style), trained here with JAX (CPU) and
written as ONNX for cv::dnn in the core (csrc/detect/proposals/proposal_net.cpp). The network and its decoding:
proposals_onnx.py.

Data: the annotated training folders (annotation.json, every vehicle boxed), each image resized to the input
(proposals_onnx.prepare) once and kept in memory (cached in an .npz beside the data when `cache` is given). Every
`HELD_OUT`-th image is held out: never fitted, it is where the detector's thresholds are chosen.

Targets on the output grid (stride 4), per annotated box (input px) whose height is at least MIN_BOX_PX:
- heat: a Gaussian around the cell holding the box's centre, sigma = max(SIGMA_MIN, size / SIGMA_DIV) cells along
  each axis, 1 at that cell; the maximum over the boxes;
- box: at the cells where a box's Gaussian is at least REG_HEAT (and the largest of the boxes'), log(distance /
  stride) from the cell's centre to the box's four edges, weighted by the Gaussian.
Every other cell of every training image is a negative: the focal loss below weighs each by how wrong it is, so the
hard negatives of the training images (road signs, guard rails, shadows, the bonnet) drive the fit.

Augmentation, drawn from the seed per image and epoch: a left-right mirror (half the images), a zoom by 0.75-1.33
about a random point with a shift of up to 10 % of the size, and brightness and contrast (g' = a g + b, a in 0.6-1.4,
b in -30..30 grey levels). The fit sees a window of CROP_ROWS x CROP_COLS of each (the network is fully
convolutional): its rows centred on the median row of the image's vehicles, moved by up to +-24 rows at random (the
vehicles of a road scene stand in a band; its sky and bonnet hold none), its columns anywhere; a full 320x180 image
costs 2.3x the arithmetic of a 192x128 window (the shipped model's 30 epochs took 35 min of the two cores). Boxes
are cut to the window; one less than half inside is neither vehicle nor background.

Loss (CenterNet's focal loss, a generalised-IoU box loss): L = focal + BOX_WEIGHT * box + decay |W|^2 / 2 with
    focal = -1/N sum_cells [y = 1] (1 - p)^2 log p + [y < 1] (1 - y)^4 p^2 log(1 - p),   N = the peaks
    box   = sum_cells g (1 - GIoU(b, t)) / sum g    (the generalised IoU of the box the cell's four predicted
            log-distances give with its target box, g the cell's Gaussian)
Adam (beta 0.9, 0.999; the learning rate falls linearly to 0), batches of `batch` images: the same command gives
the same file.
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
from app.train import proposals_onnx as po
from app.train.cascade.samples import iou, load_folders, read_gray

HELD_OUT = 10          # image k (in the folders' order) is held out when k % HELD_OUT == HELD_OUT - 1
MIN_BOX_PX = 2.0       # input px: lower boxes are neither vehicles nor background (ignored)
SIGMA_MIN, SIGMA_DIV = 0.6, 8.0
REG_HEAT = 0.5
CROP_ROWS, CROP_COLS = 128, 192  # input px of the window fitted (module docstring)
BOX_WEIGHT = 1.0


def require_train_extra():
    """jax and onnx, or a clear error naming the extra that brings them."""
    try:
        import jax  # noqa: F401
        import onnx  # noqa: F401
    except ImportError as e:
        raise SystemExit(f"headway train proposals needs the training packages ({e.name} is missing): "
                         "pip install '.[train]' (jax[cpu] and onnx)") from None


def load_images(folders: list[str], input_width: int, cache: str | None = None, progress=None):
    """(images (n, H_in, W_in) uint8, boxes: list of (m, 4) float in input px, scale (image px per input px)) of
    every annotated image of the folders; read from / written to `cache` (.npz) when it holds the same images."""
    items = load_folders(folders)
    key = hashlib.sha256(json.dumps([[str(Path(f).resolve()) for f in folders], len(items), input_width,
                                     po.INPUT_MEAN]).encode()).hexdigest()[:16]
    if cache and Path(cache).is_file():
        d = np.load(cache)
        if str(d["key"]) == key:
            split = np.cumsum(d["counts"])[:-1]
            return d["images"], np.split(d["boxes"], split), float(d["scale"])
    imgs, boxes, scale = [], [], None
    for it in items:
        g = read_gray(it.path)
        small = po.prepare(g, input_width)
        s = g.shape[1] / small.shape[1]
        if scale is None:
            scale = s
        elif imgs and small.shape != imgs[0].shape:
            raise ValueError(f"{it.path}: {g.shape[1]}x{g.shape[0]}, the other images are another size; train on "
                             "images of one size")
        imgs.append(small)
        boxes.append(np.asarray(it.boxes, np.float32).reshape(-1, 4) / s)
        if progress:
            progress(1)
    images = np.stack(imgs)
    if cache:
        Path(cache).parent.mkdir(parents=True, exist_ok=True)
        # whole or not at all: the next run would read a cache cut short; to a file, NumPy adds no .npz to the name
        with written_whole(cache) as tmp, open(tmp, "wb") as f:
            np.savez(f, images=images, boxes=np.concatenate(boxes), counts=np.array([len(b) for b in boxes]),
                     scale=scale, key=np.array(key))
    return images, boxes, float(scale)


def augment(img: np.ndarray, boxes: np.ndarray, rng: np.random.Generator, rows: int = CROP_ROWS,
            cols: int = CROP_COLS):
    """The image and its boxes mirrored, zoomed and shifted, brightened, and cut to a window of `rows` x `cols`
    around its vehicles (module docstring): (image, the boxes at least half inside, the other boxes partly inside)."""
    h, w = img.shape
    rows, cols = min(rows, h), min(cols, w)
    b = boxes.copy()
    if rng.random() < 0.5:
        img = img[:, ::-1]
        b = np.c_[w - b[:, 2], b[:, 1], w - b[:, 0], b[:, 3]]
    s = float(np.exp(rng.uniform(np.log(0.75), np.log(1.33))))
    cx, cy = rng.uniform(0, w), rng.uniform(0, h)
    tx, ty = rng.uniform(-0.1, 0.1) * w, rng.uniform(-0.1, 0.1) * h
    m = np.float32([[s, 0, (1 - s) * cx + tx], [0, s, (1 - s) * cy + ty]])
    mid = np.median((b[:, 1] + b[:, 3]) / 2) * s + m[1, 2] if len(b) else h / 2
    top = float(np.clip(np.round(mid - rows / 2 + rng.uniform(-24, 24)), 0, h - rows))
    m[1, 2] -= top
    m[0, 2] -= float(rng.integers(0, w - cols + 1))
    h, w = rows, cols
    img = cv2.warpAffine(np.ascontiguousarray(img), m, (w, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    b = b * s + np.float32([m[0, 2], m[1, 2], m[0, 2], m[1, 2]])
    area = (b[:, 2] - b[:, 0]) * (b[:, 3] - b[:, 1])
    c = np.c_[np.clip(b[:, [0, 2]], 0, w), np.clip(b[:, [1, 3]], 0, h)][:, [0, 2, 1, 3]]
    inside = (c[:, 2] - c[:, 0]) * (c[:, 3] - c[:, 1])
    kept = inside >= 0.5 * np.maximum(area, 1e-6)
    a, off = rng.uniform(0.6, 1.4), rng.uniform(-30, 30)
    img = np.clip(img.astype(np.float32) * a + off + (1 - a) * 127.5, 0, 255).astype(np.uint8)
    return img, c[kept], c[~kept & (inside > 0)]


def targets(boxes: np.ndarray, out_w: int, out_h: int, ignored=(), stride: int = 8):
    """(heat (h, w), box (4, h, w), weight (h, w), ignore (h, w) bool) of one image's boxes (input px); the cells
    of the `ignored` boxes (mostly outside the window) are neither vehicle nor background, as those of boxes lower
    than MIN_BOX_PX."""
    heat = np.zeros((out_h, out_w), np.float32)
    box = np.zeros((4, out_h, out_w), np.float32)
    owner = np.zeros((out_h, out_w), np.float32)   # the Gaussian of the box that owns each cell's regression
    ignore = np.zeros((out_h, out_w), bool)
    S = stride
    X, Y = np.meshgrid(S * np.arange(out_w) + 0.5, S * np.arange(out_h) + 0.5)   # cell centres, input px
    ignored = np.asarray(ignored, np.float32).reshape(-1, 4)
    for k, (l, t, r, b) in enumerate(np.r_[ignored, np.asarray(boxes, np.float32).reshape(-1, 4)]):
        if k < len(ignored) or b - t < MIN_BOX_PX or r - l < 1:
            i0, i1 = int(np.floor(t / S)), int(np.ceil(b / S))
            j0, j1 = int(np.floor(l / S)), int(np.ceil(r / S))
            ignore[max(0, i0):max(0, i1), max(0, j0):max(0, j1)] = True
            continue
        jc = int(np.clip(np.floor((l + r) / 2 / S), 0, out_w - 1))
        ic = int(np.clip(np.floor((t + b) / 2 / S), 0, out_h - 1))
        sx = max(SIGMA_MIN, (r - l) / S / SIGMA_DIV)
        sy = max(SIGMA_MIN, (b - t) / S / SIGMA_DIV)
        g = np.exp(-((np.arange(out_h)[:, None] - ic) ** 2 / (2 * sy * sy)
                     + (np.arange(out_w)[None, :] - jc) ** 2 / (2 * sx * sx))).astype(np.float32)
        heat = np.maximum(heat, g)
        mine = (g >= REG_HEAT) & (g > owner)
        owner = np.where(mine, g, owner)
        d = np.stack([X - l, Y - t, r - X, b - Y])
        box = np.where(mine[None], np.log(np.maximum(d, 0.25) / S), box)
    ignore &= heat < 0.5
    return heat, box, owner, ignore


def batch_arrays(images, boxes, idx, rng, aug: bool, stride: int = 8, subcells: int = po.SUBCELLS):
    """The standardised inputs and the stacked targets of images[idx] (augmented with `aug`)."""
    xs, hs, bs, ws, igs = [], [], [], [], []
    for k in idx:
        img, bx, cut = augment(images[k], boxes[k], rng) if aug else (images[k], boxes[k], ())
        t = targets(bx, *po.output_size(img.shape[1], img.shape[0], stride, subcells), cut, stride)
        xs.append(img)
        hs.append(t[0]), bs.append(t[1]), ws.append(t[2]), igs.append(t[3])
    return (po.standardise(np.stack(xs)), np.stack(hs)[:, None], np.stack(bs), np.stack(ws)[:, None],
            np.stack(igs)[:, None].astype(np.float32))


def giou(pb, yb):
    """(n, 1, h, w) generalised IoU of the boxes that two maps (n, 4, h, w) of log-distances (l, t, r, b) give about
    each cell (both boxes hold the cell's centre; the stride cancels)."""
    import jax.numpy as jnp

    dp, dt = jnp.exp(pb), jnp.exp(yb)
    inter = ((jnp.minimum(dp[:, 0], dt[:, 0]) + jnp.minimum(dp[:, 2], dt[:, 2]))
             * (jnp.minimum(dp[:, 1], dt[:, 1]) + jnp.minimum(dp[:, 3], dt[:, 3])))
    area_p = (dp[:, 0] + dp[:, 2]) * (dp[:, 1] + dp[:, 3])
    area_t = (dt[:, 0] + dt[:, 2]) * (dt[:, 1] + dt[:, 3])
    union = area_p + area_t - inter
    hull = ((jnp.maximum(dp[:, 0], dt[:, 0]) + jnp.maximum(dp[:, 2], dt[:, 2]))
            * (jnp.maximum(dp[:, 1], dt[:, 1]) + jnp.maximum(dp[:, 3], dt[:, 3])))
    return (inter / union - (hull - union) / hull)[:, None]


def fit(images, boxes, epochs: int, seed: int, batch: int = 16, lr: float = 2e-3, decay: float = 1e-5,
        width: int = po.WIDTH, blocks: int = po.BLOCKS, width8: int = po.WIDTH8, blocks8: int = po.BLOCKS8,
        subcells: int = po.SUBCELLS, on_epoch: Callable[[int, dict, float, float], None] | None = None) -> dict:
    """Parameters (numpy, proposals_onnx's names) fitted by Adam on the focal and box losses (module docstring)."""
    # JAX is optional (pip install '.[train]'): imported only where a network is fitted, written or read
    import jax
    import jax.numpy as jnp

    rng = np.random.default_rng(seed)
    p = {k: jnp.asarray(v) for k, v in po.init_params(seed, width=width, blocks=blocks, width8=width8, blocks8=blocks8,
                                                     subcells=subcells).items()}
    decayed = [k for k in p if k.endswith("_w") or k.endswith("_dw") or k.endswith("_pw")]

    def loss(p, x, yh, yb, wb, ig):
        logit, pb = po.forward_jax(p, x)
        pr = jax.nn.sigmoid(logit)
        logp, log1mp = jax.nn.log_sigmoid(logit), jax.nn.log_sigmoid(-logit)
        pos = (yh >= 1.0).astype(jnp.float32)
        neg = (1 - pos) * (1 - ig)
        focal = -(pos * (1 - pr) ** 2 * logp + neg * (1 - yh) ** 4 * pr ** 2 * log1mp).sum() / jnp.maximum(pos.sum(), 1)
        box = (wb * (1 - giou(pb, yb))).sum() / jnp.maximum(wb.sum(), 1e-6)
        return focal + BOX_WEIGHT * box + 0.5 * decay * sum(jnp.sum(p[k] ** 2) for k in decayed), (focal, box)

    @jax.jit
    def step(p, m, v, t, x, yh, yb, wb, ig, rate):
        (val, parts), g = jax.value_and_grad(loss, has_aux=True)(p, x, yh, yb, wb, ig)
        m = jax.tree_util.tree_map(lambda a, b: 0.9 * a + 0.1 * b, m, g)
        v = jax.tree_util.tree_map(lambda a, b: 0.999 * a + 0.001 * b * b, v, g)
        p = jax.tree_util.tree_map(lambda q, a, b: q - rate * (a / (1 - 0.9 ** t)) / (jnp.sqrt(b / (1 - 0.999 ** t)) + 1e-8),
                                   p, m, v)
        return p, m, v, val, parts

    m = jax.tree_util.tree_map(jnp.zeros_like, p)
    v = jax.tree_util.tree_map(jnp.zeros_like, p)
    per_epoch = max(1, len(images) // batch)
    steps, t = epochs * per_epoch, 0
    with tqdm(total=steps, desc="proposals", unit="batch", file=sys.stderr, disable=not sys.stderr.isatty(),
              leave=False) as bar:
        for ep in range(epochs):
            t0, tot, tf, tb = time.perf_counter(), 0.0, 0.0, 0.0
            order = rng.permutation(len(images))
            for b in range(per_epoch):
                idx = np.sort(order[b * batch:(b + 1) * batch])
                arrays = batch_arrays(images, boxes, idx, rng, aug=True, stride=po.stride_of(p),
                                      subcells=po.subcells_of(p))
                t += 1
                p, m, v, val, (f, bl) = step(p, m, v, t, *arrays, np.float32(lr * (1 - (t - 1) / steps)))
                tot, tf, tb = tot + float(val), tf + float(f), tb + float(bl)
                bar.update(1)
            if on_epoch:
                on_epoch(ep, finish(p), tot / per_epoch, time.perf_counter() - t0,
                         f"focal {tf / per_epoch:.4f}, box {tb / per_epoch:.4f}")
    return finish(p)


def finish(p) -> dict:
    return {k: np.asarray(v, np.float32) for k, v in p.items()}


def held_out_recall(path: str, images, boxes, scale: float, stride: int = 8, min_height_px: float = 40.0,
                    min_heat: float = 0.05):
    """On the held-out images: the share of annotated boxes >= min_height_px (image px) that some peak of the
    written ONNX (by cv2.dnn, as the core runs it) covers at IoU >= 0.5, and peaks per image; a quick check of the
    fit after each epoch (the detector's figures come from the core: docs/detection.md)."""
    net = cv2.dnn.readNetFromONNX(path)
    found = total = peaks = 0
    for img, bx in zip(images, boxes):
        net.setInput(po.standardise(img), "image")
        heat, box = po.to_grid(*(m[0] for m in net.forward(["heat", "box"])))
        det = po.decode(heat[0], box, 1.0, 1.0, min_heat, stride=stride)
        peaks += len(det)
        big = bx[(bx[:, 3] - bx[:, 1]) * scale >= min_height_px]
        if len(big):
            total += len(big)
            if len(det):
                found += int((iou(big.astype(float), det[:, :4]).max(1) >= 0.5).sum())
    return found / max(total, 1), peaks / max(len(images), 1)


def train(folders: list[str], out: str, epochs: int = 5, seed: int = 0, input_width: int = po.INPUT_WIDTH,
          batch: int = 16, lr: float = 2e-3, width: int = po.WIDTH, blocks: int = po.BLOCKS, width8: int = po.WIDTH8,
          blocks8: int = po.BLOCKS8, subcells: int = po.SUBCELLS, cache: str | None = None, limit: int = 0,
          log: Callable[[str], None] = print, threads: int = 2) -> dict:
    """Fit on the folders' images less the held-out ones (`limit` > 0: only the first `limit` images), log each
    epoch (losses, the held-out boxes >= 40 px a peak covers), write the ONNX to `out` after every epoch."""
    require_train_extra()
    if threads < 1:
        raise ValueError(f"threads={threads}: at least 1")
    # must be set before jax is first imported
    os.environ.setdefault("XLA_FLAGS", f"--xla_cpu_multi_thread_eigen={'true' if threads > 1 else 'false'} "
                                       f"intra_op_parallelism_threads={threads}")
    cv2.setNumThreads(1)
    t0 = time.perf_counter()
    n_items = len(load_folders(folders))
    with tqdm(total=n_items, desc="images", unit="img", file=sys.stderr, disable=not sys.stderr.isatty(),
              leave=False) as bar:
        images, boxes, scale = load_images(folders, input_width, cache, progress=bar.update)
    if limit > 0:
        images, boxes = images[:limit], boxes[:limit]
    held = np.arange(len(images)) % HELD_OUT == HELD_OUT - 1
    fit_i = np.flatnonzero(~held)
    held_i = np.flatnonzero(held)
    log(f"proposals: {len(images)} images ({', '.join(folders)}), {len(fit_i)} fitted, {len(held_i)} held out (every "
        f"{HELD_OUT}th); input {images.shape[2]}x{images.shape[1]} gray, stride {(8 if blocks8 else 4) // subcells} "
        f"({subcells}x{subcells} sub-cells), stem {po.STEM}, width "
        f"{width}, {blocks} blocks at stride 4, width {width8 if blocks8 else '-'}, {blocks8} blocks at stride 8; "
        f"window {CROP_ROWS}x{CROP_COLS}; {epochs} epochs, batch {batch}, lr {lr:g}, seed "
        f"{seed}; {sum(len(boxes[k]) for k in fit_i)} boxes fitted; images {(time.perf_counter() - t0) / 60:.1f} min")
    t1 = time.perf_counter()

    def save(params, doc: str) -> None:   # renamed over `out` once whole: a stopped write leaves the last one
        with written_whole(out) as tmp:
            po.save_onnx(params, tmp, doc=doc)

    def on_epoch(ep, params, loss, secs, parts):   # the ONNX after every epoch: a stopped run leaves the last one
        save(params, f"headway train proposals --out {Path(out).name}, seed {seed}, epoch {ep + 1}")
        rec, peaks = held_out_recall(out, images[held_i], [boxes[k] for k in held_i], scale, po.stride_of(params))
        log(f"epoch {ep + 1}/{epochs}: loss {loss:.4f} ({parts}), held-out boxes >= 40 px a peak >= 0.05 covers at "
            f"IoU 0.5: {rec:.3f}, {peaks:.1f} peaks an image, {secs:.0f} s")

    params = fit(images[fit_i], [boxes[k] for k in fit_i], epochs, seed, batch, lr, width=width, blocks=blocks,
                 width8=width8, blocks8=blocks8, subcells=subcells, on_epoch=on_epoch)
    save(params, f"headway train proposals --out {Path(out).name}, seed {seed}, {epochs} epochs")
    log(f"fit {(time.perf_counter() - t1) / 60:.1f} min, total {(time.perf_counter() - t0) / 60:.1f} min -> {out} "
        f"({Path(out).stat().st_size / 1024:.0f} KiB)")
    return params
