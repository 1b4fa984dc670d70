"""The phd tracker's detection on its worker thread (phd.detect_lag L > 0): the detection of frame k is taken at frame
k + L whatever the machine, so the tracks are the same however long the detection takes; FrameResult.detections
says which frame it was found on (detections_frame); the first frame detects at once; a reset or a close while a
detection runs leaves nothing running."""
from __future__ import annotations

import time

from app import config as configuration
from app.core import Pipeline
from app.sim import load_scenario, render
from app.sim.frames import scenario_camera

SCENARIO = "steady_following"
N_FRAMES = 24


def _frames() -> list:
    return list(render(load_scenario(SCENARIO), frames=range(N_FRAMES)))


def _config(lag: int, **phd) -> dict:
    values = {"pipeline": {"preset": "default"}, "camera": scenario_camera(load_scenario(SCENARIO)).to_dict(),
              "phd": {"detect_lag": lag, **phd}}
    return configuration.core_sections(configuration.load(None, values))


def _tracks(r) -> list:
    return [(t.id, t.confirmed, t.box, t.range_m, t.range_rate_mps) for t in r.tracks]


def test_a_lagged_detection_is_taken_lag_frames_after_the_frame_it_was_found_on():
    """detect_every_n 3, detect_lag 2: frame 0 detects at once (detections_frame 0); the detections of frames 1, 4, ...
    are taken at frames 3, 6, ... (the frames a synchronous detection is taken on), and no other frame takes one.
    Vehicles are found in them."""
    full = {}
    with Pipeline(_config(2, detect_every_n=3)) as p:
        for f in _frames():
            r = p.process(f.image, f.t_s)
            if r.full_detection:
                full[r.frame] = r
            else:
                assert r.detections == [] and r.detections_frame is None
    assert sorted(full) == list(range(0, N_FRAMES, 3))
    assert all(r.detections_frame == max(0, k - 2) for k, r in full.items())
    assert sum(len(r.detections) for r in full.values()) >= len(full)
    assert full[max(full)].tracks, "the lead is tracked"


def test_lag_zero_detects_on_the_frame_itself():
    with Pipeline(_config(0, detect_every_n=3)) as p:
        taken = [(r.frame, r.detections_frame) for r in (p.process(f.image, f.t_s) for f in _frames())
                 if r.full_detection]
    assert taken == [(k, k) for k in range(0, N_FRAMES, 3)]


def test_the_tracks_do_not_depend_on_how_long_the_detection_takes():
    """Frames back to back (the frame thread waits for each detection) and frames 60 ms apart (each detection done
    long before it is taken): the same tracks, bit for bit, on every frame."""
    frames = _frames()
    with Pipeline(_config(2)) as p:
        fast = [_tracks(p.process(f.image, f.t_s)) for f in frames]
    slow = []
    with Pipeline(_config(2)) as p:
        for f in frames:
            slow.append(_tracks(p.process(f.image, f.t_s)))
            time.sleep(0.06)
    assert fast == slow
    assert sum(len(t) for t in fast) >= N_FRAMES // 2  # tracks to compare


def test_a_reset_while_a_detection_runs_starts_afresh():
    """A reset on the frame a detection started: the next frame is a first frame again (it detects at once), and the
    detection that was running is not taken later."""
    frames = _frames()
    with Pipeline(_config(2)) as p:
        for f in frames[:5]:  # frame 4 starts a detection
            p.process(f.image, f.t_s)
        p.reset()
        taken = [(r.frame, r.detections_frame) for r in (p.process(f.image, f.t_s) for f in frames[:7])
                 if r.full_detection]
    assert taken == [(0, 0), (3, 1), (6, 4)]


def test_closing_while_a_detection_runs_stops_the_worker():
    """A pipeline closed on the frame a detection started, at each of the first frames: the worker is joined (a
    thread left running would abort the interpreter at exit), and a new pipeline runs afterwards."""
    frames = _frames()
    for n in (2, 5):  # frames 1 and 4 start one
        with Pipeline(_config(2)) as p:
            for f in frames[:n]:
                p.process(f.image, f.t_s)
    with Pipeline(_config(2)) as p:
        assert p.process(frames[0].image, frames[0].t_s).full_detection
