"""The door to the C++ core: versions, errors as exceptions, offline processing, the loop's queue."""
from __future__ import annotations

import math
import time

import numpy as np
import pytest

from app.core import (ConfigError, EndOfStream, InvalidArgument, Pipeline, StateError, abi_version, core_schema,
                      lib)


def gray(w=640, h=480, v=90):
    return np.full((h, w), v, np.uint8)


def test_abi_version_matches_header():
    assert abi_version() == lib.HW_ABI_VERSION == 14


def test_schema_documents_every_core_key():
    schema = core_schema()
    assert {"camera", "pipeline", "lanes", "shadow", "verify", "kalman"} <= set(schema)
    for section, keys in schema.items():
        for key, spec in keys.items():
            assert spec["doc"].strip(), f"{section}.{key} has no doc"
            assert spec["type"] in ("int", "float", "bool", "str")
            if spec["type"] in ("int", "float"):
                assert spec["min"] <= spec["default"] <= spec["max"], f"{section}.{key} default out of range"


def test_effective_config_echoes_what_was_given():
    with Pipeline({"camera": {"fx": 812.5, "width": 800, "height": 600}}) as p:
        cfg = p.config
    assert cfg["camera"]["fx"] == 812.5 and cfg["camera"]["width"] == 800
    assert cfg["camera"]["fy"] == core_schema()["camera"]["fy"]["default"]


@pytest.mark.parametrize(
    "config, key",
    [
        ({"camera": {"fx": "wide"}}, "camera.fx"),
        ({"camera": {"fx": -3.0}}, "camera.fx"),
        ({"camera": {"focal": 700.0}}, "camera.focal"),
        ({"cameras": {}}, "cameras"),
        ({"pipeline": {"preset": "magic"}}, "pipeline.preset"),
        ({"pipeline": {"preset": "fused"}}, "pipeline.preset"),
        ({"pipeline": {"queue_capacity": 2.5}}, "pipeline.queue_capacity"),
    ],
)
def test_bad_core_config_names_the_key(config, key):
    with pytest.raises(ConfigError, match=key.replace(".", r"\.")):
        Pipeline(config)


def test_process_reports_frame_time_and_stage_times():
    with Pipeline() as p:
        r = p.process(gray(), 1.25)
    assert r.t_s == 1.25 and r.width == 640 and r.height == 480
    assert "lanes" in r.stages and r.total_ms >= 0
    assert r.lead_id is None  # filled by a later stage; "not available" until then


@pytest.mark.parametrize(
    "frame, match",
    [
        (np.zeros((480, 641), np.uint8), "641x480"),
        (np.zeros((480, 640), np.float32), "uint8"),
        (np.zeros((480, 640, 3), np.uint8), "gray"),
        ("not an image", "gray"),
    ],
)
def test_process_rejects_wrong_frames(frame, match):
    with Pipeline() as p:
        with pytest.raises(InvalidArgument, match=match):
            p.process(frame, 0.0)


def test_time_going_backwards_is_rejected():
    with Pipeline() as p:
        p.process(gray(), 1.0)
        with pytest.raises(InvalidArgument, match="backwards"):
            p.process(gray(), 0.5)
        p.reset()
        p.process(gray(), 0.5)  # after reset the clock may start again


def test_image_lanes_are_the_single_image_lanes_whatever_came_before():
    """image_lanes() forgets the earlier frames: a pipeline that has tracked the lanes over 30 frames gives for the
    next image exactly what a new pipeline's first frame gives; with self_calibration.from_scratch it refuses."""
    from app.sim import load_scenario, render

    frames = [f.image for f in render(load_scenario("steady_following"), frames=range(0, 31))]
    with Pipeline({"pipeline": {"preset": "none"}}) as fresh:
        first = fresh.process(frames[30], 0.0)
    with Pipeline({"pipeline": {"preset": "none"}}) as p:
        for k, img in enumerate(frames[:30]):
            p.process(img, k / 30)
        alone = p.image_lanes(frames[30])
    assert len(first.lanes) >= 2
    assert [(l.position, l.x_bottom, l.x_top) for l in alone.lanes] == \
        [(l.position, l.x_bottom, l.x_top) for l in first.lanes]
    assert alone.vanishing_point == first.vanishing_point
    with Pipeline({"pipeline": {"preset": "none"}, "self_calibration": {"from_scratch": True}}) as p:
        with pytest.raises(ValueError, match="from_scratch"):
            p.image_lanes(frames[0])


@pytest.mark.parametrize("preset, detector, match", [
    ("none", None, "has no detector parts"), ("parallax", None, "two frames"), ("thesis", "parallax", "two frames"),
    ("thesis", "haar", r"unknown detector 'haar' \(one of cascade\|parallax\|proposals\|shadow\)")])
