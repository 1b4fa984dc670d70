"""The configuration: one YAML file, validated against one registry of keys.

The core's sections (camera, pipeline, lanes, ...) are described by the core itself
(``core_schema()``: every key with type, range, default and the reason for the default, declared next
to the field it sets in C++). The supervisor's own sections are declared below in the same form. A
configuration file gives only the keys it changes; everything else takes the default. Unknown keys,
wrong types and out-of-range values are rejected with a message that names the file and the key.
"""
from __future__ import annotations

import copy
import difflib
import functools
import re
from pathlib import Path
from typing import Any, Optional, Union

import yaml

from app.can.config_schema import CAN_SCHEMA
from app.contracts.config_key import key as _key
from app.contracts.health_config import HEALTH_SCHEMA
from app.core import (core_default_preset, core_detectors, core_moved_keys, core_presets, core_removed_presets,
                      core_schema)
from app.fcw import FCW_SCHEMA
from app.recording import FPS_MAX, FPS_MIN
from app.safe_yaml import YamlLimitError, key_lines, load_yaml, short, short_name, short_path


class ConfigFileError(ValueError):
    """A configuration that cannot be used; the message names the file and the key."""


# The supervisor's sections. Units in the names or first word of each doc.
SUPERVISOR_SCHEMA: dict[str, dict[str, dict]] = {
    "source": {
        "kind": _key("v4l2", "where frames come from in `headway run` / the service: a V4L2 or FireWire camera, "
                             "a video file or image folder (bench), or raw GRAY8 frames written to a FIFO by "
                             "another process", choices="v4l2|firewire|video|folder|fifo"),
        "device": _key("/dev/video0", "V4L2 device path, or its index as a number string such as '0'"),
        "index": _key(0, "FireWire: index of the camera on the bus (when guid is empty)", 0, 63),
        "guid": _key("", "FireWire: the camera's GUID in hex; empty = use index"),
        "fps": _key(30.0, "frames/s asked of the camera; for a folder, the rate its images were taken at",
                    FPS_MIN, FPS_MAX),
        "pixel_format": _key("", "V4L2 FOURCC such as YUYV, MJPG or GREY; empty = the driver's default"),
        "path": _key("", "video file, image folder or FIFO for kind video / folder / fifo"),
        "wait_for_device": _key(True, "start even if the camera is not there yet and keep reconnecting "
                                      "(the service must come up with the car; the camera fault says why)"),
    },
    "fcw": FCW_SCHEMA,
    **CAN_SCHEMA,
    "health": HEALTH_SCHEMA,
    "mcu": {
        "port": _key("", "serial device of the cabin microcontroller (e.g. /dev/ttyACM0); empty = no MCU"),
        "baudrate": _key(115200, "bit/s; serial speed, as in docs/firmware-protocol.md", 1200, 4000000),
        "heartbeat_s": _key(0.1, "s; heartbeat period each way (docs/firmware-protocol.md)", 0.01, 10.0),
        "silent_after_s": _key(0.5, "s; the MCU not heard for this long is the mcu_silent fault (5 heartbeats)",
                               0.05, 60.0),
    },
    "service": {
        "status_file": _key("/run/headway/status.json", "path; the status `headway status` reads, rewritten at "
                                                        "status_rate_hz"),
        "status_rate_hz": _key(2.0, "Hz; how often the status file and the journal summary are refreshed",
                               0.1, 50.0),
        "tracks_file": _key("", "path; also record the tracks of every frame here (.jsonl); empty = none"),
    },
}


def _fcw_order(cfg: dict) -> Optional[str]:
    f = cfg["fcw"]
    if f["ttc_warning_s"] >= f["ttc_prewarning_s"]:
        return (f"fcw.ttc_warning_s ({f['ttc_warning_s']:g}) must be below fcw.ttc_prewarning_s "
                f"({f['ttc_prewarning_s']:g}), or the pre-warning is never given: lower ttc_warning_s or raise "
                f"ttc_prewarning_s")
    return None


def _mcu_timing(cfg: dict) -> Optional[str]:
    m = cfg["mcu"]
    if m["silent_after_s"] <= m["heartbeat_s"]:
        return (f"mcu.silent_after_s ({m['silent_after_s']:g}) must be above mcu.heartbeat_s ({m['heartbeat_s']:g}), "
                f"or every heartbeat is late: make silent_after_s several heartbeats")
    return None


def _source_path(cfg: dict) -> Optional[str]:
    src = cfg["source"]
    if src["kind"] in ("video", "folder", "fifo") and not src["path"]:
        return f"source.path: required for source.kind {src['kind']}"
    return None


