"""The Python side of the door to the C++ core: the only module that touches cffi.

`Pipeline` wraps one ``hw_pipeline``. Calls into the core release the GIL (cffi does so for every
call), so ``pop()`` waits without stalling other Python threads, and the core's real-time thread
never calls back into Python. A running pipeline is stopped at interpreter exit, because a C++ thread
still running while the interpreter tears down aborts the process.
"""
from __future__ import annotations

import atexit
import json
import math
import weakref
from dataclasses import dataclass, field
from typing import Any, Optional

import numpy as np

try:
    from app._headway_core import ffi, lib
except ImportError as exc:  # pragma: no cover - only without a build
    raise ImportError(
        "the C++ core is not built: run ./headway.sh (or python -m app._build_core in the venv)"
    ) from exc


class CoreError(RuntimeError):
    """Base of every error the core reports; ``code`` is the hw_status."""

    code = lib.HW_ERR_INTERNAL


class InvalidArgument(CoreError, ValueError):
    code = lib.HW_ERR_INVALID_ARGUMENT


class ConfigError(CoreError, ValueError):
    code = lib.HW_ERR_CONFIG


class SourceError(CoreError):
    code = lib.HW_ERR_SOURCE


class StateError(CoreError):
    code = lib.HW_ERR_STATE


class EndOfStream(CoreError):
    code = lib.HW_ERR_END_OF_STREAM


_ERRORS = {cls.code: cls for cls in (InvalidArgument, ConfigError, SourceError, StateError, EndOfStream)}

SOURCE_STATES = {
    lib.HW_SOURCE_IDLE: "idle",
    lib.HW_SOURCE_RUNNING: "running",
    lib.HW_SOURCE_RECONNECTING: "reconnecting",
    lib.HW_SOURCE_ENDED: "ended",
    lib.HW_SOURCE_FAILED: "failed",
}

EVENTS = {
    lib.HW_EVENT_DECODE_ERROR: "decode_error",
    lib.HW_EVENT_SOURCE_LOST: "source_lost",
    lib.HW_EVENT_RECONNECTED: "reconnected",
    lib.HW_EVENT_SIZE_CHANGED: "size_changed",
    lib.HW_EVENT_CONCEALED: "concealed",
}
ROAD_MOTION = {lib.HW_ROAD_ACCEPTED: "accepted", lib.HW_ROAD_PREDICTED: "predicted"}
# hw_calib_state -> name (the status, the tracks file and HW_CALIBRATION's STATE use these names)
CALIB_STATES = {lib.HW_CALIB_OFF: "off", lib.HW_CALIB_LEARNING: "learning", lib.HW_CALIB_CONVERGED: "converged",
                lib.HW_CALIB_AT_LIMIT: "at_limit"}


def _check(status: int) -> None:
    if status != lib.HW_OK:
        msg = ffi.string(lib.hw_last_error()).decode("utf-8", "replace")
        raise _ERRORS.get(status, CoreError)(msg or ffi.string(lib.hw_error_message(status)).decode())


_LANE_UNKNOWN = -1000  # hw_track.lane_index when the lane is not known (in_path: -1)


def _opt(x: float) -> Optional[float]:
    """NaN means "not available" in the core; None in Python."""
    x = float(x)
    return None if math.isnan(x) else x


@dataclass
class Track:
    """One vehicle as the core reports it: the one track record on the Python side (the FCW's lead, the
    tracks file and the CAN objects read it). Units in the names; None = not available (NaN and the ABI's
    "unknown" values are turned into None here and nowhere else)."""
    id: int
    confirmed: bool
    age_frames: int
    box: tuple[float, float, float, float]  # left, top, right, bottom (px)
    confidence: float                       # 0..1
    vx_px_s: Optional[float]                # image velocity of the bottom centre
    vy_px_s: Optional[float]
    range_m: Optional[float]
    range_sigma_m: Optional[float]
    lateral_m: Optional[float]              # right positive
    range_rate_mps: Optional[float]         # negative when closing
    range_accel_mps2: Optional[float]
    ttc_s: Optional[float]                  # range-based time to collision
    ttc_scale_s: Optional[float]            # scale-based
    lane_index: Optional[int]               # 0 ego lane, -1 left, +1 right ...
    in_path: Optional[bool]


