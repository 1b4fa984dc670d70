"""A pipeline preset over the synthetic scenario suite: detection P/R, MOTA, IDF1, id switches, range error.

Ground truth: vehicles within `max_range_m` (60 m) whose box is at least half visible. Vehicles outside
that set (farther, mostly hidden or cut by the image border) are "don't care": a confirmed track on
one of them is neither a hit nor a false positive. Tracks are the confirmed ones, as reported.
"""
from __future__ import annotations

import dataclasses
from typing import Callable, Optional

import motmetrics as mm
import numpy as np

from app import config as configuration
from app.core import Pipeline
from app.eval.matching import iou_matrix, match

RANGE_BANDS = ((0, 20), (20, 40), (40, 60), (60, 90))


def _is_truth(v: dict, max_range_m: float, min_visible: float) -> bool:
    return v["longitudinal_m"] <= max_range_m and v["visible_fraction"] >= min_visible


def evaluate_scenario(name: str, preset: str, config_path: Optional[str] = None, max_range_m: float = 60.0,
                      min_visible: float = 0.5, on_frame: Optional[Callable] = None) -> dict:
    from app.sim import load_scenario, render
    from app.sim.frames import scenario_camera

    sc = load_scenario(name)
    cfg = configuration.load(config_path)
    cfg["camera"].update(dataclasses.asdict(scenario_camera(sc)))
    cfg["pipeline"]["preset"] = preset
    acc = mm.MOTAccumulator(auto_id=True)
    tp = fp = fn = 0
    range_errors: list[tuple[float, float]] = []  # (true range, relative error)
    first_confirmed: dict[int, int] = {}           # truth id -> first frame a track matched it
    first_half_visible: dict[int, int] = {}
    with Pipeline(configuration.core_sections(cfg)) as pipe:
        for f in render(sc):
            pipe.set_ego_motion(f.ego_speed_mps, 0.0)
            r = pipe.process(f.image, f.t_s)
            truth = [v for v in f.truth if _is_truth(v, max_range_m, min_visible)]
            dont_care = [v for v in f.truth if not _is_truth(v, max_range_m, min_visible)]
            tracks = [t for t in r.tracks if t.confirmed]
            # drop tracks that sit on a don't-care vehicle and on no real one
            if dont_care and tracks:
                dc = iou_matrix([t.box for t in tracks], [v["box_clipped"] for v in dont_care])
                gt = iou_matrix([t.box for t in tracks], [v["box_clipped"] for v in truth])
                keep = [i for i in range(len(tracks))
                        if not (dc[i].max(initial=0) >= 0.5 and gt[i].max(initial=0) < 0.5)]
                tracks = [tracks[i] for i in keep]
            for v in f.truth:
                if v["visible_fraction"] >= 0.5 and v["id"] not in first_half_visible:
                    first_half_visible[v["id"]] = f.index
            pairs = match([v["box_clipped"] for v in truth], [t.box for t in tracks])
            tp += len(pairs)
            fn += len(truth) - len(pairs)
            fp += len(tracks) - len(pairs)
            for i, j, _ in pairs:
                first_confirmed.setdefault(truth[i]["id"], f.index)
                rng = tracks[j].range_m
                if rng is not None:
                    true = truth[i]["longitudinal_m"]
                    range_errors.append((true, (rng - true) / true))
            dist = 1.0 - iou_matrix([v["box_clipped"] for v in truth], [t.box for t in tracks])
            dist[dist > 0.5] = np.nan
            acc.update([v["id"] for v in truth], [t.id for t in tracks], dist)
            if on_frame:
                on_frame(f, r)
    return {"scenario": name, "tp": tp, "fp": fp, "fn": fn, "acc": acc, "range_errors": range_errors,
            "confirm_delay_frames": {tid: first_confirmed[tid] - first_half_visible.get(tid, first_confirmed[tid])
                                     for tid in first_confirmed}}


def summarize(results: list[dict]) -> dict:
    mh = mm.metrics.create()
    names = [r["scenario"] for r in results]
    summary = mh.compute_many([r["acc"] for r in results], names=names,
                              metrics=["mota", "idf1", "num_switches", "num_fragmentations"],
                              generate_overall=True)
    per = {}
    for r in results:
        row = summary.loc[r["scenario"]]
        per[r["scenario"]] = _det_metrics(r["tp"], r["fp"], r["fn"]) | {
            "mota": float(row["mota"]), "idf1": float(row["idf1"]), "id_switches": int(row["num_switches"]),
            "fragments": int(row["num_fragmentations"])}
    tot = {k: sum(r[k] for r in results) for k in ("tp", "fp", "fn")}
    row = summary.loc["OVERALL"]
    overall = _det_metrics(tot["tp"], tot["fp"], tot["fn"]) | {
        "mota": float(row["mota"]), "idf1": float(row["idf1"]), "id_switches": int(row["num_switches"]),
        "fragments": int(row["num_fragmentations"])}
    errs = [e for r in results for e in r["range_errors"]]
    bands = {}
    for lo, hi in RANGE_BANDS:
        rel = [abs(e) for z, e in errs if lo <= z < hi]
        bands[f"{lo}-{hi} m"] = {"n": len(rel), "median_rel_error": float(np.median(rel)) if rel else None,
                                 "p90_rel_error": float(np.percentile(rel, 90)) if rel else None}
    return {"per_scenario": per, "overall": overall, "range_bands": bands}


def _det_metrics(tp: int, fp: int, fn: int) -> dict:
    return {"tp": tp, "fp": fp, "fn": fn,
            "precision": tp / (tp + fp) if tp + fp else None, "recall": tp / (tp + fn) if tp + fn else None}


def evaluate_suite(preset: str, scenarios: Optional[list[str]] = None, config_path: Optional[str] = None,
                   progress: Optional[Callable[[str], None]] = None) -> dict:
    from app.sim import list_scenarios

    results = []
    for name in scenarios or list_scenarios():
        if progress:
            progress(name)
        results.append(evaluate_scenario(name, preset, config_path))
    out = summarize(results)
    out["confirm_delay_frames"] = {r["scenario"]: r["confirm_delay_frames"] for r in results}
    return out
