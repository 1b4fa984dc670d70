"""The parallax pipeline (paper 000) on real drives: how often the road homography is accepted, how well
it aligns the road, and how continuous the tracks are.

Data (../shared/data): TME Motorway sequence tme08 (50 frames, 1024x768, calibration.ini) and the Udacity
clips (no calibration). The homography is judged on windows of ``window`` consecutive frames, each processed
from a reset pipeline (a fresh filter settles on the first pairs, the last pair is judged: accepted by the gate
or not, and the alignment residual over the road area; window_config), so that every window starts alike
whatever the earlier frames did. The camera's horizon row and yaw are taken from the median vanishing point of
the lane stage over the first frames (the TME calibration's yaw does not match its images, the Udacity clips
have none); the focal length from the TME field of view, and an assumed 1150 px at 1280 px width for Udacity.
"""
from __future__ import annotations

import configparser
import json
import math
import sys
import tempfile
from pathlib import Path
from typing import Optional

import cv2
import numpy as np
import yaml

from app import config as configuration
from app.core import Pipeline
from app.eval.matching import iou_matrix
from app.recording import open_recording
from app.sim import load_scenario, render
from app.sim.frames import scenario_camera
from app.sim.scenario import resolve_path
from app.sim.world import World

TME_FPS = 20.0  # frames/s of the TME Motorway sequences
UDACITY_FX_AT_1280 = 1150.0  # px, assumed (typical of the Udacity dash camera at 1280x720)
# Share of the image height taken by the car's bonnet (camera.hood_frac), read off the frames.
WINDOW_FPS = 30.0  # frames/s the windows are processed at (nominal: the filter's settling does not depend on the clip)
HOOD = {"tme08": 0.04, "project_video_cut.mp4": 0.07, "test_small1.mp4": 0.07, "test_small2.mp4": 0.07,
        "test_video.mp4": 0.07, "solidWhiteRight.mp4": 0.0}


def read_tme(folder: Path) -> tuple[list[np.ndarray], float]:
    """Gray frames of a TME sequence folder and its frame rate (TME Motorway: 20 fps)."""
    return open_recording(folder, TME_FPS).read_all(), TME_FPS


def read_video(path: Path, max_frames: Optional[int] = None) -> tuple[list[np.ndarray], float]:
    """Gray frames of a video (the first max_frames) and its own frame rate."""
    rec = open_recording(path)
    return rec.read_all(max_frames), rec.fps


def tme_camera(ini: Path) -> dict:
    """Intrinsics and height from calibration.ini (H-FOV, POS Z_M); pitch/yaw are fitted later."""
    text = "[c]\n" + Path(ini).read_text()
    c = configparser.ConfigParser()
    c.read_string(text)
    s = c["c"]
    w, h = int(s["IMAGE WIDTH"]), int(s["IMAGE HEIGHT"])
    fx = 0.5 * w / math.tan(math.radians(float(s["H_FOV_DEG"])) / 2)
    return {"width": w, "height": h, "fx": fx, "fy": fx, "cx": w / 2, "cy": h / 2,
            "height_m": float(s["POS Z_M"]), "pitch_deg": float(s["POS PITCH_DEG"]), "yaw_deg": 0.0}


def udacity_camera(width: int, height: int) -> dict:
    fx = UDACITY_FX_AT_1280 * width / 1280.0
    return {"width": width, "height": height, "fx": fx, "fy": fx, "cx": width / 2, "cy": height / 2,
            "height_m": 1.5, "pitch_deg": 0.0, "yaw_deg": 0.0}


