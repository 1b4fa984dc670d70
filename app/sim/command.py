"""`headway sim SCENARIO --out DIR`: a synthetic scenario rendered into a folder (frames or a video, the
ground truth, the ego-speed CAN log), as app/sim/writer.py lays it out."""
from __future__ import annotations

import sys

from tqdm import tqdm

from app.output_files import check_outputs, folder_outputs
from app.sim import load_scenario, write_scenario
from app.sim.writer import WRITTEN


def add_parser(subparsers) -> None:
    s = subparsers.add_parser("sim", help="render a synthetic scenario: frames, ground truth, ego-speed CAN log")
    s.add_argument("scenario", help="scenario name (see app/sim/scenarios) or a scenario YAML file")
    s.add_argument("--out", required=True, help="output folder")
    s.add_argument("--video", action="store_true", help="write video.mp4 instead of a PNG per frame")
    s.set_defaults(run=run)


def run(args) -> int:
    check_outputs(folder_outputs("--out", args.out, WRITTEN), {"the scenario": args.scenario})
    sc = load_scenario(args.scenario)
    with tqdm(total=None, desc=sc.name, unit="frame", file=sys.stderr, disable=not sys.stderr.isatty(),
              leave=False) as bar:
        def progress(i, n):
            bar.total = n
            bar.update(1)

        info = write_scenario(sc, args.out, video=args.video, progress=progress)
    print(f"{sc.name}: {info.get('n_frames')} frames -> {args.out}")
    return 0
