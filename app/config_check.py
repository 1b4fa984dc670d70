"""What `headway config check` and the service check before anything starts: every mistake that would
stop the service, or leave it running without doing its job, found while the car is still parked.

``validate`` (app.config) checks each key alone and the rules between keys; this checks the world the
keys point to: the core accepts its sections, the source path is what its kind needs, the DBC files
exist and every configured vehicle input can be decoded from them, the log and tracks files can be
written, and (for `config check`) the CAN interface opens. Each problem is one line naming the key.
"""
from __future__ import annotations

import os
import stat
from pathlib import Path
from typing import Callable, Optional

from app import config as configuration


def _writable_place(path: str) -> bool:
    """True if a file can be created at ``path`` (its nearest existing folder is writable)."""
    p = Path(path).resolve().parent
    while not p.exists():
        p = p.parent
    return p.is_dir() and os.access(p, os.W_OK | os.X_OK)


def _core(cfg: dict) -> Optional[str]:
    from app.core import ConfigError, Pipeline

    try:
        Pipeline(configuration.core_sections(cfg)).close()
    except ConfigError as exc:
        return str(exc)
    return None


def _source(cfg: dict) -> Optional[str]:
    from app.recording import folder_images, is_image_file

    kind, path = cfg["source"]["kind"], cfg["source"]["path"]
    p = Path(path)
    if kind == "video":
        if not p.is_file():
            return f"source.path: {path}: {'is a folder: use kind folder' if p.is_dir() else 'no such file'}"
        if is_image_file(p):
            return f"source.path: {path}: is a still image; play a folder of images (kind: folder)"
    elif kind == "folder":
        if not p.is_dir():
            return f"source.path: {path}: {'is a file: use kind video' if p.exists() else 'no such folder'}"
        if not folder_images(p):
            return f"source.path: {path}: the folder contains no images"
    elif kind == "fifo":
        if p.exists() and not stat.S_ISFIFO(p.stat().st_mode):
            return (f"source.path: {path}: exists and is not a FIFO (its frames would be read again and again "
                    f"at full speed): remove it, or give the path of a named pipe (mkfifo)")
        if not p.exists() and not _writable_place(path):
            return f"source.path: {path}: the FIFO cannot be created there (no such folder, or not writable)"
    return None


def _vehicle(cfg: dict) -> Optional[str]:
    from app.can import VehicleInputError
    from app.can.log_replay import CanLogError, channel_map
    from app.can.vehicle_input import specs_from_config

    veh = cfg["vehicle"]
    for key, value in veh.items():
        if key == "dbc" or key.endswith("_dbc"):
            if value and not Path(value).is_file():
                return f"vehicle.{key}: {value}: no such DBC file"
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


def _files(cfg: dict) -> Optional[str]:
    out_log = cfg["can"]["output_log"]
    if out_log:
        if Path(out_log).suffix.lower() not in (".log", ".asc", ".blf"):
            return f"can.output_log: {out_log}: unknown CAN log format: use .log (candump), .asc or .blf"
        if not _writable_place(out_log):
            return f"can.output_log: {out_log}: cannot be written (no such folder, or not writable)"
    tracks = cfg["service"]["tracks_file"]
    if tracks and not _writable_place(tracks):
        return f"service.tracks_file: {tracks}: cannot be written (no such folder, or not writable)"
    return None


def _bus(cfg: dict) -> Optional[str]:
    from app.can import CanBusError
    from app.can.bus import bus_from_config

    if not cfg["can"]["enabled"]:
        return None
    try:
        bus_from_config(cfg["can"]).shutdown()
    except CanBusError as exc:
        return f"can.interface/can.channel: {exc}"
    return None


CHECKS: tuple[Callable[[dict], Optional[str]], ...] = (_core, _source, _vehicle, _files)


def problems(cfg: dict, open_bus: bool = True) -> list[str]:
    """Every problem found in a validated configuration, one line each; empty when the service can start.
    ``open_bus``: also open (and close) the CAN interface, as the service will."""
    checks = CHECKS + ((_bus,) if open_bus else ())
    return [p for p in (check(cfg) for check in checks) if p]
