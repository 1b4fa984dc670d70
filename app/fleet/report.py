"""The fleet's report: a row per drive (frames, time, vehicles confirmed, FCW events, metrics), the totals,
and the drives that failed with their one-line error. Written as ``OUT/report.json`` and ``OUT/report.md``."""
from __future__ import annotations

import json
from pathlib import Path
from typing import Optional

from app.eval.track_score import detection_metrics
from app.output_files import write_whole


def _f(x, nd: int = 3) -> str:
    return "-" if x is None else f"{x:.{nd}f}"


def build(rows: list[dict], meta: dict) -> dict:
    """`rows` in manifest order, each {"name", "status": "ok" | "failed", ...} (drive.load_row's fields)."""
    ok = [r for r in rows if r["status"] == "ok"]
    failed = [{"name": r["name"], "source": r["source"], "error": r["error"]} for r in rows if r["status"] != "ok"]
    scored = [r["metrics"] for r in ok if r.get("metrics")]
    totals = {"drives": len(rows), "ok": len(ok), "failed": len(failed),
              "resumed": sum(1 for r in ok if r.get("resumed")),
              "frames": sum(r["frames"] for r in ok), "seconds": round(sum(r["seconds"] for r in ok), 3),
              "vehicles_confirmed": sum(r["vehicles_confirmed"] for r in ok),
              "warnings": sum(r["warnings"] for r in ok), "prewarnings": sum(r["prewarnings"] for r in ok),
              "can_frames": sum(r["can_frames"] for r in ok)}
    if scored:
        totals["metrics"] = detection_metrics(*(sum(m[k] for m in scored) for k in ("tp", "fp", "fn")))
        totals["metrics"]["drives_with_truth"] = len(scored)
    wall = meta.get("wall_seconds")
    ran = len(ok) - totals["resumed"]
    if wall and ran:
        meta = meta | {"drives_per_minute": round(60.0 * ran / wall, 2)}
    return {"meta": meta, "drives": [r for r in ok], "totals": totals, "failed": failed}


def markdown(report: dict) -> str:
    m, t = report["meta"], report["totals"]
    out = [f"# Fleet replay: {m.get('manifest', '')}", "",
           f"{t['drives']} drives: {t['ok']} done ({t['resumed']} from an earlier run), {t['failed']} failed; "
           f"on {m.get('where', '?')}; code {m.get('code', '?')}; wall time {_f(m.get('wall_seconds'), 1)} s"
           + (f", {m['drives_per_minute']} drives per minute" if m.get("drives_per_minute") else "") + ".", "",
           "| drive | frames | time s | vehicles confirmed | FCW warnings | pre-warnings | CAN frames | "
           "precision | recall | MOTA | IDF1 |",
           "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"]
    for r in report["drives"]:
        mt = r.get("metrics") or {}
        out.append(f"| {r['name']}{' (resumed)' if r.get('resumed') else ''} | {r['frames']} | {_f(r['seconds'], 1)} | "
                   f"{r['vehicles_confirmed']} | {r['warnings']} | {r['prewarnings']} | {r['can_frames']} | "
                   f"{_f(mt.get('precision'))} | {_f(mt.get('recall'))} | {_f(mt.get('mota'))} | {_f(mt.get('idf1'))} |")
    tm = t.get("metrics") or {}
    out.append(f"| **total** | {t['frames']} | {_f(t['seconds'], 1)} | {t['vehicles_confirmed']} | {t['warnings']} | "
               f"{t['prewarnings']} | {t['can_frames']} | {_f(tm.get('precision'))} | {_f(tm.get('recall'))} | | |")
    fcw = [(r["name"], f) for r in report["drives"] if (f := (r.get("metrics") or {}).get("fcw"))
           and (f["pass"] is not None or f["first_warning_t_s"] is not None)]
    if fcw:
        out += ["", "Scenario FCW timing (NCAP: warned by the required true TTC; others: no warning):", "",
                "| drive | first warning t s | true TTC then s | required s | verdict |", "| --- | ---: | ---: | ---: | --- |"]
        for name, f in fcw:
            verdict = {True: "pass", False: "FAIL", None: "-"}[f["pass"]]
            out.append(f"| {name} | {_f(f['first_warning_t_s'], 2)} | {_f(f['true_ttc_s'], 2)} | "
                       f"{_f(f['required_ttc_s'], 1)} | {verdict} |")
    if report["failed"]:
        out += ["", "## Failed drives", ""] + [f"- **{f['name']}** ({f['source']}): {f['error']}" for f in report["failed"]]
    return "\n".join(out) + "\n"


def write(report: dict, out: str | Path) -> tuple[Path, Path]:
    out = Path(out)
    js, md = out / "report.json", out / "report.md"
    write_whole(js, json.dumps(report, indent=1, sort_keys=True) + "\n")
    write_whole(md, markdown(report))
    return js, md


def read(out: str | Path) -> Optional[dict]:
    p = Path(out) / "report.json"
    return json.loads(p.read_text()) if p.exists() else None
