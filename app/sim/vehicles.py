"""Vehicle rear faces: body, dark gap under the body, tyres, bumper, rear window, lights.

The cues the detectors use are drawn on purpose: the darkest region of the scene is the gap
between road and underbody (the thesis' shadow cue), the rear face's sides are strong
vertical edges (dark outline against road and sky), tail lights are bright when braking.
A part is a rectangle in the rear-face plane given as (left, right) fractions of the width and
(bottom, top) heights in metres; each is projected exactly, so the picture and the truth box
share their edges.
"""
from __future__ import annotations

import numpy as np

from .camera import Camera
from .polygons import fill, project_quads
from .scenario import Scenario, VehicleSpec
from .world import VehicleState

BRAKE_LIGHT_MPS2 = -1.0  # decelerating harder than this lights the brake lights
DETAIL_PX = 10.0  # narrower rear faces are drawn without small parts (they would be sub-pixel)


class VehicleLook:
    """Gray levels of one vehicle, fixed for the whole run (seeded by scenario seed and id)."""

    def __init__(self, spec: VehicleSpec, seed: int, asphalt_gray: float, shadow_factor: float):
        rng = np.random.default_rng([seed, spec.id, 0x10C])
        body = float(spec.shade)
        self.body = body
        self.window = rng.uniform(30.0, 65.0) if body > 80 else rng.uniform(18.0, 35.0)
        self.tail = rng.uniform(95.0, 130.0)
        # The gap under the body sees only shadowed road and the underbody: darker than any cast shadow.
        self.under = 0.6 * shadow_factor * asphalt_gray
        self.tyre = 0.45 * shadow_factor * asphalt_gray
        self.outline = 0.6 * body
        self._shapes: dict[tuple[bool, bool], tuple[np.ndarray, np.ndarray]] = {}

    def shapes(self, spec: VehicleSpec, braking: bool, detailed: bool) -> tuple[np.ndarray, np.ndarray]:
        """Part corners (n, 4, 3) in the rear-face frame (x from the left side, z = 0) and gray levels; cached."""
        key = (braking, detailed)
        if key not in self._shapes:
            parts = np.array(self.parts(spec, braking, detailed))
            x0, x1 = parts[:, 0] * spec.width_m, parts[:, 1] * spec.width_m
            y0, y1, zero = parts[:, 2], parts[:, 3], np.zeros(len(parts))
            # Corner order of polygons.rect_xy.
            corners = np.stack([np.stack(c, axis=1) for c in ((x0, y0, zero), (x1, y0, zero), (x1, y1, zero), (x0, y1, zero))],
                               axis=1)
            self._shapes[key] = (corners, parts[:, 4])
        return self._shapes[key]

    def parts(self, spec: VehicleSpec, braking: bool, detailed: bool) -> list[tuple[float, float, float, float, float]]:
        """(left, right, bottom_m, top_m, gray) in drawing order."""
        h, c, w = spec.height_m, spec.clearance_m, spec.width_m
        body, under = self.body, self.under
        light = 245.0 if braking else self.tail
        if spec.kind == "truck":
            parts = [(0.0, 1.0, c, h, body), (0.0, 1.0, c, 1.15, 0.35 * body + 20.0),
                     (0.0, 1.0, h - 0.08, h, 0.75 * body)]
            if detailed:
                parts += [(0.497, 0.503, 1.25, h - 0.12, 0.6 * body), (0.03, 0.04, 1.25, h - 0.12, 0.6 * body),
                          (0.96, 0.97, 1.25, h - 0.12, 0.6 * body), (0.02, 0.14, 0.8, 0.98, light),
                          (0.86, 0.98, 0.8, 0.98, light)]
            parts += [(0.0, 1.0, 0.0, c, under), (0.0, 0.17, 0.0, 1.0, self.tyre), (0.83, 1.0, 0.0, 1.0, self.tyre)]
            if detailed:
                parts.append((0.06, 0.94, 0.38, 0.52, 60.0))  # under-run bar
        else:
            van = spec.kind == "van"
            window = (0.12, 0.88, 0.62 * h, 0.85 * h) if van else (0.1, 0.9, 0.66 * h, 0.93 * h)
            parts = [(0.0, 1.0, c, h, body), (*window, self.window)]
            if detailed:
                lights = (0.01, 0.09, 0.3 * h, 0.55 * h) if van else (0.02, 0.2, 0.56 * h, 0.68 * h)
                plate = 0.26 / w
                parts += [(0.0, 1.0, c, c + 0.22, 0.8 * body), (0.02, 0.98, c + 0.22, c + 0.25, 0.5 * body),
                          (0.5 - plate, 0.5 + plate, c + 0.3, c + 0.42, 215.0),
                          (lights[0], lights[1], lights[2], lights[3], light),
                          (1.0 - lights[1], 1.0 - lights[0], lights[2], lights[3], light)]
                if van:
                    parts.append((0.495, 0.505, c + 0.3, 0.94 * h, 0.55 * body))
            parts += [(0.0, 1.0, 0.0, c, under), (0.0, 0.12, 0.0, c, self.tyre), (0.88, 1.0, 0.0, c, self.tyre)]
        # Dark side outline: real rear faces end in pillars, seams and shadowed sides.
        parts += [(0.0, 0.03, c, h, self.outline), (0.97, 1.0, c, h, self.outline)]
        return parts


