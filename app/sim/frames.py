"""Step a scenario through time: one SimFrame (image + ground truth) per frame."""
from __future__ import annotations

import dataclasses
from typing import Any, Iterable, Iterator, Mapping

import numpy as np

from .camera import Camera
from .render import Renderer
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
    yaw_deg: float


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
    renderer = Renderer(scenario, camera, float(world.ego.at(world.times_s[-1])[0]))
    indices = range(world.n_frames) if frames is None else list(frames)
    for index in indices:
        if not 0 <= index < world.n_frames:
            raise ScenarioError(f"{scenario.label}: frame {index} out of range (0..{world.n_frames - 1})")
        state = world.frame_state(index)
        cam = camera.shaken(float(world.pitch_shake_deg[index]), float(world.yaw_shake_deg[index]))
        yield SimFrame(
            index=index, t_s=state.t_s, image=renderer.draw(state, cam, index),
            truth=frame_truth(state, cam, scenario.ego.front_m, scenario.road.lane_width_m),
            ego_speed_mps=state.ego_speed_mps, pitch_deg=cam.pitch_deg, yaw_deg=cam.yaw_deg)


def frame_count(scenario: Scenario) -> int:
    """Frames that ``render`` yields (fewer than duration x fps when the ego collides)."""
    return World(scenario).n_frames
