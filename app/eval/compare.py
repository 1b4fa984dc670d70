"""`headway eval --pipeline A,B,...`: the presets' reports side by side, one table per measure.

Each preset is evaluated into a folder of its own (`OUT/PRESET/`: report.json, report.md, examples/, as a single
`headway eval` writes it); this module only reads those reports and sets their figures beside each other, so a
figure here is the one in that preset's own report."""
from __future__ import annotations

from typing import Optional


def figure(x, nd=3) -> str:
    """A report's number as its tables print it: nd decimals, "n/a" when it was not measured."""
    return "n/a" if x is None else f"{x:.{nd}f}"


# thresholds of the TuSimple score curve shown (the curve holds more; these are where operating points lie)
CURVE_THRESHOLDS = (0.0, 0.3, 0.5, 0.7, 0.8, 0.9, 0.95, 0.99)


def _rp(recall, precision) -> str:
    return f"{figure(recall)} / {figure(precision)}"


def _rate(v: dict) -> str:
    """A vehicle's range rate and its error against the truth, or a dash when not estimated."""
    if v.get("range_rate_mps") is None:
        return "-"
    return f"{v['range_rate_mps']:+.2f} ({v['range_rate_mps'] - v['true_range_rate_mps']:+.2f})"


def _table(first: str, presets: list[str], rows: list[tuple[str, list[str]]]) -> list[str]:
    out = ["| " + " | ".join([first] + [f"`{p}`" for p in presets]) + " |",
           "| --- |" + " ---: |" * len(presets)]
    out += ["| " + " | ".join([name] + cells) + " |" for name, cells in rows]
    return out + [""]


def _keys(reports: list[dict], get) -> list:
    """Every key the reports hold in the part `get` returns, in the order first seen."""
    seen: list = []
    for r in reports:
        for k in get(r) or ():
            if k not in seen:
                seen.append(k)
    return seen


