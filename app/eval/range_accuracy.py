"""Range and range-rate accuracy of a preset on the synthetic suite, by true-range band, the paper's way
(mean absolute error in metres) and relative, mean and median; with the suite's MOTA, IDF1 and switches.

Vehicles are the suite's ground truth (within 60 m, at least half visible) plus, for the 60-90 m band, any
fully visible vehicle out to 90 m; a confirmed track matches a vehicle at IoU >= 0.5.

    python -m app.eval.range_accuracy --pipeline phd [--set phd.estimator=covariance] [--out FILE.json]
"""
from __future__ import annotations

import argparse
import json
import tempfile
from typing import Optional

import numpy as np
import yaml

from app import config as configuration
from app.eval.matching import match
from app.eval.synthetic import RANGE_BANDS, evaluate_scenario, summarize
from app.output_files import write_whole
from app.sim import list_scenarios


def _band_stats(rows: list[tuple[float, float, float, float]]) -> dict:
    out = {}
    for lo, hi in RANGE_BANDS:
        sel = [r for r in rows if lo <= r[0] < hi]
        if not sel:
            out[f"{lo}-{hi} m"] = {"n": 0}
            continue
        z, est, rate, est_rate = (np.array(c, float) for c in zip(*sel))
        err = np.abs(est - z)
        rel = err / z
        has_rate = np.isfinite(est_rate)
        rerr = np.abs(est_rate[has_rate] - rate[has_rate])
        out[f"{lo}-{hi} m"] = {
            "n": len(sel), "mean_abs_m": float(err.mean()), "median_abs_m": float(np.median(err)),
            "mean_rel": float(rel.mean()), "median_rel": float(np.median(rel)),
            "rate_n": int(has_rate.sum()),
            "rate_mean_abs_mps": float(rerr.mean()) if rerr.size else None,
            "rate_median_abs_mps": float(np.median(rerr)) if rerr.size else None,
        }
    sel = [r for r in rows if r[0] < 60.0]
    if sel:
        z, est, rate, est_rate = (np.array(c, float) for c in zip(*sel))
        has_rate = np.isfinite(est_rate)
        out["0-60 m"] = {"n": len(sel), "mean_abs_m": float(np.abs(est - z).mean()),
                         "rate_mean_abs_mps": float(np.abs(est_rate[has_rate] - rate[has_rate]).mean())}
    return out


def evaluate(preset: str, config_path: Optional[str] = None, scenarios: Optional[list[str]] = None) -> dict:
    rows: list[tuple[float, float, float, float]] = []  # true range, range, true rate, rate

    def on_frame(f, r):
        truth = [v for v in f.truth if (v["longitudinal_m"] <= 60.0 and v["visible_fraction"] >= 0.5)
                 or (v["longitudinal_m"] <= 90.0 and v["visible_fraction"] >= 0.999)]
        tracks = [t for t in r.tracks if t.confirmed and t.range_m is not None]
        for i, j, _ in match([v["box_clipped"] for v in truth], [t.box for t in tracks]):
            t = tracks[j]
            rows.append((truth[i]["longitudinal_m"], t.range_m, truth[i]["relative_speed_mps"],
                         np.nan if t.range_rate_mps is None else t.range_rate_mps))

    results = [evaluate_scenario(name, preset, config_path, on_frame=on_frame) for name in scenarios or list_scenarios()]
    s = summarize(results)
    return {"preset": preset, "tracking": {k: s["overall"][k] for k in ("mota", "idf1", "id_switches", "precision", "recall")},
            "range": _band_stats(rows)}


def main(argv: Optional[list[str]] = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--pipeline", default=configuration.default_preset())
    p.add_argument("--set", action="append", default=[], help="SECTION.KEY=VALUE (YAML value); repeatable")
    p.add_argument("--scenarios", help="comma-separated scenario names (default: the whole suite)")
    p.add_argument("--out", help="write the JSON report here")
    a = p.parse_args(argv)
    cfg: dict = {}
    for item in a.set:
        key, _, value = item.partition("=")
        sec, _, name = key.partition(".")
        cfg.setdefault(sec, {})[name] = yaml.safe_load(value)
    with tempfile.NamedTemporaryFile("w", suffix=".yaml") as tmp:
        yaml.safe_dump(cfg, tmp)
        tmp.flush()
        report = evaluate(a.pipeline, tmp.name if cfg else None, a.scenarios.split(",") if a.scenarios else None)
    report["set"] = a.set
    text = json.dumps(report, indent=1)
    if a.out:
        write_whole(a.out, text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
