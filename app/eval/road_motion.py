"""The parallax pipeline (paper 000) on real drives: how often the road homography is accepted, how well
it aligns the road, and how continuous the tracks are.

Data (../shared/data): TME Motorway sequence tme08 (50 frames, 1024x768, calibration.ini) and the Udacity
clips (no calibration). The homography is judged through the ``homography`` stage on windows of
``window`` consecutive frames (a fresh filter settles on the first pairs, the last pair is judged: accepted by
the gate or not, and the alignment residual over the road area), because the C ABI reports no homography
from ``process()``. The camera's horizon row and yaw are taken from the median vanishing point of the
lane stage over the first frames (the TME calibration's yaw does not match its images, the Udacity clips
have none); the focal length from the TME field of view, and an assumed 1150 px at 1280 px width for Udacity.
"""
from __future__ import annotations

import configparser
import math
from pathlib import Path
from typing import Optional

import cv2
import numpy as np

from app.core import Pipeline

UDACITY_FX_AT_1280 = 1150.0  # px, assumed (typical of the Udacity dash camera at 1280x720)
# Share of the image height taken by the car's bonnet (parallax.hood_frac), read off the frames.
HOOD = {"tme08": 0.04, "project_video_cut.mp4": 0.07, "test_small1.mp4": 0.07, "test_small2.mp4": 0.07,
        "test_video.mp4": 0.07, "solidWhiteRight.mp4": 0.0}


def read_tme(folder: Path) -> tuple[list[np.ndarray], float]:
    """Gray frames of a TME sequence folder and its frame rate (TME Motorway: 20 fps)."""
    files = sorted(Path(folder).glob("*.jpg"))
    return [cv2.imread(str(f), cv2.IMREAD_GRAYSCALE) for f in files], 20.0


def read_video(path: Path, max_frames: Optional[int] = None) -> tuple[list[np.ndarray], float]:
    cap = cv2.VideoCapture(str(path))
    fps = cap.get(cv2.CAP_PROP_FPS) or 25.0
    frames = []
    while max_frames is None or len(frames) < max_frames:
        ok, img = cap.read()
        if not ok:
            break
        frames.append(cv2.cvtColor(img, cv2.COLOR_BGR2GRAY))
    cap.release()
    return frames, float(fps)


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


def fit_horizon(camera: dict, frames: list[np.ndarray], n: int = 15) -> dict:
    """Pitch and yaw from the median lane vanishing point of the first n frames (row = cy - fy tan(pitch),
    column = cx - fx tan(yaw))."""
    vps = []
    with Pipeline({"camera": camera, "pipeline": {"preset": "none"}}) as p:
        for img in frames[:n]:
            vp = p.run_stage("lanes", img).vanishing_point
            if vp is not None:
                vps.append(vp)
    cam = dict(camera)
    if vps:
        x, y = np.median(np.asarray(vps), axis=0)
        cam["pitch_deg"] = math.degrees(math.atan((cam["cy"] - y) / cam["fy"]))
        cam["yaw_deg"] = math.degrees(math.atan((cam["cx"] - x) / cam["fx"]))
    return cam


def homography_windows(frames: list[np.ndarray], config: dict, window: int = 6, step: int = 1) -> dict:
    """Acceptance and alignment residual of the last pair of every window of `window` frames."""
    accepted, residuals, unwarped = [], [], []
    with Pipeline(config) as p:
        for end in range(window, len(frames) + 1, step):
            r = p.run_stage("homography", np.vstack(frames[end - window:end]))
            accepted.append(bool(r.full_detection))
            if r.image_change is not None:
                residuals.append(r.image_change)   # |I_k - warp(I_k-1, H)| on the road area
                unwarped.append(r.image_mean)      # |I_k - I_k-1| on the same pixels
    med = lambda v: float(np.median(v)) if v else None  # noqa: E731
    return {"pairs": len(accepted), "accepted_rate": float(np.mean(accepted)) if accepted else None,
            "residual_median": med(residuals),
            "residual_p90": float(np.percentile(residuals, 90)) if residuals else None,
            "aligned_pairs": len(residuals), "unwarped_median": med(unwarped)}


