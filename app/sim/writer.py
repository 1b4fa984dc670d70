"""Write a rendered scenario to disk: frames or video, truth.jsonl, CAN log, resolved inputs."""
from __future__ import annotations

import contextlib
import json
from pathlib import Path
from typing import Any, Callable, Mapping

import cv2
import yaml

from app.output_files import folder_written_whole, written_whole

from .can_log import write_ego_speed_log
from .frames import render, scenario_camera
from .scenario import Scenario, scenario_to_dict
from .world import World


# What write_scenario writes into its folder (besides frames/): a command checks them against its inputs.
WRITTEN = ("scenario.yaml", "camera.json", "truth.jsonl", "ego_speed.log", "video.mp4")


def write_scenario(scenario: Scenario, out_dir: str | Path, video: bool = False,
                   progress: Callable[[int, int], Any] | None = None,
                   camera_overrides: Mapping[str, Any] | None = None) -> dict:
    """Render ``scenario`` into ``out_dir``; returns a summary (paths, n_frames).

    Layout: ``frames/000000.png ...`` (or ``video.mp4`` with ``video=True``), ``truth.jsonl`` (one
    object per frame), ``ego_speed.log`` (candump -L), ``scenario.yaml`` (resolved), ``camera.json``.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    camera = scenario_camera(scenario, camera_overrides)
    world = World(scenario)
    n = world.n_frames
    frames_dir = out / "frames"
    with contextlib.ExitStack() as stack:
        # every file (and the frames folder) is written beside its place and renamed into it only once the
        # whole scenario is rendered: a render that fails leaves the folder's previous files as they were
        def beside(name: str) -> Path:
            return Path(stack.enter_context(written_whole(str(out / name))))

        beside("scenario.yaml").write_text(yaml.safe_dump(scenario_to_dict(scenario), sort_keys=False))
        camera_info = {**camera.to_dict(), "ego_front_m": scenario.ego.front_m, "fps": scenario.fps}
        beside("camera.json").write_text(json.dumps(camera_info, indent=2) + "\n")
        writer = frames_tmp = None
        if video:
            writer = cv2.VideoWriter(str(beside("video.mp4")), cv2.VideoWriter_fourcc(*"mp4v"), scenario.fps,
                                     (camera.width, camera.height), True)
            if not writer.isOpened():
                raise OSError(f"cannot open a video writer for {out / 'video.mp4'}")
            stack.callback(writer.release)   # released before the rename (the stack unwinds in reverse)
        else:
            frames_tmp = Path(stack.enter_context(folder_written_whole(frames_dir)))
        truth_file = stack.enter_context(open(beside("truth.jsonl"), "w", encoding="utf-8"))
        for frame in render(scenario, camera_overrides):
            if writer is not None:
                writer.write(cv2.cvtColor(frame.image, cv2.COLOR_GRAY2BGR))
            elif not cv2.imwrite(str(frames_tmp / f"{frame.index:06d}.png"), frame.image):
                raise OSError(f"cannot write {frames_dir / f'{frame.index:06d}.png'}")
            record = {"frame": frame.index, "t": round(frame.t_s, 6), "ego_speed_mps": round(frame.ego_speed_mps, 6),
                      "pitch_deg": round(frame.pitch_deg, 6), "yaw_deg": round(frame.yaw_deg, 6),
                      "vehicles": [_rounded(v) for v in frame.truth]}
            if frame.road:  # a bent road or the ego's own lane change: the road under the ego, its yaw rate
                record["road"] = {k: round(v, 9) for k, v in frame.road.items()}
                record["yaw_rate_rps"] = round(frame.yaw_rate_rps, 9)
            truth_file.write(json.dumps(record) + "\n")
            if progress is not None:
                progress(frame.index + 1, n)
        last_t = (n - 1) / scenario.fps
        n_can = write_ego_speed_log(beside("ego_speed.log"), world.ego, last_t)
    summary = {"out_dir": str(out), "n_frames": n, "fps": scenario.fps, "duration_s": n / scenario.fps,
               "collision": world.collision_frame is not None, "truth": str(out / "truth.jsonl"),
               "ego_speed_log": str(out / "ego_speed.log"), "can_frames": n_can,
               "scenario": str(out / "scenario.yaml"), "camera": str(out / "camera.json")}
    summary["video" if video else "frames"] = str(out / "video.mp4") if video else str(frames_dir)
    return summary


def _rounded(record: dict) -> dict:
    """Truth record with floats rounded for a compact file (1e-4 px / m is far below any error of interest)."""
    def r(x):
        return None if x is None else round(x, 4) if isinstance(x, float) else x
    return {k: [r(x) for x in v] if isinstance(v, list) else r(v) for k, v in record.items()}