def fit_horizon(camera: dict, frames: list[np.ndarray], n: int = 15, lanes: Optional[dict] = None) -> dict:
    """Pitch and yaw from the median lane vanishing point of the first n frames (row = cy - fy tan(pitch),
    column = cx - fx tan(yaw)); `lanes`: keys of the lanes section other than the defaults."""
    vps = []
    with Pipeline({"camera": camera, "pipeline": {"preset": "none"}, **({"lanes": lanes} if lanes else {})}) as p:
        for img in frames[:n]:
            vp = p.image_lanes(img).vanishing_point
            if vp is not None:
                vps.append(vp)
    cam = dict(camera)
    if vps:
        x, y = np.median(np.asarray(vps), axis=0)
        cam["pitch_deg"] = math.degrees(math.atan((cam["cy"] - y) / cam["fy"]))
        cam["yaw_deg"] = math.degrees(math.atan((cam["cx"] - x) / cam["fx"]))
    return cam


def window_config(config: dict) -> dict:
    """`config` for judging the homography on windows: the parallax composition, the one that runs the road-motion
    stage (the stage is the same whatever preset `config` names, so every preset's row judges it), the road's
    alignment residual reported (homography.measure_residual), and self-calibration off, so that the road-motion
    stage works around the given camera throughout (a window of a few frames is too short for self-calibration to
    settle, and its early corrections would move the camera the filter is judged with)."""
    return {**config, "pipeline": {**config.get("pipeline", {}), "preset": "parallax", "detectors": [], "tracker": ""},
            "homography": {**config.get("homography", {}), "measure_residual": True},
            "self_calibration": {**config.get("self_calibration", {}), "enabled": False}}


def last_pair(p: Pipeline, frames: list[np.ndarray]):
    """The result of the last of `frames` processed from a reset pipeline at WINDOW_FPS (no ego speed)."""
    p.reset()
    for k, img in enumerate(frames):
        r = p.process(img, k / WINDOW_FPS)
    return r


def homography_windows(frames: list[np.ndarray], config: dict, window: int = 6, step: int = 1) -> dict:
    """Acceptance and alignment residual of the last pair of every window of `window` frames."""
    accepted, residuals, unwarped, raw = [], [], [], []
    with Pipeline(window_config(config)) as p:
        for end in range(window, len(frames) + 1, step):
            r = last_pair(p, frames[end - window:end])
            accepted.append(r.road_motion == "accepted")
            if r.road_residual is not None:
                residuals.append(r.road_residual)          # |I_k - warp(I_k-1, H) - o| on the road area
                unwarped.append(r.road_residual_unaligned)  # |I_k - I_k-1 - o'| on the same pixels
                raw.append(r.road_residual_raw)             # |I_k - warp(I_k-1, H)|: brightness change left in
    med = lambda v: float(np.median(v)) if v else None  # noqa: E731
    return {"pairs": len(accepted), "accepted_rate": float(np.mean(accepted)) if accepted else None,
            "residual_median": med(residuals),
            "residual_p90": float(np.percentile(residuals, 90)) if residuals else None,
            "aligned_pairs": len(residuals), "unwarped_median": med(unwarped), "raw_residual_median": med(raw)}


def track_continuity(frames: list[np.ndarray], config: dict, fps: float) -> dict:
    """Confirmed tracks over a whole sequence: how long each id lives, and how many ids start after the
    first second (a proxy for fragments where there is no ground truth); and what the running homography
    filter did on each frame pair (accepted a measurement, coasted on its prediction, had no estimate)."""
    life: dict[int, list[int]] = {}
    road: list[Optional[str]] = []  # the running homography filter's state per frame
    coast_max = 0
    with Pipeline(config) as p:
        for k, img in enumerate(frames):
            r = p.process(img, k / fps)
            road.append(r.road_motion)
            coast_max = max(coast_max, r.road_coast_frames)
            for t in r.tracks:
                if t.confirmed:
                    life.setdefault(t.id, []).append(k)
    n = len(frames)
    spans = {i: (min(v), max(v), len(v)) for i, v in life.items()}
    pairs = max(1, n - 1)  # the first frame has no previous one
    return {"frames": n, "ids": len(spans),
            "running_filter": {"accepted_rate": road.count("accepted") / pairs,
                               "predicted_rate": road.count("predicted") / pairs,
                               "no_estimate_rate": sum(1 for x in road[1:] if x is None) / pairs,
                               "longest_coast_frames": coast_max},
            "ids_living_80pct": sum(1 for a, b, c in spans.values() if c >= 0.8 * n),
            "ids_started_after_1s": sum(1 for a, b, c in spans.values() if a >= fps),
            "longest_frames": max((c for a, b, c in spans.values()), default=0),
            "tracks": {str(i): {"first": a, "last": b, "frames": c} for i, (a, b, c) in sorted(spans.items())}}


