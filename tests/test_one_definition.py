"""One definition per concept: the FCW level, the TTC source, the fault severities and overall states, the
health parameters, the camera defaults and the camera-to-bumper distance are each written once, and
everything else reads them.

The pins check each definition against the other form that must agree with it (the C header, the DBC,
the configuration schema, the core's described defaults); the source scan fails when a level or a
severity is written again as a literal in the product's Python (app/, firmware_bridge/).
"""
from __future__ import annotations

import dataclasses
import io
import itertools
import re
import tokenize
from pathlib import Path

import pytest

from app.can import CanPacker, CanParser
from app.can.database import headway_database
from app.can.messages import fcw_signals, ttc_of
from app.contracts import faults as registry
from app.contracts.fcw_level import FcwLevel
from app.contracts.ttc_source import TtcSource
from app.core import core_schema
from app.fcw import Lead
from app.sim.camera import CAMERA_KEYS, Camera, default_camera
from app.supervisor.health import HEALTH_SCHEMA, HealthMonitor, HealthParams
from tests.conftest import REPO

HEADER = REPO / "csrc" / "include" / "headway.h"


# ---- the FCW level -----------------------------------------------------------------------------------

def test_fcw_level_is_the_c_enum_of_headway_h():
    enum = re.search(r"typedef\s+enum\s*\{([^}]*)\}\s*hw_fcw_level\s*;", HEADER.read_text())
    if enum is None:
        pytest.skip("headway.h no longer declares hw_fcw_level: app/contracts/fcw_level.py is then the only definition")
    c_levels = {name: int(value) for name, value in re.findall(r"HW_FCW_(\w+)\s*=\s*(\d+)", enum.group(1))}
    assert c_levels == {m.name: m.value for m in FcwLevel}
    from app._headway_core import lib  # the built core says the same
    assert {m.name: getattr(lib, f"HW_FCW_{m.name}") for m in FcwLevel} == c_levels


def test_hw_fcw_value_table_names_the_levels_by_their_labels():
    signal = headway_database().get_message_by_name("HW_FCW").get_signal_by_name("FCW_LEVEL")
    assert {int(k): str(v) for k, v in signal.choices.items()} == {m.value: m.label for m in FcwLevel}
    assert (signal.minimum, signal.maximum) == (min(FcwLevel), max(FcwLevel))


def test_the_mcu_link_sends_the_same_levels():
    from firmware_bridge import WarningLevel
    from firmware_bridge.messages import FcwWarning
    assert WarningLevel is FcwLevel
    assert [FcwWarning(m).fields()[0] for m in FcwLevel] == [0, 1, 2]


# ---- the TTC source -----------------------------------------------------------------------------------

def test_hw_fcw_ttc_source_table_is_the_enum_in_order():
    signal = headway_database().get_message_by_name("HW_FCW").get_signal_by_name("TTC_SOURCE")
    assert {int(k): str(v) for k, v in signal.choices.items()} == {s.raw: s.value for s in TtcSource}
    assert (signal.minimum, signal.maximum) == (0, len(TtcSource) - 1)


@pytest.mark.parametrize("source", list(TtcSource))
def test_each_ttc_source_reaches_the_wire_as_its_raw_value(source):
    sent = fcw_signals(FcwLevel.WARNING, True, 1.5, source)
    assert sent["TTC_SOURCE"] == source.raw
    db = headway_database()
    frame = CanPacker(db).pack("HW_FCW", sent)
    name, values = CanParser(db).update(frame)
    assert name == "HW_FCW" and values["TTC_SOURCE"] == source.raw
    choices = db.get_message_by_name("HW_FCW").get_signal_by_name("TTC_SOURCE").choices
    assert str(choices[values["TTC_SOURCE"]]) == source.value


def test_the_state_machine_and_the_can_fallback_name_their_sources_from_the_enum():
    from app.fcw import FcwStateMachine

    closing = Lead(id=1, range_m=30.0, range_rate_mps=-10.0, ttc_s=2.8, ttc_scale_s=3.0, range_accel_mps2=-3.0)
    assert FcwStateMachine(ego_front_m=2.0)._ttc(closing)[1] is TtcSource.RANGE_ACCEL
    steady = dataclasses.replace(closing, range_accel_mps2=0.0)
    assert FcwStateMachine(ego_front_m=2.0)._ttc(steady)[1] is TtcSource.RANGE
    assert ttc_of(None) == (None, TtcSource.NONE)


