"""`headway fleet --compare OLD_DIR NEW_DIR`: two fleet runs, drive by drive: the FCW events that appeared or
disappeared, the tracks and metrics that changed, the CAN logs that differ, and the drives only one run has."""
from __future__ import annotations

import filecmp
import json
from pathlib import Path
from typing import Optional

from app.fleet.drive import drive_dir

METRIC_KEYS = ("precision", "recall", "mota", "idf1", "id_switches", "fragments", "median_range_rel_error")


def _drives(out: str) -> list[str]:
    d = Path(out) / "drives"
    if not d.is_dir():
        raise ValueError(f"{out}: not a fleet output folder (no drives/ inside); give the --out of a `headway fleet` run")
    return sorted(x.name for x in d.iterdir() if x.is_dir() and not x.name.startswith(".") and (x / "key").exists())


def _json(path: Path) -> Optional[dict]:
    return json.loads(path.read_text()) if path.exists() else None


def _events(summary: dict) -> list[tuple[str, float, Optional[float]]]:
    return [(e["level"], e["t"], e["ttc_used_s"]) for e in summary["fcw_events"]]


def _lines_diff(a: Path, b: Path) -> dict:
    """How two line files differ: line counts, lines that differ, the first one (1-based)."""
    la, lb = a.read_text().splitlines(), b.read_text().splitlines()
    differ = [i for i in range(max(len(la), len(lb))) if i >= len(la) or i >= len(lb) or la[i] != lb[i]]
    return {"lines_old": len(la), "lines_new": len(lb), "lines_differing": len(differ),
            "first_differing_line": differ[0] + 1 if differ else None}


def compare_drive(old: Path, new: Path) -> dict:
    so, sn = _json(old / "summary.json"), _json(new / "summary.json")
    eo, en = _events(so), _events(sn)
    out: dict = {"fcw_appeared": [e for e in en if e not in eo], "fcw_disappeared": [e for e in eo if e not in en]}
    if not filecmp.cmp(old / "tracks.jsonl", new / "tracks.jsonl", shallow=False):
        out["tracks"] = _lines_diff(old / "tracks.jsonl", new / "tracks.jsonl") | {
            "vehicles_confirmed_old": so["vehicles_confirmed"], "vehicles_confirmed_new": sn["vehicles_confirmed"]}
    mo, mn = _json(old / "metrics.json") or {}, _json(new / "metrics.json") or {}
    changed = {k: [mo.get(k), mn.get(k)] for k in METRIC_KEYS if mo.get(k) != mn.get(k)}
    if changed:
        out["metrics"] = changed
    if not filecmp.cmp(old / "can.log", new / "can.log", shallow=False):
        out["can"] = _lines_diff(old / "can.log", new / "can.log")
    return out


def compare(old: str, new: str) -> dict:
    a, b = _drives(old), _drives(new)
    result = {"old": str(old), "new": str(new), "only_old": [n for n in a if n not in b],
              "only_new": [n for n in b if n not in a], "drives": {}}
    for name in a:
        if name in b:
            result["drives"][name] = compare_drive(drive_dir(old, name), drive_dir(new, name))
    result["identical"] = [n for n, d in result["drives"].items() if not any(d.values())]
    return result


def _event(e) -> str:
    level, t, ttc = e
    return f"{level} at t={t:.2f} s" + (f" (TTC {ttc:.2f} s)" if ttc is not None else "")


def markdown(c: dict) -> str:
    out = [f"# Fleet comparison: {c['old']} -> {c['new']}", "",
           f"{len(c['drives'])} drives in both, {len(c['identical'])} identical"
           + (f"; only in the old run: {', '.join(c['only_old'])}" if c["only_old"] else "")
           + (f"; only in the new run: {', '.join(c['only_new'])}" if c["only_new"] else "") + ".", ""]
    for name, d in c["drives"].items():
        if name in c["identical"]:
            continue
        out.append(f"## {name}")
        out += [f"- FCW appeared: {_event(e)}" for e in d["fcw_appeared"]]
        out += [f"- FCW disappeared: {_event(e)}" for e in d["fcw_disappeared"]]
        if "tracks" in d:
            t = d["tracks"]
            out.append(f"- tracks: {t['lines_differing']} of {max(t['lines_old'], t['lines_new'])} frames differ "
                       f"(first: line {t['first_differing_line']}); vehicles confirmed "
                       f"{t['vehicles_confirmed_old']} -> {t['vehicles_confirmed_new']}")
        for k, (o, n) in d.get("metrics", {}).items():
            out.append(f"- {k}: {o} -> {n}")
        if "can" in d:
            t = d["can"]
            out.append(f"- CAN log differs: {t['lines_differing']} of {max(t['lines_old'], t['lines_new'])} frames "
                       f"(first: line {t['first_differing_line']}; {t['lines_old']} -> {t['lines_new']} frames)")
        out.append("")
    return "\n".join(out) + ("\n" if not out[-1] == "" else "")