def test_detect_needs_a_registered_detector_that_works_on_one_image(preset, detector, match):
    with Pipeline({"pipeline": {"preset": preset}}) as p:
        with pytest.raises(InvalidArgument, match=match):
            p.detect(gray(), detector)


def test_detect_reports_the_detections_strongest_first_and_by_name():
    """detect() gives (left, top, right, bottom, score) per vehicle, strongest first, the stage's sub-stage times
    and the camera's horizon row; the composition's one part named alone gives the same; a pipeline without detector
    parts (lanes only) detects with a part named."""
    from tests import thesis_scenes

    image = thesis_scenes.frames("steady_following")[60].image
    cfg = thesis_scenes.config("steady_following")
    with Pipeline(cfg) as p:
        r = p.detect(image)
        named = p.detect(image, "shadow")
    with Pipeline({**cfg, "pipeline": {"preset": "none"}}) as lanes_only:
        alone = lanes_only.detect(image, "shadow")
    rows = r.rows()
    assert len(rows) >= 2
    assert all(len(d) == 5 and d[0] < d[2] and d[1] < d[3] and 0.0 <= d[4] <= 1.0 for d in rows)
    assert [d[4] for d in rows] == sorted((d[4] for d in rows), reverse=True)
    assert {"lanes", "hypotheses", "verify"} <= set(r.stages) and r.total_ms > 0
    cam = cfg["camera"]
    assert r.horizon_row == pytest.approx(cam["cy"] - cam["fy"] * math.tan(math.radians(cam["pitch_deg"])), abs=1e-3)
    assert np.array_equal(named.boxes, r.boxes) and np.array_equal(alone.boxes, r.boxes)


def test_push_source_round_trip_keeps_order_and_timestamps():
    with Pipeline({"pipeline": {"preset": "none", "queue_capacity": 64}}) as p:
        p.start({"kind": "push"})
        stamps = [i / 30 for i in range(20)]
        got = []
        for t in stamps:
            p.push(np.full((480, 640, 3), 50, np.uint8), t)  # colour is converted to gray in the core
            got.append(p.pop(2.0))
        p.push_end()
        with pytest.raises(EndOfStream):
            while p.pop(2.0) is not None:
                pass
    assert [r.t_s for r in got] == stamps
    assert [r.frame for r in got] == list(range(20))


def test_full_queue_drops_the_oldest_and_counts():
    with Pipeline({"pipeline": {"preset": "none", "queue_capacity": 3, "push_queue_capacity": 64}}) as p:
        p.start({"kind": "push"})
        for i in range(10):
            p.push(gray(), i * 0.1)
        p.push_end()
        deadline = time.monotonic() + 5
        while p.health()["frames_processed"] < 10 and time.monotonic() < deadline:
            time.sleep(0.01)
        results = []
        with pytest.raises(EndOfStream):
            while True:
                results.append(p.pop(1.0))
        h = p.health()
    assert h["results_dropped"] == 7
    assert [r.frame for r in results] == [7, 8, 9]  # the newest survive


def test_pushed_frame_of_wrong_size_is_a_clear_error():
    with Pipeline({"pipeline": {"preset": "none"}}) as p:
        p.start({"kind": "push"})
        with pytest.raises(InvalidArgument, match="320x240 but the camera is configured as 640x480"):
            p.push(np.zeros((240, 320), np.uint8), 0.0)
        with pytest.raises(InvalidArgument, match="uint8"):
            p.push(np.zeros((480, 640), np.int16), 0.0)


def test_process_while_running_is_refused():
    with Pipeline({"pipeline": {"preset": "none"}}) as p:
        p.start({"kind": "push"})
        with pytest.raises(StateError, match="stop it first"):
            p.process(gray(), 0.0)
        p.stop()
        p.process(gray(), 0.0)


def test_pop_before_start_and_push_without_push_source():
    with Pipeline() as p:
        with pytest.raises(StateError):
            p.pop(0.01)
        with pytest.raises(StateError):
            p.push(gray(), 0.0)


def test_close_twice_and_use_after_close():
    p = Pipeline()
    p.close()
    p.close()
    with pytest.raises(StateError, match="closed"):
        p.process(gray(), 0.0)


def test_health_before_start_says_not_available():
    with Pipeline() as p:
        h = p.health()
    assert h["running"] is False and h["source_state"] == "idle"
    assert h["last_frame_t_s"] is None and h["frames_processed"] == 0


def test_core_stopped_at_interpreter_exit(tmp_path):
    """A running loop at exit must not abort the process (atexit stops it)."""
    import subprocess
    import sys

    code = ("import numpy as np\nfrom app.core import Pipeline\np = Pipeline({'pipeline': {'preset': 'none'}})\n"
            "p.start({'kind': 'push'})\np.push(np.zeros((480, 640), np.uint8), 0.0)\nprint('ok')\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60,
                       cwd=str(__import__("pathlib").Path(__file__).resolve().parent.parent))
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "ok"
