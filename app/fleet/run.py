"""`headway fleet MANIFEST --out DIR`: every drive of a manifest replayed on the engine, the drives already
done (same key) skipped, one report at the end. `headway fleet --compare OLD NEW`: app/fleet/compare.py."""
from __future__ import annotations

import shutil
import sys
import time
from pathlib import Path
from typing import Optional

from app.fleet import compare, engine, report
from app.fleet.drive import drive_dir, is_done, load_row, partial_prefix, run_drive
from app.fleet.manifest import code_version, drive_key, load_manifest
from app.output_files import check_outputs, folder_outputs


def run_fleet(manifest: str, out: str, scheduler: Optional[str] = None, workers: Optional[int] = None,
              config: Optional[str] = None, progress: bool = True) -> dict:
    """Replay the manifest's drives into OUT/drives/NAME/ and write OUT/report.json and report.md."""
    drives = load_manifest(manifest, config)
    inputs = {"the manifest": manifest, "--config": config}
    for d in drives:
        inputs |= {f"drive {d.name}'s {what}": p for what, p in (("source", d.source), ("can_in", d.can_in),
                                                               ("truth", d.truth)) if p and p != "scenario"}
    check_outputs(folder_outputs("--out", out, ("report.json", "report.md", "drives")), inputs)
    outp = Path(out)
    (outp / "drives").mkdir(parents=True, exist_ok=True)
    _clear_partials(outp, [d.name for d in drives])
    code = code_version()
    keys = {d.name: drive_key(d) for d in drives}
    rows: dict[str, dict] = {}
    for d in drives:
        if is_done(out, d.name, keys[d.name]):
            rows[d.name] = load_row(out, d.name) | {"status": "ok", "resumed": True}
    todo = [d for d in drives if d.name not in rows]
    started = time.perf_counter()
    where = f"the cluster at {scheduler}" if scheduler else \
        f"a local cluster of {workers or 'one worker per core'} worker process(es)"
    if todo:
        with engine.cluster(scheduler, workers) as client:
            if not scheduler:
                where = f"a local cluster of {len(client.scheduler_info()['workers'])} worker process(es)"
            prog = engine.Progress(len(drives), len(rows), "fleet", enabled=progress)

            def done(name, row, error):
                if error is not None:
                    d = next(x for x in drives if x.name == name)
                    row = {"name": name, "source": d.source, "status": "failed", "error": error}
                rows[name] = row
                prog.finished(name, row["status"] == "ok", engine.running_count(client),
                              "" if row["status"] == "ok" else f": {row['error']}")

            try:
                engine.run_tasks(client, run_drive, ((d.name, (d, str(outp.resolve()), keys[d.name], code))
                                                     for d in todo), done)
            finally:
                prog.close()
        _clear_partials(outp, [d.name for d in drives])   # left by a worker that died mid-drive
    meta = {"manifest": str(manifest), "where": where, "code": code, "wall_seconds": round(time.perf_counter() - started, 3),
            "config": config}
    rep = report.build([rows[d.name] for d in drives], meta)
    report.write(rep, outp)
    return rep


def _clear_partials(out: Path, names: list[str]) -> None:
    """Partial folders left by a dead worker or an interrupted run (their process is gone)."""
    for name in names:
        for p in (out / "drives").glob(partial_prefix(name) + "*"):
            shutil.rmtree(p, ignore_errors=True)


def add_parser(subparsers) -> None:
    s = subparsers.add_parser("fleet", help="replay many drives in parallel on Dask (local or an existing cluster); "
                                     "one report; --compare two runs")
    s.add_argument("manifest", nargs="?", help="manifest YAML: one entry per drive (docs/fleet.md)")
    s.add_argument("--out", help="output folder: drives/NAME/ per drive, report.md, report.json")
    s.add_argument("--scheduler", help="address of an existing Dask scheduler, e.g. tcp://HOST:8786 "
                                       "(default: a local cluster on this machine)")
    s.add_argument("--workers", type=int, help="local cluster: worker processes (default: one per core)")
    s.add_argument("--config", help="configuration YAML under every drive's own overrides")
    s.add_argument("--compare", nargs=2, metavar=("OLD_DIR", "NEW_DIR"),
                   help="compare two fleet runs' outputs drive by drive (FCW events, tracks, metrics, CAN)")
    s.set_defaults(run=run)


def run(args) -> int:
    if args.compare:
        if args.manifest or args.out:
            raise ValueError("--compare OLD NEW takes no manifest and no --out")
        result = compare.compare(*args.compare)
        print(compare.markdown(result), end="")
        return 0
    if not args.manifest or not args.out:
        raise ValueError("give a manifest and --out DIR (headway fleet MANIFEST --out DIR), "
                         "or --compare OLD_DIR NEW_DIR")
    if args.workers is not None and args.workers < 1:
        raise ValueError(f"--workers {args.workers}: need at least one worker")
    rep = run_fleet(args.manifest, args.out, args.scheduler, args.workers, args.config)
    print(report.markdown(rep), end="")
    print(f"\nreport: {Path(args.out).resolve()}/report.md, report.json; drives in {drive_dir(args.out, '')}")
    if rep["failed"]:
        print(f"headway: {len(rep['failed'])} of {rep['totals']['drives']} drives failed (listed in the report)",
              file=sys.stderr)
        return 1
    return 0
