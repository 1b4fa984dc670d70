"""Offline runs: a recording (video file or image folder) or a synthetic scenario through the full stack.

Frames go through ``process()``, the same per-frame code as the real-time loop, at their recorded
timestamps (frame number / frame rate). The input CAN log is replayed on the same clock, and the
supervisor's stack (vehicle inputs -> FCW -> CAN frames) runs after every frame exactly as in the
car. Nothing depends on the wall clock, so two runs on the same input give identical tracks and
identical output CAN logs. A scenario without --can-in replays with its own ego-speed log.
"""
from __future__ import annotations

import contextlib
import dataclasses
import os
import statistics
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterator, Optional

import cv2

from app import config as configuration
from app.annotate import VideoOut, annotate
from app.core import FrameResult, Pipeline
from app.fcw_level import FcwLevel
from app.tracks_file import TracksWriter

IMAGE_EXTS = {".png", ".jpg", ".jpeg", ".bmp", ".pgm", ".ppm", ".tif", ".tiff", ".webp"}
SIM_DBC = Path(__file__).resolve().parent / "sim" / "ego_speed_placeholder.dbc"


class ReplayError(RuntimeError):
    """A source that cannot be replayed; the message says what and how to fix it."""


@dataclass
class ReplaySummary:
    source: str
    frames: int = 0
    skipped: list[str] = field(default_factory=list)   # frames that could not be used, and why
    total_ms: list[float] = field(default_factory=list)
    confirmed_ids: set[int] = field(default_factory=set)
    warnings: list[tuple[float, str, Optional[float]]] = field(default_factory=list)  # (t, level, ttc used)
    can: dict = field(default_factory=dict)
    outputs: dict[str, str] = field(default_factory=dict)

    def add(self, r: FrameResult) -> None:
        self.frames += 1
        self.total_ms.append(r.total_ms)
        self.confirmed_ids.update(t.id for t in r.tracks if t.confirmed)

    def text(self) -> str:
        lines = [f"{self.source}: {self.frames} frames processed"
                 + (f", {len(self.skipped)} skipped" if self.skipped else "")]
        lines += [f"  skipped: {s}" for s in self.skipped[:5]]
        if self.total_ms:
            lines.append(f"  per frame: median {statistics.median(self.total_ms):.2f} ms, "
                         f"max {max(self.total_ms):.2f} ms")
        lines.append(f"  vehicles confirmed: {len(self.confirmed_ids)}")
        for t, level, ttc in self.warnings:
            lines.append(f"  FCW {level} at t={t:.2f} s" + (f" (TTC {ttc:.2f} s)" if ttc is not None else ""))
        if self.can:
            lines.append(f"  CAN: {self.can.get('frames_sent', 0)} frames sent")
            if self.can.get("input_log"):
                lines.append(f"  CAN in: {self.can['input_log']}")
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


def _folder_images(folder: Path) -> list[Path]:
    return sorted(x for x in folder.iterdir() if x.suffix.lower() in IMAGE_EXTS)


def recording_frames(source: str, fps: Optional[float], summary: ReplaySummary) -> tuple[Iterator, float, tuple]:
    """(iterator of (index, t_s, gray), frame rate, (width, height)) for a video file or image folder.

    Frames that cannot be decoded, or whose size differs from the first frame's, are skipped and
    listed in the summary with the reason."""
    p = Path(source)
    if p.is_dir():
        if fps is None:
            raise ReplayError(f"{source}: an image folder needs its frame rate: give --fps N")
        names = _folder_images(p)
        if not names:
            raise ReplayError(f"{source}: the folder contains no images (.png .jpg .bmp .pgm .tif)")
        first = cv2.imread(str(names[0]), cv2.IMREAD_GRAYSCALE)
        if first is None:
            raise ReplayError(f"{names[0]}: cannot be decoded as an image")
        size = (first.shape[1], first.shape[0])

        def gen():
            for i, name in enumerate(names):
                img = cv2.imread(str(name), cv2.IMREAD_GRAYSCALE)
                if img is None:
                    summary.skipped.append(f"{name.name}: cannot be decoded")
                elif (img.shape[1], img.shape[0]) != size:
                    summary.skipped.append(f"{name.name}: {img.shape[1]}x{img.shape[0]}, the folder's first image is "
                                           f"{size[0]}x{size[1]}")
                else:
                    yield i, i / fps, img

        return gen(), float(fps), size
    if not p.exists():
        raise ReplayError(f"{source}: no such file or folder")
    if p.suffix.lower() in IMAGE_EXTS:
        raise ReplayError(f"{source}: is a still image; replay a folder of images (with --fps) or use `headway detect`")
    cap = cv2.VideoCapture(str(p), cv2.CAP_FFMPEG)
    ok, frame = cap.read() if cap.isOpened() else (False, None)
    if not ok:
        cap.release()
        raise ReplayError(f"{source}: cannot be read as a video (not a video file, or empty/corrupt)")
    rate = float(fps or cap.get(cv2.CAP_PROP_FPS) or 0.0)
    if not 0 < rate < 1000:
        rate = 30.0
    size = (frame.shape[1], frame.shape[0])

    def gen_video():
        i, current = 0, frame
        try:
            while current is not None:
                yield i, i / rate, cv2.cvtColor(current, cv2.COLOR_BGR2GRAY)
                ok, current = cap.read()
                i += 1
                if not ok:
                    current = None
        finally:
            cap.release()

    return gen_video(), rate, size


