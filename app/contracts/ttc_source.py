"""Which time to collision the FCW decision used: the one Python definition, used by the state machine
(app/fcw.py), the CAN frame HW_FCW and the tracks' summaries.

The value is the source's name in the FCW decision and in the value table of HW_FCW.TTC_SOURCE in
``headway.dbc``; the order of the members is the signal's raw value on the wire (``raw``).
tests/test_one_definition.py keeps the two in step.
"""
from __future__ import annotations

from enum import StrEnum


class TtcSource(StrEnum):
    NONE = "none"                # no TTC: no lead, or no usable estimate
    RANGE = "range"              # range / closing speed
    SCALE = "scale"              # image scale: w / (dw/dt), when the range is unknown
    RANGE_ACCEL = "range_accel"  # range-based with the relative acceleration (a braking lead)

    @property
    def raw(self) -> int:
        """HW_FCW.TTC_SOURCE's raw value."""
        return list(TtcSource).index(self)
