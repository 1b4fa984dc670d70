"""Per-frame ground truth: what a perfect detector and range estimator would report.

The 2D box is the bounding box of the projected rear face (a fronto-parallel rectangle
standing on the road at ``z_m``), so its bottom is the image row of the road point under the
rear face: exactly what the flat-road range formula inverts. Visibility uses an id buffer
filled far-to-near like the renderer's painter's order.
"""
from __future__ import annotations

import numpy as np

from .camera import Camera
from .polygons import fill, project_quads, rect_xy
from .world import VehicleState, WorldState

MIN_RANGE_M = 0.5  # vehicles whose rear face is closer are not reported
DRAW_RANGE_M = 0.3  # ... nor drawn (the rear face is then beside or behind the camera)


def rear_face(vehicle: VehicleState) -> np.ndarray:
    """World corners (4, 3) of the rear face."""
    half = 0.5 * vehicle.spec.width_m
    return rect_xy(vehicle.x_m - half, vehicle.x_m + half, 0.0, vehicle.spec.height_m, vehicle.z_m)


def depth_order(state: WorldState) -> list[VehicleState]:
    """Drawable vehicles far to near (painter's order)."""
    return sorted((v for v in state.vehicles if v.z_m > DRAW_RANGE_M), key=lambda v: -v.z_m)


def frame_truth(state: WorldState, camera: Camera, ego_front_m: float, lane_width_m: float) -> list[dict]:
    """Truth records of the vehicles visible in this frame, nearest first."""
    drawable = depth_order(state)
    if not drawable:
        return []
    corners = np.array([rear_face(v) for v in drawable])
    u, v = camera.project(corners.reshape(-1, 3))
    u, v = u.reshape(-1, 4), v.reshape(-1, 4)
    in_front = np.isfinite(u).all(axis=1)  # not beside a strongly yawed camera (partly behind it)
    ordered = [vehicle for vehicle, ok in zip(drawable, in_front) if ok]
    boxes = [(float(a.min()), float(b.min()), float(a.max()), float(b.max())) for a, b in zip(u[in_front], v[in_front])]
    ids = np.zeros((camera.height, camera.width), np.uint16)
    alone = []
    for index, (polygon, box) in enumerate(zip(project_quads(camera, corners[in_front]), boxes), start=1):
        fill(ids, [polygon], index, antialias=False)
        alone.append(_count(ids, box, index))  # its pixels before nearer vehicles cover some
    bend = getattr(camera, "bend", None)
    if bend is not None:  # a bent road: the rear face's bottom centre in the ego's local frame
        local = bend.apply(np.array([[v.x_m, 0.0, v.z_m] for v in ordered]).reshape(-1, 3))
    records = []
    for index, (vehicle, box, n_alone) in enumerate(zip(ordered, boxes, alone), start=1):
        clipped = clip_to_image(box, camera.width, camera.height)
        if vehicle.z_m <= MIN_RANGE_M or clipped is None:
            continue
        full_area = (box[2] - box[0]) * (box[3] - box[1])
        in_image = (clipped[2] - clipped[0]) * (clipped[3] - clipped[1]) / full_area
        unoccluded = _count(ids, box, index) / n_alone if n_alone else 1.0
        closing_mps = -vehicle.relative_speed_mps
        gap_m = (vehicle.z_m if bend is None else float(local[index - 1, 2])) - ego_front_m
        records.append({
            "id": vehicle.spec.id,
            "kind": vehicle.spec.kind,
            "box": list(box),
            "box_clipped": list(clipped),
            "visible_fraction": float(min(1.0, in_image * unoccluded)),
            "lateral_m": (vehicle.x_m if bend is None else float(local[index - 1, 0])) - camera.lateral_m,
            "longitudinal_m": vehicle.z_m if bend is None else float(local[index - 1, 2]),
            "relative_speed_mps": vehicle.relative_speed_mps,
            "ttc_s": gap_m / closing_mps if closing_mps > 0 else None,
            "lane": int(np.round(vehicle.x_m / lane_width_m)),
            "width_m": vehicle.spec.width_m,
            "height_m": vehicle.spec.height_m,
            "speed_mps": vehicle.speed_mps,
        })
    return records[::-1]


def clip_to_image(box, width: int, height: int) -> tuple[float, ...] | None:
    """Box (left, top, right, bottom) clipped to the pixel centres of a width x height image; None when nothing of it
    is inside. The truth's `box_clipped`, and what a track's box is scored as (app/eval/track_score.py)."""
    l, t = max(float(box[0]), 0.0), max(float(box[1]), 0.0)
    r, b = min(float(box[2]), width - 1.0), min(float(box[3]), height - 1.0)
    return (l, t, r, b) if r > l and b > t else None


def _count(ids: np.ndarray, box: tuple[float, float, float, float], index: int) -> int:
    h, w = ids.shape
    l, t = max(0, int(np.floor(box[0]))), max(0, int(np.floor(box[1])))
    r, b = min(w, int(np.ceil(box[2])) + 1), min(h, int(np.ceil(box[3])) + 1)
    if r <= l or b <= t:
        return 0
    return int(np.count_nonzero(ids[t:b, l:r] == index))