# Vehicles visible in every frame of tme08 and three Udacity clips, boxes per frame (read off the frames at
# key frames and interpolated; how, in the file).
VISIBLE_THROUGHOUT = Path(__file__).resolve().parent / "data" / "visible_throughout.json"


def visible_throughout(sequence: str) -> list[dict]:
    """The annotated vehicles of one sequence ("tme08", "test_video.mp4", ...): [{"name", "boxes"}], boxes
    per frame (l, t, r, b); [] when the sequence has none."""
    doc = json.loads(VISIBLE_THROUGHOUT.read_text())
    return doc["sequences"].get(sequence, {}).get("vehicles", [])


def identity(frames: list[np.ndarray], config: dict, fps: float, vehicles: list[dict],
             min_ious: tuple = (0.3, 0.5)) -> dict:
    """For each annotated vehicle and IoU level: the frames a confirmed track was on it, the id switches
    (the track on it changed id from one tracked frame to the next) and the fragments (runs of consecutive
    tracked frames; 1 = tracked without a break once it started)."""
    hits = {(v["name"], m): [] for v in vehicles for m in min_ious}
    with Pipeline(config) as p:
        for k, img in enumerate(frames):
            r = p.process(img, k / fps)
            tracks = [t for t in r.tracks if t.confirmed]
            for v in vehicles:
                if k >= len(v["boxes"]) or not tracks:
                    continue
                m = iou_matrix([t.box for t in tracks], [v["boxes"][k]])[:, 0]
                for lim in min_ious:
                    if m.max() >= lim:
                        hits[(v["name"], lim)].append((k, tracks[int(m.argmax())].id))
    res: dict = {}
    for (name, lim), h in hits.items():
        ks = [k for k, _ in h]
        ids = [i for _, i in h]
        res.setdefault(name, {"frames": min(len(frames), len(next(v for v in vehicles if v["name"] == name)["boxes"]))})
        res[name][f"iou{lim}"] = {
            "tracked_frames": len(ks),
            "first_tracked": ks[0] if ks else None,
            "fragments": sum(1 for i, k in enumerate(ks) if i == 0 or k != ks[i - 1] + 1),
            "id_switches": sum(1 for i in range(1, len(ids)) if ids[i] != ids[i - 1]),
            "ids": sorted(set(ids))}
    return res


def true_road_homography(scenario, prev, cur):
    """Synthetic frames: the exact road-plane homography (pixels, prev -> cur) of the two frames' shaken
    cameras and the ego travel between them, and the current frame's camera."""
    world = World(scenario)
    cam0 = scenario_camera(scenario)
    cp = cam0.shaken(prev.pitch_deg - cam0.pitch_deg, prev.yaw_deg - cam0.yaw_deg)
    cc = cam0.shaken(cur.pitch_deg - cam0.pitch_deg, cur.yaw_deg - cam0.yaw_deg)
    s = world.frame_state(cur.index).ego_odometer_m - world.frame_state(prev.index).ego_odometer_m
    # road point (X, Z) at k-1 is at (X, Z - s) at k
    h = cc.ground_to_image() @ np.array([[1, 0, 0], [0, 1, -s], [0, 0, 1.0]]) @ np.linalg.inv(cp.ground_to_image())
    return h, cc


