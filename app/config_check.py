"""What `headway config check` and the service check before anything starts: every mistake that would
stop the service, or leave it running without doing its job, found while the car is still parked.

``validate`` (app.config) checks each key alone and the rules between keys; this opens what the service
opens, with the same code and in the same order (``Service.run``): the core builds its pipeline (every
model file loads), the vehicle inputs are read from their DBC files, the output files (tracks, CAN log,
status) can be written where they are named and name no input, the CAN interface is created (`config
check`; the service opens it itself next), and the source opens with frames of the size `camera` says.
Each problem is one line naming the key.
"""
from __future__ import annotations

import os
import stat
from pathlib import Path
from typing import Callable, Optional

from app import config as configuration
from app.can import CanBusError, VehicleInputError
from app.can.bus import bus_from_config
from app.can.log_replay import CanLogError, channel_map
from app.can.vehicle_input import specs_from_config
from app.core import CoreError, Pipeline
from app.output_files import OutputPathError, check_outputs
from app.recording import folder_images, is_image_file
from app.safe_yaml import short_path as _short_path

QUOTE_PATH_CHARS = 40  # a path in a problem line is quoted by its last this many characters: the line stays short


def short_path(path: object) -> str:
    return _short_path(path, QUOTE_PATH_CHARS)


NAME_MAX = 255     # bytes of one file name (Linux)
PATH_MAX = 4095    # bytes of a whole path, without its NUL
SOURCE_WAIT_S = 3.0  # s; a camera that opens gets this long to deliver its first frame for the size check
MODEL_KEYS = ("model", "verifier")  # the cascade section's model files
NOT_A_FILE = ("", "off")  # model key values that name no file


def path_problem(path: str) -> Optional[str]:
    """Why ``path`` cannot name a file on this system (a NUL byte, a name or path too long), or None."""
    if "\0" in path:
        return "contains a NUL byte"
    raw = os.fsencode(path)
    if len(raw) > PATH_MAX:
        return f"is {len(raw)} bytes long; a path has at most {PATH_MAX}"
    longest = max((len(part) for part in raw.split(b"/")), default=0)
    if longest > NAME_MAX:
        return f"has a name of {longest} bytes; a file name has at most {NAME_MAX}"
    return None


def input_problem(path: str, what: str = "file") -> Optional[str]:
    """Why ``path`` is not a readable regular file (no such file, a folder, unreadable, not a path), or None."""
    bad = path_problem(path)
    if bad:
        return bad
    p = Path(path)
    if p.is_dir():
        return f"is a folder, not a {what}"
    if not p.exists():
        return f"no such {what}"
    if not os.access(p, os.R_OK):
        return "cannot be read (permission denied)"
    return None


def output_problem(path: str, make_folders: bool) -> Optional[str]:
    """Why a file cannot be written at ``path``, or None. ``make_folders``: the writer creates missing folders
    (then the nearest existing one must be writable), else the file's own folder must exist."""
    bad = path_problem(path)
    if bad:
        return bad
    p = Path(os.path.abspath(path))
    if p.is_dir():
        return "is a folder; give a file's path"
    if p.exists():
        return None if os.access(p, os.W_OK) else "exists and cannot be written (permission denied)"
    folder = p.parent
    if not make_folders and not folder.exists():
        return f"its folder {short_path(folder)} does not exist: create it"
    while not folder.exists():
        folder = folder.parent
    if not folder.is_dir():
        return f"{short_path(folder)} is a file, not a folder"
    if not os.access(folder, os.W_OK | os.X_OK):
        return f"the folder {short_path(folder)} cannot be written (permission denied)"
    return None


def _core(cfg: dict) -> Optional[str]:
    """The pipeline the service builds first: every section and model file as the core reads them."""
    cascade = cfg.get("cascade", {})
    for key in MODEL_KEYS:
        value = cascade.get(key, "")
        if value not in NOT_A_FILE:
            bad = input_problem(value, "model file")
            if bad:
                return f"cascade.{key}: {short_path(value)}: {bad}"
    try:
        Pipeline(configuration.core_sections(cfg)).close()
    except CoreError as exc:
        return str(exc)
    return None


def _vehicle(cfg: dict) -> Optional[str]:
    veh = cfg["vehicle"]
    for key, value in veh.items():
        if (key == "dbc" or key.endswith("_dbc")) and value:
            bad = input_problem(value, "DBC file")
            if bad:
                return f"vehicle.{key}: {short_path(value)}: {bad}"
    try:
        channel_map(veh["log_channels"])
    except CanLogError as exc:
        return str(exc)
    databases: dict = {}
    try:
        specs = specs_from_config(veh, databases)
    except VehicleInputError as exc:
        return str(exc)
    for spec in specs:
        msg = databases[spec.dbc].get_message_by_name(spec.message)
        try:
            msg.decode(bytes(msg.length), decode_choices=False)
        except Exception as exc:  # cantools raises several kinds for a signal it cannot place or read
            return (f"vehicle.{spec.name}_message: {spec.message} in {Path(spec.dbc).name} cannot be decoded "
                    f"({type(exc).__name__}: {str(exc)[:80]}): no frame of it would ever be used; check its "
                    f"signals' length and start bit")
    return None


def _inputs(cfg: dict) -> dict[str, str]:
    """The files the service reads, by key: an output must name none of them."""
    out = {"source.path": cfg["source"]["path"] if cfg["source"]["kind"] in ("video", "folder", "fifo") else ""}
    out.update({f"vehicle.{k}": v for k, v in cfg["vehicle"].items() if k == "dbc" or k.endswith("_dbc")})
    out.update({f"cascade.{k}": cfg.get("cascade", {}).get(k, "") for k in MODEL_KEYS})
    return {k: v for k, v in out.items() if v and v not in NOT_A_FILE and not path_problem(v)}


