"""The shared camera model: projection, its flat-road inverse, horizon, homography."""
import math

import numpy as np
import pytest

from app.sim import Camera

CAMERAS = [
    Camera.from_dict({}),
    Camera.from_dict({"pitch_deg": 2.5, "yaw_deg": -3.0, "lateral_m": 0.4, "height_m": 1.6}),
    Camera.from_dict({"width": 1280, "height": 720, "fx": 1000, "pitch_deg": -0.5, "yaw_deg": 4.0}),
]


@pytest.mark.parametrize("camera", CAMERAS)
def test_ground_point_round_trip_is_exact(camera):
    rng = np.random.default_rng(0)
    x = rng.uniform(-12.0, 12.0, 500)
    z = rng.uniform(4.0, 200.0, 500)
    u, v = camera.project(np.stack([x, np.zeros_like(x), z], axis=1))
    x2, z2 = camera.ground_from_pixel(u, v)
    assert np.max(np.abs(x2 - x)) < 1e-6
    assert np.max(np.abs(z2 - z)) < 1e-6


@pytest.mark.parametrize("camera", CAMERAS)
def test_row_of_range_and_range_of_row_are_inverse(camera):
    z = np.linspace(3.0, 300.0, 200)
    for x in (None, -3.6, 5.0):
        rows = camera.row_of_range(z, x)
        assert np.max(np.abs(camera.range_of_row(rows, x) - z)) < 1e-6
        u, v = camera.project(np.stack([np.full_like(z, camera.lateral_m if x is None else x), 0 * z, z], 1))
        assert np.max(np.abs(v - rows)) < 1e-9


def test_default_camera_horizon_row():
    camera = Camera.from_dict({})
    expected = 240.0 - 700.0 * math.tan(math.radians(1.0))
    assert abs(camera.horizon_row - expected) < 1e-6
    # Far road points approach the horizon row from below; yaw does not move it.
    assert abs(camera.row_of_range(1e7) - expected) < 1e-3
    assert abs(Camera.from_dict({"yaw_deg": 5.0}).row_of_range(1e7) - expected) < 1e-3
    assert np.isnan(camera.range_of_row(expected - 1.0))


def test_sign_conventions():
    camera = Camera.from_dict({})
    u, v = camera.project(np.array([[0.0, 0.0, 20.0], [2.0, 0.0, 20.0], [0.0, 1.3, 20.0]]))
    assert v[0] > camera.horizon_row  # road ahead is below the horizon
    assert u[1] > u[0]  # X right is image right
    assert abs(v[2] - camera.horizon_row) < 1e-9  # a point at camera height lies on the horizon
    right = Camera.from_dict({"yaw_deg": 2.0})
    assert right.project(np.array([[0.0, 0.0, 50.0]]))[0][0] < camera.cx  # looking right moves scene left
    shifted = Camera.from_dict({"lateral_m": 1.0})
    assert abs(shifted.project(np.array([[1.0, 0.0, 30.0]]))[0][0] - 320.0) < 1e-9


@pytest.mark.parametrize("camera", CAMERAS)
def test_ground_homography_matches_projection(camera):
    x = np.array([-5.0, 0.0, 3.3])
    z = np.array([6.0, 25.0, 120.0])
    u, v = camera.project(np.stack([x, 0 * x, z], 1))
    p = camera.ground_to_image() @ np.stack([x, z, np.ones(3)])
    assert np.allclose(p[0] / p[2], u) and np.allclose(p[1] / p[2], v)


def test_from_dict_defaults_and_unknown_key():
    camera = Camera.from_dict({"width": 1280, "height": 720})
    assert (camera.cx, camera.cy, camera.fx, camera.fy) == (640.0, 360.0, 700.0, 700.0)
    assert Camera.from_dict({"fx": 900}).fy == 900.0
    with pytest.raises(ValueError, match="focal"):
        Camera.from_dict({"focal": 700})