def clip_convex(polygon: np.ndarray, halfplanes: list[tuple[float, float, float]]) -> np.ndarray:
    """Sutherland-Hodgman: the part of a convex polygon (k, 2) where a p0 + b p1 + c >= 0 for all planes.

    Plain floats: a handful of vertices, where numpy's per-call overhead would dominate.
    """
    points = [(float(p), float(q)) for p, q in polygon]
    for a, b, c in halfplanes:
        kept = []
        for i, (p, q) in enumerate(points):
            p2, q2 = points[(i + 1) % len(points)]
            side, side2 = a * p + b * q + c, a * p2 + b * q2 + c
            if side >= 0:
                kept.append((p, q))
            if (side >= 0) != (side2 >= 0):
                t = side / (side - side2)
                kept.append((p + t * (p2 - p), q + t * (q2 - q)))
        points = kept
        if not points:
            break
    return np.array(points, dtype=np.float64).reshape(-1, 2)


class VehiclePainter:
    def __init__(self, scenario: Scenario):
        light = scenario.lighting
        self.looks = {v.id: VehicleLook(v, scenario.seed, light.asphalt_gray, light.shadow_factor)
                      for v in scenario.vehicles}
        self.shadow_factor = light.shadow_factor
        self.sun_side_m = light.sun_side_m

    def shadow(self, vehicle: VehicleState, camera_lateral_m: float) -> tuple[np.ndarray, float]:
        """The body's cast shadow on the road (world corners (k, 3)) and its light factor.

        Only rear faces are drawn, so the part of the shadow that a real car's side would hide
        is cut away: the footprint (shifted by the sun) is kept inside the camera's view wedge
        through the rear face's bottom corners, widened by the sun shift. What remains shows
        under the bumper and as a spill of ``sun_side_m`` beside the vehicle.
        """
        half = 0.5 * vehicle.spec.width_m - 0.05
        x, z, spill = vehicle.x_m + self.sun_side_m, vehicle.z_m, abs(self.sun_side_m)
        footprint = np.array([[x - half, z], [x + half, z], [x + half, z + 0.9 * vehicle.spec.length_m],
                              [x - half, z + 0.9 * vehicle.spec.length_m]])
        left, right = vehicle.x_m - half - camera_lateral_m, vehicle.x_m + half - camera_lateral_m
        # Half-planes a X + b Z + c >= 0 in camera-relative X: X' >= left Z / z - spill, X' <= right Z / z + spill.
        wedge = [(1.0, -left / z, -camera_lateral_m + spill), (-1.0, right / z, camera_lateral_m + spill)]
        kept = clip_convex(footprint, wedge) if spill > 0 else np.empty((0, 2))  # else all behind the face
        corners = np.stack([kept[:, 0], np.zeros(len(kept)), kept[:, 1]], axis=1)
        return corners, self.shadow_factor

    def draw(self, image: np.ndarray, camera: Camera, vehicle: VehicleState, light: float = 1.0) -> None:
        spec = vehicle.spec
        width_px = camera.fx * spec.width_m / max(vehicle.z_m, 1e-3)
        corners, grays = self.looks[spec.id].shapes(spec, vehicle.accel_mps2 < BRAKE_LIGHT_MPS2, width_px >= DETAIL_PX)
        placed = corners + np.array([vehicle.x_m - 0.5 * spec.width_m, 0.0, vehicle.z_m])
        for polygon, gray in zip(project_quads(camera, placed), np.minimum(255.0, grays * light)):
            fill(image, [polygon], gray)