# Rules between keys, checked after every key is valid alone; each says what to change.
def _pitch_unknown(overrides: dict) -> bool:
    """A camera described without its pitch (e.g. only what a calibration file holds: intrinsics and height) is
    calibrated from scratch: the configured pitch is a guess then, and holding the estimate near it fails."""
    camera, calib = overrides.get("camera"), overrides.get("self_calibration")
    return (isinstance(camera, dict) and bool(camera) and "pitch_deg" not in camera
            and not (isinstance(calib, dict) and "from_scratch" in calib))


CROSS_FIELD_RULES = (_fcw_order, _mcu_timing, _source_path)


@functools.lru_cache(maxsize=1)
def default_preset() -> str:
    """Headway's default composition, as the core's preset table names it. A configuration handed to the core
    without a preset runs the core's own, which needs no model file; a configuration file runs this one, with the
    shipped models' paths filled in here (core_sections)."""
    return core_default_preset()


def schema() -> dict[str, dict[str, dict]]:
    """Every key of the configuration: {section: {key: {default, type, min, max, choices, doc}}}."""
    s = core_schema()
    s["pipeline"]["preset"]["default"] = default_preset()
    s.update(copy.deepcopy(SUPERVISOR_SCHEMA))
    return s


@functools.lru_cache(maxsize=1)
def _moved_keys() -> dict[str, str]:
    """{"old_section.key": "new_section.key"} for the keys that moved, as the core lists them."""
    return core_moved_keys()


@functools.lru_cache(maxsize=1)
def _registry() -> dict[str, dict[str, dict]]:
    """schema() built once (the core's part is compiled in): read only, for validation."""
    return schema()


@functools.lru_cache(maxsize=1)
def presets() -> dict[str, dict]:
    """The core's named compositions with the keys each sets (app.core.core_presets); read only."""
    return core_presets()


def detectors_of(cfg: dict) -> list[str]:
    """The detector parts a configuration runs: its pipeline.detectors, else its preset's."""
    named = cfg["pipeline"].get("detectors") or presets().get(cfg["pipeline"]["preset"], {}).get("detectors") or []
    return [d.strip() for d in (named.split(",") if isinstance(named, str) else named)]


def works_on_one_image(detectors: list[str]) -> bool:
    """Whether there are detector parts and all work on one image (the core's registrations: parallax needs two
    frames)."""
    known = core_detectors()
    return bool(detectors) and all(known[d]["single_image"] for d in detectors)


def single_image_presets() -> list[str]:
    """The presets whose detection stage runs on one image (`headway detect`'s choices)."""
    return [name for name, p in presets().items() if works_on_one_image(p["detectors"])]


def defaults(preset: Optional[str] = None) -> dict[str, dict[str, Any]]:
    """Every key's default; with `preset`, that preset's own keys over them (None: the default preset's)."""
    cfg = {sec: {k: d["default"] for k, d in keys.items()} for sec, keys in _registry().items()}
    name = cfg["pipeline"]["preset"] if preset is None else preset
    for sec, keys in presets().get(name, {}).get("keys", {}).items():
        for key, value in keys.items():
            cfg[sec][key] = _check_value(f"preset {name}: {sec}.{key}", value, _registry()[sec][key])
    if name in presets():
        cfg["pipeline"]["preset"] = name
    return cfg


def _check_value(path: str, value: Any, spec: dict) -> Any:
    t = spec["type"]
    if spec.get("list"):  # names, as a YAML list or one string separated by commas; kept as that string
        names = value.split(",") if isinstance(value, str) else value
        if not isinstance(names, list) or not all(isinstance(v, str) for v in names):
            raise ConfigFileError(f"{path}: expected a list of names, got {short(value)}")
        names = [v.strip() for v in names if v.strip()]
        for v in names:
            if "choices" in spec and v not in spec["choices"].split("|"):
                raise ConfigFileError(f"{path}: {short(v)} is not one of {_choices(spec)}")
        return ",".join(names)
    if t == "bool":
        if not isinstance(value, bool):
            raise ConfigFileError(f"{path}: expected true or false, got {short(value)}")
        return value
    if t == "int":
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigFileError(f"{path}: expected an integer, got {short(value)}")
    elif t == "float":
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigFileError(f"{path}: expected a number, got {short(value)}")
        value = float(value)
    elif t == "str":
        if isinstance(value, int) and not isinstance(value, bool) and path.endswith("source.device"):
            value = str(value)  # `device: 0` means /dev/video0 by index
        if not isinstance(value, str):
            raise ConfigFileError(f"{path}: expected a string, got {short(value)}")
        if "choices" in spec and value not in spec["choices"].split("|"):
            raise ConfigFileError(f"{path}: {short(value)} is not one of {spec['choices'].replace('|', ', ')}")
        return value
    if "min" in spec and not (spec["min"] <= value <= spec["max"]):
        raise ConfigFileError(f"{path}: {short(value)} is outside [{spec['min']}, {spec['max']}]")
    return value


