"""The parallax pipeline (paper 000) through process(): the filtered road homography, how well it aligns the road
(homography.measure_residual) and the aligned difference's detections."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from app.core import ConfigError, Pipeline, core_schema
from app.eval.road_motion import last_pair, road_residuals, true_road_homography, window_config
from app.sim import load_scenario, render

SCENARIOS = Path(__file__).resolve().parent.parent / "app" / "sim" / "scenarios"


def shaken_scenario(tmp_path: Path, name: str, pitch_deg: float, duration_s: float = 3.0):
    """A shipped scenario with stronger camera shake (yaw a third of the pitch amplitude)."""
    doc = yaml.safe_load((SCENARIOS / f"{name}.yaml").read_text())
    doc["shake"] = {"pitch_deg": pitch_deg, "yaw_deg": pitch_deg / 3}
    doc["duration_s"] = duration_s
    path = tmp_path / f"{name}_shake.yaml"
    path.write_text(yaml.safe_dump(doc))
    return load_scenario(path)


def test_every_parallax_key_is_documented_and_the_preset_exists():
    schema = core_schema()
    for section in ("road_features", "homography", "parallax", "particles"):
        assert schema[section], section
        for key, spec in schema[section].items():
            assert spec["doc"].strip(), f"{section}.{key}"
    assert "parallax" in schema["pipeline"]["preset"]["choices"]
    with Pipeline({"pipeline": {"preset": "parallax"}, "homography": {"q": 1e-6, "r": 1e-3}}) as p:
        assert p.config["homography"]["r"] == 1e-3
    with pytest.raises(ConfigError, match=r"homography\.gate"):
        Pipeline({"homography": {"gate": -1.0}})


@pytest.mark.parametrize("pitch_deg", [0.15, 0.4])
def test_estimated_homography_aligns_the_shaken_road(tmp_path, pitch_deg):
    """Measured: residual 2.3-3.4 gray levels (true homography 2.1-2.2, none 4.6-6.4) at 0.4 deg."""
    scenario = shaken_scenario(tmp_path, "empty_road", pitch_deg)
    frames = list(render(scenario, frames=range(0, 60)))
    residuals = []
    with Pipeline(window_config({"pipeline": {"preset": "parallax"}})) as p:
        for end in range(10, 61, 10):  # windows of 6 frames: 4 to settle, the last pair judged
            r = last_pair(p, [f.image for f in frames[end - 6:end]])
            true, unwarped = road_residuals(scenario, frames[end - 2], frames[end - 1])
            assert r.road_residual is not None, f"no alignment at frame {end - 1}"
            assert r.road_residual < 0.75 * unwarped, (end, r.road_residual, unwarped)
            assert r.road_residual < true + 1.5, (end, r.road_residual, true)
            assert r.road_residual_unaligned > r.road_residual, (end, r.road_residual, r.road_residual_unaligned)
            residuals.append(r.road_residual)
    assert np.median(residuals) < 3.0, residuals


@pytest.mark.parametrize("name, pitch_deg", [("empty_road", 0.4), ("dense_traffic", 0.15)])
def test_process_reports_the_running_road_homography(tmp_path, name, pitch_deg):
    """process() reports the running filter's homography and what it did, and it maps the whole road, not only
    the marked lanes: the worst road point 5-40 m ahead (within 5 m of the ego lane's centre) against the exact
    homography, median over frames, without CAN speed. Measured with the road-motion model: 0.74 px (p90 1.48)
    under 0.4 deg shake, 0.23 px (p90 0.40) on dense_traffic; with the plain DLT (homography.road_model false)
    1.13 and 14.2 px: vehicles hide the markings on the image's right side, where it extrapolated 15-20 px off.
    Accepted on 98 % of the pairs (DLT 95 %)."""
    scenario = shaken_scenario(tmp_path, name, pitch_deg, duration_s=4.0)
    frames = list(render(scenario))
    worst, states = [], []
    with Pipeline({"pipeline": {"preset": "parallax"}}) as p:
        for k, f in enumerate(frames):
            r = p.process(f.image, f.t_s)
            states.append(r.road_motion)
            if r.road_homography is None:
                assert k < 5 and not worst, (k, states)  # only before the filter has started
                continue
            assert r.road_homography.shape == (3, 3), k
            true, cam = true_road_homography(scenario, frames[k - 1], f)
            v, u = np.mgrid[0:f.image.shape[0]:10, 0:f.image.shape[1]:10]
            x, z = cam.ground_from_pixel(u, v)
            road = np.isfinite(z) & (z > 5) & (z < 40) & (np.abs(x) < 5)
            prev_pts = np.linalg.inv(true) @ np.stack([u[road], v[road], np.ones(road.sum())])
            a, b = true @ prev_pts, r.road_homography @ prev_pts
            worst.append(float(np.max(np.hypot(*(a[:2] / a[2] - b[:2] / b[2])))))
    assert states[0] is None  # no previous frame
    assert states.count("accepted") >= 0.9 * (len(frames) - 1), states
    assert set(states[5:]) <= {"accepted", "predicted"}, states
    assert np.median(worst) < 1.0 and np.percentile(worst, 90) < 2.0, np.round(worst, 2)
    with Pipeline({"pipeline": {"preset": "thesis"}}) as p:  # no road-motion estimate there
        r = p.process(frames[1].image, frames[1].t_s)
        assert r.road_motion is None and r.road_homography is None
    with Pipeline({"pipeline": {"preset": "parallax"}}) as p:  # the residual costs two warps: off by default
        assert all(p.process(f.image, f.t_s).road_residual is None for f in frames[:8])


def test_measurement_outside_the_gate_is_not_accepted():
    """A pair that is not two consecutive views of one road (a jump of 2 s) gives a homography far
    from the prediction: the filter keeps its prediction."""
    frames = [f.image for f in render(load_scenario("steady_following"), frames=list(range(30, 36)) + [96])]
    with Pipeline(window_config({"pipeline": {"preset": "parallax"}})) as p:
        settled = last_pair(p, frames[:6])
        jumped = last_pair(p, frames[:5] + [frames[6]])
    assert settled.road_motion == "accepted"
    assert jumped.road_motion == "predicted"


def test_aligned_difference_finds_an_overtaking_car_at_its_bottom_edge():
    """The bottom of the region of differences (the parallax part's detection) sits on the car's contact row."""
    scenario = load_scenario("overtaking_from_side")
    frames = list(render(scenario, frames=range(70, 76)))
    car = next(v for v in frames[-1].truth if v["id"] == 1)
    with Pipeline(window_config({"pipeline": {"preset": "parallax"}})) as p:
        r = last_pair(p, [f.image for f in frames])
    assert r.full_detection and r.detections_frame == r.frame
    l, t, rr, b = car["box_clipped"]
    found = [d for d in r.detections if d[0] < rr and d[2] > l]
    assert found, r.detections
    best = min(found, key=lambda d: abs(d[3] - b))
    assert abs(best[3] - b) <= 4.0, (best, car["box_clipped"])
    assert abs(0.5 * (best[0] + best[2]) - 0.5 * (l + rr)) < 0.25 * (rr - l), (best, car["box_clipped"])
