"""False warnings on real freeway video: the whole stack (pipeline, supervisor, FCW, CAN) over the Udacity
clips, in which nothing dangerous happens, so every warning is a false one.

The clips come without CAN: the ego speed is a constant 27 m/s (97 km/h, freeway traffic) played in as a
CAN log, and the camera is the one app/eval/road_motion.py assumes for these clips (fx 1150 px at 1280 px,
1.5 m high, level). The speed only opens the FCW's gates; TTCs come from the images.

    python -m app.eval.real_video_fcw [--pipeline thesis] [--data ../shared/data]
"""
from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path
from typing import Optional

import cv2
import yaml

from app.eval.road_motion import udacity_camera
from app.replay import replay_recording
from app.sim.can_log import DBC_PATH, write_ego_speed_log
from app.sim.world import Motion1D

EGO_SPEED_MPS = 27.0


def clips(data: Path) -> list[Path]:
    folder = data / "udacity"
    return sorted((folder / "clips").glob("*.mp4")) + [folder / "test_video.mp4"]


def evaluate(data: str, preset: str = "thesis") -> list[dict]:
    out = []
    with tempfile.TemporaryDirectory() as tmp:
        for clip in clips(Path(data)):
            cap = cv2.VideoCapture(str(clip))
            size = int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT))
            fps = cap.get(cv2.CAP_PROP_FPS) or 25.0
            seconds = cap.get(cv2.CAP_PROP_FRAME_COUNT) / fps
            cap.release()
            log = Path(tmp) / f"{clip.stem}.log"
            write_ego_speed_log(log, Motion1D(0.0, EGO_SPEED_MPS, []), seconds + 1.0)
            cfg = {"camera": udacity_camera(*size), "pipeline": {"preset": preset},
                   "vehicle": {"speed_dbc": str(DBC_PATH), "speed_message": "EGO_SPEED", "speed_signals": "SPEED_MPS"}}
            cfg_path = Path(tmp) / "config.yaml"
            cfg_path.write_text(yaml.safe_dump(cfg))
            s = replay_recording(str(clip), str(cfg_path), can_in=str(log), progress=False)
            out.append({"clip": clip.name, "frames": s.frames, "seconds": round(s.frames / fps, 2),
                        "vehicles_confirmed": len(s.confirmed_ids),
                        "warnings": sum(1 for _, level, _ in s.warnings if level == "warning"),
                        "prewarnings": sum(1 for _, level, _ in s.warnings if level == "prewarning"),
                        "events": [(round(t, 2), level, None if ttc is None else round(ttc, 2))
                                   for t, level, ttc in s.warnings]})
    return out


def markdown(rows: list[dict], preset: str) -> str:
    lines = [f"| clip ({preset}) | frames | seconds | vehicles confirmed | warnings | pre-warnings |",
             "| --- | ---: | ---: | ---: | ---: | ---: |"]
    lines += [f"| {r['clip']} | {r['frames']} | {r['seconds']} | {r['vehicles_confirmed']} | {r['warnings']} | "
              f"{r['prewarnings']} |" for r in rows]
    return "\n".join(lines)


def main(argv: Optional[list[str]] = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--pipeline", default="thesis")
    p.add_argument("--data", default=str(Path(__file__).resolve().parents[2].parent / "shared" / "data"))
    a = p.parse_args(argv)
    if not (Path(a.data) / "udacity").exists():
        print(f"real_video_fcw: {Path(a.data) / 'udacity'} not found (../shared/data is absent)", file=sys.stderr)
        return 2
    print(markdown(evaluate(a.data, a.pipeline), a.pipeline))
    return 0


if __name__ == "__main__":
    sys.exit(main())
