"""Shared helpers for the synthetic-scenario tests."""
from __future__ import annotations

import functools

import pytest

from app.sim import frame_count, list_scenarios, load_scenario, render


@functools.lru_cache(maxsize=None)
def _sampled(name: str) -> tuple:
    scenario = load_scenario(name)
    n = frame_count(scenario)
    indices = sorted(set(range(min(10, n))) | {n // 4, n // 2, (3 * n) // 4, n - 1})
    return tuple(render(scenario, frames=indices))


@pytest.fixture(scope="session")
def sampled_frames():
    """name -> the first 10 frames plus 4 spread through the run (rendering all would be slow); cached."""
    return _sampled


@pytest.fixture(params=list_scenarios())
def scenario_name(request) -> str:
    return request.param