def test_the_fcw_takes_the_bumper_distance_from_the_core_and_the_sim_ego_agrees_by_default():
    from app.fcw import FcwStateMachine
    from app.sim.scenario import EgoSpec

    with pytest.raises(TypeError, match="ego_front_m"):
        FcwStateMachine()   # no default of its own: the service passes kinematics.ego_front_m
    assert EgoSpec(speed_kmh=0.0).front_m == core_schema()["kinematics"]["ego_front_m"]["default"]


# ---- fault severities and the overall state ----------------------------------------------------------

def test_hw_status_state_table_is_the_registry_states_in_order():
    signal = headway_database().get_message_by_name("HW_STATUS").get_signal_by_name("STATE")
    assert {int(k): str(v) for k, v in signal.choices.items()} == dict(enumerate(registry.STATES))
    assert set(registry.STATES) >= {f.severity for f in registry.FAULTS}


def test_hw_status_has_a_bit_for_every_registry_fault_and_no_other():
    status = headway_database().get_message_by_name("HW_STATUS")
    in_dbc = {s.name for s in status.signals if s.name.startswith("FAULT_")}
    assert in_dbc == {f"FAULT_{f.name.upper()}" for f in registry.FAULTS}


@pytest.mark.parametrize("started", [False, True])
def test_overall_state_over_every_set_of_faults(started):
    """The rule as docs/can.md and the HW_STATUS comment state it, for all 2^8 fault sets."""
    names = [f.name for f in registry.FAULTS]
    for n in range(len(names) + 1):
        for faults in itertools.combinations(names, n):
            severities = {registry.BY_NAME[f].severity for f in faults}
            expected = ("fault" if "fault" in severities else "starting" if not started
                        else "degraded" if faults else "ok")
            assert registry.overall_state(faults, started) == expected, faults


def test_the_health_monitor_and_a_replay_decide_the_state_alike():
    """The same faults give the same state in the monitor (service) and in the CAN session's own status
    (replay, no monitor): both call registry.overall_state."""
    from app.can import messages as hm
    from app.can import session
    assert session.overall_state is registry.overall_state
    assert not hasattr(hm, "overall_state")
    h = HealthMonitor(HealthParams(camera_timeout_s=0.5))
    h.start(0.0)
    before_frames = h.evaluate(0.1, 0.1, True, 0, can_ok=False, ego_speed_fresh=False)
    assert before_frames.state == registry.overall_state(before_frames.faults, started=False) == "fault"
    h.on_result(0.2, 10.0, 30.0, 5.0)
    report = h.evaluate(0.25, 0.25, True, 0, ego_speed_fresh=False)
    assert report.faults == ["ego_speed_stale"]
    assert report.state == registry.overall_state(report.faults, started=True) == "degraded"


# ---- health parameters -------------------------------------------------------------------------------

def test_health_params_are_the_schema_keys_with_the_schema_defaults():
    fields = {f.name: f for f in dataclasses.fields(HealthParams)}
    assert list(fields) == list(HEALTH_SCHEMA)
    defaults = HealthParams()
    for name, spec in HEALTH_SCHEMA.items():
        assert getattr(defaults, name) == spec["default"], name
        assert fields[name].type == spec["type"], name


# ---- camera defaults ---------------------------------------------------------------------------------

def test_the_sim_camera_defaults_are_the_core_camera_params():
    core = {k: spec["default"] for k, spec in core_schema()["camera"].items()}
    assert set(CAMERA_KEYS) <= set(core)
    assert default_camera() == {k: core[k] for k in CAMERA_KEYS}
    assert Camera.from_dict({}).to_dict() == pytest.approx(default_camera())
    default_camera()["fx"] = 1.0  # a caller's copy: the next caller still gets the core's value
    assert default_camera()["fx"] == core["fx"]


def test_the_sim_camera_module_writes_no_number_of_its_own_for_a_default():
    text = (REPO / "app" / "sim" / "camera.py").read_text()
    assert not re.search(r"^\s*\w+\s*:\s*(int|float)\s*=\s*[\d.]+", text, re.M), "a camera field has a default"
    assert not re.search(r'"(fx|fy|cx|cy|height_m|pitch_deg)"\s*:\s*[\d.]+', text), "a camera default dict"


# ---- shared physical constants -----------------------------------------------------------------------

