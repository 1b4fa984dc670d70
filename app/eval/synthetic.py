"""A pipeline preset over the synthetic scenario suite: detection P/R, MOTA, IDF1, id switches, range error.

Ground truth: vehicles within `max_range_m` (60 m) whose box is at least half visible; the others are
"don't care" (app/eval/track_score.py). Tracks are the confirmed ones, as reported.
"""
from __future__ import annotations

import dataclasses
import functools
from typing import Callable, Optional

import motmetrics as mm
import numpy as np

from app import config as configuration
from app.core import Pipeline
from app.eval.track_score import TrackScorer, detection_metrics
from app.sim import list_scenarios, load_scenario, render
from app.sim.frames import scenario_camera

RANGE_BANDS = ((0, 20), (20, 40), (40, 60), (60, 90))


def evaluate_scenario(name: str, preset: str, config_path: Optional[str] = None, max_range_m: float = 60.0,
                      min_visible: float = 0.5, on_frame: Optional[Callable] = None,
                      vehicle_look: Optional[str] = None) -> dict:
    """`vehicle_look` ("real" or "plain", docs/sim.md) replaces the scenario's own."""
    sc = load_scenario(name)
    if vehicle_look is not None:
        sc = dataclasses.replace(sc, vehicle_look=vehicle_look)
    cfg = configuration.load(config_path, {"pipeline": {"preset": preset}})
    cfg["camera"].update(dataclasses.asdict(scenario_camera(sc)))
    score = TrackScorer(max_range_m, min_visible)
    with Pipeline(configuration.core_sections(cfg)) as pipe:
        for f in render(sc):
            pipe.set_ego_motion(f.ego_speed_mps, 0.0)
            r = pipe.process(f.image, f.t_s)
            score.update(f.index, f.truth, [t for t in r.tracks if t.confirmed], (r.width, r.height))
            if on_frame:
                on_frame(f, r)
    return {"scenario": name, "tp": score.tp, "fp": score.fp, "fn": score.fn, "acc": score.acc,
            "range_errors": score.range_errors, "confirm_delay_frames": score.confirm_delay_frames()}


def summarize(results: list[dict]) -> dict:
    mh = mm.metrics.create()
    names = [r["scenario"] for r in results]
    summary = mh.compute_many([r["acc"] for r in results], names=names,
                              metrics=["mota", "idf1", "num_switches", "num_fragmentations"],
                              generate_overall=True)
    per = {}
    for r in results:
        row = summary.loc[r["scenario"]]
        per[r["scenario"]] = detection_metrics(r["tp"], r["fp"], r["fn"]) | {
            "mota": float(row["mota"]), "idf1": float(row["idf1"]), "id_switches": int(row["num_switches"]),
            "fragments": int(row["num_fragmentations"])}
    tot = {k: sum(r[k] for r in results) for k in ("tp", "fp", "fn")}
    row = summary.loc["OVERALL"]
    overall = detection_metrics(tot["tp"], tot["fp"], tot["fn"]) | {
        "mota": float(row["mota"]), "idf1": float(row["idf1"]), "id_switches": int(row["num_switches"]),
        "fragments": int(row["num_fragmentations"])}
    errs = [e for r in results for e in r["range_errors"]]
    bands = {}
    for lo, hi in RANGE_BANDS:
        rel = [abs(e) for z, e in errs if lo <= z < hi]
        bands[f"{lo}-{hi} m"] = {"n": len(rel), "median_rel_error": float(np.median(rel)) if rel else None,
                                 "p90_rel_error": float(np.percentile(rel, 90)) if rel else None}
    return {"per_scenario": per, "overall": overall, "range_bands": bands}


def evaluate_suite(preset: str, scenarios: Optional[list[str]] = None, config_path: Optional[str] = None,
                   progress: Optional[Callable[[str], None]] = None, mapper: Optional[Callable] = None,
                   vehicle_look: Optional[str] = None) -> dict:
    """`mapper(fn, arg_list, names, desc)`, when given, runs the scenarios (app/fleet/engine.map_ordered);
    `vehicle_look` replaces every scenario's own (None: each scenario's, "real" unless it says)."""
    names = scenarios or list_scenarios()
    if mapper is not None:
        results = mapper(functools.partial(evaluate_scenario, vehicle_look=vehicle_look),
                         [(n, preset, config_path) for n in names], names, "synthetic")
    else:
        results = []
        for name in names:
            if progress:
                progress(name)
            results.append(evaluate_scenario(name, preset, config_path, vehicle_look=vehicle_look))
    out = summarize(results)
    out["confirm_delay_frames"] = {r["scenario"]: r["confirm_delay_frames"] for r in results}
    return out
