"""`headway calibrate --from-video CLIP`: the camera's mounting (pitch, yaw, height) from a drive on a marked road.

The clip is replayed through the whole stack as `headway replay` does, with the configuration given (its camera's
intrinsics, and its height as the starting value) and self-calibration from scratch (self_calibration.enabled and
from_scratch: csrc/geometry/self_calibration.*, docs/calibration.md): pitch and yaw from the lanes' vanishing point
over the search range, the configured ones ignored, and the height from the lane width. The estimate at the clip's end, with its 1-sigma, is printed and written into the camera section of
a copy of the configuration, so that the next run starts from it.
"""
from __future__ import annotations

from pathlib import Path
from typing import Optional

import yaml

from app.output_files import write_whole
from app.replay import replay_recording
from app.safe_yaml import load_yaml

STATES_USABLE = ("converged", "learning")  # an estimate at a bound or switched off is not written


class DriveCalibrationError(ValueError):
    """A drive that gives no estimate; the message says why and what to do."""


def calibrate_drive(clip: str, config_path: Optional[str] = None, fps: Optional[float] = None) -> dict:
    """Self-calibration's estimate at the end of `clip`: {pitch_deg, yaw_deg, height_m, *_sigma_*, updates, state,
    frames, converged_frame (first frame in the converged state, or None)}."""
    seen: dict = {"frames": 0, "converged_frame": None, "last": None}

    def keep(r, _decision, _truth):
        seen["frames"] += 1
        seen["last"] = r.calibration
        if seen["converged_frame"] is None and (r.calibration or {}).get("state") == "converged":
            seen["converged_frame"] = seen["frames"] - 1

    replay_recording(clip, config_path=config_path, fps=fps, on_result=keep, progress=False,
                     overrides={"self_calibration": {"enabled": True, "from_scratch": True}})
    cal = seen["last"]
    if not cal or cal["updates"] == 0:
        raise DriveCalibrationError(f"{clip}: no frame had both ego lane boundaries measured on a straight road: "
                                    f"nothing to calibrate from ({seen['frames']} frames); give a drive on a marked "
                                    "road, and check the camera's intrinsics and camera.hood_frac")
    out = dict(cal)
    out.update(frames=seen["frames"], converged_frame=seen["converged_frame"])
    return out


def write_config(est: dict, out: str, config_path: Optional[str], clip: str) -> None:
    """A copy of `config_path` (or an empty configuration) with the estimate in its camera section."""
    cfg = (load_yaml(Path(config_path).read_text()) if config_path else None) or {}  # checked by the replay
    cam = cfg.setdefault("camera", {})
    cam.update(pitch_deg=round(est["pitch_deg"], 3), yaw_deg=round(est["yaw_deg"], 3),
               height_m=round(est["height_m"], 3))
    head = (f"# headway calibrate --from-video {clip}: {est['updates']} of {est['frames']} frames measured, "
            f"state {est['state']}\n"
            f"# pitch {est['pitch_deg']:.2f} +- {est['pitch_sigma_deg']:.2f} deg, yaw {est['yaw_deg']:.2f} +- "
            f"{est['yaw_sigma_deg']:.2f} deg, height {est['height_m']:.3f} +- {est['height_sigma_m']:.3f} m\n")
    write_whole(out, head + yaml.safe_dump(cfg, sort_keys=False))


def main(args) -> int:
    est = calibrate_drive(args.from_video, args.config, args.fps)
    print(f"{args.from_video}: {est['frames']} frames, {est['updates']} with lanes measured; state {est['state']}"
          + (f" (converged at frame {est['converged_frame']})" if est["converged_frame"] is not None else ""))
    print(f"pitch  {est['pitch_deg']:7.2f} +- {est['pitch_sigma_deg']:.2f} deg")
    print(f"yaw    {est['yaw_deg']:7.2f} +- {est['yaw_sigma_deg']:.2f} deg")
    print(f"height {est['height_m']:7.3f} +- {est['height_sigma_m']:.3f} m")
    if est["state"] not in STATES_USABLE:
        raise DriveCalibrationError(f"{args.from_video}: the estimate ended {est['state']} (at the end of its search "
                                    "range or of the height's bound): not written; check the intrinsics, the hood "
                                    "line and self_calibration.pitch_min_deg / pitch_max_deg")
    write_config(est, args.out, args.config, args.from_video)
    print(f"camera pitch_deg, yaw_deg, height_m -> {args.out}")
    return 0