def road_residuals(scenario, prev, cur) -> tuple[float, float]:
    """Synthetic frames: mean |difference| on the road 4-40 m ahead (no vehicles) after warping `prev` with the
    exact road homography of the two frames' shaken cameras and the ego travel, and without warping."""
    h, cc = true_road_homography(scenario, prev, cur)
    v, u = np.mgrid[0:cur.image.shape[0], 0:cur.image.shape[1]]
    x, z = cc.ground_from_pixel(u, v)
    road = np.isfinite(z) & (z > 4) & (z < 40) & (np.abs(x) < 5)
    for veh in cur.truth + prev.truth:
        l, t, r, b = veh["box"]
        road &= ~((u >= l - 3) & (u <= r + 3) & (v >= t - 3) & (v <= b + 3))
    warped = cv2.warpPerspective(prev.image, h, (cur.image.shape[1], cur.image.shape[0])).astype(float)
    return float(np.abs(warped - cur.image)[road].mean()), float(np.abs(prev.image.astype(float) - cur.image)[road].mean())


def synthetic_homography(cases=(("empty_road", None), ("empty_road", 0.4), ("overtaking_from_side", None),
                                ("dense_traffic", None)),
                         kalman=(("q = r = 1e-5 (default)", {}), ("paper Q = 1e-6, R = 1e-3", {"q": 1e-6, "r": 1e-3})),
                         duration_s: float = 5.0, window: int = 8, step: int = 4) -> list[dict]:
    """The homography on shaken synthetic roads: per (scenario, shake pitch deg or None = the file's, Kalman
    setting), windows of `window` frames every `step` frames, each from a reset pipeline, the last pair judged."""
    rows = []
    for name, shake in cases:
        doc = yaml.safe_load(resolve_path(name).read_text())
        if shake is not None:
            doc["shake"] = {"pitch_deg": shake, "yaw_deg": shake / 3}
        doc["duration_s"] = min(float(doc["duration_s"]), duration_s)
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / f"{name}.yaml"
            path.write_text(yaml.safe_dump(doc))
            sc = load_scenario(path)
        frames = list(render(sc))
        for label, kal in kalman:
            acc, est, true, unw = [], [], [], []
            with Pipeline(window_config({"pipeline": {"preset": "parallax"}, "homography": dict(kal)})) as p:
                for end in range(window, len(frames) + 1, step):
                    r = last_pair(p, [f.image for f in frames[end - window:end]])
                    acc.append(r.road_motion == "accepted")
                    if r.road_residual is not None:
                        est.append(r.road_residual)
                    t, u = road_residuals(sc, frames[end - 2], frames[end - 1])
                    true.append(t)
                    unw.append(u)
            rows.append({"scenario": name, "shake_pitch_deg": doc.get("shake", {}).get("pitch_deg", 0.15),
                         "kalman": label, "windows": len(acc), "accepted_rate": float(np.mean(acc)),
                         "residual_median": float(np.median(est)) if est else None,
                         "true_h_residual_median": float(np.median(true)), "unwarped_median": float(np.median(unw))})
    return rows


def core_config(values: dict, config_path: Optional[str] = None) -> dict:
    """The core's configuration as `headway eval` builds it: `config_path`'s (or the defaults) with `values`
    over them, the shipped cascade and verifier filled in."""
    return configuration.core_sections(configuration.load(config_path, values))


def evaluate(data_dir: str = "../shared/data", preset: str = "parallax", window: int = 6,
             udacity_max_frames: Optional[int] = None, config_path: Optional[str] = None) -> dict:
    """The whole real-data part: TME homography + identity, Udacity homography + continuity per clip."""
    data = Path(data_dir)
    report: dict = {"skipped": {}}
    tme = data / "tme" / "tme08"
    if tme.exists():
        frames, fps = read_tme(tme)
        cam = fit_horizon(tme_camera(data / "tme" / "calibration.ini"), frames)
        cfg = core_config({"camera": {**cam, "hood_frac": HOOD["tme08"]}, "pipeline": {"preset": preset}}, config_path)
        report["tme08"] = {"camera": cam, "homography": homography_windows(frames, cfg, window),
                           "continuity": track_continuity(frames, cfg, fps),
                           "visible_throughout": identity(frames, cfg, fps, visible_throughout("tme08"))}
    else:
        report["skipped"]["tme08"] = f"{tme} not found"
    clips = sorted((data / "udacity" / "clips").glob("*.mp4")) + [data / "udacity" / "test_video.mp4"]
    for clip in clips:
        if not clip.exists():
            report["skipped"][clip.name] = f"{clip} not found"
            continue
        frames, fps = read_video(clip, udacity_max_frames)
        cam = fit_horizon(udacity_camera(frames[0].shape[1], frames[0].shape[0]), frames)
        cfg = core_config({"camera": {**cam, "hood_frac": HOOD.get(clip.name, 0.0)}, "pipeline": {"preset": preset}}, config_path)
        report[clip.name] = {"camera": cam, "homography": homography_windows(frames, cfg, window),
                             "continuity": track_continuity(frames, cfg, fps)}
        if visible_throughout(clip.name) and udacity_max_frames is None:
            report[clip.name]["visible_throughout"] = identity(frames, cfg, fps, visible_throughout(clip.name))
    return report


