"""The registry of health fault bits: one table, used by the monitor, the status CAN frame and the docs.

Severity "fault" means Headway cannot warn the driver reliably; "degraded" means it still warns but
something needs attention. The bit numbers are part of the CAN interface: never renumber a bit.
The overall states and the rule that picks one from the faults are here too, so that the health
monitor and a replay without one decide alike. headway.dbc's HW_STATUS (its STATE value table, its
FAULT_* bits and their comments) is checked against this file by tests/test_can_dbc.py and
tests/test_one_definition.py.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable

FAULT, DEGRADED = "fault", "degraded"  # the severities, also the names of the states they lead to
STARTING, OK = "starting", "ok"
# The overall states in the order of their codes (HW_STATUS.STATE, the status file).
STATES = (STARTING, OK, DEGRADED, FAULT)


@dataclass(frozen=True)
class Fault:
    name: str
    bit: int
    severity: str
    meaning: str


FAULTS = (
    Fault("camera_lost", 0, FAULT, "no frame for longer than health.camera_timeout_s (unplugged, power, driver); "
                                   "the core keeps reconnecting with back-off and the bit clears when frames return"),
    Fault("camera_blinded", 1, DEGRADED, "near-constant picture for health.blinded_frames frames (glare, covered or "
                                         "dirty lens, dead sensor): detections are unreliable"),
    Fault("camera_frozen", 2, DEGRADED, "identical frames for health.frozen_frames frames: the camera or its driver "
                                        "repeats a buffer"),
    Fault("core_stalled", 3, FAULT, "the real-time loop has not gone round for health.stall_timeout_s: the "
                                    "systemd watchdog pings stop and systemd restarts the service"),
    Fault("overload", 4, DEGRADED, "p99 processing latency above health.latency_budget_ms, or results dropped "
                                   "because the supervisor fell behind"),
    Fault("can_error", 5, FAULT, "CAN frames could not be sent (bus off, no interface): warnings do not reach "
                                 "the car"),
    Fault("ego_speed_stale", 6, DEGRADED, "no valid ego speed from the vehicle bus within its timeout: warnings "
                                          "that need it are suppressed, never guessed"),
    Fault("mcu_silent", 7, DEGRADED, "the cabin microcontroller has not been heard within its timeout: the buzzer "
                                     "and LED may not work"),
)

BY_NAME = {f.name: f for f in FAULTS}


def fault_bits(names) -> int:
    return sum(1 << BY_NAME[n].bit for n in names)


def fault_names(bits: int) -> list[str]:
    return [f.name for f in FAULTS if bits & (1 << f.bit)]


def overall_state(faults: Iterable[str], started: bool) -> str:
    """The one rule: fault on any fault of severity fault, else starting until the first frame, else
    degraded on any other fault, else ok. An unknown fault name is a KeyError (a programming error)."""
    severities = {BY_NAME[f].severity for f in faults}
    if FAULT in severities:
        return FAULT
    if not started:
        return STARTING
    return DEGRADED if DEGRADED in severities else OK