# Each physical constant that several stages use is one key, in the section named here: the
# hood line in the camera section, lane widths in the road section, the vehicles' size and aspects in the
# vehicle_shape section.
SHARED_KEYS = {
    "hood_frac": "camera",
    "lane_width_m": "road",
    "min_lane_width_m": "road",
    "max_lane_width_m": "road",
    "width_m": "vehicle_shape",
    "max_height_m": "vehicle_shape",
    "aspect": "vehicle_shape",
    "top_min_aspect": "vehicle_shape",
    "max_aspect": "vehicle_shape",
}
# Earlier names of the same constants (the hood line was also called bottom_ignore_frac). proposals'
# max_vehicle_height_m is not one: a looser gate on the network's boxes (detect/proposals/part.hpp).
OLD_NAMES = {"bottom_ignore_frac": "hood_frac", "vehicle_width_m": "width_m", "top_max_height_m": "max_height_m",
             "aspect_ratio": "aspect", "top_max_aspect": "max_aspect"}


def second_definitions(schema: dict) -> list[str]:
    """Every key of `schema` ({section: {key: spec}}) that defines a shared constant outside its section."""
    found = []
    for section, keys in schema.items():
        for key in keys:
            name = OLD_NAMES.get(key, key)
            if name in SHARED_KEYS and section != SHARED_KEYS[name]:
                found.append(f"{section}.{key} (the one definition is {SHARED_KEYS[name]}.{name})")
    return found


def test_each_shared_constant_is_one_key_of_the_core():
    schema = core_schema()
    assert not second_definitions(schema), second_definitions(schema)
    for key, section in SHARED_KEYS.items():
        assert key in schema[section], f"{section}.{key} missing"


@pytest.mark.parametrize("section, key", [("lanes", "hood_frac"), ("parallax", "hood_frac"),
                                          ("shadow", "bottom_ignore_frac"), ("lanes", "lane_width_m"),
                                          ("lead", "lane_width_m"), ("self_calibration", "lane_width_m"),
                                          ("parallax", "vehicle_width_m"), ("lead", "max_lane_width_m"),
                                          ("road", "vehicle_width_m"), ("parallax", "top_max_height_m"),
                                          ("verify", "aspect_ratio"), ("verify", "top_min_aspect"),
                                          ("parallax", "max_aspect")])
def test_the_check_catches_a_second_definition(section, key):
    """Each second definition of a shared key, added back, is found."""
    schema = core_schema()
    schema.setdefault(section, {})[key] = {"default": 0.0, "type": "float"}
    assert [f for f in second_definitions(schema) if f.startswith(f"{section}.{key} ")], (section, key)


def test_the_stages_read_the_shared_constants_from_their_one_section():
    """No stage of the core binds a width, vehicle shape or hood key of its own: `m.add("lane_width_m"` and the
    others appear only where camera.hood_frac, the road section and the vehicle_shape section are defined."""
    csrc = REPO / "csrc"
    homes = {"hood_frac": csrc / "geometry" / "camera.hpp"}
    homes.update({k: csrc / "geometry" / "road_params.hpp" for k, s in SHARED_KEYS.items() if s == "road"})
    homes.update({k: csrc / "geometry" / "vehicle_shape.hpp" for k, s in SHARED_KEYS.items() if s == "vehicle_shape"})
    for path in sorted(csrc.rglob("*.[ch]pp")):
        text = path.read_text()
        for key in list(SHARED_KEYS) + list(OLD_NAMES):
            if re.search(rf'\.add\(\s*"{key}"', text):
                assert path == homes.get(key), f"{path.relative_to(REPO)} binds {key}"


# ---- the source scan ---------------------------------------------------------------------------------

_FAULT_NAMES = "|".join(f.name for f in registry.FAULTS)
_LEVEL_WORDS = r"(?:none|pre_?warning|warning)"
# (what it catches, pattern): each pattern is a level or a severity written as a literal.
PATTERNS = [
    ("an FCW level compared with a number", re.compile(r"\w*level\w*\s*(?:==|!=|<=|>=|<|>)\s*[0-2]\b", re.I)),
    ("a number assigned as an FCW level",
     re.compile(r"\b\w*level\w*\s*(?::\s*[\w.]+\s*)?(?<![=!<>])=(?!=)\s*[0-2]\b(?!\.)", re.I)),
    ("an FCW level defaulted to a number", re.compile(r"[\"'](?:fcw_)?level[\"']\s*[,:]\s*[0-2]\b")),
    ("FCW levels cycled by their count written out", re.compile(r"(?:Level\(|level\w*\s*=).*%\s*3\b", re.I)),
    ("FCW level constants defined as numbers",
     re.compile(r"^\s*(?:NONE|PRE_?WARNING|WARNING)\b(?:\s*,\s*\w+)*\s*=\s*[0-2]\b(?![.x])")),
    ("FCW level names by number", re.compile(rf"[0-2]\s*:\s*[\"']{_LEVEL_WORDS}[\"']")),
    ("an FCW level name written out", re.compile(r"[\"'](?:pre_?warning|warning)[\"']")),
    ("a severity or state name written out", re.compile(r"[\"'](?:fault|degraded|starting)[\"'](?!\s*:)")),
    ("fault names grouped by hand (a severity set)",
     re.compile(rf"[\"'](?:{_FAULT_NAMES})[\"']\s*,\s*[\"'](?:{_FAULT_NAMES})[\"']")),
]
# The one definition of each: the scan does not look there.
DEFINITIONS = {Path("app/contracts/fcw_level.py"), Path("app/contracts/faults.py")}


