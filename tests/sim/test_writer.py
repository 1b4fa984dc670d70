"""write_scenario: the files a replay or an evaluation reads."""
import dataclasses
import json

import can
import cv2
import numpy as np
import yaml

from app.sim import load_scenario, render, write_scenario
from app.sim.scenario import parse_scenario, scenario_to_dict


def _short(name, duration_s=0.5):
    return dataclasses.replace(load_scenario(name), duration_s=duration_s)


def test_frames_truth_log_and_inputs(tmp_path):
    scenario = _short("cut_in")
    calls = []
    summary = write_scenario(scenario, tmp_path / "out", progress=lambda i, n: calls.append((i, n)))
    out = tmp_path / "out"
    assert summary["n_frames"] == 15 and calls[-1] == (15, 15) and len(calls) == 15
    pngs = sorted((out / "frames").glob("*.png"))
    assert [p.name for p in pngs[:2]] == ["000000.png", "000001.png"] and len(pngs) == 15
    rendered = list(render(scenario, frames=[0, 14]))
    assert np.array_equal(cv2.imread(str(pngs[0]), cv2.IMREAD_UNCHANGED), rendered[0].image)
    assert np.array_equal(cv2.imread(str(pngs[14]), cv2.IMREAD_UNCHANGED), rendered[1].image)

    lines = [json.loads(line) for line in (out / "truth.jsonl").read_text().splitlines()]
    assert [r["frame"] for r in lines] == list(range(15))
    assert set(lines[0]) == {"frame", "t", "ego_speed_mps", "pitch_deg", "yaw_deg", "vehicles"}
    assert abs(lines[14]["t"] - 14 / 30) < 1e-6
    vehicle = lines[0]["vehicles"][0]
    for key in ("id", "box", "box_clipped", "visible_fraction", "lateral_m", "longitudinal_m",
                "relative_speed_mps", "ttc_s", "lane", "kind"):
        assert key in vehicle
    assert abs(vehicle["box"][3] - rendered[0].truth[0]["box"][3]) < 1e-3

    log = list(can.CanutilsLogReader(str(out / "ego_speed.log")))
    assert log[0].timestamp == 0.0 and abs(log[-1].timestamp - 14 / 30) < 0.02
    camera = json.loads((out / "camera.json").read_text())
    assert camera["fx"] == 700.0 and camera["ego_front_m"] == 2.0 and camera["fps"] == 30.0


def test_resolved_scenario_reloads_to_the_same_scenario(tmp_path):
    scenario = load_scenario("dense_traffic")
    write_scenario(dataclasses.replace(scenario, duration_s=0.1), tmp_path)
    resolved = yaml.safe_load((tmp_path / "scenario.yaml").read_text())
    again = parse_scenario(resolved, "scenario scenario.yaml", source=str(tmp_path / "scenario.yaml"))
    assert scenario_to_dict(again) == scenario_to_dict(dataclasses.replace(scenario, duration_s=0.1))
    # Sizes and shades drawn from the seed are written out explicitly.
    assert all("width_m" in v and "shade" in v for v in resolved["vehicles"])


def test_video_output(tmp_path):
    summary = write_scenario(_short("empty_road", 0.3), tmp_path, video=True)
    capture = cv2.VideoCapture(summary["video"])
    frames = 0
    while True:
        ok, image = capture.read()
        if not ok:
            break
        frames += 1
        assert image.shape == (480, 640, 3)
    assert frames == summary["n_frames"] == 9
    assert not (tmp_path / "frames").exists()
