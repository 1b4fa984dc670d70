"""Scenario files: read, validate strictly, resolve defaults.

A scenario is a YAML mapping (every key is documented in docs/sim.md). Validation is strict
because a typo in a test scenario silently changes what a test proves: an unknown key, a
wrong type or an out-of-range value raises :class:`ScenarioError` naming the file and the
key path (``vehicles[2].speed_kmh``), never a traceback from deep inside the renderer.
Per-vehicle sizes and shades that the file leaves open are drawn from the scenario seed and
the vehicle id, so the resolved scenario (``scenario_to_dict``) is explicit and reloadable.
"""
from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np
import yaml

from .camera import CAMERA_KEYS

SCENARIO_DIR = Path(__file__).resolve().parent / "scenarios"
# Scenarios on curves and hills or with the ego's own lane changes: shipped apart, because the flat, straight
# scenarios' contract (tests/sim: a box's bottom row is the flat road's row of its range, the camera keeps
# its lane) does not hold on them; a bare name finds them too.
ROAD_GEOMETRY_DIR = SCENARIO_DIR / "road_geometry"
KMH = 1.0 / 3.6  # m/s per km/h
MAX_TIME_S = 3600.0  # upper bound for any time in a scenario file


class ScenarioError(ValueError):
    """A scenario file (or camera override) that cannot be used; the message names file and key."""


# Kind defaults: (width_m range, height_m range, length_m range, ground clearance m).
# Ranges give "different widths and heights" while staying within real vehicle sizes.
KINDS: dict[str, tuple[tuple[float, float], tuple[float, float], tuple[float, float], float]] = {
    "car": ((1.68, 1.88), (1.38, 1.55), (4.2, 4.9), 0.30),
    "van": ((1.90, 2.05), (1.95, 2.50), (4.9, 5.8), 0.36),
    "truck": ((2.45, 2.55), (3.40, 4.00), (10.0, 16.5), 0.55),
}
# Body gray levels for named shades; numbers in between look like the road and are harder.
SHADES = {"dark": (30, 70), "mid": (95, 140), "light": (165, 225)}


@dataclasses.dataclass(frozen=True)
class SpeedStep:
    """From ``t_s`` on, accelerate at ``accel_mps2`` (until ``until_speed_kmh`` is reached, if given)."""

    t_s: float
    accel_mps2: float
    until_speed_kmh: float | None = None


@dataclasses.dataclass(frozen=True)
class LaneChange:
    t_s: float
    to_lane: int
    duration_s: float


@dataclasses.dataclass(frozen=True)
class BendSpec:
    """A constant-curvature stretch of the road (app/sim/road_shape.py): from arc length ``s_m`` (m ahead of
    the ego's start) over ``length_m``; curves: ``radius_m`` > 0 bends right, < 0 left; hills: > 0 a sag
    (the road curves up), < 0 a crest."""

    s_m: float
    length_m: float
    radius_m: float


@dataclasses.dataclass(frozen=True)
class VehicleSpec:
    id: int
    kind: str
    lane: int
    z_m: float
    speed_kmh: float
    width_m: float
    height_m: float
    length_m: float
    clearance_m: float
    shade: int
    lateral_offset_m: float = 0.0
    profile: tuple[SpeedStep, ...] = ()
    lane_changes: tuple[LaneChange, ...] = ()


@dataclasses.dataclass(frozen=True)
class EgoSpec:
    speed_kmh: float
    profile: tuple[SpeedStep, ...] = ()
    front_m: float = 2.0  # front bumper ahead of the camera (TTC reference)
    width_m: float = 1.8  # for deciding what the ego runs into
    length_m: float = 4.6
    lane_changes: tuple[LaneChange, ...] = ()  # the ego's own, to_lane relative to its starting lane


@dataclasses.dataclass(frozen=True)
class OverpassSpec:
    z_m: float  # front face of the bridge, distance from the camera at t = 0
    depth_m: float = 12.0  # bridge width along the road
    clearance_m: float = 5.5  # deck underside above the road
    thickness_m: float = 1.6
    shadow_offset_m: float = -4.0  # shadow band start relative to the bridge front (sun behind the ego: < 0)


