"""Curves and hills: the road's reference line in 3-D, and the bend it gives everything on the road.

A straight, level road is the flat world of camera.py. A scenario with ``road.curves`` or
``road.hills`` bends it: the road's reference line (the centre of the ego's starting lane) has a
plan curvature kappa(s) and a vertical curvature kappa_v(s), both piecewise constant in the arc
length s (constant-curvature segments). With heading theta (right of the start direction) and grade
gamma (uphill positive)

    theta(s) = int_0^s kappa,  gamma(s) = int_0^s kappa_v      (piecewise linear: exact)
    C(s) = int_0^s (sin theta cos gamma, sin gamma, cos theta cos gamma) ds   (the line, world x y z)
    T = dC/ds,  N = (cos theta, 0, -sin theta) (right, level: no cross slope),  U = T x N (up)

and a point given in *road coordinates* (X right of the reference line, Y above the surface, Z ahead
along the road from the ego's position s_e) is P = C(s_e + Z) + X N + Y U. The ego stands on the
road at s_e, aligned with it (its wheels on the local surface, so its frame is (N, U, T) at s_e):
the camera sees the point at R_e (P - C(s_e)) in that local frame (x right, y up, z forward), which
is exactly the flat world's coordinates when the road is straight and level. So the camera pose
relative to the *local* road stays the configured mounting, and everything the renderer places in
road coordinates (markings, vehicles, shadows, scenery) follows the road.

C(s) is integrated on a 0.5 m grid (midpoint rule; its error for a 500 m radius is below 0.1 mm)
and interpolated linearly between grid points.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from .camera import CAMERA_KEYS, Camera

GRID_M = 0.5  # integration step of the reference line
BEHIND_M = 100.0  # the line is also built this far behind the start (vehicles behind the ego)
# Bent polygons are cut into pieces no longer (in Z) than max(MIN_PIECE_M, PIECE_FRACTION * Z): the chord
# of a bent edge then deviates from the road by kappa (f Z)^2 / 8, below 0.05 px for radii >= 300 m.
MIN_PIECE_M = 0.5
PIECE_FRACTION = 0.03
MAX_VIEW_M = 1500.0  # bent ground is drawn to this range (haze has covered it long before)


@dataclasses.dataclass(frozen=True)
class Segment:
    """Constant curvature over [s_m, s_m + length_m] of the reference line (1/m; sign in the spec)."""

    s_m: float
    length_m: float
    curvature_1pm: float


def _integrate(segments: tuple[Segment, ...], s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(curvature at s, its integral from 0 to s) for piecewise-constant curvature segments."""
    kappa = np.zeros_like(s)
    angle = np.zeros_like(s)
    for seg in segments:
        inside = np.clip(s - seg.s_m, 0.0, seg.length_m)  # arc of this segment covered up to s (<= 0: none)
        angle = angle + seg.curvature_1pm * inside
        kappa = np.where((s >= seg.s_m) & (s < seg.s_m + seg.length_m), kappa + seg.curvature_1pm, kappa)
    return kappa, angle


class RoadShape:
    """The reference line of a bent road over arc lengths [-BEHIND_M, length_m]."""

    def __init__(self, curves: tuple[Segment, ...], hills: tuple[Segment, ...], length_m: float):
        self.curves, self.hills = curves, hills
        self.s = np.arange(-BEHIND_M, length_m + GRID_M, GRID_M)
        mid = self.s[:-1] + 0.5 * GRID_M
        theta, gamma = self.heading(mid), self.grade(mid)
        steps = np.stack([np.sin(theta) * np.cos(gamma), np.sin(gamma), np.cos(theta) * np.cos(gamma)], 1) * GRID_M
        line = np.concatenate([np.zeros((1, 3)), np.cumsum(steps, axis=0)])
        self.line = line - self._interp(line, 0.0)  # C(0) = origin
        self.angles = np.stack([self.heading(self.s), self.grade(self.s)], 1)  # piecewise linear: exact at the grid

    def curvature(self, s) -> np.ndarray:
        """Plan curvature (1/m, > 0 bends right) at arc length s."""
        return _integrate(self.curves, np.asarray(s, float))[0]

    def vertical_curvature(self, s) -> np.ndarray:
        """Vertical curvature (1/m, > 0 sag: the road curves up) at arc length s."""
        return _integrate(self.hills, np.asarray(s, float))[0]

    def heading(self, s) -> np.ndarray:
        """theta(s), rad, right of the start direction."""
        return _integrate(self.curves, np.asarray(s, float))[1]

    def grade(self, s) -> np.ndarray:
        """gamma(s), rad, uphill positive."""
        return _integrate(self.hills, np.asarray(s, float))[1]

    def _interp(self, table: np.ndarray, s) -> np.ndarray:
        s = np.asarray(s, float)
        if (s < self.s[0]).any() or (s > self.s[-1]).any():
            raise ValueError(f"arc length outside the road built ({self.s[0]:.0f}..{self.s[-1]:.0f} m)")
        return np.stack([np.interp(s, self.s, table[:, k]) for k in range(3)], axis=-1)

    def frame(self, s) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """C, N, U, T at arc length(s) s: each (..., 3) in world x right, y up, z forward."""
        s = np.asarray(s, float)
        th = np.interp(s, self.s, self.angles[:, 0])  # exact unless a segment ends between grid points
        ga = np.interp(s, self.s, self.angles[:, 1])
        zero = np.zeros_like(th)
        t = np.stack([np.sin(th) * np.cos(ga), np.sin(ga), np.cos(th) * np.cos(ga)], -1)
        n = np.stack([np.cos(th), zero, -np.sin(th)], -1)
        u = np.cross(t, n)
        return self._interp(self.line, s), n, u, t

    def bend_at(self, s_ego: float) -> "Bend":
        c, n, u, t = self.frame(s_ego)
        return Bend(self, float(s_ego), c, np.stack([n, u, t]))


