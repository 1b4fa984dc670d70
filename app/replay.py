"""Offline runs: a recording (video file or image folder) or a synthetic scenario through the pipeline.

Recordings go through the core's own frame sources and real-time loop, which waits for this consumer
instead of dropping frames, so every frame is processed and two runs give the same tracks. Scenarios
are rendered here and fed through ``process()``, the same per-frame code as the loop.
"""
from __future__ import annotations

import contextlib
import os
import statistics
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterator, Optional

import cv2
import numpy as np

from app import config as configuration
from app.annotate import VideoOut, annotate
from app.core import EndOfStream, FrameResult, Pipeline, SourceError
from app.tracks_file import TracksWriter

IMAGE_EXTS = {".png", ".jpg", ".jpeg", ".bmp", ".pgm", ".ppm", ".tif", ".tiff", ".webp"}


class ReplayError(RuntimeError):
    """A source that cannot be replayed; the message says what and how to fix it."""


@dataclass
class ReplaySummary:
    source: str
    frames: int = 0
    skipped: int = 0               # frames the source could not decode or that had another size
    stage_ms: dict[str, list[float]] = field(default_factory=dict)
    total_ms: list[float] = field(default_factory=list)
    confirmed_ids: set[int] = field(default_factory=set)
    outputs: dict[str, str] = field(default_factory=dict)

    def add(self, r: FrameResult) -> None:
        self.frames += 1
        self.total_ms.append(r.total_ms)
        for k, v in r.stages.items():
            self.stage_ms.setdefault(k, []).append(v)
        self.confirmed_ids.update(t.id for t in r.tracks if t.confirmed)

    def text(self) -> str:
        lines = [f"{self.source}: {self.frames} frames processed"
                 + (f", {self.skipped} skipped (undecodable or of another size)" if self.skipped else "")]
        if self.total_ms:
            lines.append(f"  per frame: median {statistics.median(self.total_ms):.2f} ms, "
                         f"max {max(self.total_ms):.2f} ms")
        lines.append(f"  vehicles confirmed: {len(self.confirmed_ids)}")
        for name, path in self.outputs.items():
            lines.append(f"  {name}: {path}")
        return "\n".join(lines)


def is_scenario(source: str) -> bool:
    p = Path(source)
    if p.suffix in (".yaml", ".yml"):
        return True
    if p.exists():
        return False
    from app.sim import list_scenarios

    return source in list_scenarios()


def probe_size(source: str) -> tuple[int, int]:
    """(width, height) of a recording's frames, to fit the camera to it."""
    p = Path(source)
    if p.is_dir():
        names = sorted(x for x in p.iterdir() if x.suffix.lower() in IMAGE_EXTS)
        if not names:
            raise ReplayError(f"{source}: the folder contains no images (.png .jpg .bmp .pgm .tif)")
        img = cv2.imread(str(names[0]), cv2.IMREAD_UNCHANGED)
        if img is None:
            raise ReplayError(f"{names[0]}: cannot be decoded as an image")
        return img.shape[1], img.shape[0]
    if not p.exists():
        raise ReplayError(f"{source}: no such file or folder")
    cap = cv2.VideoCapture(str(p), cv2.CAP_FFMPEG)
    ok, frame = cap.read() if cap.isOpened() else (False, None)
    cap.release()
    if not ok:
        raise ReplayError(f"{source}: cannot be read as a video (not a video file, or empty/corrupt)")
    return frame.shape[1], frame.shape[0]


def fit_config(cfg_path: Optional[str], size: tuple[int, int]) -> dict:
    """The configuration for a recording of `size`: the file's camera if it names that size, else the
    default camera scaled to the recording (same field of view)."""
    cfg = configuration.load(cfg_path)
    cam = cfg["camera"]
    if (cam["width"], cam["height"]) != size:
        cfg["camera"] = configuration.scaled_camera(cam, *size)
    return cfg


def _recording_frames(source: str) -> Iterator[tuple[int, np.ndarray]]:
    """Frames decoded on the Python side (only to draw the annotated video), by frame number."""
    p = Path(source)
    if p.is_dir():
        for i, name in enumerate(sorted(x for x in p.iterdir() if x.suffix.lower() in IMAGE_EXTS)):
            img = cv2.imread(str(name), cv2.IMREAD_GRAYSCALE)
            if img is not None:
                yield i, img
        return
    cap = cv2.VideoCapture(str(p), cv2.CAP_FFMPEG)
    i = 0
    while True:
        ok, frame = cap.read()
        if not ok:
            break
        yield i, cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
        i += 1
    cap.release()


