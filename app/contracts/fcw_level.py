"""The forward-collision warning level: the one Python definition, used by the state machine, the tracks
file, replay, the CAN frame HW_FCW, the annotated video and the cabin-MCU link.

The numbers are the C enum ``hw_fcw_level`` of ``csrc/include/headway.h`` (tests/test_one_definition.py
keeps the two in step) and the raw values of HW_FCW.FCW_LEVEL in ``headway.dbc``, whose value table names
them by ``label`` (the test checks that too).
"""
from __future__ import annotations

from enum import IntEnum


class FcwLevel(IntEnum):
    NONE = 0        # no threat, or FCW not available
    PREWARNING = 1  # visual only: the display lights (MCU: amber LED, no sound)
    WARNING = 2     # brake now: display and buzzer (MCU: red LED and buzzer)

    @property
    def label(self) -> str:
        """The level's name in the tracks file, replay summaries and the DBC value table."""
        return self.name.lower()