def _files(cfg: dict) -> Optional[str]:
    out_log = cfg["can"]["output_log"]
    if out_log:
        if Path(out_log).suffix.lower() not in (".log", ".asc", ".blf"):
            return f"can.output_log: {short_path(out_log)}: unknown CAN log format: use .log (candump), .asc or .blf"
        bad = output_problem(out_log, make_folders=True)   # the log writer creates its folders
        if bad:
            return f"can.output_log: {short_path(out_log)}: {bad}"
    tracks = cfg["service"]["tracks_file"]
    if tracks:
        bad = output_problem(tracks, make_folders=False)   # opened for appending as it is
        if bad:
            return f"service.tracks_file: {short_path(tracks)}: {bad}"
    status = cfg["service"]["status_file"]
    bad = path_problem(status)   # its folder is made at the first write, and a failed write is only a warning
    if bad:
        return f"service.status_file: {short_path(status)}: {bad}"
    try:
        check_outputs({"can.output_log": out_log, "service.tracks_file": tracks, "service.status_file": status},
                      _inputs(cfg))
    except OutputPathError as exc:
        return str(exc)
    return None


def _bus(cfg: dict) -> Optional[str]:
    if not cfg["can"]["enabled"]:
        return None
    try:
        bus_from_config(cfg["can"]).shutdown()
    except CanBusError as exc:
        return f"can.interface/can.channel: {exc}"
    return None


def _device_absent(src: dict) -> bool:
    if src["kind"] == "v4l2":
        dev = src["device"]
        return not Path(f"/dev/video{dev}" if dev.isdigit() else dev).exists()
    return not any(Path("/dev").glob("fw*"))


def _source_path(cfg: dict) -> Optional[str]:
    """The source's path is what its kind needs."""
    src = cfg["source"]
    kind, path = src["kind"], src["path"]
    if kind in ("video", "folder", "fifo"):
        bad = path_problem(path)
        if bad:
            return f"source.path: {short_path(path)}: {bad}"
    p = Path(path)
    if kind == "video":
        bad = input_problem(path, "video file")
        if bad:
            return f"source.path: {short_path(path)}: {bad}{': use kind folder' if p.is_dir() else ''}"
        if is_image_file(p):
            return f"source.path: {short_path(path)}: is a still image; play a folder of images (kind: folder)"
    elif kind == "folder":
        if not p.is_dir():
            return f"source.path: {short_path(path)}: {'is a file: use kind video' if p.exists() else 'no such folder'}"
        if not folder_images(p):
            return f"source.path: {short_path(path)}: the folder contains no images"
    elif kind == "fifo":
        if p.exists() and not stat.S_ISFIFO(p.stat().st_mode):
            return (f"source.path: {short_path(path)}: exists and is not a FIFO (its frames would be read again "
                    f"and again at full speed): remove it, or give the path of a named pipe (mkfifo)")
        if not p.exists():
            bad = output_problem(path, make_folders=False)
            if bad:
                return f"source.path: {short_path(path)}: the FIFO cannot be made there: {bad}"
    return None


def _source_opens(cfg: dict, skip_absent_devices: bool = False) -> Optional[str]:
    """The source opens as the service opens it, and its frames have the size `camera` gives."""
    src, cam = cfg["source"], cfg["camera"]
    kind = src["kind"]
    key = "source.path" if kind in ("video", "folder", "fifo") else "source.device"
    if kind == "fifo":   # frames of camera.width x camera.height bytes by construction
        return None
    if kind in ("v4l2", "firewire") and _device_absent(src):
        # the service waits for a camera that is not there yet (wait_for_device), else it stops at once
        if skip_absent_devices or src["wait_for_device"]:
            return None
        return (f"source.device: {src['device'] if kind == 'v4l2' else 'FireWire camera'}: not on this machine and "
                f"source.wait_for_device is false; plug it in, or check elsewhere with --skip-absent-devices")
    spec = configuration.source_spec(cfg)
    spec["wait_for_device"] = False
    try:
        with Pipeline(configuration.core_sections(cfg)) as pipe:
            pipe.start(spec)
            try:
                first = pipe.pop(timeout_s=SOURCE_WAIT_S)
            finally:
                pipe.stop()
    except CoreError as exc:
        return f"{key}: {exc}"
    if first is not None and (first.width, first.height) != (cam["width"], cam["height"]):
        return (f"{key}: frames are {first.width}x{first.height} but camera.width/camera.height say "
                f"{cam['width']}x{cam['height']}")
    return None


# In the order the service opens them (Service.run): pipeline, vehicle inputs, output files, bus, source.
CHECKS: tuple[Callable[[dict], Optional[str]], ...] = (_core, _vehicle, _files, _source_path)


def problems(cfg: dict, open_bus: bool = True, open_source: bool = True, skip_absent_devices: bool = False) -> list[str]:
    """Every problem found in a validated configuration, one line each; empty when the service can start.
    ``open_bus``: also create (and close) the CAN interface; ``open_source``: also open the source and read a
    frame, as the service will; ``skip_absent_devices``: a camera that is not on this machine is not checked."""
    checks = CHECKS + ((_bus,) if open_bus else ())
    found = [p for p in (check(cfg) for check in checks) if p]
    if open_source and not found:   # opening a source takes a moment: only when all else is right
        bad = _source_opens(cfg, skip_absent_devices)
        if bad:
            found.append(bad)
    return found
