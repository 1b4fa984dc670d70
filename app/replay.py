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

from tqdm import tqdm

from app import config as configuration
from app.annotate import VideoOut, annotate
from app.can import CanLogError, CanSession, DbcError, VehicleInputError
from app.contracts.fcw_level import FcwLevel
from app.core import FrameResult, Pipeline
from app.output_files import check_outputs, written_whole
from app.recording import RecordingError, open_recording
from app.sim import ScenarioError, frame_count, list_scenarios, load_scenario, render
from app.sim.can_log import write_ego_speed_log
from app.sim.frames import scenario_camera
from app.sim.world import World
from app.supervisor.stack import Stack
from app.tracks_file import TracksWriter

SIM_DBC = Path(__file__).resolve().parent / "sim" / "ego_speed_placeholder.dbc"


class ReplayError(RuntimeError):
    """A source that cannot be replayed; the message says what and how to fix it."""


def _recording(source: str, fps: Optional[float]):
    try:
        return open_recording(source, fps)
    except RecordingError as exc:
        raise ReplayError(str(exc)) from None


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
    decoded: str = ""   # a recording's "N of M frames decoded"

    def add(self, r: FrameResult) -> None:
        self.frames += 1
        self.total_ms.append(r.total_ms)
        self.confirmed_ids.update(t.id for t in r.tracks if t.confirmed)

    def text(self) -> str:
        lines = [f"{self.source}: {self.frames} frames processed"
                 + (f", {len(self.skipped)} skipped" if self.skipped else "")
                 + (f" ({self.decoded})" if self.decoded else "")]
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
                c = self.can.get("input") or {}
                if c:
                    dropped = ", ".join(f"{k} {n}" for k, n in c["dropped"].items()) or "none"
                    lines.append(f"  CAN in: {c['read']} frames read, {c['used']} used, dropped: {dropped}"
                                 + (f", {c['not_reached']} after the recording's end" if c.get("not_reached") else ""))
            for line in self.can.get("never_decoded", []):
                lines.append(f"  WARNING: {line}")
        for name, path in self.outputs.items():
            lines.append(f"  {name}: {path}")
        return "\n".join(lines)


def is_scenario(source: str) -> bool:
    p = Path(source)
    if p.suffix in (".yaml", ".yml"):
        return True
    if p.exists():
        return False
    return source in list_scenarios()


def _progress(total: Optional[int], desc: str, enabled: bool):
    if not enabled or not sys.stderr.isatty():
        return contextlib.nullcontext(None)
    return tqdm(total=total, desc=desc, unit="frame", file=sys.stderr, leave=False)


def _run(frames, cfg: dict, summary: ReplaySummary, n_frames: Optional[int], label: str,
         out_video: Optional[str], fps: float, tracks_path: Optional[str], can_in: Optional[str],
         can_out: Optional[str], on_result: Optional[Callable], progress: bool) -> ReplaySummary:
    with contextlib.ExitStack() as stack:
        # each output is written beside its place and renamed into it once the run is complete
        tracks_tmp, video_tmp, can_tmp = (stack.enter_context(written_whole(p)) for p in (tracks_path, out_video, can_out))
        pipe = stack.enter_context(Pipeline(configuration.core_sections(cfg)))
        writer = TracksWriter(stack.enter_context(open(tracks_tmp, "w"))) if tracks_path else None
        video = VideoOut(video_tmp, fps) if out_video else None
        if video:
            stack.callback(video.close)
        try:
            session = stack.enter_context(CanSession.for_replay(cfg, can_in=can_in, can_out=can_tmp))
        except (CanLogError, DbcError, VehicleInputError, OSError) as exc:
            raise ReplayError(str(exc)) from None
        sup = Stack(cfg, session)
        bar = stack.enter_context(_progress(n_frames, label, progress))
        for index, t_s, gray, truth, colour in frames:
            r = pipe.process(gray, t_s)
            decision = sup.step(r, r.t_s, pipe)
            summary.add(r)
            if decision.changed and decision.level != FcwLevel.NONE:
                summary.warnings.append((r.t_s, decision.level.label, decision.ttc_used_s))
            if writer:
                writer.write(r, decision.level)
            if video:
                video.write(annotate(gray if colour is None else colour, r, truth, decision))
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
                     on_result: Optional[Callable] = None, progress: bool = True,
                     overrides: Optional[dict] = None) -> ReplaySummary:
    """`overrides`: configuration values applied over the file's (same shape, e.g. {"self_calibration": {...}})."""
    summary = ReplaySummary(source)
    rec = _recording(source, fps)
    summary.skipped = rec.skipped  # the reader lists what it could not use, as it goes
    cfg = configuration.load(config_path, overrides)
    size = rec.size
    problem = configuration.frame_size_problem(*size)
    if problem:
        raise ReplayError(f"{source}: {problem}")
    if (cfg["camera"]["width"], cfg["camera"]["height"]) != size:
        # a camera calibrated for another size: same field of view, intrinsics scaled to the recording
        cfg["camera"] = configuration.scaled_camera(cfg["camera"], *size)
    frames = ((i, t, g, None, bgr) for i, t, g, bgr in rec.colour_frames(colour=out_video is not None))
    out = _run(frames, cfg, summary, rec.expected, Path(source).name,
               out_video, rec.fps, tracks_path, can_in, can_out, on_result, progress)
    summary.decoded = rec.account()
    return out