@dataclass
class Lane:
    x_bottom: float
    y_bottom: float
    x_top: float
    y_top: float
    position: int  # -1 ego left, +1 ego right, -2/+2 adjacent lanes' outer, -3/+3 one further (lanes.outer_lanes)
    observed: bool
    # the boundary as it bends with the road: image points (x, y) from the bottom point to the top point,
    # straight lines between them
    points: list[tuple[float, float]] = field(default_factory=list)


@dataclass
class FrameResult:
    frame: int
    t_s: float          # capture time (monotonic clock for live sources, media time otherwise)
    t_done_s: float     # monotonic clock when the core finished the frame
    width: int
    height: int
    events: list[str]
    full_detection: bool
    tracks: list[Track]
    lanes: list[Lane]
    vanishing_point: Optional[tuple[float, float]]
    horizon_row: Optional[float]
    lead: Optional[Track]  # the in-path vehicle the FCW watches: one of `tracks`, None if there is none
    stages: dict[str, float] = field(default_factory=dict)
    total_ms: float = 0.0
    image_mean: Optional[float] = None     # gray level
    image_stddev: Optional[float] = None   # near 0: blinded
    image_change: Optional[float] = None   # mean |change| since the previous frame; 0: frozen
    # the road plane's motion since the previous frame (parallax preset): "accepted" (a measurement passed
    # the gate), "predicted" (the filter coasts), None (no estimate); the filtered homography (3x3, pixels,
    # previous -> current) and the frames coasted
    road_motion: Optional[str] = None
    road_coast_frames: int = 0
    road_homography: Optional[np.ndarray] = None
    # how well road_homography aligns the road (homography.measure_residual), gray levels over the road pixels
    # outside this frame's detections: |I_k - warp(I_k-1) - o| with o the smooth brightness change between the
    # two fitted and taken out, the same without warping, and warped with the brightness change left in
    road_residual: Optional[float] = None
    road_residual_unaligned: Optional[float] = None
    road_residual_raw: Optional[float] = None
    # the camera as self-calibration has it: {pitch_deg, yaw_deg, height_m, *_sigma, updates, active, state}
    # (state: off, learning, converged, at_limit)
    calibration: Optional[dict] = None
    lane_width_m: Optional[float] = None   # ego-lane width, None unless both ego boundaries are known
    lane_offset_m: Optional[float] = None  # the car's centre right of the ego lane's centre, None unless both known
    # the lane model is believed (both ego boundaries have paint along the road, lanes.evidence_min): the road
    # prior and the lead selection use only such a model
    lanes_certain: bool = False
    # the detection stage's vehicles the tracker took this frame (full_detection), strongest first: (left, top,
    # right, bottom, score), found on frame `detections_frame`: this one, or phd.detect_lag frames earlier when the
    # detection ran on its worker thread; what `headway detect` writes for that frame's image alone
    detections: list[tuple[float, float, float, float, float]] = field(default_factory=list)
    detections_frame: Optional[int] = None

    @property
    def lead_id(self) -> Optional[int]:
        return None if self.lead is None else self.lead.id


@dataclass
class Detections:
    """The detection stage's vehicles on one image (Pipeline.detect)."""
    boxes: np.ndarray               # (n, 5) float32 rows: left, top, right, bottom, score (0-1); strongest first
    horizon_row: Optional[float]    # the horizon row they were found with (the configured camera's)
    stages: dict[str, float]        # ms of the stage's sub-stages (lanes, the detector parts' own)
    total_ms: float

    def rows(self) -> list[tuple[float, float, float, float, float]]:
        """The boxes as tuples of floats, as FrameResult.detections holds a tracked frame's."""
        return [tuple(float(v) for v in b) for b in self.boxes]


def _stage_times(r: Any) -> dict[str, float]:
    """{stage: ms} of an hw_frame_result or hw_detect_info."""
    return {ffi.string(r.stages[i].name).decode(): float(r.stages[i].ms) for i in range(r.n_stages)}