def markdown(report: dict) -> str:
    out = ["### Parallax pipeline on real drives: road homography and track continuity", "",
           "| sequence | pairs | accepted | residual median | residual p90 | without alignment | "
           "brightness change left in | running filter accepted / coasting / none | longest coast | ids | "
           "ids living 80 % | ids started after 1 s |",
           "| --- | ---: | ---: | ---: | ---: | ---: | ---: | --- | ---: | ---: | ---: | ---: |"]
    for name, r in report.items():
        if name == "skipped":
            continue
        h, c = r["homography"], r["continuity"]
        rf = c["running_filter"]
        f = lambda x: "n/a" if x is None else f"{x:.2f}"  # noqa: E731
        out.append(f"| {name} | {h['pairs']} | {f(h['accepted_rate'])} | {f(h['residual_median'])} | "
                   f"{f(h['residual_p90'])} | {f(h['unwarped_median'])} | {f(h.get('raw_residual_median'))} | "
                   f"{rf['accepted_rate']:.0%} / {rf['predicted_rate']:.0%} / {rf['no_estimate_rate']:.0%} | "
                   f"{rf['longest_coast_frames']} | {c['ids']} | "
                   f"{c['ids_living_80pct']} | {c['ids_started_after_1s']} |")
    rows = [(seq, name, v) for seq, r in report.items() if seq != "skipped"
            for name, v in r.get("visible_throughout", {}).items()]
    if rows:
        out += ["", "Vehicles visible throughout (app/eval/data/visible_throughout.json), confirmed tracks on them at "
                "IoU >= 0.3 (and 0.5):", "",
                "| sequence | vehicle | frames | tracked | first tracked | fragments | id switches | tracked at IoU 0.5 |",
                "| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: |"]
        for seq, name, v in rows:
            a, b = v["iou0.3"], v["iou0.5"]
            out.append(f"| {seq} | {name} | {v['frames']} | {a['tracked_frames']} | {a['first_tracked']} | "
                       f"{a['fragments']} | {a['id_switches']} | {b['tracked_frames']} |")
    for name, why in report.get("skipped", {}).items():
        out.append(f"\n(skipped {name}: {why})")
    return "\n".join(out)


if __name__ == "__main__":  # python -m app.eval.road_motion [data_dir | synthetic]
    if sys.argv[1:2] == ["synthetic"]:
        print("| scenario | shake pitch deg | Kalman | windows | accepted | residual | true H | none |")
        print("| --- | ---: | --- | ---: | ---: | ---: | ---: | ---: |")
        for r in synthetic_homography():
            print(f"| {r['scenario']} | {r['shake_pitch_deg']:.2f} | {r['kalman']} | {r['windows']} | "
                  f"{r['accepted_rate']:.0%} | {r['residual_median']:.2f} | {r['true_h_residual_median']:.2f} | "
                  f"{r['unwarped_median']:.2f} |")
    else:
        rep = evaluate(sys.argv[1] if len(sys.argv) > 1 else "../shared/data")
        print(json.dumps(rep, indent=1, default=str))
        print(markdown(rep))
