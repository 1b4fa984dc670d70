"""Synthetic highway scenarios with exact ground truth (see docs/sim.md)."""
from __future__ import annotations

from pathlib import Path

from .camera import Camera
from .frames import SimFrame, frame_count, render
from .scenario import Scenario, ScenarioError, list_scenarios, read_scenario
from .world import World
from .writer import write_scenario

__all__ = ["Camera", "Scenario", "ScenarioError", "SimFrame", "frame_count", "list_scenarios", "load_scenario",
           "render", "write_scenario"]


def load_scenario(path_or_name: str | Path) -> Scenario:
    """Read and validate a scenario file (a bare name means a shipped scenario).

    Besides the file's own schema this checks the motion: no two vehicles may drive into each
    other, and none into the ego except head-on from ahead (which ends the run).
    """
    scenario = read_scenario(path_or_name)
    World(scenario)  # raises ScenarioError for impossible motion
    return scenario
