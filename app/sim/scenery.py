"""Things that stand beside and over the road: guardrails, roadside clutter, the overpass.

All of it is world-fixed (positions along the road drawn once from the seed), so it moves with
ego motion like real scenery and gives a parallax detector something that is *not* on the road
plane. Clutter, bridge pillars and guardrails stand outside the road edges; seen from a camera
inside the road they can never hide a vehicle on the road, so they are drawn before the
vehicles. The bridge deck spans the road and is drawn in depth order with the vehicles.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from .camera import Camera
from .polygons import fill, project_quads, rect_xy, rect_xz, rect_yz
from .scenario import Scenario

CLUTTER_RANGE_M = 200.0  # farther clutter is a few pixels of haze
POST_RANGE_M = 90.0  # guardrail posts beyond this are thinner than a pixel
POST_SPACING_M = 4.0
NEAR_M = 1.0  # scenery closer than this (in Z) is outside the image anyway
VERTICES = 16  # every shape is a convex polygon with this many vertices (rectangles repeat corners)


def _rect(x0: float, x1: float, y0: float, y1: float, z: float) -> np.ndarray:
    return np.concatenate([rect_xy(x0, x1, y0, y1, z), np.repeat(rect_xy(x0, x1, y0, y1, z)[3:], VERTICES - 4, 0)])


def _ellipse(x: float, y: float, z: float, rx: float, ry: float) -> np.ndarray:
    """Upright ellipse facing the camera (tree crowns, bushes) as a world polygon."""
    a = np.linspace(0.0, 2.0 * math.pi, VERTICES, endpoint=False)
    return np.stack([x + rx * np.cos(a), y + ry * np.sin(a), np.full(VERTICES, z)], axis=1)


def clutter_shapes(kind: str, x: float, z: float, size: float, gray: float) -> list[tuple[np.ndarray, float]]:
    """(world polygon, gray) of one roadside object standing at (x, z), in drawing order."""
    if kind == "tree":
        trunk = 0.6 * size + 1.0
        return [(_rect(x - 0.15, x + 0.15, 0.0, trunk + 0.3, z), 55.0),
                (_ellipse(x, trunk + 0.8 * size, z, size, 1.15 * size), gray)]
    if kind == "bush":
        return [(_ellipse(x, 0.35 * size, z, 0.5 * size, 0.4 * size), gray)]
    if kind == "pole":  # lamp post with its arm reaching towards the road
        arm = (x, x + 1.6) if x < 0 else (x - 1.6, x)
        return [(_rect(x - 0.09, x + 0.09, 0.0, size, z), gray), (_rect(*arm, size - 0.15, size, z), gray)]
    if kind == "pillar":  # bridge pillar: size is its height
        return [(_rect(x - 0.6, x + 0.6, 0.0, size, z), gray)]
    half = 0.5 * size  # sign board on two posts, with a border
    top = 2.0 + 0.6 * size
    return [(_rect(x - half + 0.2, x - half + 0.3, 0.0, 2.2, z), 120.0),
            (_rect(x + half - 0.3, x + half - 0.2, 0.0, 2.2, z), 120.0),
            (_rect(x - half, x + half, 2.0, top, z), 255.0 - gray),
            (_rect(x - half + 0.12, x + half - 0.12, 2.12, top - 0.12, z), gray)]


@dataclasses.dataclass
class Objects:
    """World-fixed roadside objects sorted by Z, flattened into shapes grouped per object."""

    z_world_m: np.ndarray  # (objects,)
    first: np.ndarray  # (objects + 1,): the shapes of object k are first[k]:first[k + 1]
    polygons: np.ndarray  # (shapes, VERTICES, 3) world coordinates
    gray: np.ndarray  # (shapes,)

    @classmethod
    def from_list(cls, objects: list[tuple[float, list[tuple[np.ndarray, float]]]]) -> "Objects":
        objects = sorted(objects, key=lambda o: o[0])
        shapes = [shape for _, obj in objects for shape in obj]
        return cls(np.array([z for z, _ in objects]), np.concatenate([[0], np.cumsum([len(o) for _, o in objects])]),
                   np.array([p for p, _ in shapes]).reshape(-1, VERTICES, 3), np.array([g for _, g in shapes]))

    def draw(self, image: np.ndarray, camera: Camera, odometer_m: float, z_range_m: tuple[float, float]) -> None:
        """Objects in the Z range (relative to the camera), far to near; each object's shapes in order."""
        lo, hi = np.searchsorted(self.z_world_m, [odometer_m + z_range_m[0], odometer_m + z_range_m[1]])
        if hi <= lo:
            return
        order = np.concatenate([np.arange(self.first[k], self.first[k + 1]) for k in range(hi - 1, lo - 1, -1)])
        polygons = self.polygons[order]
        polygons[:, :, 2] -= odometer_m
        for polygon, gray in zip(project_quads(camera, polygons), self.gray[order]):
            fill(image, [polygon], gray)