def track_continuity(frames: list[np.ndarray], config: dict, fps: float) -> dict:
    """Confirmed tracks over a whole sequence: how long each id lives, and how many ids start after the
    first second (a proxy for fragments where there is no ground truth)."""
    life: dict[int, list[int]] = {}
    with Pipeline(config) as p:
        for k, img in enumerate(frames):
            r = p.process(img, k / fps)
            for t in r.tracks:
                if t.confirmed:
                    life.setdefault(t.id, []).append(k)
    n = len(frames)
    spans = {i: (min(v), max(v), len(v)) for i, v in life.items()}
    return {"frames": n, "ids": len(spans),
            "ids_living_80pct": sum(1 for a, b, c in spans.values() if c >= 0.8 * n),
            "ids_started_after_1s": sum(1 for a, b, c in spans.values() if a >= fps),
            "longest_frames": max((c for a, b, c in spans.values()), default=0),
            "tracks": {str(i): {"first": a, "last": b, "frames": c} for i, (a, b, c) in sorted(spans.items())}}


# Vehicles visible through all of tme08, marked by hand at frames 0, 25 and 49 (l, t, r, b in px of the
# 1024x768 frames) and interpolated linearly in between; a track is on one when IoU >= 0.3.
TME08_VISIBLE_THROUGHOUT = {
    "silver car, right of the ego lane": {0: (470, 368, 520, 407), 25: (500, 368, 570, 420), 49: (548, 372, 645, 442)},
    "dark car ahead left": {0: (365, 370, 420, 410), 25: (335, 370, 390, 420), 49: (285, 370, 348, 425)},
}


def _interpolate(keys: dict, k: int) -> tuple:
    ks = sorted(keys)
    lo = max(x for x in ks if x <= k)
    hi = min(x for x in ks if x >= k)
    if lo == hi:
        return keys[lo]
    a = (k - lo) / (hi - lo)
    return tuple((1 - a) * u + a * v for u, v in zip(keys[lo], keys[hi]))


def tme_identity(frames: list[np.ndarray], config: dict, fps: float = 20.0) -> dict:
    """For each hand-marked vehicle: frames it was tracked (confirmed, IoU >= 0.3), ids that followed it
    (more than one = id switches), and fragments (runs of consecutive tracked frames)."""
    from app.eval.matching import iou_matrix

    out = {name: {"tracked": [], "ids": []} for name in TME08_VISIBLE_THROUGHOUT}
    with Pipeline(config) as p:
        for k, img in enumerate(frames):
            r = p.process(img, k / fps)
            tracks = [t for t in r.tracks if t.confirmed]
            for name, keys in TME08_VISIBLE_THROUGHOUT.items():
                box = _interpolate(keys, k)
                m = iou_matrix([t.box for t in tracks], [box])[:, 0] if tracks else np.zeros(0)
                if m.size and m.max() >= 0.3:
                    out[name]["tracked"].append(k)
                    out[name]["ids"].append(tracks[int(m.argmax())].id)
    res = {}
    for name, v in out.items():
        ks = v["tracked"]
        runs = sum(1 for i, k in enumerate(ks) if i == 0 or k != ks[i - 1] + 1)
        switches = sum(1 for i in range(1, len(v["ids"])) if v["ids"][i] != v["ids"][i - 1])
        res[name] = {"frames": len(frames), "tracked_frames": len(ks), "fragments": runs,
                     "id_switches": switches, "ids": sorted(set(v["ids"]))}
    return res