def _result(r: Any) -> FrameResult:
    tracks = []
    for i in range(r.n_tracks):
        t = r.tracks[i]
        tracks.append(
            Track(
                id=int(t.id),
                confirmed=bool(t.confirmed),
                age_frames=int(t.age_frames),
                box=(float(t.left), float(t.top), float(t.right), float(t.bottom)),
                confidence=float(t.confidence),
                vx_px_s=_opt(t.vx_px_s),
                vy_px_s=_opt(t.vy_px_s),
                range_m=_opt(t.range_m),
                range_sigma_m=_opt(t.range_sigma_m),
                lateral_m=_opt(t.lateral_m),
                range_rate_mps=_opt(t.range_rate_mps),
                range_accel_mps2=_opt(t.range_accel_mps2),
                ttc_s=_opt(t.ttc_s),
                ttc_scale_s=_opt(t.ttc_scale_s),
                lane_index=None if t.lane_index == _LANE_UNKNOWN else int(t.lane_index),
                in_path=None if t.in_path < 0 else bool(t.in_path),
            )
        )
    lanes = [
        Lane(float(l.x_bottom), float(l.y_bottom), float(l.x_top), float(l.y_top), int(l.position), bool(l.observed),
             [(float(l.px[j]), float(l.py[j])) for j in range(l.n_points)])
        for l in (r.lanes[i] for i in range(r.n_lanes))
    ]
    vp = None if math.isnan(r.vanishing_x) else (float(r.vanishing_x), float(r.vanishing_y))
    lead = next((t for t in tracks if t.id == r.lead_id), None) if r.lead_id >= 0 else None
    stages = _stage_times(r)
    return FrameResult(
        frame=int(r.frame_number),
        t_s=float(r.t_capture_s),
        t_done_s=float(r.t_done_s),
        width=int(r.width),
        height=int(r.height),
        events=[name for bit, name in EVENTS.items() if r.events & bit],
        full_detection=bool(r.full_detection),
        tracks=tracks,
        detections=[(float(d.left), float(d.top), float(d.right), float(d.bottom), float(d.confidence))
                    for d in (r.detections[i] for i in range(r.n_detections))],
        detections_frame=int(r.detections_frame) if r.full_detection else None,
        lanes=lanes,
        vanishing_point=vp,
        lane_width_m=_opt(r.lane_width_m),
        lane_offset_m=_opt(r.lane_offset_m),
        lanes_certain=bool(r.lanes_certain),
        horizon_row=_opt(r.horizon_row),
        lead=lead,
        stages=stages,
        total_ms=float(r.total_ms),
        image_mean=_opt(r.image_mean),
        image_stddev=_opt(r.image_stddev),
        image_change=_opt(r.image_change),
        road_motion=ROAD_MOTION.get(int(r.road_motion)),
        road_coast_frames=int(r.road_coast_frames),
        road_homography=(None if r.road_motion == lib.HW_ROAD_NONE
                         else np.array([r.road_homography[i] for i in range(9)], dtype=float).reshape(3, 3)),
        road_residual=_opt(r.road_residual),
        road_residual_unaligned=_opt(r.road_residual_unaligned),
        road_residual_raw=_opt(r.road_residual_raw),
        calibration=_calibration(r),
    )


def _calibration(r: Any) -> Optional[dict]:
    if math.isnan(r.calib_pitch_deg):
        return None  # single-image stages: no calibration state
    return {"pitch_deg": float(r.calib_pitch_deg), "yaw_deg": float(r.calib_yaw_deg),
            "height_m": float(r.calib_height_m), "pitch_sigma_deg": float(r.calib_pitch_sigma_deg),
            "yaw_sigma_deg": float(r.calib_yaw_sigma_deg), "height_sigma_m": float(r.calib_height_sigma_m),
            "updates": int(r.calib_updates), "active": bool(r.calib_active),
            "state": CALIB_STATES[int(r.calib_state)]}


def abi_version() -> int:
    return int(lib.hw_abi_version())


def monotonic_s() -> float:
    """The core's monotonic clock (the clock of live capture timestamps and ``t_done_s``)."""
    return float(lib.hw_monotonic_s())


def _config_json(p: Any) -> dict:
    needed = ffi.new("int32_t *")
    lib.hw_pipeline_config(p, ffi.NULL, 0, needed)  # asks for the size only
    buf = ffi.new("char[]", int(needed[0]))
    _check(lib.hw_pipeline_config(p, buf, len(buf), needed))
    return json.loads(ffi.string(buf).decode())


