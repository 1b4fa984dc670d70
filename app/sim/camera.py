"""Pinhole camera over a flat road: the projection every Headway module shares.

Axes follow OpenCV: camera x right, y down, z forward. World: X right, Y up, Z forward,
origin on the road below the camera's longitudinal position in the centre of the ego lane
(so the camera sits at (lateral_m, height_m, 0)). A world point goes to the *level* camera
frame as (X - lateral_m, height_m - Y, Z); the camera is then turned by yaw (about its y
axis, positive = looking right) and afterwards by pitch (about its x axis, positive =
looking down). Because pitch is applied after yaw, the horizon of the flat road is the
row ``cy - fy * tan(pitch)`` whatever the yaw.
"""
from __future__ import annotations

import dataclasses
import functools
import math
from typing import Any, Mapping

import numpy as np

@dataclasses.dataclass(frozen=True)
class Camera:
    """The keys of the configuration's `camera` section (units and meaning there); ``from_dict`` fills
    the missing ones with the core's defaults."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    height_m: float
    pitch_deg: float
    yaw_deg: float
    lateral_m: float

    @classmethod
    def from_dict(cls, cfg: Mapping[str, Any] | None = None) -> "Camera":
        """Camera from the documented keys; missing keys take the defaults (``default_camera()``).

        When only ``width``/``height`` are given, the principal point defaults to the image centre.
        """
        cfg = dict(cfg or {})
        unknown = set(cfg) - set(CAMERA_KEYS)
        if unknown:
            raise ValueError(f"unknown camera key(s): {', '.join(sorted(unknown))}")
        merged = default_camera()
        merged.update(cfg)
        if "cx" not in cfg:
            merged["cx"] = merged["width"] / 2.0
        if "cy" not in cfg:
            merged["cy"] = merged["height"] / 2.0
        if "fy" not in cfg and "fx" in cfg:
            merged["fy"] = merged["fx"]
        merged["width"] = int(merged["width"])
        merged["height"] = int(merged["height"])
        return cls(**{k: (v if k in ("width", "height") else float(v)) for k, v in merged.items()})

    def to_dict(self) -> dict[str, float]:
        return dataclasses.asdict(self)

    def shaken(self, pitch_offset_deg: float, yaw_offset_deg: float) -> "Camera":
        """The same camera turned by this frame's shake offsets."""
        return dataclasses.replace(
            self, pitch_deg=self.pitch_deg + pitch_offset_deg, yaw_deg=self.yaw_deg + yaw_offset_deg
        )

    # --- rotations -------------------------------------------------------------------------
    @functools.cached_property
    def rotation(self) -> np.ndarray:
        """R mapping level-camera coordinates to camera coordinates (pitch after yaw); cached (frozen)."""
        b = math.radians(self.yaw_deg)
        p = math.radians(self.pitch_deg)
        # Yaw right by b: x_c = x cos b - z sin b, z_c = x sin b + z cos b.
        r_yaw = np.array([[math.cos(b), 0.0, -math.sin(b)], [0.0, 1.0, 0.0], [math.sin(b), 0.0, math.cos(b)]])
        # Pitch down by p: y_c = y cos p - z sin p, z_c = y sin p + z cos p.
        r_pitch = np.array([[1.0, 0.0, 0.0], [0.0, math.cos(p), -math.sin(p)], [0.0, math.sin(p), math.cos(p)]])
        return r_pitch @ r_yaw

    @functools.cached_property
    def K(self) -> np.ndarray:
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def horizon_row(self) -> float:
        """Image row of the flat road's vanishing line (independent of yaw, see module doc)."""
        return self.cy - self.fy * math.tan(math.radians(self.pitch_deg))

    # --- projection --------------------------------------------------------------------------
    def to_camera(self, points_xyz: np.ndarray) -> np.ndarray:
        """World points (N, 3) -> camera coordinates (N, 3)."""
        pts = np.asarray(points_xyz, dtype=np.float64).reshape(-1, 3)
        level = np.stack([pts[:, 0] - self.lateral_m, self.height_m - pts[:, 1], pts[:, 2]], axis=1)
        return level @ self.rotation.T

    def project(self, points_xyz: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World points (N, 3) -> pixel coordinates (u, v); points behind the camera give NaN."""
        cam = self.to_camera(points_xyz)
        z = cam[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = np.where(z > 1e-9, 1.0 / z, np.nan)
        return self.cx + self.fx * cam[:, 0] * inv, self.cy + self.fy * cam[:, 1] * inv

    def ground_from_pixel(self, u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixels -> flat-road point (X, Z); pixels on or above the horizon give NaN."""
        u = np.asarray(u, dtype=np.float64)
        v = np.asarray(v, dtype=np.float64)
        rays = np.stack([(u - self.cx) / self.fx, (v - self.cy) / self.fy, np.ones(np.broadcast(u, v).shape)], -1)
        level = rays @ self.rotation  # R^T applied to each ray (R is orthonormal)
        with np.errstate(divide="ignore", invalid="ignore"):
            scale = np.where(level[..., 1] > 1e-12, self.height_m / level[..., 1], np.nan)
        return self.lateral_m + scale * level[..., 0], scale * level[..., 2]

    def row_of_range(self, z_m: np.ndarray, x_m: np.ndarray | float | None = None) -> np.ndarray:
        """Image row of the road point at range ``z_m`` and lateral ``x_m`` (default: below the camera)."""
        z = np.asarray(z_m, dtype=np.float64)
        x = np.full_like(z, self.lateral_m) if x_m is None else np.broadcast_to(np.asarray(x_m, float), z.shape)
        _, v = self.project(np.stack([x.ravel(), np.zeros(z.size), z.ravel()], axis=1))
        return v.reshape(z.shape)

    def range_of_row(self, v_px: np.ndarray, x_m: np.ndarray | float | None = None) -> np.ndarray:
        """Range Z of the road point with lateral ``x_m`` that images at row ``v_px``.

        Exact inverse of :meth:`row_of_range`; rows on or above the horizon give NaN.
        """
        v = np.asarray(v_px, dtype=np.float64)
        x = (0.0 if x_m is None else np.asarray(x_m, float) - self.lateral_m)
        b = math.radians(self.yaw_deg)
        p = math.radians(self.pitch_deg)
        r = (v - self.cy) / self.fy
        # Row equation for level point (x, h, z): with z1 = x sin b + z cos b (depth after yaw),
        # r = (h cos p - z1 sin p) / (h sin p + z1 cos p)  =>  z1 = h (cos p - r sin p) / (sin p + r cos p).
        den = math.sin(p) + r * math.cos(p)
        with np.errstate(divide="ignore", invalid="ignore"):
            z1 = np.where(den > 1e-12, self.height_m * (math.cos(p) - r * math.sin(p)) / den, np.nan)
        return (z1 - x * math.sin(b)) / math.cos(b)

    def ground_to_image(self) -> np.ndarray:
        """Homography H with (u, v, 1) ~ H (X, Z, 1) for road points (Y = 0)."""
        # Level coordinates of a road point: (X - lateral, h, Z) = M (X, Z, 1).
        m = np.array([[1.0, 0.0, -self.lateral_m], [0.0, 0.0, self.height_m], [0.0, 1.0, 0.0]])
        return self.K @ self.rotation @ m


CAMERA_KEYS = tuple(f.name for f in dataclasses.fields(Camera))


def default_camera() -> dict[str, Any]:
    """The default camera of the product, the demo and every scenario that does not set its own: the
    core's ``CameraParams`` (csrc/geometry/camera.hpp) as the core describes them (``app.core.core_schema``),
    so that they are written once. A fresh dict each call."""
    return dict(_core_camera_defaults())


@functools.cache
def _core_camera_defaults() -> dict[str, Any]:
    from app.core import core_schema  # on first use, so that `import app.sim` alone does not load the core
    section = core_schema()["camera"]
    return {k: section[k]["default"] for k in CAMERA_KEYS}
