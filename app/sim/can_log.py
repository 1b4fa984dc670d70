"""The ego speed of a scenario as a candump log of the placeholder EGO_SPEED message.

The message layout lives in ``ego_speed_placeholder.dbc`` (a placeholder until the CAN issue
defines Headway's DBC) and is encoded with cantools. Timestamps share the frames' origin:
the log's ``(0.000000)`` is frame 0's ``t``.
"""
from __future__ import annotations

from pathlib import Path

import can
import cantools
import numpy as np

from .world import Motion1D

DBC_PATH = Path(__file__).resolve().parent / "ego_speed_placeholder.dbc"
MESSAGE = "EGO_SPEED"
RATE_HZ = 50.0
CHANNEL = "vcan0"


def ego_speed_times(end_s: float) -> np.ndarray:
    """Send times from 0 to ``end_s`` inclusive, every 1/RATE_HZ (exact multiples, no drift)."""
    return np.arange(int(np.floor(end_s * RATE_HZ + 1e-9)) + 1) / RATE_HZ


def write_ego_speed_log(path: Path, ego: Motion1D, end_s: float) -> int:
    """Write the log; returns the number of frames written."""
    message = cantools.database.load_file(str(DBC_PATH)).get_message_by_name(MESSAGE)
    times = ego_speed_times(end_s)
    _, speeds, _ = ego.at(times)
    writer = can.CanutilsLogWriter(str(path), channel=CHANNEL)
    try:
        for counter, (t, speed) in enumerate(zip(times, speeds)):
            data = message.encode({"SPEED_MPS": float(speed), "COUNTER": counter % 16})
            writer.on_message_received(can.Message(timestamp=float(t), arbitration_id=message.frame_id,
                                                   is_extended_id=False, data=data, channel=CHANNEL))
    finally:
        writer.stop()
    return len(times)
