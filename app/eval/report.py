"""`headway eval`: run a pipeline preset over the evaluation sets and write a JSON report, a markdown
table and a few annotated example images into one folder."""
from __future__ import annotations

import contextlib
import functools
import json
import sys
import time
from pathlib import Path
from typing import Optional

import cv2

from app import config as configuration
from app.annotate import annotate, annotate_detections
from app.bench.pipeline import run_bench
from app.eval import (compare, fcw_scenarios, lane_clips, lanes_sample, range_clip, real_video_fcw, road_motion,
                      synthetic, tusimple_boxes)
from app.eval import results_doc
from app.eval.compare import figure as _f
from app.fleet.engine import map_ordered
from app.output_files import check_outputs, folder_outputs, folder_written_whole, write_whole, written_whole

PARTS = ("synthetic", "tusimple", "lanes", "range", "fcw", "road_motion", "real_fcw", "cost")
# What one preset's run writes into its folder, and what several presets' comparison adds beside their folders.
RUN_FILES = ("report.json", "report.md", "lanes_sample_pred.json", "lane_clips_pred.json", "examples")
COMPARE_FILES = ("compare.md", "compare.json")


def markdown(report: dict) -> str:
    out = [f"## Preset `{report['preset']}`", ""]
    syn = report.get("synthetic")
    if syn:
        o = syn["overall"]
        out += ["### Synthetic suite (vehicles within 60 m, at least half visible; IoU >= 0.5 of the boxes' parts in "
                "the image; a track more than half on a vehicle not scored counts neither way)", "",
                "| scenario | precision | recall | MOTA | IDF1 | id switches | fragments |",
                "| --- | ---: | ---: | ---: | ---: | ---: | ---: |"]
        for name, m in syn["per_scenario"].items():
            out.append(f"| {name} | {_f(m['precision'])} | {_f(m['recall'])} | {_f(m['mota'])} | {_f(m['idf1'])} | "
                       f"{m['id_switches']} | {m['fragments']} |")
        out.append(f"| **all** | {_f(o['precision'])} | {_f(o['recall'])} | {_f(o['mota'])} | {_f(o['idf1'])} | "
                   f"{o['id_switches']} | {o['fragments']} |")
        out += ["", "Range error of matched confirmed tracks, by true range:", "",
                "| band | n | median relative error | p90 relative error |", "| --- | ---: | ---: | ---: |"]
        for band, b in syn["range_bands"].items():
            out.append(f"| {band} | {b['n']} | {_f(b['median_rel_error'])} | {_f(b['p90_rel_error'])} |")
        out.append("")
    tu = report.get("tusimple")
    if tu:
        out += [f"### TuSimple highway images ({tu['images']} images, single-image detection, IoU >= 0.5)", "",
                "| box height | ground truth | detected | false positives | recall | precision |",
                "| --- | ---: | ---: | ---: | ---: | ---: |"]
        for band, b in tu["bands"].items():
            label = "all" if band == "overall" else f"{band} px"
            out.append(f"| {label} | {b['gt']} | {b['tp']} | {b['fp']} | {_f(b['recall'])} | {_f(b['precision'])} |")
        best = tu.get("best_at_precision_0.8")
        out += ["", "Best recall at precision >= 0.8 for boxes >= 40 px, keeping only detections above a score: " +
                ("none reaches that precision" if not best else
                 f"{best['recall']:.3f} at score >= {best['threshold']:.2f} (precision {best['precision']:.3f})") + "."]
        op = tu.get("operating_point")
        if op and op["threshold"] > 0:
            out += ["", f"At the detector's operating point (what `headway detect` writes; score >= {op['threshold']:.2f}, "
                    f"chosen on held-out training images), boxes >= 40 px: recall {_f(op['recall'])}, precision "
                    f"{_f(op['precision'])}."]
        elif op:
            out += ["", "`headway detect` writes every detection of this detector (no score reaches precision 0.85 "
                    "on held-out training images)."]
        out.append("")
    ln = report.get("lanes")
    if ln:
        out += [f"### TuSimple lane sample ({ln['images']} images)", "",
                "| accuracy | false positives | false negatives | ego lane found |", "| ---: | ---: | ---: | ---: |",
                f"| {_f(ln['accuracy'])} | {_f(ln['fp'])} | {_f(ln['fn'])} | {ln['ego_lane_found']} of {ln['images']} |",
                ""]
    lc = report.get("lane_clips")
    if lc:
        out += [f"### TuSimple lane clips ({lc['clips']} clips of 20 frames through the whole pipeline, "
                "scored on frame 20)", "",
                "| accuracy | false positives | false negatives |", "| ---: | ---: | ---: |",
                f"| {_f(lc['accuracy'])} | {_f(lc['fp'])} | {_f(lc['fn'])} |", "",
                "| clip | accuracy | FP | FN | lanes predicted | lanes labelled |",
                "| --- | ---: | ---: | ---: | ---: | ---: |"]
        for im in lc["per_image"]:
            out.append(f"| {Path(im['raw_file']).parent.as_posix().removeprefix('clips/')} | {_f(im['accuracy'])} | "
                       f"{_f(im['fp'], 2)} | {_f(im['fn'], 2)} | {im['n_pred']} | {im['n_gt']} |")
        out += ["", "Predictions in TuSimple's format: `lane_clips_pred.json`, `lanes_sample_pred.json`.", ""]
    rc = report.get("range")
    if rc:
        out += [f"### Range on TuSimple train_clip1 (frame {rc['frames']}, range-sensor truth)", "",
                "| true range m | estimated m | error m | relative | range rate m/s (true) |",
                "| ---: | ---: | ---: | ---: | ---: |"]
        for v in rc["vehicles"]:
            if v["found"]:
                rr = "n/a" if v["range_rate_mps"] is None else f"{v['range_rate_mps']:.2f}"
                out.append(f"| {v['true_range_m']:.1f} | {v['range_m']:.1f} | {v['error_m']:+.1f} | "
                           f"{v['rel_error']:+.1%} | {rr} ({v['true_range_rate_mps']:.2f}) |")
            else:
                out.append(f"| {v['true_range_m']:.1f} | not found | | | |")
        out.append("")
    rm = report.get("road_motion")
    if rm:
        out += [road_motion.markdown(rm), ""]
    fc = report.get("fcw")
    if fc:
        out += ["### Forward-collision warning through the whole stack (CAN output decoded with cantools)", "",
                "| scenario | first warning at t | TTC used | true TTC then | required | margin | warnings | "
                "pre-warnings | verdict | TTC used vs true (true TTC 1-5 s): frames, median error / p90 absolute error |",
                "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | --- | ---: |"]
        for r in fc:
            req = r.get("required_ttc_s")
            verdict = "pass" if r["pass"] else "FAIL"
            if req is None:
                verdict += " (no warning expected)" if not r["warnings"] else " (false warning)"
            elif r.get("dropped_at_ttc_s"):
                ended = ", ".join(f"{x:.2f}" for x in r["dropped_at_ttc_s"])
                verdict += f" (the warning ended at true TTC {ended} s)"
            t_first = "none" if r["first_warning_t_s"] is None else f"{r['first_warning_t_s']:.2f} s"
            margin = "-" if r.get("margin_s") is None else f"{r['margin_s']:+.2f} s"
            acc = r.get("ttc_accuracy")
            acc = "-" if not acc else f"{acc['frames']}: {acc['median']:+.1%} / {acc['p90_abs']:.1%}"
            out.append(f"| {r['scenario']} | {t_first} | {_f(r['ttc_used_s'], 2)} | {_f(r['true_ttc_s'], 2)} | "
                       f"{'-' if req is None else req} | {margin} | {r['warnings']} | {r['prewarnings']} | {verdict} "
                       f"| {acc} |")
        out.append("")
    rv = report.get("real_fcw")
    if rv:
        out += ["### False warnings on the real recordings (nothing dangerous happens in them)", "",
                real_video_fcw.markdown(rv, report["preset"]), ""]
    cost = report.get("cost")
    if cost:
        t = cost["total"]
        out += ["### Cost per frame (`headway bench --scenario dense_traffic`, one pass)", "",
                f"{cost['frames']} frames of {cost['frame_size']} on {cost['machine']}: median {t['median_ms']:.2f} ms, "
                f"p99 {t['p99_ms']:.2f} ms per frame", ""]
    out += [f"(skipped {name}: {why})" for name, why in report.get("skipped", {}).items()]
    return "\n".join(out)


