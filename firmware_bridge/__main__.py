"""Bench tool, the host end: `python -m firmware_bridge --port /dev/ttyMCU [--warn-cycle]`.

Runs McuLink against a real MCU (or `python -m firmware_bridge.mcu_sim --pty`), prints the link's
health and the vehicle signals once a second; with --warn-cycle steps the warning level
none -> pre-warning -> warning every 2 s so the buzzer and LED can be checked by eye and ear.
"""
from __future__ import annotations

import argparse
import json
import logging
import sys
import time

from .link import LinkConfig, McuLink
from .messages import WarningLevel


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m firmware_bridge", description=__doc__.split("\n\n")[1])
    p.add_argument("--port", required=True, help="serial port of the cabin MCU")
    p.add_argument("--baud", type=int, default=115200)
    p.add_argument("--warn-cycle", action="store_true", help="cycle the warning level every 2 s")
    p.add_argument("--duration", type=float, default=0.0, help="seconds to run (0: until Ctrl-C)")
    a = p.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s")

    link = McuLink(a.port, LinkConfig(baudrate=a.baud))
    start = time.monotonic()
    end = start + a.duration if a.duration > 0 else float("inf")
    next_print = start
    try:
        while (now := time.monotonic()) < end:
            if a.warn_cycle:
                level = WarningLevel(int((now - start) / 2.0) % len(WarningLevel))
                link.send_warning(level, 1.5 if level else None, 20.0 if level else None)
            link.poll(now)
            if now >= next_print:
                next_print += 1.0
                health = link.health(now)
                health["vehicle_signals"] = link.vehicle_signals(now)
                print(json.dumps(health, default=str), flush=True)
            time.sleep(0.005)
    except KeyboardInterrupt:
        pass
    link.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