def _progress(total: Optional[int], desc: str, enabled: bool):
    if not enabled or not sys.stderr.isatty():
        return contextlib.nullcontext(None)
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit="frame", file=sys.stderr, leave=False)


def _frame_count(source: str) -> Optional[int]:
    p = Path(source)
    if p.is_dir():
        return len(_folder_images(p))
    cap = cv2.VideoCapture(str(p), cv2.CAP_FFMPEG)
    n = int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) if cap.isOpened() else 0
    cap.release()
    return n or None


def _run(frames, cfg: dict, summary: ReplaySummary, n_frames: Optional[int], label: str,
         out_video: Optional[str], fps: float, tracks_path: Optional[str], can_in: Optional[str],
         can_out: Optional[str], on_result: Optional[Callable], progress: bool) -> ReplaySummary:
    from app.can import CanLogError, CanSession, DbcError, VehicleInputError
    from app.supervisor.stack import Stack

    with contextlib.ExitStack() as stack:
        pipe = stack.enter_context(Pipeline(configuration.core_sections(cfg)))
        writer = TracksWriter(stack.enter_context(open(tracks_path, "w"))) if tracks_path else None
        video = VideoOut(out_video, fps) if out_video else None
        if video:
            stack.callback(video.close)
        try:
            session = stack.enter_context(CanSession.for_replay(cfg, can_in=can_in, can_out=can_out))
        except (CanLogError, DbcError, VehicleInputError, OSError) as exc:
            raise ReplayError(str(exc)) from None
        sup = Stack(cfg, session)
        bar = stack.enter_context(_progress(n_frames, label, progress))
        for index, t_s, gray, truth in frames:
            r = pipe.process(gray, t_s)
            decision = sup.step(r, r.t_s, pipe)
            summary.add(r)
            if decision.changed and decision.level != FcwLevel.NONE:
                summary.warnings.append((r.t_s, decision.level.label, decision.ttc_used_s))
            if writer:
                writer.write(r, decision.level)
            if video:
                video.write(annotate(gray, r, truth, decision.level))
            if on_result:
                on_result(r, decision, truth)
            if bar is not None:
                bar.update(1)
        summary.can = session.summary()
    if tracks_path:
        summary.outputs["tracks"] = os.path.abspath(tracks_path)
    if out_video:
        summary.outputs["annotated video"] = os.path.abspath(out_video)
    if can_out:
        summary.outputs["CAN out"] = os.path.abspath(can_out)
    return summary


def replay_recording(source: str, config_path: Optional[str] = None, fps: Optional[float] = None,
                     out_video: Optional[str] = None, tracks_path: Optional[str] = None,
                     can_in: Optional[str] = None, can_out: Optional[str] = None,
                     on_result: Optional[Callable] = None, progress: bool = True) -> ReplaySummary:
    summary = ReplaySummary(source)
    frames, rate, size = recording_frames(source, fps, summary)
    cfg = configuration.load(config_path)
    if (cfg["camera"]["width"], cfg["camera"]["height"]) != size:
        # a camera calibrated for another size: same field of view, intrinsics scaled to the recording
        cfg["camera"] = configuration.scaled_camera(cfg["camera"], *size)
    return _run(((i, t, g, None) for i, t, g in frames), cfg, summary, _frame_count(source), Path(source).name,
                out_video, rate, tracks_path, can_in, can_out, on_result, progress)


def replay_scenario(source: str, config_path: Optional[str] = None, out_video: Optional[str] = None,
                    tracks_path: Optional[str] = None, can_in: Optional[str] = None, can_out: Optional[str] = None,
                    on_result: Optional[Callable] = None, progress: bool = True) -> ReplaySummary:
    from app.sim import ScenarioError, frame_count, load_scenario, render
    from app.sim.can_log import write_ego_speed_log
    from app.sim.frames import scenario_camera
    from app.sim.world import World

    try:
        scenario = load_scenario(source)
    except ScenarioError as exc:
        raise ReplayError(str(exc)) from None
    cfg = configuration.load(config_path)
    # The renderer knows its camera exactly, as a calibrated car would: use it.
    cfg["camera"].update(dataclasses.asdict(scenario_camera(scenario)))
    summary = ReplaySummary(scenario.name)
    n = frame_count(scenario)
    with tempfile.TemporaryDirectory(prefix="headway-replay-") as tmp:
        if can_in is None and not cfg["vehicle"]["speed_message"]:
            # the scenario's own ego-speed log, decoded through its (placeholder) DBC
            world = World(scenario)
            can_in = str(Path(tmp) / "ego_speed.log")
            write_ego_speed_log(Path(can_in), world.ego, float(world.times_s[-1]))
            cfg["vehicle"].update(speed_dbc=str(SIM_DBC), speed_message="EGO_SPEED", speed_signals="SPEED_MPS")
        frames = ((f.index, f.t_s, f.image, f.truth) for f in render(scenario))
        return _run(frames, cfg, summary, n, scenario.name, out_video, scenario.fps, tracks_path, can_in, can_out,
                    on_result, progress)


def replay(source: str, **kw) -> ReplaySummary:
    if is_scenario(source):
        kw.pop("fps", None)
        return replay_scenario(source, **kw)
    return replay_recording(source, **kw)
