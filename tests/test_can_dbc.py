"""headway.dbc: loads strictly, documents every message and signal, and the config keys of the CAN
layer are well-formed; bad DBC files give errors that name the file."""
from __future__ import annotations

import cantools
import pytest

from app.can import DbcError, headway_database, load_dbc
from app.can.config_schema import CAN_SCHEMA, INPUTS
from app.can.database import HEADWAY_DBC, fault_names, wire_id
from app.can.messages import FATAL_FAULTS
from app.can.packer import sna_raw
from tests.conftest import REPO


def test_headway_dbc_loads_strictly_with_the_documented_ids():
    db = cantools.database.load_file(str(HEADWAY_DBC), strict=True)
    ids = {m.name: m.frame_id for m in db.messages}
    assert ids == {"HW_FCW": 0x600, "HW_LEAD": 0x601, "HW_LEAD_TTC": 0x602, "HW_OBJECT_HEADER": 0x603,
                   "HW_OBJECT": 0x604, "HW_STATUS": 0x605, "HW_CALIBRATION": 0x606}
    assert all(m.length == 8 and not m.is_extended_frame for m in db.messages)


UNITS = {"M": "m", "S": "s", "MPS": "m/s", "RAD": "rad", "HZ": "Hz", "MS": "ms", "DEG": "deg"}


def test_every_message_and_signal_is_commented_and_carries_counter_and_checksum():
    db = headway_database()
    for m in db.messages:
        assert m.comment and len(m.comment) > 20, m.name
        names = {s.name for s in m.signals}
        assert {"COUNTER", "CHECKSUM"} <= names, m.name
        for s in m.signals:
            assert s.comment and len(s.comment) > 15, f"{m.name}.{s.name} has no comment"
            suffix = s.name.rsplit("_", 1)[-1]
            if suffix in UNITS:  # units in the names, SI units in the DBC, and a value for 'not available'
                assert s.unit == UNITS[suffix], f"{m.name}.{s.name}: unit {s.unit!r}"
                assert sna_raw(s) is not None, f"{m.name}.{s.name} has no SNA value"
    assert "CRC-8 SAE J1850 (poly 0x1D, init 0xFF, final XOR 0xFF" in HEADWAY_DBC.read_text()


def test_value_tables_name_the_states_and_levels():
    db = headway_database()
    fcw = db.get_message_by_name("HW_FCW")
    assert {int(k): str(v) for k, v in fcw.get_signal_by_name("FCW_LEVEL").choices.items()} == \
        {0: "none", 1: "prewarning", 2: "warning"}
    status = db.get_message_by_name("HW_STATUS")
    assert [str(v) for v in status.get_signal_by_name("STATE").choices.values()] == \
        ["starting", "ok", "degraded", "fault"]
    assert db.get_message_by_name("HW_OBJECT").is_multiplexed()
    cal = db.get_message_by_name("HW_CALIBRATION")
    assert {int(k): str(v) for k, v in cal.get_signal_by_name("STATE").choices.items()} == \
        {0: "off", 1: "learning", 2: "converged", 3: "at_limit"}
    assert cal.is_multiplexed()


def test_fault_bits_are_the_health_registry_bit_for_bit():
    faults = pytest.importorskip("app.contracts.faults", reason="the health registry is not in this tree")
    status = headway_database().get_message_by_name("HW_STATUS")
    assert fault_names(headway_database()) == [f.name for f in sorted(faults.FAULTS, key=lambda f: f.bit)]
    for f in faults.FAULTS:
        sig = status.get_signal_by_name(f"FAULT_{f.name.upper()}")
        assert (sig.start, sig.length) == (8 + f.bit, 1), f.name
        assert sig.comment.startswith(f"Fault bit {f.bit} ({f.severity}): "), f.name
    assert FATAL_FAULTS == {f.name for f in faults.FAULTS if f.severity == faults.FAULT}


def test_id_base_moves_every_message():
    db = headway_database(0x680)
    assert sorted(m.frame_id for m in db.messages) == list(range(0x680, 0x687))
    assert db.get_message_by_frame_id(0x680).name == "HW_FCW"
    with pytest.raises(DbcError, match="outside 0x000-0x7FF"):
        headway_database(0x7FD)


def test_wire_ids_wrap_and_keep_zero_for_none():
    assert [wire_id(x) for x in (None, 0, 1, 4095, 4096, 8191)] == [0, 0, 1, 4095, 1, 1]


@pytest.mark.parametrize("text, message", [
    ("this is not a DBC\n", "not a usable DBC file"),
    ('VERSION ""\nBO_ 100 M: 8 X\n SG_ A : 60|8@1+ (1,0) [0|255] "" X\n', "not a usable DBC file"),
])
def test_a_dbc_that_does_not_parse_names_the_file(tmp_path, text, message):
    bad = tmp_path / "broken.dbc"
    bad.write_text(text)
    with pytest.raises(DbcError) as e:
        load_dbc(bad)
    assert str(bad) in str(e.value) and message in str(e.value)


def test_a_missing_dbc_names_the_file(tmp_path):
    with pytest.raises(DbcError, match="no such DBC file"):
        load_dbc(tmp_path / "nope.dbc")


def test_config_keys_are_documented_typed_and_in_range():
    assert set(CAN_SCHEMA) == {"can", "vehicle"}
    for sec, keys in CAN_SCHEMA.items():
        for key, spec in keys.items():
            where = f"{sec}.{key}"
            assert spec["type"] in {"int", "float", "bool", "str"}, where
            assert len(spec["doc"]) > 25, where
            py = {"int": int, "float": float, "bool": bool, "str": str}[spec["type"]]
            assert type(spec["default"]) is py, where
            if "min" in spec:
                assert spec["min"] <= spec["default"] <= spec["max"], where
            if "choices" in spec:
                assert spec["default"] in spec["choices"].split("|"), where
    for name in INPUTS:
        assert f"{name}_message" in CAN_SCHEMA["vehicle"] and f"{name}_stale_after_s" in CAN_SCHEMA["vehicle"]


def test_docs_list_every_message_and_signal():
    docs = (REPO / "docs" / "can.md").read_text()
    for m in headway_database().messages:
        assert f"`{m.name}`" in docs and f"0x{m.frame_id:03X}" in docs, m.name
        for s in m.signals:
            if not s.name.startswith("FAULT_") and s.name not in ("COUNTER", "CHECKSUM"):
                assert f"`{s.name}`" in docs, f"{m.name}.{s.name} missing from docs/can.md"
    for name in fault_names(headway_database()):
        assert f"`FAULT_{name.upper()}`" in docs
