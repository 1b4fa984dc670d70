"""`headway calibrate`: the camera's intrinsics and lens distortion from chessboard photos (the mounting from a
drive, `--from-video`, is app/calibrate_drive.py).

For each photo: cv2.findChessboardCorners finds the board's inner corners, cv2.cornerSubPix refines
them to a tenth of a pixel; cv2.calibrateCamera then fits K = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]
and the distortion (k1, k2, p1, p2, k3) of OpenCV's model
    x_d = x (1 + k1 r^2 + k2 r^4 + k3 r^6) + 2 p1 x y + p2 (r^2 + 2 x^2)
    y_d = y (1 + k1 r^2 + k2 r^4 + k3 r^6) + p1 (r^2 + 2 y^2) + 2 p2 x y,    r^2 = x^2 + y^2
(x, y normalised ideal coordinates, x_d, y_d the distorted ones) by minimising the reprojection
error of every corner (cv2.calibrateCameraRO: the board's points are fitted too, see _fit; a view far
worse than the rest is dropped and named). The RMS of that error (px) is reported and written beside the keys.

The output is a configuration YAML with the `camera:` section (width, height, fx, fy, cx, cy, k1,
k2, p1, p2, k3); the mounting keys (height_m, pitch_deg, yaw_deg) are not written: the chessboard
says nothing about them. The core undistorts image points where it maps them to the road
(csrc/geometry/lens.hpp), not whole images.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
import yaml

from app import calibrate_drive
from app.output_files import check_outputs, numbered, write_whole

MIN_VIEWS = 3
# Photos a pixel or two larger than the first are the same camera (Udacity's camera_cal has 1281x721
# among its 1280x720 photos: an export's rounding); the corners are unaffected, the first size is used.
MAX_SIZE_SLACK_PX = 2
OUTLIER_FACTOR = 2.5  # a view whose RMS exceeds this many times the median view's is dropped  # calibrateCamera needs several views of the board in different poses to fit 9 unknowns


@dataclass
class Calibration:
    width: int
    height: int
    K: np.ndarray                 # 3x3 camera matrix
    dist: np.ndarray              # k1, k2, p1, p2, k3
    rms_px: float                 # RMS reprojection error over every corner of every used view
    used: list[str] = field(default_factory=list)     # photos whose board was found
    skipped: list[str] = field(default_factory=list)  # photos without a board (named in the report)
    corners: list[np.ndarray] = field(default_factory=list)  # refined corners per used photo, (N, 2)
    rejected: dict[str, float] = field(default_factory=dict)  # photos dropped as outliers -> their RMS px

    def camera_section(self) -> dict:
        k1, k2, p1, p2, k3 = (float(x) for x in self.dist.ravel()[:5])
        return {"width": self.width, "height": self.height,
                "fx": float(self.K[0, 0]), "fy": float(self.K[1, 1]),
                "cx": float(self.K[0, 2]), "cy": float(self.K[1, 2]),
                "k1": k1, "k2": k2, "p1": p1, "p2": p2, "k3": k3}


def parse_board(text: str) -> tuple[int, int]:
    """'9x6' -> (9, 6) inner corners per row and per column."""
    try:
        cols, rows = (int(x) for x in text.lower().split("x"))
    except ValueError:
        raise ValueError(f"--board {text!r}: expected inner corners as COLSxROWS, e.g. 9x6") from None
    if cols < 2 or rows < 2:
        raise ValueError(f"--board {text!r}: a board needs at least 2x2 inner corners")
    return cols, rows


def find_corners(gray: np.ndarray, board: tuple[int, int]) -> np.ndarray | None:
    """The board's inner corners refined to sub-pixel, (N, 2) row by row; None when not found."""
    ok, corners = cv2.findChessboardCorners(gray, board, flags=cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE)
    if not ok:
        return None
    # 11x11 window: the squares of a photographed board are 30-100 px, the window stays inside one
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 1e-3)
    corners = cv2.cornerSubPix(gray, corners, (11, 11), (-1, -1), criteria)
    return corners.reshape(-1, 2)


def calibrate(paths: list[str], board: tuple[int, int]) -> Calibration:
    """Intrinsics from chessboard photos; ValueError naming the photos when it cannot be done."""
    if not paths:
        raise ValueError("no chessboard images given")
    size = None
    used, skipped, corners = [], [], []
    for p in paths:
        img = cv2.imread(str(p), cv2.IMREAD_GRAYSCALE)
        if img is None:
            raise ValueError(f"{p}: cannot read the image (missing file or not an image)")
        if size is None:
            size = img.shape[::-1]
        elif max(abs(img.shape[1] - size[0]), abs(img.shape[0] - size[1])) > MAX_SIZE_SLACK_PX:
            raise ValueError(f"{p}: image is {img.shape[1]}x{img.shape[0]}, the first one is {size[0]}x{size[1]}; "
                             "all photos must come from the same camera at the same resolution")
        c = find_corners(img, board)
        if c is None:
            skipped.append(str(p))
        else:
            used.append(str(p))
            corners.append(c)
    if len(used) < MIN_VIEWS:
        raise ValueError(f"the {board[0]}x{board[1]} board was found in {len(used)} of {len(paths)} images, "
                         f"at least {MIN_VIEWS} are needed; check --board (inner corners, not squares) and "
                         "that the whole board is in view")
    obj = np.zeros((board[0] * board[1], 3), np.float32)
    obj[:, :2] = np.mgrid[0:board[0], 0:board[1]].T.reshape(-1, 2)  # unit squares: scale does not matter
    rms, K, dist, per_view = _fit(obj, corners, size, board)
    # A view far worse than the others (a photo resampled on export, a blurred board) pulls every
    # parameter: drop views beyond OUTLIER_FACTOR x the median view error once, and fit again.
    keep = [i for i, e in enumerate(per_view) if e <= OUTLIER_FACTOR * float(np.median(per_view))]
    rejected = {used[i]: per_view[i] for i in range(len(used)) if i not in keep}
    if rejected and len(keep) >= MIN_VIEWS:
        used, corners = [used[i] for i in keep], [corners[i] for i in keep]
        rms, K, dist, per_view = _fit(obj, corners, size, board)
    else:
        rejected = {}
    return Calibration(size[0], size[1], K, dist.ravel()[:5], float(rms), used, skipped, corners, rejected)