def _code_lines(text: str) -> list[tuple[int, str]]:
    """(line number, code) with comments removed; docstrings stay (they are strings to the tokenizer
    but hold prose, which the patterns need quotes around to match)."""
    lines = text.splitlines()
    try:
        for tok in tokenize.generate_tokens(io.StringIO(text).readline):
            if tok.type == tokenize.COMMENT:
                row, col = tok.start
                lines[row - 1] = lines[row - 1][:col]
    except (tokenize.TokenError, IndentationError):  # a fragment (the examples below): comments so far
        pass
    return list(enumerate(lines, 1))


def scan(text: str) -> list[tuple[int, str, str]]:
    return [(n, what, line.strip()) for n, line in _code_lines(text) for what, rx in PATTERNS if rx.search(line)]


def _product_sources(root: Path):
    for folder in ("app", "firmware_bridge"):
        for path in sorted((root / folder).rglob("*.py")):
            rel = path.relative_to(root)
            if rel not in DEFINITIONS:
                yield rel, path.read_text()


def test_no_fcw_level_or_severity_is_written_outside_its_one_definition():
    found = [f"{rel}:{n}: {what}: {line}" for rel, text in _product_sources(REPO) for n, what, line in scan(text)]
    assert not found, "written again outside app/contracts/fcw_level.py / app/contracts/faults.py:\n" + "\n".join(found)


# Lines that write a level or a severity again, and lines that do not.
BEFORE = [
    "NONE, PREWARNING, WARNING = 0, 1, 2",
    'LEVEL_NAMES = {NONE: "none", PREWARNING: "prewarning", WARNING: "warning"}',
    'FCW_NAMES = {0: "none", 1: "prewarning", 2: "warning"}',
    'FCW_LEVELS = ("none", "prewarning", "warning")',
    "            if decision.changed and decision.level > 0:",
    '    if r.fcw_level > 0:',
    '        text = "BRAKE!" if r.fcw_level == 2 else "caution"',
    "def fcw_signals(level: int = 0, available: bool = False,",
    "        level = 0",
    '            fcw = {"level": int(getattr(result, "fcw_level", 0) or 0), "ttc_s": ttc}',
    '        f = hm.fcw_signals(get("level", 0), speed_ok)',
    "def fake_result(frame: int, n_objects: int, fcw_level: int = 0, lead: int = 1):",
    "            result = fake_result(k, n_objects, fcw_level=k % 3)",
    "                level = WarningLevel(int((now - start) / 2.0) % 3)",
    "    PRE_WARNING = 1  # MCU: amber LED, no sound",
    'STATES = ("starting", "ok", "degraded", "fault")',
    'STARTING, OK, DEGRADED_STATE, FAULT_STATE = "starting", "ok", "degraded", "fault"',
    'FATAL_FAULTS = frozenset({"camera_lost", "core_stalled", "can_error"})',
    '        return "fault"',
    '    return "degraded" if faults else "ok"',
    '    mcu.set_system_ok(self.report is None or self.report.state != "fault")',
    '"warnings": sum(1 for _, level, _ in s.warnings if level == "warning"),',
]
UNRELATED = [
    "    WARNING = 0x10",
    "        level = logging.WARNING if bad else logging.INFO",
    '                "fault": None if self._state is LinkState.UP else self._fault,',
    "    lane_index=i % 3 - 1, in_path=i % 3 == 1)",
    '            faults.append("camera_lost")',
    "            level = 0.8 * level + 0.6 * e  # AR(1)",
    "    level = r.fcw_level if fcw_level is None else fcw_level",
    'os.environ.setdefault("OPENCV_LOG_LEVEL", "ERROR")',
    "        root.setLevel(level)",
    '    return None, "none"',
]


@pytest.mark.parametrize("line", BEFORE)
def test_the_scan_finds_each_way_the_old_code_wrote_a_level_or_severity(line):
    assert scan(line + "\n"), line


@pytest.mark.parametrize("line", UNRELATED)
def test_the_scan_leaves_unrelated_numbers_and_names_alone(line):
    assert not scan(line + "\n"), scan(line + "\n")
