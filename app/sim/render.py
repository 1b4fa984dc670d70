"""One gray frame of the scenario world, composed back to front.

Order: sky and the road plane (with cast shadows), then what stands outside the road
(clutter, bridge pillars, guardrails), then vehicles and the bridge deck far to near, then
sensor noise. The painter's order of the vehicles is the one the ground truth's id buffer uses.
"""
from __future__ import annotations

import math

import cv2
import numpy as np

from .camera import Camera
from .road import Ground, Sky
from .scenario import Scenario
from .scenery import Scenery
from .sprite_painter import SpritePainter
from .truth import depth_order
from .vehicles import VehiclePainter
from .world import WorldState

_NOISE_MARGIN = 64  # the noise tile is this much larger than a frame; each frame takes a random window


class Renderer:
    """Draws frames of one scenario for one camera; all randomness comes from the scenario seed."""

    def __init__(self, scenario: Scenario, camera: Camera, max_odometer_m: float):
        seed = scenario.seed
        # Separate streams per part, so adding clutter does not change the asphalt of a seed.
        self.ground = Ground(scenario, np.random.default_rng([seed, 1]))
        self.sky = Sky(scenario, np.random.default_rng([seed, 2]))
        self.scenery = Scenery(scenario, np.random.default_rng([seed, 3]), max_odometer_m)
        self.vehicles = SpritePainter(scenario) if scenario.vehicle_look == "real" else VehiclePainter(scenario)
        self.seed = seed
        sigma = scenario.lighting.noise_sigma
        shape = (camera.height + _NOISE_MARGIN, camera.width + _NOISE_MARGIN)
        noise = np.round(np.random.default_rng([seed, 4]).normal(0.0, sigma, shape))
        # Kept as positive and negative parts: two saturating uint8 operations per frame.
        self.noise = (np.clip(noise, 0, 255).astype(np.uint8), np.clip(-noise, 0, 255).astype(np.uint8)) if sigma > 0 else None

    def draw(self, state: WorldState, camera: Camera, frame_index: int) -> np.ndarray:
        odometer_m = state.ego_odometer_m
        r0 = int(np.clip(math.floor(camera.horizon_row) + 1, 0, camera.height))
        vehicles = depth_order(state)
        shadows = self.scenery.shadow(odometer_m) + [self.vehicles.shadow(v, camera.lateral_m) for v in vehicles]
        if getattr(camera, "bend", None) is not None:  # a bent road: the ground's outline is not the horizon row
            ground, where = self.ground.draw_bent(camera, odometer_m, shadows)
            image = cv2.convertScaleAbs(np.where(where, ground, self.sky.draw(camera.sky_camera(), camera.height)))
        else:
            image = self._flat_background(camera, odometer_m, shadows, r0)
        self.scenery.draw_roadside(image, camera, odometer_m)
        items = [(v.z_m, v) for v in vehicles]
        deck_z = self.scenery.deck_z(odometer_m)
        if deck_z is not None:
            items.append((deck_z, None))
        for _, vehicle in sorted(items, key=lambda item: -item[0]):
            if vehicle is None:
                self.scenery.draw_deck(image, camera, odometer_m)
            else:
                light = self.scenery.light_at(vehicle.z_m, odometer_m)
                self.vehicles.draw(image, camera, vehicle, light)
        return self._add_noise(image, frame_index)

    def _flat_background(self, camera: Camera, odometer_m: float, shadows: list, r0: int) -> np.ndarray:
        """Sky above row r0 (below the horizon), the flat road from r0 down."""
        image = np.empty((camera.height, camera.width), np.uint8)
        # Gray levels are >= 0, so convertScaleAbs is a fast rounding, saturating float -> uint8.
        if r0 > 0:
            image[:r0] = cv2.convertScaleAbs(self.sky.draw(camera, r0))
        if r0 < camera.height:
            image[r0:] = cv2.convertScaleAbs(self.ground.draw(camera, odometer_m, shadows, r0))
        return image

    def _add_noise(self, image: np.ndarray, frame_index: int) -> np.ndarray:
        if self.noise is None:
            return image
        dy, dx = np.random.default_rng([self.seed, 5, frame_index]).integers(0, _NOISE_MARGIN, size=2)
        rows, cols = slice(dy, dy + image.shape[0]), slice(dx, dx + image.shape[1])
        return cv2.subtract(cv2.add(image, self.noise[0][rows, cols]), self.noise[1][rows, cols])