@dataclasses.dataclass(frozen=True)
class RoadSpec:
    lanes: int = 3
    ego_lane: int = 1  # 0 = leftmost lane
    lane_width_m: float = 3.6
    shoulder_m: float = 1.0  # paved strip between the edge line and the guardrail
    marking_width_m: float = 0.15
    dash_length_m: float = 3.0
    dash_gap_m: float = 9.0
    markings: str = "painted"  # "none": bare asphalt, no painted lines (worn roads, lead without lanes)
    overpass: OverpassSpec | None = None
    curves: tuple[BendSpec, ...] = ()  # plan curvature; none = straight
    hills: tuple[BendSpec, ...] = ()  # vertical curvature; none = level

    @property
    def left_edge_m(self) -> float:
        return -(self.ego_lane + 0.5) * self.lane_width_m

    @property
    def right_edge_m(self) -> float:
        return (self.lanes - self.ego_lane - 0.5) * self.lane_width_m


@dataclasses.dataclass(frozen=True)
class ShakeSpec:
    pitch_deg: float = 0.15
    yaw_deg: float = 0.05


@dataclasses.dataclass(frozen=True)
class LightingSpec:
    asphalt_gray: float = 118.0  # sun-lit asphalt mean
    grass_gray: float = 92.0
    sky_gray: float = 205.0  # sky just above the horizon
    shadow_factor: float = 0.32  # share of sun-lit brightness left in a cast shadow
    texture_contrast: float = 1.0  # scales the asphalt texture amplitude
    noise_sigma: float = 1.5  # sensor noise, gray levels
    sun_side_m: float = 0.0  # vehicle shadows shifted right (+) or left (-) by this much


@dataclasses.dataclass(frozen=True)
class Scenario:
    name: str
    description: str
    duration_s: float
    fps: float
    seed: int
    camera: dict
    road: RoadSpec
    shake: ShakeSpec
    lighting: LightingSpec
    ego: EgoSpec
    vehicles: tuple[VehicleSpec, ...]
    source: str = "<memory>"
    # "real": cars and vans drawn from real rear views (app/sim/sprites.py, needs ../shared/data/patches);
    # "plain": drawn rear faces whose dark gap and outline are the shadow method's cues (app/sim/vehicles.py).
    vehicle_look: str = "real"

    @property
    def label(self) -> str:
        """How error messages name this scenario (its file name when it came from a file)."""
        return f"scenario {Path(self.source).name}" if self.source != "<memory>" else f"scenario {self.name}"

    @property
    def n_frames_nominal(self) -> int:
        return int(round(self.duration_s * self.fps))


# --- small typed readers --------------------------------------------------------------------------
_REQUIRED = object()