def evaluate(preset: str, out_dir: str, parts=PARTS, data_dir: str = "../shared/data",
             config_path: Optional[str] = None, scenarios: Optional[list[str]] = None, examples: int = 4,
             workers: Optional[int] = None, scheduler: Optional[str] = None) -> dict:
    """With `workers` or `scheduler`, the synthetic suite and the FCW scenarios run one task per scenario on
    the fleet's engine (app/fleet/engine.py); the other parts run here."""
    mapper = None
    if workers is not None or scheduler is not None:
        mapper = functools.partial(map_ordered, scheduler=scheduler, workers=workers)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    with contextlib.ExitStack() as stack:
        # every output is written beside its place and renamed into it once the whole evaluation is done: an
        # evaluation that fails leaves the folder's previous report, predictions and examples as they were
        examples_dir = Path(stack.enter_context(folder_written_whole(out / "examples")))

        def beside(name: str) -> str:
            return stack.enter_context(written_whole(str(out / name)))

        report = _measure(preset, parts, Path(data_dir), config_path, scenarios, examples, mapper, examples_dir,
                          beside)
        Path(beside("report.json")).write_text(json.dumps(report, indent=1, default=str))
        Path(beside("report.md")).write_text(markdown(report) + "\n")
    return report


def _measure(preset: str, parts, data: Path, config_path: Optional[str], scenarios: Optional[list[str]],
             examples: int, mapper, examples_dir: Path, beside) -> dict:
    """The report of `evaluate`: up to `examples` annotated images of each kind into `examples_dir`, the lane
    predictions to the path `beside(name)` gives for the file's name."""
    report: dict = {"preset": preset, "skipped": {}}

    def say(msg: str) -> None:
        print(f"eval {preset}: {msg}", file=sys.stderr)

    if "synthetic" in parts:
        report["synthetic"] = synthetic.evaluate_suite(preset, scenarios, config_path,
                                                       progress=lambda n: say(f"scenario {n}"), mapper=mapper)
    if "tusimple" in parts:
        supp = data / "tusimple" / "supp"
        if supp.exists():
            shown = [0]

            def keep(e, gray, r):
                if shown[0] < examples and e["bbox"]:
                    truth = [{"box": b} for b in tusimple_boxes.entry_boxes(e)]
                    cv2.imwrite(str(examples_dir / f"tusimple_{Path(e['file_name']).stem}.jpg"),
                                annotate_detections(gray, r.boxes, truth))
                    shown[0] += 1

            say("TuSimple images")
            try:
                report["tusimple"] = tusimple_boxes.evaluate(str(supp), config_path, preset, on_image=keep)
            except tusimple_boxes.NoSingleImageDetector as e:
                report["skipped"]["tusimple"] = str(e)
        else:
            report["skipped"]["tusimple"] = f"{supp} not found"
    if "lanes" in parts:
        def lane_example(prefix: str):
            """Writes a scored lane image, annotated, as examples/PREFIX_NAME.jpg (NAME: its folder): the
            model's boundaries as `annotate` draws them and the labelled lanes as red dots (one per h_samples row),
            so a miss can be told apart at a glance (wrong line, extent, curvature)."""
            def keep(lab, gray, r):
                name = Path(lab["raw_file"]).parent.name
                img = annotate(gray, r)
                for lane in lab["lanes"]:
                    for x, y in zip(lane, lab["h_samples"]):
                        if x >= 0:
                            cv2.circle(img, (int(round(x)), int(y)), max(2, img.shape[1] // 400), (0, 0, 255), -1)
                cv2.imwrite(str(examples_dir / f"{prefix}_{name}.jpg"), img)
            return keep

        sample = data / "tusimple" / "lane_sample"
        if sample.exists():
            say("lane sample")
            report["lanes"] = lanes_sample.evaluate(str(sample), config_path, on_image=lane_example("lanes"),
                                                    predictions_out=beside("lanes_sample_pred.json"))
        else:
            report["skipped"]["lanes"] = f"{sample} not found"
        clips = data / "tusimple" / "lane_clips"
        if clips.exists():
            say("lane clips")
            report["lane_clips"] = lane_clips.evaluate(str(clips), config_path, preset,
                                                       predictions_out=beside("lane_clips_pred.json"),
                                                       on_clip=lane_example("lane_clip"))
        else:
            report["skipped"]["lane_clips"] = f"{clips} not found"
    if "range" in parts:
        clip = data / "tusimple" / "train_clip1"
        if clip.exists():
            say("train_clip1 range")
            report["range"] = range_clip.evaluate(str(clip), config_path, preset)
        else:
            report["skipped"]["range"] = f"{clip} not found"
    if "fcw" in parts:
        names = list(fcw_scenarios.REQUIRED_TTC_S) + list(fcw_scenarios.NO_WARNING)
        if mapper is not None:
            report["fcw"] = mapper(fcw_scenarios.evaluate, [(n, config_path, preset) for n in names], names, "FCW")
        else:
            report["fcw"] = []
            for name in names:
                say(f"FCW {name}")
                report["fcw"].append(fcw_scenarios.evaluate(name, config_path, preset))
    if "road_motion" in parts:
        say("road homography and track continuity on TME / Udacity")
        report["road_motion"] = road_motion.evaluate(str(data), preset, config_path=config_path)
    if "real_fcw" in parts:
        if (data / "udacity").exists():
            say("false warnings on the real recordings")
            report["real_fcw"] = real_video_fcw.evaluate(str(data), preset, config_path)
        else:
            report["skipped"]["real_fcw"] = f"{data / 'udacity'} not found"
    if "cost" in parts:
        say("ms per frame (dense_traffic, 640x480, this machine)")
        bench = run_bench("dense_traffic", preset, 640, 480, repeats=1, config_path=config_path, fps=0)
        report["cost"] = {"frame_size": bench["frame_size"], "frames": bench["frames"], "machine": bench["machine"],
                          "total": bench["stages"]["all"]["total"]}
    return report


def presets_of(arg: str) -> list[str]:
    """The presets --pipeline names (one, or several separated by commas), each checked against the core's list."""
    known = list(configuration.presets())
    presets = [p.strip() for p in arg.split(",") if p.strip()]
    bad = [p for p in presets if p not in known]
    if bad or not presets:
        raise ValueError(f"--pipeline: unknown preset(s) {', '.join(bad) or repr(arg)}; choose from {', '.join(known)} "
                         "(several separated by commas are set side by side)")
    if len(set(presets)) != len(presets):
        raise ValueError(f"--pipeline: {arg!r} names a preset twice")
    return presets


def _write_document(path: str, presets: list[str], parts: tuple, args, scenarios, sections: list[str],
                    started: float) -> None:
    cmd = results_doc.command(presets, parts, PARTS, path, args.data, args.config, scenarios)
    write_whole(path, results_doc.document(cmd, sections, time.monotonic() - started))
    print(f"document: {Path(path).resolve()}")


def add_parser(subparsers) -> None:
    s = subparsers.add_parser("eval", help="measure a pipeline on the synthetic suite and the real data; JSON + markdown")
    s.add_argument("--pipeline", default=configuration.default_preset(),
                   help="preset to evaluate: default, thesis, parallax, paper004 (default: %(default)s); several separated "
                        "by commas (e.g. default,thesis,parallax,paper004) are evaluated one after another, each into "
                        "OUT/PRESET/, and set side by side in OUT/compare.md")
    s.add_argument("--parts", help="comma-separated subset of synthetic,tusimple,lanes,range,fcw,road_motion,real_fcw,cost "
                                         "(default all)")
    s.add_argument("--scenarios", help="comma-separated scenario names (default: the whole suite)")
    s.add_argument("--data", default="../shared/data", help="real data folder (default ../shared/data)")
    s.add_argument("--out", help="report folder (default reports/eval-PIPELINE; with several presets "
                                 "reports/eval-A-B-...), or FILE.md: the whole results document (docs/RESULTS.md)")
    s.add_argument("--config", help="configuration YAML")
    s.add_argument("--workers", type=int, help="run the synthetic and FCW scenarios on a local Dask cluster of N "
                                               "worker processes (docs/fleet.md)")
    s.add_argument("--scheduler", help="... or on an existing Dask cluster (tcp://HOST:8786)")
    s.set_defaults(run=run)


def run(args) -> int:
    parts = tuple(args.parts.split(",")) if args.parts else PARTS
    unknown = set(parts) - set(PARTS)
    if unknown:
        raise ValueError(f"--parts: unknown part(s) {', '.join(sorted(unknown))}; choose from {', '.join(PARTS)}")
    presets = presets_of(args.pipeline)
    if args.workers is not None and args.workers < 1:
        raise ValueError(f"--workers {args.workers}: need at least one worker")
    scenarios = args.scenarios.split(",") if args.scenarios else None
    # --out FILE.md: the whole document (docs/RESULTS.md); the report folders go to the default place
    doc = args.out if results_doc.is_document(args.out) else None
    started = time.monotonic()
    out = Path(args.out if args.out and not doc else f"reports/eval-{'-'.join(presets)}")
    written = RUN_FILES if len(presets) == 1 else \
        COMPARE_FILES + tuple(presets) + tuple(f"{p}/{name}" for p in presets for name in RUN_FILES)
    check_outputs(folder_outputs("--out", str(out), written), {"--config": args.config, "--data": args.data})
    if doc:
        check_outputs({"--out": doc}, {"--config": args.config, "--data": args.data})
    if len(presets) == 1:
        report = evaluate(presets[0], str(out), parts, args.data, args.config, scenarios, workers=args.workers,
                     scheduler=args.scheduler)
        print(markdown(report))
        print(f"\nreport: {out.resolve()}/report.json, report.md, examples/")
        if doc:
            _write_document(doc, presets, parts, args, scenarios, [markdown(report)], started)
        return 0
    reports = [evaluate(p, str(out / p), parts, args.data, args.config, scenarios, workers=args.workers,
                   scheduler=args.scheduler) for p in presets]
    text = compare.markdown(reports, folders=[str(out / p) for p in presets] if doc else presets)
    if doc:
        _write_document(doc, presets, parts, args, scenarios, [text] + [markdown(r) for r in reports], started)
    write_whole(out / "compare.md", text)
    write_whole(out / "compare.json", json.dumps({"presets": presets, "parts": list(parts),
                                                  "reports": [f"{p}/report.json" for p in presets]}, indent=1))
    print(text, end="")
    print(f"\nreport: {out.resolve()}/compare.md, and each preset's in {out.resolve()}/PRESET/")
    return 0
