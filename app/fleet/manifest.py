"""The fleet manifest: which drives to replay, each with its inputs, and the key that says whether a drive's
outputs are already up to date.

A YAML file with a list of entries under ``drives:`` (paths are relative to the manifest's folder)::

    drives:
      - source: recordings/highway.mp4      # a video file, an image folder (give fps) or a scenario
        name: highway                        # optional; default the file, folder or scenario name
        fps: 25                              # an image folder's frame rate (or to override a video's)
        can_in: recordings/highway.log       # optional vehicle CAN log (candump .log, .asc, .blf)
        config: {fcw: {ttc_warning_s: 2.8}}  # optional overrides of the configuration, by section
        truth: recordings/highway.truth.jsonl   # optional boxes: {"frame", "vehicles": [{"id", "box"}]}
      - suite: synthetic                     # every shipped scenario (or a list of scenario names)
      - folder: recordings/                  # every video file and image folder inside it
        fps: 25

A scenario's truth is its own (``truth: scenario`` is implied). ``suite`` and ``folder`` entries take
``fps``, ``can_in`` (folder only), ``config`` and apply them to every drive they name.
"""
from __future__ import annotations

import functools
import hashlib
import json
import re
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Optional

import yaml

from app import config as configuration
from app.recording import is_image_file
from app.replay import is_scenario
from app.sim import list_scenarios
from app.sim.scenario import SCENARIO_DIR

VIDEO_EXTS = {".mp4", ".avi", ".mkv", ".mov", ".webm", ".m4v", ".mpg", ".mpeg"}
DRIVE_KEYS = {"source", "name", "fps", "can_in", "config", "truth"}
SUITE_KEYS = {"suite", "fps", "config"}
FOLDER_KEYS = {"folder", "fps", "can_in", "config"}
NAME_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]*$")
REPO = Path(__file__).resolve().parents[2]


class ManifestError(ValueError):
    """A manifest that cannot be used; the message names the file, the entry and what to fix."""


@dataclass(frozen=True)
class Drive:
    name: str
    kind: str                       # "scenario" | "recording"
    source: str                     # absolute path, or a shipped scenario's name
    fps: Optional[float] = None
    can_in: Optional[str] = None    # absolute path
    truth: Optional[str] = None     # "scenario", or the absolute path of a boxes file
    config: dict = field(default_factory=dict)   # the whole effective configuration (validated)

    def to_dict(self) -> dict:
        return asdict(self)


def load_manifest(path: str, base_config: Optional[str] = None) -> list[Drive]:
    """The drives of a manifest, each with its effective configuration (`base_config` then the entry's
    overrides). Raises ManifestError naming the entry for anything wrong."""
    p = Path(path)
    if not p.is_file():
        raise ManifestError(f"{path}: no such manifest file")
    try:
        data = yaml.safe_load(p.read_text())
    except yaml.YAMLError as exc:
        raise ManifestError(f"{path}: not valid YAML: {exc}".replace("\n", " ")) from None
    if not isinstance(data, dict) or not isinstance(data.get("drives"), list) or not data["drives"]:
        raise ManifestError(f"{path}: expected a mapping with a non-empty list `drives:` (see docs/fleet.md)")
    extra = set(data) - {"drives"}
    if extra:
        raise ManifestError(f"{path}: unknown top-level key(s) {', '.join(sorted(map(str, extra)))}; only `drives:`")
    root = p.resolve().parent
    drives: list[Drive] = []
    for i, entry in enumerate(data["drives"]):
        where = f"{path}: drives[{i}]"
        if not isinstance(entry, dict):
            raise ManifestError(f"{where}: expected a mapping (source:, suite: or folder:)")
        drives += _expand(entry, where, root, base_config)
    seen: dict[str, str] = {}
    for d in drives:
        if d.name in seen:
            raise ManifestError(f"{path}: two drives are named {d.name!r} ({seen[d.name]} and {d.source}); "
                                "give one of them `name:`")
        seen[d.name] = d.source
    return drives