def road_residuals(scenario, prev, cur) -> tuple[float, float]:
    """Synthetic frames: mean |difference| on the road 4-40 m ahead (no vehicles) after warping `prev` with the
    exact road homography of the two frames' shaken cameras and the ego travel, and without warping."""
    from app.sim.frames import scenario_camera
    from app.sim.world import World

    world = World(scenario)
    cam0 = scenario_camera(scenario)
    cp = cam0.shaken(prev.pitch_deg - cam0.pitch_deg, prev.yaw_deg - cam0.yaw_deg)
    cc = cam0.shaken(cur.pitch_deg - cam0.pitch_deg, cur.yaw_deg - cam0.yaw_deg)
    s = world.frame_state(cur.index).ego_odometer_m - world.frame_state(prev.index).ego_odometer_m
    # road point (X, Z) at k-1 is at (X, Z - s) at k
    h = cc.ground_to_image() @ np.array([[1, 0, 0], [0, 1, -s], [0, 0, 1.0]]) @ np.linalg.inv(cp.ground_to_image())
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
    setting), windows of `window` frames through run_stage every `step` frames, the last pair judged."""
    import tempfile

    import yaml

    from app.sim import load_scenario, render
    from app.sim.scenario import resolve_path

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
            with Pipeline({"pipeline": {"preset": "parallax"}, "homography": dict(kal)}) as p:
                for end in range(window, len(frames) + 1, step):
                    r = p.run_stage("homography", np.vstack([f.image for f in frames[end - window:end]]))
                    acc.append(bool(r.full_detection))
                    if r.image_change is not None:
                        est.append(r.image_change)
                    t, u = road_residuals(sc, frames[end - 2], frames[end - 1])
                    true.append(t)
                    unw.append(u)
            rows.append({"scenario": name, "shake_pitch_deg": doc.get("shake", {}).get("pitch_deg", 0.15),
                         "kalman": label, "windows": len(acc), "accepted_rate": float(np.mean(acc)),
                         "residual_median": float(np.median(est)) if est else None,
                         "true_h_residual_median": float(np.median(true)), "unwarped_median": float(np.median(unw))})
    return rows


def evaluate(data_dir: str = "../shared/data", preset: str = "parallax", window: int = 6,
             udacity_max_frames: Optional[int] = None) -> dict:
    """The whole real-data part: TME homography + identity, Udacity homography + continuity per clip."""
    data = Path(data_dir)
    report: dict = {"skipped": {}}
    tme = data / "tme" / "tme08"
    if tme.exists():
        frames, fps = read_tme(tme)
        cam = fit_horizon(tme_camera(data / "tme" / "calibration.ini"), frames)
        cfg = {"camera": cam, "pipeline": {"preset": preset}, "parallax": {"hood_frac": HOOD["tme08"]}}
        report["tme08"] = {"camera": cam, "homography": homography_windows(frames, cfg, window),
                           "continuity": track_continuity(frames, cfg, fps),
                           "visible_throughout": tme_identity(frames, cfg, fps)}
    else:
        report["skipped"]["tme08"] = f"{tme} not found"
    clips = sorted((data / "udacity" / "clips").glob("*.mp4")) + [data / "udacity" / "test_video.mp4"]
    for clip in clips:
        if not clip.exists():
            report["skipped"][clip.name] = f"{clip} not found"
            continue
        frames, fps = read_video(clip, udacity_max_frames)
        cam = fit_horizon(udacity_camera(frames[0].shape[1], frames[0].shape[0]), frames)
        cfg = {"camera": cam, "pipeline": {"preset": preset}, "parallax": {"hood_frac": HOOD.get(clip.name, 0.0)}}
        report[clip.name] = {"camera": cam, "homography": homography_windows(frames, cfg, window),
                             "continuity": track_continuity(frames, cfg, fps)}
    return report


def markdown(report: dict) -> str:
    out = ["### Parallax pipeline on real drives: road homography and track continuity", "",
           "| sequence | pairs | accepted | residual median | residual p90 | without alignment | ids | "
           "ids living 80 % | ids started after 1 s |",
           "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"]
    for name, r in report.items():
        if name == "skipped":
            continue
        h, c = r["homography"], r["continuity"]
        f = lambda x: "n/a" if x is None else f"{x:.2f}"  # noqa: E731
        out.append(f"| {name} | {h['pairs']} | {f(h['accepted_rate'])} | {f(h['residual_median'])} | "
                   f"{f(h['residual_p90'])} | {f(h['unwarped_median'])} | {c['ids']} | "
                   f"{c['ids_living_80pct']} | {c['ids_started_after_1s']} |")
    vt = report.get("tme08", {}).get("visible_throughout")
    if vt:
        out += ["", "tme08, vehicles visible throughout (hand-marked, IoU >= 0.3):", "",
                "| vehicle | frames | tracked | fragments | id switches |", "| --- | ---: | ---: | ---: | ---: |"]
        for name, v in vt.items():
            out.append(f"| {name} | {v['frames']} | {v['tracked_frames']} | {v['fragments']} | {v['id_switches']} |")
    for name, why in report.get("skipped", {}).items():
        out.append(f"\n(skipped {name}: {why})")
    return "\n".join(out)


if __name__ == "__main__":  # python -m app.eval.road_motion [data_dir | synthetic]
    import json
    import sys

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