def make_objects(rng: np.random.Generator, scenario: Scenario, rail_m: tuple[float, float],
                 z_world_range_m: tuple[float, float]) -> Objects:
    """Random trees, bushes, lamp posts and signs along both sides, plus the bridge pillars."""
    objects = []
    for side, rail in ((-1.0, rail_m[0]), (1.0, rail_m[1])):
        z = z_world_range_m[0]
        while z < z_world_range_m[1]:
            z += rng.uniform(6.0, 30.0)
            kind = str(rng.choice(["tree", "tree", "tree", "bush", "bush", "pole", "sign"]))
            setback = rng.uniform(1.5, 4.0) if kind in ("pole", "sign") else rng.uniform(2.0, 16.0)
            size = {"tree": rng.uniform(1.4, 3.2), "bush": rng.uniform(1.0, 3.0), "pole": rng.uniform(7.0, 10.0),
                    "sign": rng.uniform(1.6, 3.0)}[kind]
            gray = {"tree": rng.uniform(45, 90), "bush": rng.uniform(60, 100), "pole": rng.uniform(120, 170),
                    "sign": rng.choice([60.0, 215.0])}[kind]
            objects.append((z, clutter_shapes(kind, rail + side * setback, z, size, gray)))
    bridge = scenario.road.overpass
    if bridge is not None:
        z = bridge.z_m + 0.5 * bridge.depth_m - 0.6
        for x in (rail_m[0] - 1.6, rail_m[1] + 1.6):
            objects.append((z, clutter_shapes("pillar", x, z, bridge.clearance_m, 150.0)))
    return Objects.from_list(objects)


class Scenery:
    def __init__(self, scenario: Scenario, rng: np.random.Generator, max_odometer_m: float):
        road = scenario.road
        self.rail_m = (road.left_edge_m - road.shoulder_m, road.right_edge_m + road.shoulder_m)
        self.objects = make_objects(rng, scenario, self.rail_m, (-60.0, max_odometer_m + CLUTTER_RANGE_M + 40.0))
        self.overpass = road.overpass
        self.shadow_factor = scenario.lighting.shadow_factor
        self.span_m = (self.rail_m[0] - 60.0, self.rail_m[1] + 60.0)  # the bridge runs well past the road

    def draw_roadside(self, image: np.ndarray, camera: Camera, odometer_m: float) -> None:
        """Clutter and pillars far to near, then the guardrails (between them and the road)."""
        self.objects.draw(image, camera, odometer_m, (NEAR_M, CLUTTER_RANGE_M))
        first = math.ceil((odometer_m + NEAR_M) / POST_SPACING_M)
        last = math.floor((odometer_m + POST_RANGE_M) / POST_SPACING_M)
        post_z = np.arange(last, first - 1, -1) * POST_SPACING_M - odometer_m  # far to near
        for rail, out in ((self.rail_m[0], -0.12), (self.rail_m[1], 0.12)):
            # W-beam on posts: posts (world-fixed, every 4 m) stand behind the beam.
            post = rail + out
            fill(image, project_quads(camera, [rect_xy(post - 0.06, post + 0.06, 0.0, 0.72, z) for z in post_z]), 95.0)
            lower, upper = project_quads(camera, [rect_yz(rail, 0.42, 0.58, 0.3, 400.0),
                                                  rect_yz(rail, 0.58, 0.75, 0.3, 400.0)])
            fill(image, [lower], 125.0)
            fill(image, [upper], 185.0)

    # --- the overpass --------------------------------------------------------------------------
    def deck_z(self, odometer_m: float) -> float | None:
        """Range of the bridge's front face, while any of the deck is ahead of the camera."""
        if self.overpass is None:
            return None
        z = self.overpass.z_m - odometer_m
        return z if z + self.overpass.depth_m > NEAR_M else None

    def draw_deck(self, image: np.ndarray, camera: Camera, odometer_m: float) -> None:
        o = self.overpass
        z = o.z_m - odometer_m
        x0, x1 = self.span_m
        bottom, top = o.clearance_m, o.clearance_m + o.thickness_m
        # The underside is in its own shadow; the front face is sun-lit concrete with a darker lip
        # and a parapet on top.
        fill(image, project_quads(camera, [rect_xz(x0, x1, max(z, NEAR_M), z + o.depth_m, bottom)]), 70.0)
        if z > NEAR_M:
            face, lip, rail = project_quads(camera, [rect_xy(x0, x1, bottom, top + 1.0, z),
                                                     rect_xy(x0, x1, bottom, bottom + 0.25, z),
                                                     rect_xy(x0, x1, top, top + 0.15, z)])
            fill(image, [face], 160.0)
            fill(image, [lip], 115.0)
            fill(image, [rail], 120.0)

    def shadow(self, odometer_m: float) -> list[tuple[np.ndarray, float]]:
        """The bridge's shadow band on the road, full road width: as dark as any cast shadow."""
        if self.overpass is None:
            return []
        o = self.overpass
        z0 = o.z_m + o.shadow_offset_m - odometer_m
        z1 = z0 + o.depth_m
        if z1 <= 0.3:
            return []
        return [(rect_xz(*self.span_m, max(z0, 0.3), z1), self.shadow_factor)]

    def light_at(self, z_m: float, odometer_m: float) -> float:
        """Brightness factor for a vehicle whose rear is at range z_m: in the bridge's shadow or not."""
        if self.overpass is None:
            return 1.0
        z0 = self.overpass.z_m + self.overpass.shadow_offset_m - odometer_m
        if z0 <= z_m <= z0 + self.overpass.depth_m:
            return min(1.0, 1.25 * self.shadow_factor)  # sky light only
        return 1.0