@dataclasses.dataclass(frozen=True, eq=False)
class Bend:
    """Road coordinates -> the ego's local frame (flat-world coordinates) at arc length s_ego."""

    shape: RoadShape
    s_ego: float
    origin: np.ndarray  # C(s_ego), world
    rows: np.ndarray  # (3, 3): N, U, T at s_ego (world -> local is rows @ (P - origin))

    def apply(self, points: np.ndarray) -> np.ndarray:
        """Road-coordinate points (N, 3) -> local frame (N, 3)."""
        p = np.asarray(points, float).reshape(-1, 3)
        c, n, u, _ = self.shape.frame(self.s_ego + p[:, 2])
        world = c + p[:, :1] * n + p[:, 1:2] * u
        return (world - self.origin) @ self.rows.T

    def view_limit_m(self, height_m: float) -> float:
        """Farthest Z (road coordinates) of the surface a camera at height_m sees before a crest hides it.

        The road's image row falls with range while the sight line's slope (Y - h) / Z rises; beyond
        the crest's tangent point the road is hidden behind the nearer road.
        """
        z = np.concatenate([np.arange(1.0, 50.0, 0.5), np.geomspace(50.0, MAX_VIEW_M, 300)])
        z = z[self.s_ego + z <= self.shape.s[-1]]
        local = self.apply(np.stack([np.zeros_like(z), np.zeros_like(z), z], 1))
        slope = (local[:, 1] - height_m) / np.maximum(local[:, 2], 1e-6)  # tan of the sight line's elevation
        rising = np.maximum.accumulate(slope)
        hidden = np.nonzero(slope < rising - 1e-9)[0]
        return float(z[hidden[0] - 1] if hidden.size else z[-1])


def _piece_grid() -> np.ndarray:
    """Breakpoints from -BEHIND_M to MAX_VIEW_M spaced by max(MIN_PIECE_M, PIECE_FRACTION |Z|)."""
    ahead = [0.0]
    while ahead[-1] < MAX_VIEW_M + 100.0:
        ahead.append(ahead[-1] + max(MIN_PIECE_M, PIECE_FRACTION * ahead[-1]))
    ahead = np.array(ahead)
    behind = -ahead[(ahead > 0) & (ahead <= BEHIND_M + 10.0)][::-1]
    return np.concatenate([behind, ahead])


_GRID = _piece_grid()


def pieces(z0: float, z1: float) -> np.ndarray:
    """Z values from z0 to z1 (both included), the breakpoints in between spaced by
    max(MIN_PIECE_M, PIECE_FRACTION |Z|)."""
    lo, hi = min(z0, z1), max(z0, z1)
    inner = _GRID[(_GRID > lo) & (_GRID < hi)]
    out = np.concatenate([[lo], inner, [hi]])
    return out if z0 <= z1 else out[::-1]


@dataclasses.dataclass(frozen=True)
class BentCamera(Camera):
    """A camera on a bent road: points in road coordinates go through the bend before the flat camera's
    projection (``to_camera``); with ``bend`` None it is the flat camera. ``heading_rad`` and ``grade_rad``
    (the ego's direction against the start of the road) turn the sky's tree line, which is at infinity."""

    bend: Bend | None = None
    heading_rad: float = 0.0
    grade_rad: float = 0.0
    view_m: float = math.inf  # road-coordinate Z beyond which nothing is drawn (behind a crest)

    def to_camera(self, points_xyz: np.ndarray) -> np.ndarray:
        pts = np.asarray(points_xyz, dtype=np.float64).reshape(-1, 3)
        return super().to_camera(self.bend.apply(pts) if self.bend is not None else pts)

    def to_dict(self) -> dict[str, float]:
        return {k: getattr(self, k) for k in CAMERA_KEYS}

    def sky_camera(self) -> Camera:
        """The flat camera turned as the ego is against the world: what sees the tree line at infinity."""
        return Camera(**{**self.to_dict(), "yaw_deg": self.yaw_deg + math.degrees(self.heading_rad),
                         "pitch_deg": self.pitch_deg - math.degrees(self.grade_rad)})