def markdown(reports: list[dict], folders: Optional[list[str]] = None) -> str:
    presets = [r["preset"] for r in reports]
    out = ["## Presets side by side: " + ", ".join(f"`{p}`" for p in presets), ""]
    if folders:
        out += ["Each preset's own report, with its annotated examples: " +
                ", ".join(f"`{f}/report.md` (`{f}/examples/`)" for f in folders) + ".", ""]
    dash = "-"

    if any(r.get("synthetic") for r in reports):
        out += ["### Synthetic suite (vehicles within 60 m, at least half visible; IoU >= 0.5 of the boxes' parts in "
                "the image; a track more than half on a vehicle not scored counts neither way)", ""]
        rows = []
        for label, key, nd in (("precision", "precision", 3), ("recall", "recall", 3), ("MOTA", "mota", 3),
                               ("IDF1", "idf1", 3), ("id switches", "id_switches", None),
                               ("fragments", "fragments", None)):
            cells = []
            for r in reports:
                o = (r.get("synthetic") or {}).get("overall")
                cells.append(dash if o is None else (str(o[key]) if nd is None else figure(o[key], nd)))
            rows.append((f"all scenarios: {label}", cells))
        for name in _keys(reports, lambda r: (r.get("synthetic") or {}).get("per_scenario")):
            cells = []
            for r in reports:
                m = ((r.get("synthetic") or {}).get("per_scenario") or {}).get(name)
                cells.append(dash if m is None else f"{figure(m['mota'])} / {figure(m['idf1'])}")
            rows.append((f"{name}: MOTA / IDF1", cells))
        out += _table("measure", presets, rows)

    if any(r.get("tusimple") for r in reports):
        images = next(r["tusimple"]["images"] for r in reports if r.get("tusimple"))
        out += [f"### TuSimple validation images ({images}, single-image detection, IoU >= 0.5): recall / precision", ""]
        rows = []
        for band in _keys(reports, lambda r: (r.get("tusimple") or {}).get("bands")):
            label = "all boxes" if band == "overall" else f"boxes {band} px"
            cells = []
            for r in reports:
                b = ((r.get("tusimple") or {}).get("bands") or {}).get(band)
                cells.append(dash if b is None else _rp(b["recall"], b["precision"]))
            rows.append((f"{label}, every detection kept", cells))
        for label, key in (("best at precision >= 0.8", "best_at_precision_0.8"),
                           ("best at precision >= 0.85", "best_at_precision_0.85"),
                           ("operating point (what `headway detect` writes)", "operating_point")):
            cells = []
            for r in reports:
                c = (r.get("tusimple") or {}).get(key)
                cells.append(dash if not c else f"{_rp(c['recall'], c['precision'])} (score >= {c['threshold']:.2f})")
            rows.append((f"boxes >= 40 px, {label}", cells))
        out += _table("measure", presets, rows)
        out += ["Score curve, boxes >= 40 px: recall / precision of the detections scoring at least the threshold.", ""]
        rows = []
        for t in CURVE_THRESHOLDS:
            cells = []
            for r in reports:
                curve = (r.get("tusimple") or {}).get("curve_ge40") or []
                c = next((c for c in curve if abs(c["threshold"] - t) < 1e-9), None)
                cells.append(dash if c is None else _rp(c["recall"], c["precision"]))
            rows.append((f">= {t:.2f}", cells))
        out += _table("score", presets, rows)

    if any(r.get("lanes") or r.get("lane_clips") for r in reports):
        out += ["### Lanes (TuSimple metric): accuracy / false positives / false negatives", ""]
        rows = []
        for label, key in (("lane sample", "lanes"), ("lane clips, frame 20", "lane_clips")):
            cells = []
            for r in reports:
                x = r.get(key)
                cells.append(dash if not x else f"{figure(x['accuracy'])} / {figure(x['fp'])} / {figure(x['fn'])}")
            rows.append((label, cells))
        out += _table("set", presets, rows)

    if any(r.get("range") for r in reports):
        out += ["### Range on TuSimple train_clip1 (range-sensor truth): estimated range m (relative error), range "
                "rate m/s (error)", ""]
        n = max(len(r["range"]["vehicles"]) for r in reports if r.get("range"))
        rows = []
        for k in range(n):
            cells, truth = [], None
            for r in reports:
                vs = (r.get("range") or {}).get("vehicles") or []
                v = vs[k] if k < len(vs) else None
                truth = truth if v is None else v["true_range_m"]
                cells.append(dash if v is None else (
                    f"{v['range_m']:.1f} ({v['rel_error']:+.1%}), {_rate(v)}" if v["found"] else "not found"))
            rows.append((f"vehicle at {truth:.1f} m", cells))
        out += _table("vehicle", presets, rows)

    if any(r.get("cost") for r in reports):
        out += ["### Cost per frame: `headway bench` on dense_traffic at 640x480, one pass, median / p99 ms", ""]
        out += _table("frames", presets, [("all", [
            dash if not r.get("cost") else f"{r['cost']['total']['median_ms']:.2f} / {r['cost']['total']['p99_ms']:.2f}"
            for r in reports])])

    if any(r.get("fcw") for r in reports):
        out += ["### Forward-collision warning through the whole stack: margin over the required TTC, or the verdict", ""]
        rows = []
        for name in _keys(reports, lambda r: [x["scenario"] for x in r.get("fcw") or []]):
            cells = []
            for r in reports:
                x = next((x for x in r.get("fcw") or [] if x["scenario"] == name), None)
                if x is None:
                    cells.append(dash)
                elif x.get("required_ttc_s") is None:
                    cells.append(("pass" if x["pass"] else "FAIL") + f", {x['warnings']} warnings")
                else:
                    m = "no warning" if x.get("margin_s") is None else f"{x['margin_s']:+.2f} s"
                    if x.get("dropped_at_ttc_s"):
                        m += f", ended at true TTC {x['dropped_at_ttc_s'][0]:.2f} s"
                    cells.append(("" if x["pass"] else "FAIL ") + m)
            rows.append((name, cells))
        out += _table("scenario", presets, rows)

    if any(r.get("road_motion") for r in reports):
        out += ["### Real video: the vehicles visible throughout, frames tracked (IoU >= 0.3) of their frames, "
                "id switches", ""]
        rows = []
        seqs = _keys(reports, lambda r: [k for k in (r.get("road_motion") or {}) if k != "skipped"])
        for seq in seqs:
            names = _keys(reports, lambda r: ((r.get("road_motion") or {}).get(seq) or {}).get("visible_throughout"))
            for name in names:
                cells = []
                for r in reports:
                    v = (((r.get("road_motion") or {}).get(seq) or {}).get("visible_throughout") or {}).get(name)
                    if v is None:
                        cells.append(dash)
                    else:
                        a = v["iou0.3"]
                        cells.append(f"{a['tracked_frames']} of {v['frames']} ({a['tracked_frames'] / v['frames']:.0%}), "
                                     f"{a['id_switches']}")
                rows.append((f"{seq}: {name}", cells))
        out += _table("vehicle", presets, rows)

    if any(r.get("real_fcw") for r in reports):
        out += ["### Real recordings (nothing dangerous happens in them): warnings / pre-warnings (vehicles "
                "confirmed)", ""]
        rows = []
        for clip in _keys(reports, lambda r: [x["clip"] for x in r.get("real_fcw") or []]):
            cells = []
            for r in reports:
                x = next((x for x in r.get("real_fcw") or [] if x["clip"] == clip), None)
                cells.append(dash if x is None else f"{x['warnings']} / {x['prewarnings']} ({x['vehicles_confirmed']})")
            rows.append((clip, cells))
        out += _table("recording", presets, rows)

    for r in reports:
        for name, why in (r.get("skipped") or {}).items():
            out.append(f"(`{r['preset']}`: skipped {name}: {why})")
    return "\n".join(out).rstrip() + "\n"
