"""One detection stage: what `headway detect` writes for an image (app.detect_images.detect_images) is the
detections of Pipeline.detect(image) for the preset's composition, and a tracked pipeline reports the
detections its detection stage gave the tracker (FrameResult.detections) on each frame with a full detection."""
from __future__ import annotations

import json

import cv2
import pytest

from app import config as configuration
from app._headway_core import lib
from app.core import Pipeline
from tests.conftest import data_path


def _validation_images(n: int = 4) -> list:
    """The first n TuSimple validation images (../shared/data/tusimple/supp; skipped when absent)."""
    supp = data_path("tusimple", "supp")
    entries = json.loads((supp / "annotation.json").read_text())[:n]
    return [supp / e["file_name"] for e in entries]


def _stage_detections(preset: str, path) -> list:
    """Pipeline.detect's detections for the image, by a pipeline of the preset's defaults with the camera
    scaled to the image's size (as `headway detect` sets it up)."""
    gray = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    cfg = configuration.load(None, {"pipeline": {"preset": preset}})
    cfg["camera"] = configuration.scaled_camera(cfg["camera"], gray.shape[1], gray.shape[0])
    with Pipeline(configuration.core_sections(cfg)) as pipe:
        return pipe.detect(gray).rows()


def _same(written: list[dict], detections: list) -> bool:
    """The written boxes (px to 0.1, scores to 1e-4) are the detections, in their order."""
    return len(written) == len(detections) and all(
        all(abs(b[k] - v) <= 0.05 + 1e-6 for k, v in zip(("left", "top", "right", "bottom"), d[:4]))
        and abs(b["score"] - d[4]) <= 5e-5 + 1e-9 for b, d in zip(written, detections))


@pytest.mark.parametrize("preset", ["default", "paper004", "thesis"])
def test_headway_detect_writes_the_detection_stages_boxes_and_scores(preset):
    """Every detection written (--min-score 0) is Pipeline.detect's, box and score, in its order; at the
    preset's operating point (the default --min-score) exactly those scoring at least it."""
    from app.detect_images import OPERATING_POINT, detect_images

    paths = _validation_images()
    every = detect_images([str(p) for p in paths], preset=preset, min_score=0.0)
    at_point = detect_images([str(p) for p in paths], preset=preset)
    point = OPERATING_POINT.get(preset, 0.0)
    assert [e["file_name"] for e in every] == [e["file_name"] for e in at_point] == [p.name for p in paths]
    found = 0
    for path, e, e_point in zip(paths, every, at_point):
        dets = _stage_detections(preset, path)
        found += len(dets)
        assert _same(e["bbox"], dets), (path.name, e["bbox"][:3], dets[:3])
        assert _same(e_point["bbox"], [d for d in dets if d[4] >= point]), path.name
    assert found >= len(paths)   # the stage finds vehicles on these images: the comparison compares something


def test_headway_detect_on_the_recordings_camera_writes_what_headway_eval_scores(tmp_path):
    """The figures the docs give for `headway detect` on the TuSimple images are `headway eval`'s (its detection
    stage on the recordings' camera); `headway detect --config app/eval/data/tusimple_camera.yaml --min-score 0`
    writes those very detections, box and score, in their order; without the camera file (the default camera
    scaled to the images) it finds others, and says on stderr that it scaled the camera and how to give the
    images' own."""
    from app.eval.tusimple_boxes import TUSIMPLE_CAMERA_FILE, evaluate
    from tests.test_cli import headway

    n = 6
    scored = []
    evaluate(str(data_path("tusimple", "supp")), preset="default", limit=n,
             on_image=lambda e, gray, r: scored.append(r.rows()))
    paths = [str(p) for p in _validation_images(n)]
    runs = {}
    for name, extra in (("camera", ["--config", str(TUSIMPLE_CAMERA_FILE)]), ("default", [])):
        r = headway("detect", *paths, "--out", str(tmp_path / f"{name}.json"), "--min-score", "0", *extra)
        assert r.returncode == 0, r.stderr
        runs[name] = json.loads((tmp_path / f"{name}.json").read_text())
        scaled = "1280x720 images: the default camera (640x480) scaled to them" in r.stderr
        assert scaled == (name == "default") and ("tusimple_camera.yaml" in r.stderr) == scaled, r.stderr
    assert len(runs["camera"]) == len(scored) == n
    assert all(_same(e["bbox"], dets) for e, dets in zip(runs["camera"], scored))
    assert sum(len(d) for d in scored) >= n
    assert not all(_same(e["bbox"], dets) for e, dets in zip(runs["default"], scored))


def test_a_tracked_pipeline_reports_its_detections_on_full_detection_frames():
    """The default preset tracking a rendered drive: on a frame with full_detection, FrameResult.detections is a list
    of (left, top, right, bottom, score) 5-tuples of floats, boxes inside the frame and scores in [0, 1] (vehicles
    found on some of them); on a frame without, it is empty."""
    from app.sim import load_scenario, render
    from app.sim.frames import scenario_camera

    sc = load_scenario("steady_following")
    cfg = configuration.load(None, {"pipeline": {"preset": "default"}, "camera": scenario_camera(sc).to_dict()})
    full = []
    with Pipeline(configuration.core_sections(cfg)) as pipe:
        for f in list(render(sc, frames=range(20))):
            r = pipe.process(f.image, f.t_s)
            if not r.full_detection:
                assert r.detections == []
                continue
            full.append(r)
            assert isinstance(r.detections, list)
            for d in r.detections:
                assert isinstance(d, tuple) and len(d) == 5 and all(isinstance(v, float) for v in d)
                left, top, right, bottom, score = d
                assert 0 <= left < right <= r.width and 0 <= top < bottom <= r.height and 0.0 <= score <= 1.0
    assert full and sum(len(r.detections) for r in full) >= 1


def test_the_tracked_pipelines_detection_stage_on_one_image_is_headway_detect():
    """On 20 validation images, a tracked default pipeline given the image as its first frame (after a reset)
    hands its tracker exactly the detections `headway detect` finds in it: the same boxes and scores, bit for bit,
    in the same order (a first frame has nothing tracked yet, and gets the single image's lane model); a frame
    result holds the strongest HW_MAX_TRACKS (64) of them, Pipeline.detect every one."""
    from app.eval.tusimple_boxes import tusimple_config

    cfg = configuration.core_sections(tusimple_config(configuration.load(None, {"pipeline": {"preset": "default"}})))
    compared = 0
    with Pipeline(cfg) as tracked, Pipeline(cfg) as single:
        for path in _validation_images(20):
            gray = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
            tracked.reset()
            r = tracked.process(gray, 0.0)
            assert r.full_detection, path.name
            assert r.detections == single.detect(gray).rows()[:lib.HW_MAX_TRACKS], path.name
            compared += len(r.detections)
    assert compared >= 20