class _Reader:
    """Typed access to one mapping of the YAML tree, raising ScenarioError with the key path."""

    def __init__(self, where: str, value: Any, path: str, allowed: tuple[str, ...]):
        self.where = where
        self.path = path
        if not isinstance(value, Mapping):
            self.fail(path, f"expected a mapping, got {_show(value)}")
        unknown = [k for k in value if k not in allowed]
        if unknown:
            self.fail(self.key(unknown[0]), f"unknown key (allowed: {', '.join(allowed)})")
        self.data = value

    def fail(self, path: str, message: str):
        raise ScenarioError(f"{self.where}: {path or '<top>'}: {message}")

    def key(self, name: Any) -> str:
        return f"{self.path}.{name}" if self.path else str(name)

    def _get(self, name: str, default: Any) -> tuple[bool, Any]:
        """(given, value): a key written as null counts as not given."""
        if self.data.get(name) is None:
            if default is _REQUIRED:
                self.fail(self.key(name), "missing required key")
            return False, default
        return True, self.data[name]

    def number(self, name: str, default: Any = _REQUIRED, lo: float | None = None, hi: float | None = None,
               lo_open: bool = False) -> float:
        given, value = self._get(name, default)
        if not given:
            return value
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            self.fail(self.key(name), f"expected a number, got {_show(value)}")
        self._check_range(name, value, lo, hi, lo_open)
        return float(value)

    def integer(self, name: str, default: Any = _REQUIRED, lo: int | None = None, hi: int | None = None) -> int:
        given, value = self._get(name, default)
        if not given:
            return value
        if isinstance(value, bool) or not isinstance(value, int):
            self.fail(self.key(name), f"expected an integer, got {_show(value)}")
        self._check_range(name, value, lo, hi, False)
        return int(value)

    def string(self, name: str, default: Any = _REQUIRED, choices: tuple[str, ...] | None = None) -> str:
        given, value = self._get(name, default)
        if not given:
            return value
        if not isinstance(value, str):
            self.fail(self.key(name), f"expected a string, got {_show(value)}")
        if choices is not None and value not in choices:
            self.fail(self.key(name), f"expected one of {', '.join(choices)}, got {_show(value)}")
        return value

    def _check_range(self, name: str, value: float, lo: float | None, hi: float | None, lo_open: bool) -> None:
        if lo is not None and (value <= lo if lo_open else value < lo):
            self.fail(self.key(name), f"must be {'>' if lo_open else '>='} {lo}, got {value}")
        if hi is not None and value > hi:
            self.fail(self.key(name), f"must be <= {hi}, got {value}")

    def items(self, name: str, read_item: Callable[["_Reader", int, Any], Any]) -> tuple:
        _, value = self._get(name, [])
        if not isinstance(value, list):
            self.fail(self.key(name), f"expected a list, got {_show(value)}")
        return tuple(read_item(self, i, item) for i, item in enumerate(value))

    def sub(self, name: str, allowed: tuple[str, ...]) -> "_Reader":
        return _Reader(self.where, self._get(name, {})[1], self.key(name), allowed)

    def item(self, name: str, index: int, value: Any, allowed: tuple[str, ...]) -> "_Reader":
        return _Reader(self.where, value, f"{self.key(name)}[{index}]", allowed)