def _known(name: Any, options) -> str:
    """The known names when they are few, else the closest ones: an error line stays short."""
    known = ", ".join(sorted(options))
    if len(known) <= 160:
        return f"known: {known}"
    close = difflib.get_close_matches(str(name)[:60], sorted(options), n=3)
    return (f"did you mean {' or '.join(close)}? " if close else "") + "`headway config default` lists every key"


def validate(overrides: dict, origin: str = "configuration") -> dict[str, dict[str, Any]]:
    """Defaults updated with `overrides` (a partial configuration), every key checked."""
    if overrides is None:
        overrides = {}
    if not isinstance(overrides, dict):
        raise ConfigFileError(f"{origin}: expected a mapping of sections (camera:, source:, ...)")
    sch = _registry()
    # the chosen preset's own keys are its defaults; the configuration's values override them key by key
    chosen = overrides.get("pipeline").get("preset") if isinstance(overrides.get("pipeline"), dict) else None
    cfg = defaults(chosen if isinstance(chosen, str) else None)
    for sec, values in overrides.items():
        if sec not in sch:
            raise ConfigFileError(f"{origin}: {short_name(sec)}: unknown section ({_known(sec, sch)})")
        if values is None:
            continue
        if not isinstance(values, dict):
            raise ConfigFileError(f"{origin}: {sec}: expected a mapping of keys to values")
        for key, value in values.items():
            if sec == "pipeline" and key == "preset" and isinstance(value, str) and value in core_removed_presets():
                raise ConfigFileError(f"{origin}: pipeline.preset: preset '{value}' was removed; use "
                                      f"{core_removed_presets()[value]}")
            moved_to = _moved_keys().get(f"{sec}.{key}")
            if moved_to:
                raise ConfigFileError(f"{origin}: {sec}.{key}: moved to {moved_to} (one definition for every stage); "
                                      f"set {moved_to} instead")
            if key not in sch[sec]:
                raise ConfigFileError(f"{origin}: {sec}.{short_name(key)}: unknown key ({_known(key, sch[sec])})")
            cfg[sec][key] = _check_value(f"{origin}: {sec}.{key}", value, sch[sec][key])
    if _pitch_unknown(overrides):
        cfg["self_calibration"]["from_scratch"] = True
    for rule in CROSS_FIELD_RULES:
        problem = rule(cfg)
        if problem:
            raise ConfigFileError(f"{origin}: {problem}")
    return cfg


def parse(text: str, origin: str = "configuration") -> dict:
    """The sections of a configuration text (not yet validated); ConfigFileError if it is not one."""
    try:
        data = load_yaml(text) or {}
    except YamlLimitError as exc:
        raise ConfigFileError(f"{origin}: {exc}") from None
    if not isinstance(data, dict):
        raise ConfigFileError(f"{origin}: expected a mapping of sections (camera:, source:, ...)")
    return data


def load(path: Optional[Union[str, Path]] = None, overrides: Optional[dict] = None) -> dict[str, dict[str, Any]]:
    """Loads a configuration file (None = defaults), then applies `overrides` (same shape)."""
    data: dict = {}
    origin = "configuration"
    if path is not None:
        origin = str(path)
        p = Path(path)
        if not p.is_file():
            raise ConfigFileError(f"{origin}: {'is a folder, not a configuration file' if p.is_dir() else 'no such file'}")
        try:
            text = p.read_text(errors="replace")
        except OSError as exc:
            raise ConfigFileError(f"{origin}: cannot be read ({exc.strerror or exc})") from None
        data = parse(text, origin)
    merged = copy.deepcopy(data)
    for sec, values in (overrides or {}).items():
        if not isinstance(merged.get(sec) or {}, dict):
            raise ConfigFileError(f"{origin}: {sec}: expected a mapping of keys to values")
        merged[sec] = {**(merged.get(sec) or {}), **values}
    return validate(merged, origin)


