"""Cost of Headway's CAN output per frame set: pack (cantools, counter, checksum) and send on a
python-can ``virtual`` bus, with and without a candump log. ``python -m app.bench.can_output``.

A frame set is what one camera frame produces when every group is due: HW_FCW, HW_LEAD,
HW_LEAD_TTC, HW_STATUS, HW_OBJECT_HEADER and two HW_OBJECT pages per object.
"""
from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path
from types import SimpleNamespace

import can

from app import config as configuration
from app.can.bus import CanOutput
from app.can.config_schema import defaults
from app.can.messages import ttc_of
from app.can.session import CanSession
from app.can.vehicle_input import VehicleInput
from app.contracts.fcw_level import FcwLevel


def fake_track(i: int) -> SimpleNamespace:
    """A plausible confirmed track, i metres further out per index (attributes as app.core.Track)."""
    left = 280.0 + 7 * i
    return SimpleNamespace(id=i + 1, confirmed=True, box=(left, 240.0, left + 40.0, 270.0), confidence=0.8,
                           range_m=10.0 + 7.5 * i, lateral_m=-1.5 + 0.5 * (i % 7), range_rate_mps=-1.0 - 0.1 * i,
                           ttc_s=(10.0 + 7.5 * i) / (1.0 + 0.1 * i), ttc_scale_s=9.0 + i, lane_index=i % 3 - 1,
                           in_path=i % 3 == 1)


def fake_result(frame: int, n_objects: int, lead: int = 1) -> SimpleNamespace:
    """A frame result (attributes as app.core.FrameResult) with ``n_objects`` tracks; track ``lead`` leads."""
    tracks = [fake_track(i) for i in range(n_objects)]
    return SimpleNamespace(frame=frame, t_s=frame / 30.0, t_done_s=frame / 30.0 + 0.02, tracks=tracks,
                           lead=tracks[lead - 1] if n_objects >= lead else None)


def measure(n_objects: int, log: bool, repeats: int = 300) -> tuple[float, int]:
    """(median CPU microseconds of this thread per frame set, frames per set); CPU time, so that a
    busy machine does not inflate it."""
    cfg = defaults()
    cfg["can"].update(max_objects=64)
    cfg["camera"] = configuration.defaults()["camera"]  # the product's camera, for the objects' angles
    with tempfile.TemporaryDirectory() as tmp, can.Bus(interface="virtual", channel="bench") as bus, \
            can.Bus(interface="virtual", channel="bench") as sink:
        output = CanOutput(bus, Path(tmp) / "out.log" if log else None)
        session = CanSession(cfg, output, VehicleInput([]), deterministic=True)
        times, frames = [], 0
        for k in range(repeats):
            t = k * 0.1  # every group due every call
            result = fake_result(k, n_objects)
            ttc, source = ttc_of(result.lead)
            fcw = {"level": FcwLevel(k % len(FcwLevel)), "ttc_s": ttc, "ttc_source": source}
            t_start = time.thread_time()
            frames = len(session.publish(t, result, fcw=fcw))
            times.append(time.thread_time() - t_start)
            while sink.recv(timeout=0) is not None:
                pass
        session.close()
    return statistics.median(times) * 1e6, frames


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=300)
    args = ap.parse_args()
    print("objects  frames/set  us/set (bus)  us/set (bus + .log)  us/frame")
    for n in (0, 4, 16, 32, 64):
        us, frames = measure(n, False, args.repeats)
        us_log, _ = measure(n, True, args.repeats)
        print(f"{n:7d}  {frames:10d}  {us:12.0f}  {us_log:19.0f}  {us / frames:8.1f}")


if __name__ == "__main__":
    main()