def core_schema() -> dict:
    """Every key the core knows: {section: {key: {default, type, min, max, doc}}}."""
    described = _config_json(ffi.NULL)
    described.pop("moved_keys")
    described.pop("presets")
    described.pop("default_preset")
    described.pop("removed_presets")
    described.pop("detectors")
    return described


def core_presets() -> dict[str, dict]:
    """The named compositions: {name: {"detectors": [...], "tracker": str, "keys": {section: {key: value}}}};
    "keys" are the preset's own defaults, which a configuration's own values override."""
    return _config_json(ffi.NULL)["presets"]


def core_default_preset() -> str:
    """The preset a configuration file that names none runs (the core's preset table names it)."""
    return _config_json(ffi.NULL)["default_preset"]


def core_detectors() -> dict[str, dict]:
    """The registered detector parts: {name: {"single_image": whether it works on one image (not parallax)}}."""
    return _config_json(ffi.NULL)["detectors"]


def core_removed_presets() -> dict[str, str]:
    """The presets that were removed: {name: what replaces it}."""
    return _config_json(ffi.NULL)["removed_presets"]


def core_moved_keys() -> dict[str, str]:
    """The core's keys that moved to a shared definition: {"old_section.key": "new_section.key"}."""
    return _config_json(ffi.NULL)["moved_keys"]


_live: "weakref.WeakSet[Pipeline]" = weakref.WeakSet()


@atexit.register
def _stop_all() -> None:
    for p in list(_live):
        p.close()


def _as_gray(image: np.ndarray, what: str) -> np.ndarray:
    if not isinstance(image, np.ndarray) or image.dtype != np.uint8 or image.ndim != 2:
        shape = getattr(image, "shape", None)
        dtype = getattr(image, "dtype", type(image).__name__)
        raise InvalidArgument(f"{what}: expected an 8-bit gray image (uint8, HxW), got {dtype} {shape}")
    return np.ascontiguousarray(image)