def _show(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


# --- sections -----------------------------------------------------------------------------------
_TOP_KEYS = ("name", "description", "duration_s", "fps", "seed", "camera", "road", "shake", "lighting", "ego",
             "vehicles", "vehicle_look")
VEHICLE_LOOKS = ("real", "plain")
_CAMERA_LIMITS = {
    "width": (16, 8192), "height": (16, 8192), "fx": (50.0, 20000.0), "fy": (50.0, 20000.0),
    "cx": (0.0, 8192.0), "cy": (0.0, 8192.0), "height_m": (0.3, 5.0), "pitch_deg": (-15.0, 15.0),
    "yaw_deg": (-15.0, 15.0), "lateral_m": (-3.0, 3.0),
}


def read_camera(where: str, value: Any, path: str = "camera") -> dict:
    """Validated camera overrides (any subset of the documented camera keys)."""
    reader = _Reader(where, value if value is not None else {}, path, CAMERA_KEYS)
    out: dict[str, float] = {}
    for name, (lo, hi) in _CAMERA_LIMITS.items():
        if reader.data.get(name) is not None:
            read = reader.integer if name in ("width", "height") else reader.number
            out[name] = read(name, None, lo, hi)
    return out


def _read_steps(reader: _Reader, name: str) -> tuple[SpeedStep, ...]:
    def read(parent: _Reader, i: int, value: Any) -> SpeedStep:
        r = parent.item(name, i, value, ("t_s", "accel_mps2", "until_speed_kmh"))
        # Entries after the end of the run are allowed (they never take effect): a scenario can be
        # shortened by its duration alone.
        return SpeedStep(r.number("t_s", lo=0.0, hi=MAX_TIME_S), r.number("accel_mps2", lo=-12.0, hi=8.0),
                         r.number("until_speed_kmh", None, lo=0.0, hi=250.0))

    steps = reader.items(name, read)
    _check_increasing(reader, name, [s.t_s for s in steps])
    return steps


def _check_increasing(reader: _Reader, name: str, times: list[float]) -> None:
    for i in range(1, len(times)):
        if times[i] <= times[i - 1]:
            reader.fail(f"{reader.key(name)}[{i}].t_s", f"must be later than the previous entry ({times[i - 1]})")


def _numbers(reader: _Reader, cls: type, limits: dict[str, tuple[float, float]]) -> dict[str, float]:
    """Number fields of a spec dataclass: its defaults, the file's values checked against ``limits``."""
    defaults = {f.name: _REQUIRED if f.default is dataclasses.MISSING else f.default for f in dataclasses.fields(cls)}
    return {name: reader.number(name, defaults[name], lo, hi) for name, (lo, hi) in limits.items()}


def _read_road(top: _Reader) -> RoadSpec:
    r = top.sub("road", tuple(f.name for f in dataclasses.fields(RoadSpec)))
    lanes = r.integer("lanes", RoadSpec.lanes, 1, 6)
    ego_lane = r.integer("ego_lane", (lanes - 1) // 2, 0, lanes - 1)
    overpass = None
    if r.data.get("overpass") is not None:
        o = r.sub("overpass", tuple(f.name for f in dataclasses.fields(OverpassSpec)))
        overpass = OverpassSpec(**_numbers(o, OverpassSpec, {
            "z_m": (5.0, 1000.0), "depth_m": (2.0, 60.0), "clearance_m": (4.5, 10.0), "thickness_m": (0.5, 4.0),
            "shadow_offset_m": (-30.0, 30.0)}))
    markings = r.string("markings", RoadSpec.markings, ("painted", "none"))
    curves = _read_bends(r, "curves", 200.0)
    hills = _read_bends(r, "hills", 500.0)
    return RoadSpec(lanes=lanes, ego_lane=ego_lane, overpass=overpass, markings=markings, curves=curves, hills=hills,
                    **_numbers(r, RoadSpec, {
        "lane_width_m": (2.5, 5.0), "shoulder_m": (0.2, 4.0), "marking_width_m": (0.08, 0.5),
        "dash_length_m": (0.5, 20.0), "dash_gap_m": (0.5, 30.0)}))


def _read_bends(r: _Reader, name: str, min_radius_m: float) -> tuple[BendSpec, ...]:
    """Constant-curvature stretches, in order and not overlapping; |radius_m| >= min_radius_m."""
    def read(parent: _Reader, i: int, value: Any) -> BendSpec:
        b = parent.item(name, i, value, ("s_m", "length_m", "radius_m"))
        radius = b.number("radius_m", lo=-1e6, hi=1e6)
        if abs(radius) < min_radius_m:
            b.fail(b.key("radius_m"), f"|radius_m| must be >= {min_radius_m} (sharper bends are not motorway "
                                      f"roads and the renderer's pieces assume gentler ones), got {radius}")
        return BendSpec(b.number("s_m", lo=0.0, hi=10000.0), b.number("length_m", lo=1.0, hi=3000.0), radius)

    bends = r.items(name, read)
    for i in range(1, len(bends)):
        if bends[i].s_m < bends[i - 1].s_m + bends[i - 1].length_m:
            r.fail(f"{r.key(name)}[{i}].s_m", "starts before the previous stretch has ended")
    return bends


def _read_lane_changes(r: _Reader, lane_lo: int, lane_hi: int) -> tuple[LaneChange, ...]:
    """Lane changes in time order, each starting after the previous one ended."""
    def read_change(parent: _Reader, i: int, item: Any) -> LaneChange:
        c = parent.item("lane_changes", i, item, ("t_s", "to_lane", "duration_s"))
        return LaneChange(c.number("t_s", lo=0.0, hi=MAX_TIME_S), c.integer("to_lane", lo=lane_lo, hi=lane_hi),
                          c.number("duration_s", 3.0, 0.5, 10.0))

    changes = r.items("lane_changes", read_change)
    for i in range(1, len(changes)):
        if changes[i].t_s < changes[i - 1].t_s + changes[i - 1].duration_s:
            r.fail(f"{r.key('lane_changes')}[{i}].t_s", "starts before the previous lane change has ended")
    return changes


def _read_lighting(top: _Reader) -> LightingSpec:
    r = top.sub("lighting", tuple(f.name for f in dataclasses.fields(LightingSpec)))
    return LightingSpec(**_numbers(r, LightingSpec, {
        "asphalt_gray": (60.0, 200.0), "grass_gray": (20.0, 220.0), "sky_gray": (60.0, 255.0),
        "shadow_factor": (0.1, 0.6), "texture_contrast": (0.0, 3.0), "noise_sigma": (0.0, 10.0),
        "sun_side_m": (-1.0, 1.0)}))


def _read_shake(top: _Reader) -> ShakeSpec:
    r = top.sub("shake", tuple(f.name for f in dataclasses.fields(ShakeSpec)))
    return ShakeSpec(**_numbers(r, ShakeSpec, {"pitch_deg": (0.0, 2.0), "yaw_deg": (0.0, 2.0)}))


def _read_ego(top: _Reader, road: RoadSpec) -> EgoSpec:
    r = top.sub("ego", tuple(f.name for f in dataclasses.fields(EgoSpec)))
    changes = _read_lane_changes(r, -road.ego_lane, road.lanes - 1 - road.ego_lane)
    return EgoSpec(profile=_read_steps(r, "profile"), lane_changes=changes, **_numbers(r, EgoSpec, {
        "speed_kmh": (0.0, 250.0), "front_m": (0.0, 5.0), "width_m": (1.2, 3.0), "length_m": (2.0, 20.0)}))


def _read_vehicle(top: _Reader, index: int, value: Any, road: RoadSpec, seed: int) -> VehicleSpec:
    r = top.item("vehicles", index, value, ("id", "kind", "lane", "z_m", "speed_kmh", "width_m", "height_m",
                                            "length_m", "shade", "lateral_offset_m", "profile", "lane_changes"))
    lane_lo, lane_hi = -road.ego_lane, road.lanes - 1 - road.ego_lane
    vid = r.integer("id", lo=1, hi=9999)
    kind = r.string("kind", "car", tuple(KINDS))
    (w_lo, w_hi), (h_lo, h_hi), (l_lo, l_hi), clearance_m = KINDS[kind]
    # Sizes and shade the file leaves open come from (seed, id): stable when vehicles are reordered.
    rng = np.random.default_rng([seed, vid])
    drawn = rng.uniform(size=5)
    shade = _read_shade(r, drawn[3], drawn[4])
    lane = r.integer("lane", 0, lane_lo, lane_hi)
    changes = _read_lane_changes(r, lane_lo, lane_hi)
    return VehicleSpec(
        id=vid, kind=kind, lane=lane, z_m=r.number("z_m", lo=-80.0, hi=600.0),
        speed_kmh=r.number("speed_kmh", lo=0.0, hi=250.0),
        width_m=r.number("width_m", float(round(w_lo + drawn[0] * (w_hi - w_lo), 3)), 1.2, 2.6),
        height_m=r.number("height_m", float(round(h_lo + drawn[1] * (h_hi - h_lo), 3)), 1.0, 4.5),
        length_m=r.number("length_m", float(round(l_lo + drawn[2] * (l_hi - l_lo), 2)), 2.5, 20.0),
        clearance_m=clearance_m, shade=shade,
        lateral_offset_m=r.number("lateral_offset_m", 0.0, -1.0, 1.0),
        profile=_read_steps(r, "profile"), lane_changes=changes)


def _read_shade(r: _Reader, pick: float, level: float) -> int:
    value = r.data.get("shade")
    if value is None:
        # Mostly dark or light bodies, some mid-gray ones (the hard case for a shadow detector).
        name = "dark" if pick < 0.45 else "light" if pick < 0.85 else "mid"
    elif isinstance(value, str):
        name = r.string("shade", choices=tuple(SHADES))
    else:
        return r.integer("shade", lo=0, hi=255)
    lo, hi = SHADES[name]
    return int(round(lo + level * (hi - lo)))


def parse_scenario(data: Any, where: str, default_name: str = "scenario", source: str = "<memory>") -> Scenario:
    """Validate a YAML tree already loaded into Python objects."""
    top = _Reader(where, data, "", _TOP_KEYS)
    duration_s = top.number("duration_s", lo=0.0, hi=120.0, lo_open=True)
    seed = top.integer("seed", 0, 0, 2**31 - 1)
    road = _read_road(top)
    vehicles = top.items("vehicles", lambda parent, i, v: _read_vehicle(parent, i, v, road, seed))
    ids = [v.id for v in vehicles]
    for i, vid in enumerate(ids):
        if vid in ids[:i]:
            top.fail(f"vehicles[{i}].id", f"duplicate id {vid}")
    return Scenario(
        name=top.string("name", default_name), description=top.string("description", ""),
        duration_s=duration_s, fps=top.number("fps", 30.0, 1.0, 240.0), seed=seed,
        camera=read_camera(where, top.data.get("camera"), "camera"), road=road,
        shake=_read_shake(top),
        lighting=_read_lighting(top), ego=_read_ego(top, road), vehicles=vehicles, source=source,
        vehicle_look=top.string("vehicle_look", Scenario.vehicle_look, VEHICLE_LOOKS))


def resolve_path(path_or_name: str | Path) -> Path:
    """A bare name (``steady_following``) means the shipped file ``scenarios/<name>.yaml`` (or, when only
    there, ``scenarios/road_geometry/<name>.yaml``)."""
    text = str(path_or_name)
    if "/" not in text and "\\" not in text and not text.endswith((".yaml", ".yml")):
        bent = ROAD_GEOMETRY_DIR / f"{text}.yaml"
        return bent if bent.is_file() and not (SCENARIO_DIR / f"{text}.yaml").is_file() else SCENARIO_DIR / f"{text}.yaml"
    return Path(text)


def read_scenario(path_or_name: str | Path) -> Scenario:
    path = resolve_path(path_or_name)
    where = f"scenario {path.name}"
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        hint = f" (shipped: {', '.join(list_scenarios())})" if path.parent == SCENARIO_DIR else ""
        raise ScenarioError(f"{where}: file not found: {path}{hint}") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ScenarioError(f"{where}: cannot read {path}: {exc}") from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        at = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
        problem = getattr(exc, "problem", None) or str(exc)
        raise ScenarioError(f"{where}: YAML syntax error{at}: {problem}") from None
    return parse_scenario(data, where, default_name=path.stem, source=str(path))


def list_scenarios() -> list[str]:
    """The shipped flat, straight-road scenarios."""
    return sorted(p.stem for p in SCENARIO_DIR.glob("*.yaml"))


def list_road_geometry_scenarios() -> list[str]:
    """The shipped scenarios with curves, hills or the ego's own lane changes."""
    return sorted(p.stem for p in ROAD_GEOMETRY_DIR.glob("*.yaml"))


def scenario_to_dict(scenario: Scenario) -> dict:
    """The resolved scenario in the file schema (every default made explicit; reloads to the same)."""
    def steps(items):
        return [{k: v for k, v in dataclasses.asdict(s).items() if v is not None} for s in items]

    road = dataclasses.asdict(scenario.road)
    if road["overpass"] is None:
        del road["overpass"]
    for key in ("curves", "hills"):  # straight, level roads' files stay as they were
        if road[key]:
            road[key] = [dict(b) for b in road[key]]
        else:
            del road[key]
    vehicles = []
    for v in scenario.vehicles:
        d = dataclasses.asdict(v)
        del d["clearance_m"]  # follows from the kind
        d["profile"] = steps(v.profile)
        d["lane_changes"] = [dataclasses.asdict(c) for c in v.lane_changes]
        vehicles.append(d)
    ego = dataclasses.asdict(scenario.ego)
    ego["profile"] = steps(scenario.ego.profile)
    ego["lane_changes"] = [dict(c) for c in ego["lane_changes"]]
    if not ego["lane_changes"]:
        del ego["lane_changes"]
    return {
        "name": scenario.name, "description": scenario.description, "duration_s": scenario.duration_s,
        "fps": scenario.fps, "seed": scenario.seed, "camera": dict(scenario.camera), "road": road,
        "shake": dataclasses.asdict(scenario.shake), "lighting": dataclasses.asdict(scenario.lighting),
        "ego": ego, "vehicles": vehicles, "vehicle_look": scenario.vehicle_look,
    }