MAX_ERROR_CHARS = 170   # an error line's text after "headway: configuration error: ": 200 in all
_FOLDERS = re.compile(r"(?<![\w.])/(?:[^\s/:'\"()]+/)+")   # the folders of an absolute path in a message
_KEY_PATH = re.compile(r"(?<![\w./-])([A-Za-z_]\w*\.[A-Za-z_]\w*)")


def error_line(message: object, path: Optional[Union[str, Path]] = None, limit: int = MAX_ERROR_CHARS) -> str:
    """A configuration error as one line of at most ``limit`` characters: the file, the line of the first key the
    message names (as written in the file), the message with its whitespace and newlines folded."""
    text = " ".join(str(message).split())
    where = ""
    if path is not None:
        name = str(path)
        text = text[len(name) + 2:] if text.startswith(name + ": ") else text
        try:
            lines = key_lines(Path(path).read_text(errors="replace")) if Path(path).is_file() else {}
        except (OSError, ValueError):
            lines = {}
        named = next((m.group(1) for m in _KEY_PATH.finditer(text) if m.group(1) in lines), None)
        if named is None:   # an unknown or misplaced section: its own line (its name may be quoted cut short)
            first = text.split(":", 1)[0]
            named = next((k for k in lines if "." not in k and (text.startswith(f"{k}: ") or first.endswith("...")
                                                                  and k.startswith(first[:-3]))), None)
        line = f"line {lines[named]}: " if named and not text.startswith("line ") else ""
        where = f"{short_path(name)}: {line}"
        if len(where) + len(text) > limit:   # too long: the file by its name (the user knows which one was checked)
            where = f"{Path(name).name}: {line}"
        if len(where) + len(text) > limit:   # still: the paths in the message by their names too
            text = _FOLDERS.sub("", text)
    room = max(40, limit - len(where))
    return where + (text if len(text) <= room else text[:room - 3] + "...")


# The Haar cascade trained by `headway train cascade` (recipe and log in docs/detection.md).
SHIPPED_CASCADE = Path(__file__).resolve().parent / "models" / "vehicle_cascade.xml"
# Its second stage, trained by `headway train verifier` on the cascade's detections (docs/detection.md).
# A small CNN on the box's crop (ONNX, run by cv::dnn), better than the HOG network on the TuSimple validation
# split (docs/detection.md); the HOG network stays shipped as the alternative (cascade.verifier: its path).
SHIPPED_VERIFIER = Path(__file__).resolve().parent / "models" / "vehicle_verifier.onnx"
SHIPPED_HOG_VERIFIER = Path(__file__).resolve().parent / "models" / "vehicle_verifier.yml.gz"
# The learned first stage (detector part proposals), trained by `headway train proposals` (docs/detection.md).
SHIPPED_PROPOSALS = Path(__file__).resolve().parent / "models" / "vehicle_proposals.onnx"


def core_sections(cfg: dict) -> dict:
    """The part of a validated configuration that the C++ core takes (cascade.model and verifier, proposals.model
    and verifier empty: the shipped ones)."""
    core = {sec: dict(values) for sec, values in cfg.items() if sec not in SUPERVISOR_SCHEMA}
    if "cascade" in core and not core["cascade"].get("model"):
        core["cascade"]["model"] = str(SHIPPED_CASCADE)
    if "cascade" in core and not core["cascade"].get("verifier"):
        core["cascade"]["verifier"] = str(SHIPPED_VERIFIER)
    for key, shipped in (("model", SHIPPED_PROPOSALS), ("verifier", SHIPPED_VERIFIER)):
        if "proposals" in core and not core["proposals"].get(key):
            core["proposals"][key] = str(shipped)
    return core


def source_spec(cfg: dict) -> dict:
    """The core's source description for the configured live or recorded source."""
    src, cam = cfg["source"], cfg["camera"]
    kind = src["kind"]
    if kind == "fifo":
        raise ConfigFileError("source.kind fifo: frames come through the service's FIFO reader, not a core source")
    if kind in ("video", "folder"):
        if not src["path"]:
            raise ConfigFileError(f"source.path: required for source.kind {kind}")
        spec = {"kind": kind, "path": src["path"]}
        if kind == "folder":
            spec["fps"] = src["fps"]
        return spec
    spec = {"kind": kind, "width": cam["width"], "height": cam["height"], "fps": src["fps"],
            "wait_for_device": src["wait_for_device"]}
    if kind == "v4l2":
        spec["device"] = int(src["device"]) if src["device"].isdigit() else src["device"]
        if src["pixel_format"]:
            spec["pixel_format"] = src["pixel_format"]
    else:
        spec["index"] = src["index"]
        if src["guid"]:
            spec["guid"] = src["guid"]
    return spec


