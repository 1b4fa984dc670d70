"""The Viola-Jones training loop: stage after stage, each boosted on the positives the cascade still
accepts and on negatives that all pass the cascade so far (random windows for the first stage, then
the cascade's own false alarms mined from the training images), written after each stage as OpenCV
cascade XML. Deterministic for a given seed and data.
"""
from __future__ import annotations

import contextlib
import os
import sys
import tempfile
import time
from dataclasses import asdict, dataclass
from typing import Callable, ContextManager

import numpy as np
from tqdm import tqdm

from .boost import train_stage
from .haar import FeatureSet, responses, integrals, variance_norm
from .model import Cascade
from .samples import Miner, ScanBand, load_folders, positives, random_negatives


@dataclass
class TrainParams:
    width: int = 30                 # window width, px (vehicle boxes: median width/height 1.5-1.6)
    height: int = 20                # window height, px (smallest vehicle the cascade sees)
    stages: int = 20                # most stages trained
    min_hit_rate: float = 0.995     # per stage, on its training positives
    max_false_alarm: float = 0.5    # per stage, on its training negatives
    max_weak: int = 120             # most stumps per stage
    num_pos: int = 6000             # positives per stage, drawn from those the cascade still accepts
    num_neg: int = 6000             # negatives per stage, all accepted by the cascade so far
    features: int = 3000            # candidate features per stage, drawn at random from all of them
    min_box_height: float = 24.0    # px: smaller boxes are too blurred to be positives
    max_aspect: float = 3.0         # width/height above this: a long side view, not used as positive
    min_aspect: float = 0.0         # width/height below this not used as positive (a cascade for one view only)
    seed: int = 0
    max_minutes: float = 55.0       # no new stage starts after this (the whole run fits in an hour)
    resume: str = ""                # cascade XML written by this trainer: its stages are kept, more are added
    booster: str = "gentle"         # gentle (OpenCV's default, shipped) or discrete (paper 004); docs/decisions.md
    # negatives only from the rows a flat-road detector scans for each window size: (horizon row px,
    # camera height m[, lowest, tallest vehicle m]); () = anywhere in the image (samples.ScanBand)
    scan_band: tuple = ()


def train(folders: list[str], out_xml: str, p: TrainParams, log: Callable[[str], None] = print,
          written: Callable[[str], ContextManager[str]] = contextlib.nullcontext) -> Cascade:
    """The cascade trained on `folders`, written after every stage through `written(out_xml)`: a context
    giving the path to write, put in place when its block ends (the command's is output_files.written_whole,
    a file renamed over `out_xml` once whole; the default writes `out_xml` itself, keeping this package free
    of the rest of Headway)."""
    rng = np.random.default_rng(p.seed)
    t_start = time.perf_counter()
    items = load_folders(folders)
    fs = FeatureSet(p.width, p.height)
    bar_opts = dict(file=sys.stderr, disable=not sys.stderr.isatty(), leave=False)
    with tqdm(total=len(items), desc="positives", unit="img", **bar_opts) as bar:
        pool = positives(items, p.width, p.height, p.min_box_height, p.max_aspect, progress=bar.update,
                         min_aspect=p.min_aspect)
    _, ok = variance_norm(pool)
    pool = pool[ok]
    log(f"data: {len(items)} images from {', '.join(folders)}; {len(pool)} positive windows "
        f"({p.width}x{p.height}, boxes >= {p.min_box_height:g} px, width/height {p.min_aspect:g}-{p.max_aspect:g}, mirrored, contrast > 10 grey levels); "
        f"{len(fs)} Haar features; params {asdict(p)}")
    cascade = Cascade(p.width, p.height, params=asdict(p))
    # the cascade's false alarms per window scanned, measured while mining (resumed: each stage's nominal rate)
    fa_rate = 1.0
    if p.resume:
        cascade.stages = Cascade.from_xml(fs, p.resume).stages
        fa_rate = p.max_false_alarm ** len(cascade.stages)
        log(f"resumed: {len(cascade.stages)} stages from {p.resume}")
    band = ScanBand(*p.scan_band) if p.scan_band else None
    miner = Miner(items, p.width, p.height, rng, band=band)
    tmp = tempfile.NamedTemporaryFile(suffix=".xml", delete=False)
    tmp.close()
    try:
        for s in range(len(cascade.stages), p.stages):
            if time.perf_counter() - t_start > p.max_minutes * 60:
                log(f"stop: {p.max_minutes:g} min used")
                break
            t0 = time.perf_counter()
            accepted = cascade.evaluate(fs, pool)[0] if cascade.stages else np.ones(len(pool), bool)
            pos = pool[accepted]
            pos = pos[rng.permutation(len(pos))[: p.num_pos]]
            if s == 0:
                neg = random_negatives(items, p.num_neg, p.width, p.height, rng, band=band)
                ratio_txt = "random windows"
            else:
                cascade.save(fs, tmp.name)
                with tqdm(total=p.num_neg, desc=f"stage {s} mining", unit="win", **bar_opts) as bar:
                    def prog(k, n):
                        bar.n = k
                        bar.refresh()

                    neg, scanned, seen = miner.mine(tmp.name, p.num_neg, fa_rate, 4 * len(items), progress=prog)
                agree = cascade.evaluate(fs, neg)[0]
                neg = neg[agree]
                fa_rate = seen / max(1, scanned)
                ratio_txt = (f"{scanned} windows scanned, cascade false-alarm rate {fa_rate:.2e} per window, "
                             f"{agree.mean() if len(agree) else 1:.4f} accepted by the trainer's evaluator")
                if len(neg) < max(50, p.num_neg // 10):
                    log(f"stop before stage {s}: only {len(neg)} false alarms left in the training images ({ratio_txt})")
                    break
            x = np.concatenate([pos, neg])
            y = np.r_[np.ones(len(pos)), -np.ones(len(neg))]
            norm, valid = variance_norm(x)
            x, y, norm = x[valid], y[valid], norm[valid]
            feats = np.sort(rng.choice(len(fs), min(p.features, len(fs)), replace=False))
            values = responses(fs, feats, integrals(x), norm)
            with tqdm(total=p.max_weak, desc=f"stage {s}", unit="stump", **bar_opts) as bar:
                def on_round(r, hit, fa):
                    bar.update(1)
                    bar.set_postfix(hit=f"{hit:.4f}", fa=f"{fa:.3f}")

                stage, hit, fa = train_stage(values, feats, y, p.min_hit_rate, p.max_false_alarm, p.max_weak, on_round,
                                             p.booster)
            cascade.stages.append(stage)
            fa_rate *= fa
            with written(out_xml) as path:
                cascade.save(fs, path)
            log(f"stage {s:2d}: {len(stage.features):3d} stumps, hit rate {hit:.4f}, false alarm {fa:.4f}, "
                f"{int((y > 0).sum())} positives ({accepted.mean():.3f} of the pool still accepted), "
                f"{int((y < 0).sum())} negatives ({ratio_txt}), {time.perf_counter() - t0:.1f} s")
    finally:
        os.unlink(tmp.name)
    log(f"done: {len(cascade.stages)} stages, {sum(len(s.features) for s in cascade.stages)} stumps, "
        f"{(time.perf_counter() - t_start) / 60:.1f} min -> {out_xml}")
    return cascade