class Pipeline:
    """One configured pipeline: offline ``process()``, or a real-time loop over a frame source."""

    def __init__(self, config: Optional[dict] = None):
        out = ffi.new("hw_pipeline **")
        _check(lib.hw_pipeline_create(json.dumps(config or {}).encode(), out))
        self._p = ffi.gc(out[0], lib.hw_pipeline_destroy)
        self._res = ffi.new("hw_frame_result *")  # reused: one result buffer per pipeline
        self._box_cap = 1024  # detect(): detections room is made for (grows when a stage gives more)
        _live.add(self)

    @property
    def config(self) -> dict:
        """The effective configuration of the core (every key, with the value in use)."""
        return _config_json(self._handle())

    def _handle(self) -> Any:
        if self._p is None:
            raise StateError("the pipeline is closed")
        return self._p

    def process(self, gray: np.ndarray, t_s: float) -> FrameResult:
        """Run one frame through the same code as the real-time loop (tracking state advances)."""
        g = _as_gray(gray, "process()")
        _check(lib.hw_pipeline_process(self._handle(), ffi.from_buffer(g), g.shape[1], g.shape[0], g.strides[0],
                                       float(t_s), self._res))
        return _result(self._res)

    def detect(self, gray: np.ndarray, detector: Optional[str] = None) -> "Detections":
        """The detection stage on one image alone (tracking state untouched; what `headway detect` writes): the
        registered detector part ``detector`` (one of the configuration's pipeline.detectors choices), or the
        pipeline's own detection stage (its composition's parts, fused) when None. Every detection, strongest
        first, and the horizon row they were found with."""
        g = _as_gray(gray, "detect()")
        info = ffi.new("hw_detect_info *")
        name = detector.encode() if detector else ffi.NULL
        cap = self._box_cap
        while True:
            buf = ffi.new("hw_box[]", cap)
            _check(lib.hw_pipeline_detect(self._handle(), name, ffi.from_buffer(g), g.shape[1], g.shape[0],
                                          g.strides[0], buf, cap, info))
            n = int(info.n_detections)
            if n <= cap:
                break
            cap = self._box_cap = n   # more than ever before: once more with room for all
        boxes = np.frombuffer(ffi.buffer(buf, n * ffi.sizeof("hw_box")), np.float32).reshape(n, 5).copy()
        return Detections(boxes, _opt(info.horizon_row), _stage_times(info), float(info.total_ms))

    def image_lanes(self, gray: np.ndarray) -> FrameResult:
        """The lane model of one image alone: the state is reset and the image processed as a first frame, which
        gets the single-image lane detection (a configuration with pipeline.preset none runs nothing else)."""
        if self.config["self_calibration"]["from_scratch"]:
            raise ValueError("image_lanes(): with self_calibration.from_scratch the first frame runs the lane "
                             "tracker's wide search, not the single-image lanes; set it false")
        self.reset()
        return self.process(gray, 0.0)

    def reset(self) -> None:
        _check(lib.hw_pipeline_reset(self._handle()))

    def set_ego_motion(self, speed_mps: Optional[float], yaw_rate_rps: Optional[float] = None) -> None:
        """The car's speed and yaw rate (left positive) from the bus; None = not available."""
        nan = float("nan")
        _check(lib.hw_pipeline_set_ego_motion(self._handle(), nan if speed_mps is None else float(speed_mps),
                                              nan if yaw_rate_rps is None else float(yaw_rate_rps)))

    def start(self, source: dict) -> None:
        """Open the source (SourceError if it cannot be) and start the real-time thread."""
        _check(lib.hw_pipeline_start(self._handle(), json.dumps(source).encode()))

    def stop(self) -> None:
        if self._p is not None:
            _check(lib.hw_pipeline_stop(self._p))

    def pop(self, timeout_s: float = 1.0) -> Optional[FrameResult]:
        """Next result, or None on timeout. Raises EndOfStream once the source ended and all was popped."""
        status = lib.hw_pipeline_pop(self._handle(), int(max(0.0, timeout_s) * 1000), self._res)
        if status == lib.HW_ERR_TIMEOUT:
            return None
        _check(status)
        return _result(self._res)

    def push(self, image: np.ndarray, t_s: float) -> None:
        """Hand one frame (uint8 gray HxW or BGR HxWx3) to a pipeline started with {"kind": "push"}."""
        if not isinstance(image, np.ndarray) or image.dtype != np.uint8 or image.ndim not in (2, 3):
            raise InvalidArgument(
                f"push(): expected a uint8 image HxW or HxWx3, got {getattr(image, 'dtype', type(image).__name__)} "
                f"{getattr(image, 'shape', None)}"
            )
        img = np.ascontiguousarray(image)
        channels = 1 if img.ndim == 2 else img.shape[2]
        _check(lib.hw_pipeline_push(self._handle(), ffi.from_buffer(img), img.shape[1], img.shape[0], channels,
                                    img.strides[0], float(t_s)))

    def push_end(self) -> None:
        _check(lib.hw_pipeline_push_end(self._handle()))

    def health(self) -> dict:
        h = ffi.new("hw_health *")
        _check(lib.hw_pipeline_health(self._handle(), h))
        return {
            "running": bool(h.running),
            "source_state": SOURCE_STATES.get(int(h.source_state), "unknown"),
            "frames_captured": int(h.frames_captured),
            "frames_processed": int(h.frames_processed),
            "results_dropped": int(h.results_dropped),
            "frames_pushed_dropped": int(h.frames_pushed_dropped),
            "decode_errors": int(h.decode_errors),
            "source_losses": int(h.source_losses),
            "reconnects": int(h.reconnects),
            "last_frame_t_s": _opt(h.last_frame_t_s),
            "last_progress_s": _opt(h.last_progress_s),
            "last_alive_s": _opt(h.last_alive_s),
            "last_total_ms": _opt(h.last_total_ms),
            "queue_depth": int(h.queue_depth),
            "queue_capacity": int(h.queue_capacity),
        }

    def close(self) -> None:
        """Stop the loop and free the core's pipeline. Safe to call twice."""
        if self._p is not None:
            lib.hw_pipeline_stop(self._p)
            p, self._p = self._p, None
            ffi.release(p)  # runs hw_pipeline_destroy now instead of at garbage collection

    def __enter__(self) -> "Pipeline":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