def _progress(total: Optional[int], desc: str, enabled: bool):
    if not enabled:
        return contextlib.nullcontext(None)
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit="frame", file=sys.stderr, leave=False,
                disable=not sys.stderr.isatty())


def _frame_count(source: str) -> Optional[int]:
    p = Path(source)
    if p.is_dir():
        return sum(1 for x in p.iterdir() if x.suffix.lower() in IMAGE_EXTS)
    cap = cv2.VideoCapture(str(p), cv2.CAP_FFMPEG)
    n = int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) if cap.isOpened() else 0
    cap.release()
    return n or None


def replay_recording(source: str, config_path: Optional[str] = None, fps: Optional[float] = None,
                     out_video: Optional[str] = None, tracks_path: Optional[str] = None,
                     on_result: Optional[Callable[[FrameResult], None]] = None,
                     progress: bool = True) -> ReplaySummary:
    p = Path(source)
    if p.is_dir() and fps is None:
        raise ReplayError(f"{source}: an image folder needs its frame rate: give --fps N")
    size = probe_size(source)
    cfg = fit_config(config_path, size)
    spec = {"kind": "folder", "path": str(p), "fps": float(fps)} if p.is_dir() else {"kind": "video", "path": str(p)}
    video_fps = float(fps) if fps else (cv2.VideoCapture(str(p)).get(cv2.CAP_PROP_FPS) or 25.0)
    summary = ReplaySummary(source)
    with contextlib.ExitStack() as stack:
        pipe = stack.enter_context(Pipeline(configuration.core_sections(cfg)))
        writer = TracksWriter(stack.enter_context(open(tracks_path, "w"))) if tracks_path else None
        video = VideoOut(out_video, video_fps) if out_video else None
        if video:
            stack.callback(video.close)
        frames = _recording_frames(source) if video else None
        try:
            pipe.start(spec)
        except SourceError as exc:
            raise ReplayError(str(exc)) from None
        bar = stack.enter_context(_progress(_frame_count(source), p.name, progress))
        while True:
            try:
                r = pipe.pop(timeout_s=10.0)
            except EndOfStream:
                break
            if r is None:
                raise ReplayError(f"{source}: the core produced no frame for 10 s (health: {pipe.health()})")
            summary.add(r)
            if writer:
                writer.write(r)
            if video:
                for i, gray in frames:
                    if i == r.frame:
                        video.write(annotate(gray, r))
                        break
            if on_result:
                on_result(r)
            if bar is not None:
                bar.update(1)
        summary.skipped = pipe.health()["decode_errors"]
    if tracks_path:
        summary.outputs["tracks"] = os.path.abspath(tracks_path)
    if out_video:
        summary.outputs["annotated video"] = os.path.abspath(out_video)
    return summary


def replay_scenario(source: str, config_path: Optional[str] = None, out_video: Optional[str] = None,
                    tracks_path: Optional[str] = None,
                    on_result: Optional[Callable[[FrameResult, object], None]] = None,
                    progress: bool = True) -> ReplaySummary:
    import dataclasses

    from app.sim import ScenarioError, frame_count, load_scenario, render
    from app.sim.frames import scenario_camera

    try:
        scenario = load_scenario(source)
    except ScenarioError as exc:
        raise ReplayError(str(exc)) from None
    # The renderer knows its camera exactly, as a calibrated car would: use it.
    cfg = configuration.load(config_path)
    cfg["camera"].update(dataclasses.asdict(scenario_camera(scenario)))
    summary = ReplaySummary(source)
    n_frames = frame_count(scenario)
    with contextlib.ExitStack() as stack:
        pipe = stack.enter_context(Pipeline(configuration.core_sections(cfg)))
        writer = TracksWriter(stack.enter_context(open(tracks_path, "w"))) if tracks_path else None
        video = VideoOut(out_video, scenario.fps) if out_video else None
        if video:
            stack.callback(video.close)
        bar = stack.enter_context(_progress(n_frames, scenario.name, progress))
        for f in render(scenario):
            r = pipe.process(f.image, f.t_s)
            summary.add(r)
            if writer:
                writer.write(r)
            if video:
                video.write(annotate(f.image, r, f.truth))
            if on_result:
                on_result(r, f)
            if bar is not None:
                bar.update(1)
    if tracks_path:
        summary.outputs["tracks"] = os.path.abspath(tracks_path)
    if out_video:
        summary.outputs["annotated video"] = os.path.abspath(out_video)
    return summary


def replay(source: str, **kw) -> ReplaySummary:
    if is_scenario(source):
        kw.pop("fps", None)
        return replay_scenario(source, **kw)
    return replay_recording(source, **kw)
