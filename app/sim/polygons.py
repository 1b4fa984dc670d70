"""World rectangles -> sub-pixel image polygons, shared by the renderer and the ground truth.

Every flat thing in the scene (rear faces, lane dashes, guardrail beams, shadows on the road)
is a planar rectangle in the world; its image is the exact projected quadrilateral, filled
with OpenCV in fixed point (``SHIFT`` fractional bits) so edges land at sub-pixel positions
and the truth boxes and the pixels agree. Pixel centres are at integer coordinates.
"""
from __future__ import annotations

import cv2
import numpy as np

from .camera import Camera
from .road_shape import pieces

SHIFT = 4  # fractional bits of the polygon vertices (1/16 px)
_SCALE = float(1 << SHIFT)
# Safety clamp for OpenCV's fixed point (int32 after the SHIFT): the near-plane clip keeps real
# vertices well inside it (100 m sideways at 5 cm depth is 1.4e6 px for fx = 700).
_LIMIT_PX = 1.0e7
_NEAR_CAM_M = 0.05  # near clipping plane (camera z)


def rect_xy(x0: float, x1: float, y0: float, y1: float, z: float) -> np.ndarray:
    """Fronto-parallel rectangle at depth z: corners (4, 3) in drawing order."""
    return np.array([[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]], dtype=np.float64)


def rect_xz(x0: float, x1: float, z0: float, z1: float, y: float = 0.0) -> np.ndarray:
    """Horizontal rectangle at height y (on the road for y = 0): corners (4, 3)."""
    return np.array([[x0, y, z0], [x1, y, z0], [x1, y, z1], [x0, y, z1]], dtype=np.float64)


def rect_yz(x: float, y0: float, y1: float, z0: float, z1: float) -> np.ndarray:
    """Vertical rectangle along the road at lateral x (guardrail faces): corners (4, 3)."""
    return np.array([[x, y0, z0], [x, y0, z1], [x, y1, z1], [x, y1, z0]], dtype=np.float64)


def project_quads(camera: Camera, corners: np.ndarray, row_offset: float = 0.0) -> list[np.ndarray]:
    """World polygons (n, k, 3) -> fixed-point image polygons (each (m, 2) int32).

    Parts behind the camera's near plane are cut off first (a bridge deck reaching past the
    side of a yawed camera), so every returned vertex is a finite projection. ``row_offset``
    is subtracted from the rows (for drawing into a band of the image).
    """
    if getattr(camera, "bend", None) is not None:
        return _project_bent(camera, corners, row_offset)
    corners = np.asarray(corners, dtype=np.float64)
    n, k = corners.shape[:2]
    cam = camera.to_camera(corners.reshape(-1, 3)).reshape(n, k, 3)
    if cam[..., 2].min() >= _NEAR_CAM_M:  # the usual case: all in front, one vectorised step
        return list(_to_fixed(camera, cam, row_offset))
    # One output per input (an empty one when all of it is behind the camera): callers zip them.
    return [_to_fixed(camera, _clip_near(poly), row_offset) for poly in cam]


def _project_bent(camera: Camera, corners, row_offset: float) -> list[np.ndarray]:
    """Road-coordinate polygons on a bent road (road_shape.BentCamera): each cut at the camera's view limit
    (a crest), its edges divided into pieces short enough to follow the road, bent (all polygons in one
    call), clipped at the near plane. A divided polygon's image is no longer convex but still crosses every
    image row at most twice (its rows rise monotonically with the range up to the view limit), which
    cv2.fillConvexPoly fills exactly; cv2.fillPoly would round its vertices to whole rows (2 px sideways
    on a line that slants 4 px a row)."""
    outlines = []
    for poly in corners:
        poly = _clip_plane(np.asarray(poly, dtype=np.float64), 2, camera.view_m, keep_below=True)
        points = []
        for i in range(len(poly)):
            a, b = poly[i], poly[(i + 1) % len(poly)]
            points.append(a[None, :])
            if abs(b[2] - a[2]) > 1e-9:
                z = pieces(a[2], b[2])[1:-1]
                points.append(a + ((z - a[2]) / (b[2] - a[2]))[:, None] * (b - a))
        outline = np.concatenate(points) if points else np.empty((0, 3))
        outlines.append(outline)
    sizes = np.cumsum([len(o) for o in outlines])[:-1]
    cams = np.split(camera.to_camera(np.concatenate(outlines)), sizes) if sizes.size or outlines else []
    out = []
    for cam in cams:
        cam = _clip_near(cam) if len(cam) >= 3 else cam
        out.append(_to_fixed(camera, cam, row_offset) if len(cam) >= 3 else np.empty((0, 2), np.int32))
    return out


def _to_fixed(camera: Camera, cam: np.ndarray, row_offset: float) -> np.ndarray:
    """Camera coordinates (..., 3) -> fixed-point pixel coordinates (..., 2) int32."""
    uv = np.stack([camera.cx + camera.fx * cam[..., 0] / cam[..., 2],
                   camera.cy + camera.fy * cam[..., 1] / cam[..., 2] - row_offset], axis=-1)
    return np.round(np.clip(uv, -_LIMIT_PX, _LIMIT_PX) * _SCALE).astype(np.int32)


def _clip_near(poly: np.ndarray) -> np.ndarray:
    """Sutherland-Hodgman against the plane z = _NEAR_CAM_M (camera coordinates)."""
    return _clip_plane(poly, 2, _NEAR_CAM_M, keep_below=False)


def _clip_plane(poly: np.ndarray, axis: int, level: float, keep_below: bool) -> np.ndarray:
    """Sutherland-Hodgman: the part of a polygon (k, 3) with coordinate ``axis`` >= level (<= when keep_below)."""
    kept = []
    for i in range(len(poly)):
        a, b = poly[i], poly[(i + 1) % len(poly)]
        a_in, b_in = (a[axis] <= level, b[axis] <= level) if keep_below else (a[axis] >= level, b[axis] >= level)
        if a_in:
            kept.append(a)
        if a_in != b_in:
            t = (level - a[axis]) / (b[axis] - a[axis])
            kept.append(a + t * (b - a))
    return np.array(kept).reshape(-1, 3)


def fill(image: np.ndarray, polygons: list[np.ndarray], value: float, antialias: bool = True) -> None:
    """Fill fixed-point convex polygons (from :func:`project_quads`) one by one with one value (in place).

    One by one because ``cv2.fillPoly`` fills a polygon set by the even-odd rule: where two
    overlap (lines meeting at the vanishing point) it would leave a hole.
    """
    line = cv2.LINE_AA if antialias else cv2.LINE_8
    for polygon in polygons:
        if len(polygon) >= 3:
            cv2.fillConvexPoly(image, polygon, float(value), line, SHIFT)