def _fit(obj: np.ndarray, corners: list[np.ndarray], size: tuple[int, int], board: tuple[int, int]):
    """calibrateCamera's model fitted with the board's own points released (cv2.calibrateCameraRO, Strobl &
    Hirzinger 2011): a board printed on paper is not quite flat, and fitting its 3-D points besides K and the
    distortion keeps that from showing up as reprojection error and bending the intrinsics (Udacity
    camera_cal, 16 views: RMS 0.83 px with the board taken as flat, 0.48 px released). The corner at the end
    of the first row stays fixed with the first corner (the scale)."""
    pts = [c.astype(np.float32) for c in corners]
    rms, K, dist, rvecs, tvecs, new_obj = cv2.calibrateCameraRO([obj] * len(pts), pts, size, board[0] - 1,
                                                               None, None)[:6]
    per_view = []
    for c, r, t in zip(pts, rvecs, tvecs):
        proj, _ = cv2.projectPoints(new_obj, r, t, K, dist)
        per_view.append(float(np.sqrt(np.mean(np.sum((proj.reshape(-1, 2) - c) ** 2, axis=1)))))
    return float(rms), K, dist, per_view


def undistort(cal: Calibration, pts: np.ndarray) -> np.ndarray:
    """Image points (N, 2) without the lens distortion, in pixels of the same camera matrix."""
    return cv2.undistortPoints(pts.reshape(-1, 1, 2).astype(np.float64), cal.K, cal.dist, P=cal.K).reshape(-1, 2)


def row_straightness(corners: np.ndarray, board: tuple[int, int]) -> float:
    """RMS distance (px) of the corners from the straight line fitted through each board row (total least
    squares): 0 for a pinhole camera, larger the more the lens bends straight lines."""
    cols, rows = board
    res = []
    for r in range(rows):
        p = corners[r * cols:(r + 1) * cols]
        q = p - p.mean(axis=0)
        # smallest singular value = residual along the line's normal
        s = np.linalg.svd(q, compute_uv=False)
        res.append(s[-1] ** 2 / len(p))
    return float(np.sqrt(np.mean(res)))


def write_yaml(cal: Calibration, out: str | Path) -> None:
    text = (f"# headway calibrate: {len(cal.used)} views, RMS reprojection error {cal.rms_px:.3f} px\n"
            "# the mounting (height_m, pitch_deg, yaw_deg) is not measured by a chessboard: set it separately\n")
    text += yaml.safe_dump({"camera": cal.camera_section()}, sort_keys=False)
    write_whole(out, text)


def add_parser(subparsers) -> None:
    s = subparsers.add_parser("calibrate", help="camera intrinsics and lens distortion from chessboard photos, or the "
                                         "mounting (pitch, yaw, height) from a drive (--from-video) -> YAML")
    s.add_argument("images", nargs="*", help="chessboard photos from the camera, the board in different poses")
    s.add_argument("--board", default="9x6", help="inner corners per row x per column (default 9x6)")
    s.add_argument("--from-video", metavar="CLIP",
                   help="a drive on a marked road (video file or image folder): self-calibration's pitch, yaw and "
                        "height with their sigmas, written into the camera section of --config's copy")
    s.add_argument("--config", help="with --from-video: the configuration with the camera's intrinsics (and height)")
    s.add_argument("--fps", type=float, help="with --from-video: an image folder's frame rate")
    s.add_argument("--out", required=True, help="write the configuration here (.yaml)")
    s.set_defaults(run=run)


def run(args) -> int:
    check_outputs({"--out": args.out}, {**numbered("input", args.images), "--config": args.config})
    if args.from_video:
        if args.images:
            raise ValueError("give chessboard photos or --from-video CLIP, not both")
        return calibrate_drive.main(args)
    if not args.images:
        raise ValueError("give chessboard photos (intrinsics) or --from-video CLIP (the mounting from a drive)")
    board = parse_board(args.board)
    cal = calibrate(args.images, board)
    write_yaml(cal, args.out)
    before = float(np.mean([row_straightness(c, board) for c in cal.corners]))
    after = float(np.mean([row_straightness(undistort(cal, c), board) for c in cal.corners]))
    s = cal.camera_section()
    print(f"{len(cal.used)} of {len(args.images)} images used; RMS reprojection error {cal.rms_px:.3f} px")
    for p in cal.skipped:
        print(f"  board not found: {p}")
    for p, e in cal.rejected.items():
        print(f"  dropped as an outlier (reprojection {e:.2f} px): {p}")
    print(f"fx {s['fx']:.1f} fy {s['fy']:.1f} cx {s['cx']:.1f} cy {s['cy']:.1f}  "
          f"k1 {s['k1']:.4f} k2 {s['k2']:.4f} p1 {s['p1']:.5f} p2 {s['p2']:.5f} k3 {s['k3']:.4f}")
    print(f"board rows off a straight line: {before:.2f} px as photographed, {after:.3f} px undistorted")
    print(f"camera section -> {args.out}")
    return 0
