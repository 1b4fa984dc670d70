"""DBC files: Headway's own (``dbc/headway.dbc``, the one registry of its CAN messages and fault bits)
and the user's car DBC for vehicle inputs. Both are loaded with cantools; a file that cannot be used
raises :class:`DbcError` naming the file."""
from __future__ import annotations

from pathlib import Path
from typing import Union

import cantools
from cantools.database.can import Database

HEADWAY_DBC = Path(__file__).resolve().parent / "dbc" / "headway.dbc"
DBC_ID_BASE = 0x600          # the base id written in headway.dbc; can.id_base moves every message
MAX_STANDARD_ID = 0x7FF
WIRE_ID_MAX = 4095           # track ids go on the wire as 12 bits, 0 = none
FAULT_PREFIX = "FAULT_"


class DbcError(ValueError):
    """A DBC file that cannot be used; the message names the file and what is wrong."""


def load_dbc(path: Union[str, Path], strict: bool = True) -> Database:
    """Loads a DBC. ``strict`` also rejects overlapping signals; car DBCs collected from many model
    years (opendbc) often have overlaps in messages nobody uses, so vehicle inputs load with
    ``strict=False`` and check only the signals they map."""
    p = Path(path)
    if not p.is_file():
        raise DbcError(f"{p}: no such DBC file")
    try:
        return cantools.database.load_file(str(p), database_format="dbc", strict=strict)
    except Exception as exc:  # cantools raises several types (parse, unsupported, value errors)
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise DbcError(f"{p}: not a usable DBC file: {first}") from None


def headway_database(id_base: int = DBC_ID_BASE, path: Union[str, Path] = HEADWAY_DBC) -> Database:
    """Headway's messages with every id moved by ``id_base - 0x600`` (ids stay in the same order)."""
    db = load_dbc(path, strict=True)
    shift = id_base - DBC_ID_BASE
    if shift:
        top = max(m.frame_id for m in db.messages) + shift
        low = min(m.frame_id for m in db.messages) + shift
        if low < 0 or top > MAX_STANDARD_ID:
            raise DbcError(f"{path}: id_base 0x{id_base:X} puts ids outside 0x000-0x7FF "
                           f"(the messages span {len(db.messages)} ids)")
        for m in db.messages:
            m.frame_id += shift
        db.refresh()
    return db


def wire_id(track_id) -> int:
    """A track id as its 12-bit wire id: 0 = none, else ((id - 1) mod 4095) + 1."""
    if track_id is None or track_id < 1:
        return 0
    return (int(track_id) - 1) % WIRE_ID_MAX + 1


def fault_names(db: Database) -> list[str]:
    """The fault bits of HW_STATUS in bit order, as lower-case names (``camera_lost``, ...)."""
    status = db.get_message_by_name("HW_STATUS")
    sigs = sorted((s for s in status.signals if s.name.startswith(FAULT_PREFIX)), key=lambda s: s.start)
    return [s.name[len(FAULT_PREFIX):].lower() for s in sigs]