def _expand(entry: dict, where: str, root: Path, base_config: Optional[str]) -> list[Drive]:
    kinds = [k for k in ("source", "suite", "folder") if k in entry]
    if len(kinds) != 1:
        raise ManifestError(f"{where}: give exactly one of source:, suite:, folder:")
    allowed = {"source": DRIVE_KEYS, "suite": SUITE_KEYS, "folder": FOLDER_KEYS}[kinds[0]]
    unknown = set(entry) - allowed
    if unknown:
        raise ManifestError(f"{where}: unknown key(s) {', '.join(sorted(map(str, unknown)))} "
                            f"(known: {', '.join(sorted(allowed))})")
    fps = entry.get("fps")
    if fps is not None and (isinstance(fps, bool) or not isinstance(fps, (int, float)) or not 0 < fps < 1000):
        raise ManifestError(f"{where}: fps must be a number of frames per second in (0, 1000), got {fps!r}")
    overrides = entry.get("config") or {}
    if not isinstance(overrides, dict) or not all(isinstance(v, dict) for v in overrides.values()):
        raise ManifestError(f"{where}: config: expected sections of keys, e.g. {{fcw: {{ttc_warning_s: 2.8}}}}")
    try:
        cfg = configuration.load(base_config, overrides)
    except ValueError as exc:
        raise ManifestError(f"{where}: config: {exc}") from None
    can_in = _path(entry["can_in"], root, where, "can_in") if entry.get("can_in") else None
    common = dict(fps=float(fps) if fps is not None else None, config=cfg)
    if "suite" in entry:
        names = list_scenarios() if entry["suite"] == "synthetic" else entry["suite"]
        if not isinstance(names, list) or not names:
            raise ManifestError(f"{where}: suite: `synthetic` (every shipped scenario) or a list of scenario names")
        for n in names:
            if n not in list_scenarios():
                raise ManifestError(f"{where}: suite: no scenario {n!r} (shipped: {', '.join(list_scenarios())})")
        return [Drive(name=n, kind="scenario", source=n, truth="scenario", **common) for n in names]
    if "folder" in entry:
        folder = _path(entry["folder"], root, where, "folder")
        if not Path(folder).is_dir():
            raise ManifestError(f"{where}: folder: {folder} is not a folder")
        found = sorted(x for x in Path(folder).iterdir()
                       if (x.is_file() and x.suffix.lower() in VIDEO_EXTS)
                       or (x.is_dir() and any(is_image_file(y) for y in x.iterdir())))
        if not found:
            raise ManifestError(f"{where}: folder: {folder} holds no video file and no image folder")
        return [Drive(name=_name(x.stem if x.is_file() else x.name, where), kind="recording", source=str(x),
                      can_in=can_in, **common) for x in found]
    src = entry["source"]
    if not isinstance(src, str) or not src:
        raise ManifestError(f"{where}: source: expected a path or a scenario name")
    local = root / src
    if is_scenario(str(local)) or (not local.exists() and is_scenario(src)):
        source = str(local) if local.exists() else src
        truth = entry.get("truth", "scenario")
        if truth != "scenario":
            raise ManifestError(f"{where}: a scenario's truth is its own; drop truth:")
        return [Drive(name=_name(entry.get("name") or Path(src).stem, where), kind="scenario", source=source,
                      can_in=can_in, truth="scenario", **common)]
    if not local.exists():
        raise ManifestError(f"{where}: source: {local} does not exist and is not a shipped scenario")
    truth = None
    if entry.get("truth") is not None:
        truth = _path(entry["truth"], root, where, "truth")
        if fps is None:
            raise ManifestError(f"{where}: truth boxes are matched to frames by time: give the drive's fps")
    return [Drive(name=_name(entry.get("name") or (local.stem if local.is_file() else local.name), where),
                  kind="recording", source=str(local.resolve()), can_in=can_in, truth=truth, **common)]


def _path(value: Any, root: Path, where: str, key: str) -> str:
    if not isinstance(value, str) or not value:
        raise ManifestError(f"{where}: {key}: expected a path")
    p = (root / value).resolve()
    if not p.exists():
        raise ManifestError(f"{where}: {key}: {p} does not exist")
    return str(p)


def _name(name: str, where: str) -> str:
    if not isinstance(name, str) or not NAME_RE.match(name):
        raise ManifestError(f"{where}: name {name!r}: use letters, digits, '.', '_' and '-' (it names a folder)")
    return name


# ---- the key: inputs + configuration + code version ------------------------------------------------------------
def _hash_file(path: Path, h) -> None:
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)


def _hash_input(path: Optional[str]) -> Optional[str]:
    if path is None:
        return None
    p = Path(path)
    if not p.exists():   # a shipped scenario's name
        p = SCENARIO_DIR / f"{path}.yaml"
    h = hashlib.sha256()
    if p.is_dir():
        for x in sorted(p.iterdir()):
            if is_image_file(x):
                h.update(x.name.encode() + b"\0")
                _hash_file(x, h)
    elif p.exists():
        _hash_file(p, h)
    return h.hexdigest()


@functools.lru_cache(maxsize=1)
def code_version() -> str:
    """A hash of Headway's own code (app/ and csrc/ sources, scenarios, DBC files): any change re-runs
    every drive. Workers compare theirs with the client's."""
    h = hashlib.sha256()
    for top in ("app", "csrc"):
        base = REPO / top
        if not base.is_dir():
            continue
        for x in sorted(base.rglob("*")):
            if x.is_file() and "__pycache__" not in x.parts and x.suffix in (
                    ".py", ".yaml", ".dbc", ".json", ".h", ".hpp", ".cpp", ".cc", ".txt", ".xml"):
                h.update(str(x.relative_to(REPO)).encode() + b"\0")
                _hash_file(x, h)
    return h.hexdigest()[:16]


def drive_key(d: Drive) -> str:
    """Decides whether a drive's outputs are up to date: its inputs' contents, its effective
    configuration and the code version (the drive's name and paths do not enter)."""
    spec = {"kind": d.kind, "fps": d.fps, "config": d.config, "code": code_version(),
            "source": _hash_input(d.source), "can_in": _hash_input(d.can_in),
            "truth": d.truth if d.truth in (None, "scenario") else _hash_input(d.truth)}
    return hashlib.sha256(json.dumps(spec, sort_keys=True, default=str).encode()).hexdigest()[:32]
