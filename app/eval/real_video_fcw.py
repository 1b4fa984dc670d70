"""False warnings on real motorway video: the whole stack (pipeline, supervisor, FCW, CAN) over the Udacity
clips and the TME tme08 frames, in which nothing dangerous happens, so every warning is a false one.

They come without CAN: the ego speed is a constant 27 m/s (97 km/h, motorway traffic) played in as a CAN
log. The cameras are those of app/eval/road_motion.py (Udacity: fx 1150 px at 1280 px assumed, 1.5 m high;
TME: from its calibration.ini; pitch and yaw from the lanes' vanishing point). For the thesis preset the
speed only opens the FCW's gates (TTCs come from the images); the parallax preset also predicts its road
homography from it, so for that preset a wrong assumed speed also degrades detection.

    python -m app.eval.real_video_fcw [--pipeline thesis] [--data ../shared/data]
"""
from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path
from typing import Optional

import yaml

from app import config as configuration
from app.eval.road_motion import fit_horizon, read_tme, read_video, tme_camera, udacity_camera
from app.contracts.fcw_level import FcwLevel
from app.replay import replay_recording
from app.sim.can_log import DBC_PATH, write_ego_speed_log
from app.sim.world import Motion1D

EGO_SPEED_MPS = 27.0


def recordings(data: Path, only: Optional[str] = None) -> list[tuple[Path, dict, float, bool]]:
    """(source, camera, frame rate, is an image folder) for every recording (or the one named `only`); pitch and
    yaw fitted to the lanes as in app/eval/road_motion.py."""
    out = []
    folder = data / "udacity"
    for clip in sorted((folder / "clips").glob("*.mp4")) + [folder / "test_video.mp4"]:
        if only not in (None, clip.name):
            continue
        frames, fps = read_video(clip, 15)
        out.append((clip, fit_horizon(udacity_camera(frames[0].shape[1], frames[0].shape[0]), frames), fps, False))
    tme = data / "tme"
    if (tme / "tme08").exists() and only in (None, "tme08"):
        frames, fps = read_tme(tme / "tme08")
        out.append((tme / "tme08", fit_horizon(tme_camera(tme / "calibration.ini"), frames), fps, True))
    return out


def recording_config(camera: dict, preset: str, config_path: Optional[str] = None) -> dict:
    """A recording's replay configuration: the user's (`headway eval --config`; validated, so a bad key fails
    here naming it) under the recording's camera, the preset and the ego speed log's signals."""
    cfg = {"camera": camera, "pipeline": {"preset": preset},
           "vehicle": {"speed_dbc": str(DBC_PATH), "speed_message": "EGO_SPEED", "speed_signals": "SPEED_MPS"}}
    return configuration.load(config_path, cfg) if config_path else cfg


def evaluate(data: str, preset: str = "thesis", config_path: Optional[str] = None,
             only: Optional[str] = None) -> list[dict]:
    """One row per recording (or for the one named `only`, e.g. "tme08"): frames, vehicles confirmed, warnings,
    pre-warnings and every FCW event (time, level, TTC)."""
    out = []
    with tempfile.TemporaryDirectory() as tmp:
        for source, camera, fps, is_folder in recordings(Path(data), only):
            log = Path(tmp) / f"{source.stem}.log"
            write_ego_speed_log(log, Motion1D(0.0, EGO_SPEED_MPS, []), 60.0)
            cfg_path = Path(tmp) / "config.yaml"
            cfg_path.write_text(yaml.safe_dump(recording_config(camera, preset, config_path)))
            s = replay_recording(str(source), str(cfg_path), fps=fps if is_folder else None, can_in=str(log),
                                 progress=False)
            out.append({"clip": source.name, "frames": s.frames, "seconds": round(s.frames / fps, 2),
                        "vehicles_confirmed": len(s.confirmed_ids),
                        "warnings": sum(1 for _, level, _ in s.warnings if level == FcwLevel.WARNING.label),
                        "prewarnings": sum(1 for _, level, _ in s.warnings if level == FcwLevel.PREWARNING.label),
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
