"""Step a scenario through time: one SimFrame (image + ground truth) per frame."""
from __future__ import annotations

import dataclasses
import math
from typing import Any, Iterable, Iterator, Mapping

import numpy as np

from .camera import Camera
from .render import Renderer
from .road_shape import MAX_VIEW_M, BentCamera, RoadShape, Segment
from .scenario import Scenario, ScenarioError, read_camera
from .truth import frame_truth
from .world import World


@dataclasses.dataclass
class SimFrame:
    index: int
    t_s: float
    image: np.ndarray  # uint8, height x width
    truth: list[dict]  # see truth.frame_truth
    ego_speed_mps: float
    pitch_deg: float  # of this frame's camera, shake included
    yaw_deg: float  # ... and the ego's heading against its lane in its own lane changes
    yaw_rate_rps: float = 0.0  # the ego's, left positive (what the CAN bus reports): the road's curve, the lane change
    road: dict = dataclasses.field(default_factory=dict)  # on a bent road or in an ego lane change: see ego_pose


def scenario_camera(scenario: Scenario, camera_overrides: Mapping[str, Any] | None = None) -> Camera:
    """The scenario's camera with the caller's overrides (validated like the file's ``camera``)."""
    overrides = read_camera(f"{scenario.label}: camera overrides", camera_overrides, "camera")
    return Camera.from_dict({**scenario.camera, **overrides})


def render(scenario: Scenario, camera_overrides: Mapping[str, Any] | None = None,
           frames: Iterable[int] | None = None) -> Iterator[SimFrame]:
    """Render the scenario frame by frame (all frames, or only the given indices, in that order).

    The run ends early when the ego runs into a vehicle ahead: the last frame is the last one
    before contact, so its TTC is at most one frame period.
    """
    camera = scenario_camera(scenario, camera_overrides)
    world = World(scenario)
    max_odometer_m = float(world.ego.at(world.times_s[-1])[0])
    renderer = Renderer(scenario, camera, max_odometer_m)
    shape = road_shape(scenario, max_odometer_m)
    posed = shape is not None or bool(scenario.ego.lane_changes)
    indices = range(world.n_frames) if frames is None else list(frames)
    for index in indices:
        if not 0 <= index < world.n_frames:
            raise ScenarioError(f"{scenario.label}: frame {index} out of range (0..{world.n_frames - 1})")
        state = world.frame_state(index)
        cam = camera.shaken(float(world.pitch_shake_deg[index]), float(world.yaw_shake_deg[index]))
        yaw_rate, road = 0.0, {}
        if posed:
            cam, yaw_rate, road = ego_pose(cam, shape, world, state)
        yield SimFrame(
            index=index, t_s=state.t_s, image=renderer.draw(state, cam, index),
            truth=frame_truth(state, cam, scenario.ego.front_m, scenario.road.lane_width_m),
            ego_speed_mps=state.ego_speed_mps, pitch_deg=cam.pitch_deg, yaw_deg=cam.yaw_deg,
            yaw_rate_rps=yaw_rate, road=road)


def road_shape(scenario: Scenario, max_odometer_m: float) -> RoadShape | None:
    """The bent road of a scenario with curves or hills (built to the farthest point seen), else None."""
    road = scenario.road
    if not (road.curves or road.hills):
        return None
    def segments(bends):
        return tuple(Segment(b.s_m, b.length_m, 1.0 / b.radius_m) for b in bends)
    return RoadShape(segments(road.curves), segments(road.hills), max_odometer_m + MAX_VIEW_M + 50.0)


def ego_pose(cam: Camera, shape: RoadShape | None, world: World, state) -> tuple[BentCamera, float, dict]:
    """This frame's camera on the bent road / in the ego's lane change, the ego's yaw rate (rad/s, left
    positive) and the road under the ego: curvature (1/m, > 0 right), vertical curvature (1/m, > 0 sag),
    grade (deg), the ego's lateral position (m right of its starting lane) and heading against the lane
    (deg, right positive). The camera's pose relative to the local road is the mounting (plus shake)
    turned by that heading: what self-calibration should find is the mounting."""
    t, odo, v = state.t_s, state.ego_odometer_m, max(state.ego_speed_mps, 0.1)

    def heading(t_s: float) -> float:  # against the lane, rad, right positive: atan(de/ds)
        return math.atan2(world.ego_lateral.speed(t_s), max(float(world.ego.at(t_s)[1]), 0.1))

    lateral = float(world.ego_lateral.at(t))
    psi = heading(t)
    dt = 0.5 / world.scenario.fps
    psi_rate = (heading(t + dt) - heading(max(t - dt, 0.0))) / (t + dt - max(t - dt, 0.0))
    kappa = float(shape.curvature(odo)) if shape is not None else 0.0
    theta = float(shape.heading(odo)) if shape is not None else 0.0
    gamma = float(shape.grade(odo)) if shape is not None else 0.0
    bend = shape.bend_at(odo) if shape is not None else None
    fields = {**cam.to_dict(), "lateral_m": cam.lateral_m + lateral, "yaw_deg": cam.yaw_deg + math.degrees(psi)}
    posed = BentCamera(**fields, bend=bend, heading_rad=theta + psi, grade_rad=gamma,
                       view_m=bend.view_limit_m(cam.height_m) if bend is not None else math.inf)
    road = {"curvature_1pm": kappa, "vertical_curvature_1pm": float(shape.vertical_curvature(odo)) if shape else 0.0,
            "grade_deg": math.degrees(gamma), "ego_lateral_m": lateral, "heading_deg": math.degrees(psi)}
    return posed, -(v * kappa + psi_rate), road


def frame_count(scenario: Scenario) -> int:
    """Frames that ``render`` yields (fewer than duration x fps when the ego collides)."""
    return World(scenario).n_frames
