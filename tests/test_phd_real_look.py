"""Where the phd tracker starts and ends vehicles, preset default on rendered scenarios with real-looking vehicles
(the suite's own look): it starts them only on the road ahead, also where the road has no lane markings (the ego path
and road.lane_width_m stand in for the lane model), measured as the lateral offsets of the vehicles it starts and as
the frames with a confirmed track on no rendered vehicle at all (IoU < 0.1 with every one), the false tracks a driver
would see; and it ends a vehicle that drives behind a nearer one, which weak detections on the nearer one's edge no
longer keep alive."""
from __future__ import annotations

import functools
import json

from app import config as configuration
from app.core import Pipeline
from app.eval.matching import iou_matrix
from app.sim import load_scenario, render
from app.sim.frames import scenario_camera


@functools.lru_cache(maxsize=None)
def _run(name: str, sections_json: str = "{}") -> tuple:
    """(frames, results) of the scenario through the default preset, the ego speed handed in as the suite does."""
    sc = load_scenario(name)
    values = {"pipeline": {"preset": "default"}, "camera": scenario_camera(sc).to_dict(), **json.loads(sections_json)}
    frames, results = [], []
    with Pipeline(configuration.core_sections(configuration.load(None, values))) as pipe:
        for f in render(sc):
            pipe.set_ego_motion(f.ego_speed_mps, 0.0)
            results.append(pipe.process(f.image, f.t_s))
            frames.append(f)
    return tuple(frames), tuple(results)


def _frames_on_nothing(name: str, sections_json: str = "{}") -> int:
    frames, results = _run(name, sections_json)
    n = 0
    for f, r in zip(frames, results):
        boxes = [v.get("box_clipped") or v["box"] for v in f.truth]
        for t in r.tracks:
            if t.confirmed and (not boxes or iou_matrix([t.box], boxes)[0].max() < 0.1):
                n += 1
    return n


def _starts_without_lanes(name: str, sections_json: str = "{}") -> list[float]:
    """Lateral offset (m) of each vehicle the tracker started on a frame without a lane model (not both ego-lane
    boundaries reported)."""
    _, results = _run(name, sections_json)
    seen, out = set(), []
    for r in results:
        no_lanes = {-1, 1} - {lane.position for lane in r.lanes} != set()
        for t in r.tracks:
            if t.id not in seen:
                seen.add(t.id)
                if no_lanes and t.lateral_m is not None:
                    out.append(t.lateral_m)
    return out


def test_without_lane_markings_vehicles_start_only_on_the_road_ahead():
    """congestion_no_markings: no lane markings, so no lane model for most of the run. A vehicle starts only within
    2.5 lane widths (2 lanes beside the ego lane, 9 m) of the ego path. Measured: confirmed tracks on nothing on 85
    frames (those started where the lane stage took the barriers' and vehicles' edges for lanes). The shipped
    verifier scores the bushes beyond the barriers (12-15 m beside the path) under phd.birth_min_appearance (0.9);
    with that bar at 0.5 they reach it, and then the lane gate alone keeps every start within 9 m (measured 8.9 m),
    while a gate as wide as the detectors' scan (4 lanes beside) lets them start vehicles 15 m beside the path."""
    lateral = _starts_without_lanes("congestion_no_markings")
    assert lateral and max(abs(x) for x in lateral) <= 2.5 * 3.6 + 0.5, lateral
    assert _frames_on_nothing("congestion_no_markings") <= 110
    weak = _starts_without_lanes("congestion_no_markings", json.dumps({"phd": {"birth_min_appearance": 0.5}}))
    assert max(abs(x) for x in weak) <= 2.5 * 3.6 + 0.5, weak
    # as wide as the detectors' scan (4 lanes beside): the roadside starts vehicles again
    wide = _starts_without_lanes("congestion_no_markings",
                                 json.dumps({"phd": {"birth_lanes_beside": 4, "birth_min_appearance": 0.5}}))
    assert max(abs(x) for x in wide) > 2.5 * 3.6 + 0.5, "nothing started beside the road: the test no longer tests it"


def _track_of(name: str, vehicle: int, sections_json: str = "{}") -> tuple[int, int, int]:
    """(the last frame the vehicle is at least half visible, the id of the confirmed track on it most often at
    IoU >= 0.5, the last frame that track is confirmed)."""
    frames, results = _run(name, sections_json)
    counts, last_half = {}, -1
    for f, r in zip(frames, results):
        v = next((v for v in f.truth if v["id"] == vehicle), None)
        if v is None or v["visible_fraction"] < 0.5:
            continue
        last_half = f.index
        conf = [t for t in r.tracks if t.confirmed]
        if conf:
            m = iou_matrix([v.get("box_clipped") or v["box"]], [t.box for t in conf])[0]
            if m.max() >= 0.5:
                tid = conf[int(m.argmax())].id
                counts[tid] = counts.get(tid, 0) + 1
    tid = max(counts, key=counts.get)
    last = max(f.index for f, r in zip(frames, results) if any(t.id == tid and t.confirmed for t in r.tracks))
    return last_half, tid, last


def test_a_car_driving_behind_a_nearer_one_ends():
    """calibration_drive: the car in the left lane (40 -> 50 m) drives behind a nearer car in that lane and is under
    half visible from frame 377. Its track ends 7 frames later. With weak detections keeping a hidden vehicle alive
    (phd.weak_keeps_hidden), the cascade's low-scoring boxes on the nearer car's edge kept it confirmed until frame 464,
    its range drifting from 46 to 95 m."""
    last_half, _, last = _track_of("calibration_drive", 2)
    assert last - last_half <= 15, (last_half, last)
    _, _, kept = _track_of("calibration_drive", 2, json.dumps({"phd": {"weak_keeps_hidden": True}}))
    assert kept - last_half >= 60, "the hidden car's track ended anyway: the test no longer tests it"
