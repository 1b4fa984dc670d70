"""`headway demo`: the built-in scenario through the full pipeline, with nothing to set up.

Writes ./headway-demo/: the annotated video, the tracks file, the scenario's ground truth, and a short
summary that compares what was tracked with the truth.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

from app.eval.matching import iou_matrix
from app.output_files import check_outputs, folder_outputs, write_whole, written_whole
from app.replay import replay_scenario
from app.sim.sprites import patches_problem

DEMO_SCENARIO = "cut_in"


# What the demo writes into its folder.
WRITTEN = ("annotated.mp4", "tracks.jsonl", "truth.jsonl", "can_out.log", "summary.txt")


def add_parser(subparsers) -> None:
    s = subparsers.add_parser("demo", help="render the built-in scenario, run the full pipeline, write ./headway-demo/")
    s.add_argument("--out", default="headway-demo", help="output folder (default ./headway-demo)")
    s.add_argument("--scenario", default=DEMO_SCENARIO, help=argparse.SUPPRESS)
    s.add_argument("--config", default=None, help=argparse.SUPPRESS)
    s.set_defaults(run=run)


def run(args) -> int:
    check_outputs(folder_outputs("--out", args.out, WRITTEN), {"--scenario": args.scenario, "--config": args.config})
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    counts = {"truth": 0, "found": 0}

    def on_result(r, decision, truth):
        truth_f.write(json.dumps({"frame": r.frame, "t": r.t_s, "vehicles": truth}) + "\n")
        # vehicles a driver would care about: mostly visible and within 60 m
        for v in truth:
            if v["visible_fraction"] >= 0.9 and v["longitudinal_m"] <= 60:
                counts["truth"] += 1
                if any(t.confirmed and iou_matrix([t.box], [v["box"]])[0, 0] >= 0.5 for t in r.tracks):
                    counts["found"] += 1

    # The demo must run on a fresh install without ../shared/data: it says so and draws plain vehicles.
    problem = patches_problem()
    if problem:
        print(f"warning: {problem}; the demo draws plain vehicles")
    # the truth, as the replay's own outputs, is renamed into place only once the replay completed
    with written_whole(str(out / "truth.jsonl")) as truth_tmp, open(truth_tmp, "w") as truth_f:
        s = replay_scenario(args.scenario, config_path=args.config, out_video=str(out / "annotated.mp4"),
                            tracks_path=str(out / "tracks.jsonl"), can_out=str(out / "can_out.log"),
                            on_result=on_result, vehicle_look="plain" if problem else None)
    recall = counts["found"] / counts["truth"] if counts["truth"] else float("nan")
    summary = s.text() + (f"\n  vehicles within 60 m tracked (IoU >= 0.5): {counts['found']} of "
                          f"{counts['truth']} vehicle-frames ({recall:.0%})")
    write_whole(out / "summary.txt", summary + "\n")
    print(summary)
    print(f"\nDemo written to {out.resolve()}/ ({', '.join(WRITTEN)})")
    return 0