def replay_scenario(source: str, config_path: Optional[str] = None, out_video: Optional[str] = None,
                    tracks_path: Optional[str] = None, can_in: Optional[str] = None, can_out: Optional[str] = None,
                    on_result: Optional[Callable] = None, progress: bool = True,
                    overrides: Optional[dict] = None, vehicle_look: Optional[str] = None) -> ReplaySummary:
    """`overrides`: configuration values applied over the file's (same shape, e.g. {"pipeline": {"preset": ...}});
    `vehicle_look` ("real" or "plain") replaces the scenario's own."""
    try:
        scenario = load_scenario(source)
    except ScenarioError as exc:
        raise ReplayError(str(exc)) from None
    if vehicle_look is not None:
        scenario = dataclasses.replace(scenario, vehicle_look=vehicle_look)
    cfg = configuration.load(config_path, overrides)
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
        frames = ((f.index, f.t_s, f.image, f.truth, None) for f in render(scenario))
        return _run(frames, cfg, summary, n, scenario.name, out_video, scenario.fps, tracks_path, can_in, can_out,
                    on_result, progress)


def add_parser(subparsers) -> None:
    s = subparsers.add_parser("replay", help="run a video file, an image folder or a scenario through the pipeline")
    s.add_argument("source", help="video file, image folder (give --fps) or scenario")
    s.add_argument("--config", help="configuration YAML (default: built-in defaults)")
    s.add_argument("--fps", type=float, help="frame rate of an image folder, or to override a video's own "
                                              "(0.1 to 1000 frames/s)")
    s.add_argument("--out-video", help="write an annotated video here (.mp4)")
    s.add_argument("--tracks", help="write the tracks here (.jsonl, one line per frame)")
    s.add_argument("--can-in", help="vehicle CAN log replayed on the frame clock (.log candump, .asc, .blf); "
                                    "a scenario uses its own ego-speed log when not given")
    s.add_argument("--can-out", help="write every CAN frame Headway sends here (.log, .asc or .blf)")
    s.set_defaults(run=run)


def run(args) -> int:
    s = replay(args.source, config_path=args.config, fps=args.fps, out_video=args.out_video,
               tracks_path=args.tracks, can_in=args.can_in, can_out=args.can_out)
    print(s.text())
    return 0


def replay(source: str, **kw) -> ReplaySummary:
    check_outputs({"--tracks": kw.get("tracks_path"), "--out-video": kw.get("out_video"), "--can-out": kw.get("can_out")},
                  {"the source": source, "--can-in": kw.get("can_in"), "--config": kw.get("config_path")})
    if is_scenario(source):
        kw.pop("fps", None)
        return replay_scenario(source, **kw)
    return replay_recording(source, **kw)