def scaled_camera(camera: dict, width: int, height: int) -> dict:
    """The camera keys for frames of another size than configured, same field of view: intrinsics scale
    with the image (used when a recording's size differs from a camera that was not calibrated for it)."""
    sx, sy = width / camera["width"], height / camera["height"]
    cam = dict(camera)
    cam.update(width=width, height=height, fx=camera["fx"] * sx, fy=camera["fy"] * sy,
               cx=camera["cx"] * sx, cy=camera["cy"] * sy)
    return cam


def _choices(spec: dict) -> str:
    """A key's allowed values for people (an empty name, "keep the preset's", is left out)."""
    return ", ".join(c for c in spec.get("choices", "").split("|") if c)


def frame_size_problem(width: int, height: int) -> Optional[str]:
    """Why frames of this size cannot be processed (outside the camera's width/height range), or None."""
    cam = _registry()["camera"]  # built once: detect and replay ask for every image
    lo_w, hi_w, lo_h, hi_h = cam["width"]["min"], cam["width"]["max"], cam["height"]["min"], cam["height"]["max"]
    if lo_w <= width <= hi_w and lo_h <= height <= hi_h:
        return None
    return f"{width}x{height} px: frames must be {lo_w}x{lo_h} to {hi_w}x{hi_h} px"


def default_yaml() -> str:
    """The documented default configuration, every key with its reason (for `headway config default`)."""
    lines = ["# Headway configuration. Give only the keys you change; the rest are these defaults.", ""]
    # keys the default preset sets are shown commented out: written out, they would stay set under another preset
    sections = schema()
    preset = sections["pipeline"]["preset"]["default"]
    by_preset = presets().get(preset, {}).get("keys", {})
    as_text = lambda v: yaml.safe_dump(v, default_flow_style=True).strip().removesuffix("...").strip()  # noqa: E731
    for sec, keys in sections.items():
        lines.append(f"{sec}:")
        for key, spec in keys.items():
            rng = f" [{spec['min']}, {spec['max']}]" if "min" in spec else ""
            ch = f" one of {_choices(spec)}" if "choices" in spec else ""
            lines.append(f"  # {spec['doc']}{rng}{ch}")
            if key in by_preset.get(sec, {}):
                lines.append(f"  # {key}: {as_text(by_preset[sec][key])}   (set by the preset {preset}; without it "
                             f"{as_text(spec['default'])})")
            else:
                lines.append(f"  {key}: {as_text(spec['default'])}")
        lines.append("")
    return "\n".join(lines)


def _preset_keys_text(keys: dict) -> str:
    return ", ".join(f"`{sec}.{k}: {v}`" for sec, kv in keys.items() for k, v in kv.items()) or "-"


def _presets_markdown() -> list[str]:
    """The presets (`pipeline.preset`): the parts each composes and the keys it sets."""
    out = ["## Presets", "",
           "`pipeline.preset` names a composition of parts (docs/ARCHITECTURE.md); `pipeline.detectors` and "
           "`pipeline.tracker` replace its parts when set. A preset may also set keys: those are its defaults, and a "
           "key the configuration file sets itself wins over them.", "",
           "| preset | detectors | tracker | keys it sets |", "| --- | --- | --- | --- |"]
    for name, p in presets().items():
        out.append(f"| `{name}` | {', '.join(p['detectors']) or '-'} | {p['tracker'] or '-'} | "
                   f"{_preset_keys_text(p['keys'])} |")
    return out + [""]


def markdown() -> str:
    """Every key as a table per section (docs/CONFIG.md is this text; a test keeps it current)."""
    out = ["# Configuration reference", "",
           "Generated by `headway config doc > docs/CONFIG.md` from the registry (the core's parameter structs "
           "and the supervisor's sections); a configuration file gives only the keys it changes.", ""]
    out += _presets_markdown()
    for sec, keys in schema().items():
        out += [f"## `{sec}`", "", "| key | default | range | meaning |", "| --- | --- | --- | --- |"]
        for key, spec in keys.items():
            rng = f"{spec['min']} .. {spec['max']}" if "min" in spec else _choices(spec)
            default = spec["default"] if spec["default"] != "" else '""'
            out.append(f"| `{key}` | `{default}` | {rng} | {spec['doc'].replace('|', '/')} |")
        out.append("")
    return "\n".join(out)
