"""The configuration section `health`: the supervisor's health monitor (app/supervisor/health.py) reads it,
and the configuration (app/config.py), which sits below the supervisor, checks and documents it."""
from __future__ import annotations

from app.contracts.config_key import key as _key

HEALTH_SCHEMA = {
    "camera_timeout_s": _key(0.5, "s; no frame for this long is a camera fault (15 frames at 30 fps: longer than "
                                  "any driver hiccup, short enough that FCW is not blind unnoticed)", 0.05, 60.0),
    "stall_timeout_s": _key(2.0, "s; the real-time loop not going round for this long is a stalled core "
                                 "(watchdog pings stop)", 0.1, 120.0),
    "blinded_stddev": _key(3.0, "gray levels; image contrast below this is a blinded frame (a road scene has "
                                "20-60)", 0.0, 100.0),
    "blinded_frames": _key(15, "frames; consecutive blinded frames before the camera is called blinded", 1, 10000),
    "frozen_change": _key(0.05, "gray levels; mean change between frames below this is a frozen frame (sensor "
                                "noise alone gives > 0.5)", 0.0, 50.0),
    "frozen_frames": _key(30, "frames; consecutive frozen frames before the camera is called frozen", 2, 10000),
    "latency_budget_ms": _key(50.0, "ms; p99 processing latency above this is overload (1.5 frame periods at 30 "
                                    "fps)", 1.0, 10000.0),
    "window_frames": _key(300, "frames; sliding window of the frame-rate and latency statistics (10 s at 30 fps)",
                          10, 100000),
}
