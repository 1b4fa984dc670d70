"""Vehicles drawn as real cars (``vehicle_look: real``): a sprite warped onto the projected rear face.

Each car and van gets one sprite (app/sim/sprites.py) for the run, chosen by (seed, id) among those as light
as its ``shade``. Per frame the sprite is mapped by the homography from its pixel edges to the rear face's four
projected corners, so it covers exactly the polygon whose bounding box is the truth box, and composited
through that polygon's anti-aliased coverage (the same fixed-point fill the truth's id buffer uses). On top:
brightness scaled to the scene's asphalt and light (the overpass shadow), a soft contact shadow along the
bottom, a blur for the box's image motion during the exposure and the optics, the tail lights brightened
while braking. Trucks keep the plain drawing: the patches hold no truck.
"""
from __future__ import annotations

import math

import cv2
import numpy as np

from .camera import Camera
from .polygons import SHIFT, fill, project_quads
from .scenario import Scenario
from .sprites import REFERENCE_ROAD_GRAY, Sprite, load_sprites, pick_sprite
from .truth import rear_face
from .vehicles import BRAKE_LIGHT_MPS2, VehiclePainter
from .world import VehicleState

BRAKE_GRAY = 245.0  # tail lights while braking, as the plain look's
CONTACT_SHADOW_FRAC = 0.12  # the bottom share of the face darkened towards the road contact ...
CONTACT_SHADOW_DEPTH = 0.5  # ... down to this share of its brightness at the bottom row
OPTICS_BLUR_PX = 0.4  # Gaussian sigma of the lens and sensor, px
EXPOSURE_FRAC = 0.5  # exposure time as a share of the frame period (motion blur)


class SpritePainter:
    """Draws the scenario's cars and vans as real rear views; shadows and trucks as ``VehiclePainter``."""

    def __init__(self, scenario: Scenario, sprites: tuple[Sprite, ...] | None = None):
        self.plain = VehiclePainter(scenario)
        sprites = load_sprites() if sprites is None else sprites
        self.sprites = {v.id: pick_sprite(sprites, v.shade, scenario.seed, v.id)
                        for v in scenario.vehicles if v.kind != "truck"}
        self.gain = scenario.lighting.asphalt_gray / REFERENCE_ROAD_GRAY
        self.fps = scenario.fps

    def shadow(self, vehicle: VehicleState, camera_lateral_m: float):
        return self.plain.shadow(vehicle, camera_lateral_m)

    def draw(self, image: np.ndarray, camera: Camera, vehicle: VehicleState, light: float = 1.0) -> None:
        sprite = self.sprites.get(vehicle.spec.id)
        if sprite is None:
            self.plain.draw(image, camera, vehicle, light)
            return
        corners = rear_face(vehicle)
        u, v = camera.project(corners)
        if not (np.isfinite(u).all() and np.isfinite(v).all()):
            return
        height, width = image.shape
        x0, y0 = max(0, math.floor(u.min())), max(0, math.floor(v.min()))
        x1, y1 = min(width, math.ceil(u.max()) + 1), min(height, math.ceil(v.max()) + 1)
        if x1 <= x0 or y1 <= y0:
            return
        polygon = project_quads(camera, corners[None])[0]
        coverage = np.zeros((y1 - y0, x1 - x0), np.uint8)
        fill(coverage, [polygon - np.array([x0, y0], np.int32) * (1 << SHIFT)], 255)
        face = self._face(sprite, u - x0, v - y0, coverage.shape, vehicle, camera, light)
        alpha = coverage.astype(np.float32) / 255.0
        roi = image[y0:y1, x0:x1]
        roi[...] = cv2.convertScaleAbs(roi * (1.0 - alpha) + face * alpha)

    def _face(self, sprite: Sprite, u: np.ndarray, v: np.ndarray, shape: tuple[int, int], vehicle: VehicleState,
              camera: Camera, light: float) -> np.ndarray:
        """The sprite warped onto the corners (u, v) (relative to the region, rear-face corner order), lit, shaded,
        blurred: float32 of ``shape``."""
        gray, lights = sprite.gray, sprite.lights
        box_w = max(float(u.max() - u.min()), 1.0)
        if box_w < gray.shape[1]:  # shrink first with area averaging: a warp alone would alias
            size = (max(2, round(box_w)), max(2, round(gray.shape[0] * box_w / gray.shape[1])))
            gray, lights = (cv2.resize(a, size, interpolation=cv2.INTER_AREA) for a in (gray, lights))
        h, w = gray.shape
        # rear_face corners: bottom-left, bottom-right, top-right, top-left; sprite pixel edges in the same order.
        src = np.float32([[-0.5, h - 0.5], [w - 0.5, h - 0.5], [w - 0.5, -0.5], [-0.5, -0.5]])
        homography = cv2.getPerspectiveTransform(src, np.float32(np.stack([u, v], axis=1)))
        size = (shape[1], shape[0])
        face = cv2.warpPerspective(gray, homography, size, flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        face *= self.gain * light
        if vehicle.accel_mps2 < BRAKE_LIGHT_MPS2:
            lit = cv2.warpPerspective(lights, homography, size, flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
            face += lit * (BRAKE_GRAY - face)
        face *= self._contact_shadow(v, shape[0])
        sigma = math.hypot(OPTICS_BLUR_PX, self._motion_blur_px(vehicle, camera))
        return cv2.GaussianBlur(face, (0, 0), sigma, borderType=cv2.BORDER_REPLICATE)

    @staticmethod
    def _contact_shadow(v: np.ndarray, rows: int) -> np.ndarray:
        """Per-row factor (rows, 1): 1 above the bottom CONTACT_SHADOW_FRAC of the face, falling linearly to
        1 - CONTACT_SHADOW_DEPTH at its bottom edge (the shade under the body where it meets the road)."""
        top, bottom = float(v.min()), float(v.max())
        start = bottom - CONTACT_SHADOW_FRAC * (bottom - top)
        ramp = np.clip((np.arange(rows, dtype=np.float32) - start) / max(bottom - start, 1e-3), 0.0, 1.0)
        return (1.0 - CONTACT_SHADOW_DEPTH * ramp)[:, None]

    def _motion_blur_px(self, vehicle: VehicleState, camera: Camera) -> float:
        """Sigma (px) of the face's growth or shrinking during the exposure: its width changes by fx W |dz/dt| / z^2
        px/s, each edge by half of that; a streak of length L has sigma L / sqrt(12)."""
        z = max(vehicle.z_m, 0.5)
        streak = 0.5 * camera.fx * vehicle.spec.width_m * abs(vehicle.relative_speed_mps) / (z * z) * EXPOSURE_FRAC / self.fps
        return streak / math.sqrt(12.0)
