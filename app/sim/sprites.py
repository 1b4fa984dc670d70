"""Real vehicle rear views for the renderer: the GTI patches of ../shared/data, each cut to its car's extent.

The patches (64x64 colour crops of cars on Spanish motorways, rear views) hold a car with a margin of road
and traffic around it that differs from patch to patch. A sprite is drawn onto the rear face's projected box,
so the crop must be exactly the car: then the truth box is the drawn car's extent. ``vehicle_extent`` finds it
by two independent measurements and keeps only the patches where they agree (docs/sim.md, "Real-looking
vehicles", has the rule, the counts and the check with the learned detector):

- bottom: the tyres' contact line, the lowest row of the dark band under the car (the centre half's row mean
  below halfway between its darkest lower row and the road in the patch's last two rows);
- sides, twice: (a) the dark run through the centre of the tyre rows (the five rows above the bottom),
  against the road below each column; (b) the mirror-symmetric pair of columns with the strongest vertical
  edges over the car's lower half (a rear view is symmetric about the centre of its patch, within 4 px);
  a patch is kept when (a) and (b) agree within ``SIDE_TOLERANCE_PX`` on both sides and neither side is the
  patch's first or last column (there the car may go on past the border: a van's side, a car cut by the crop);
- top: the car's rear-face aspect (``CAR_ASPECT``, the middle of the scenarios' car sizes) above the bottom;
  a patch whose car would reach above its top row is dropped.
"""
from __future__ import annotations

import dataclasses
import functools
from pathlib import Path

import cv2
import numpy as np

from .scenario import ScenarioError

# ../shared/data beside the repository (as tests/conftest.py finds it); never copied into the repository.
PATCHES_DIR = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "patches" / "vehicles"
# The GTI rear views (far, middle/close, left and right lanes). KITTI_extracted is left out: most of its crops are
# side views or blurred upscales with colour fringes, and its cars seldom sit on a visible road line.
SPRITE_FOLDERS = ("GTI_Far", "GTI_MiddleClose", "GTI_Left", "GTI_Right")
CAR_ASPECT = 1.21  # rear-face width / height of the scenarios' cars: (1.68..1.88) / (1.38..1.55)
SIDE_TOLERANCE_PX = 3  # the two side measurements must agree this well (64 px patches)
MIN_CONTRAST = 25.0  # gray levels between the dark band under the car and the road below it
REFERENCE_ROAD_GRAY = 118.0  # each sprite is scaled so that the road under its car has this gray (the default asphalt)
TAIL_RED_RATIO = 1.35  # a tail-light pixel: red above this multiple of green and of blue ...
TAIL_MIN_RED = 70  # ... and at least this red
MAX_LIGHT_SHARE = 0.12  # more red than this share of the car is a red body: the lamps are then placed as on a car
# (left, right) share of the width and (top, bottom) share of the height of each tail lamp on a car's rear
# (the plain look's lamps: 0.02-0.2 of the width, 0.56-0.68 of the height above the road)
LAMPS = (((0.02, 0.2), (0.32, 0.44)), ((0.8, 0.98), (0.32, 0.44)))


@dataclasses.dataclass(frozen=True)
class Sprite:
    """One car cut to its extent: gray scaled to ``REFERENCE_ROAD_GRAY`` road, and where its tail lights are."""

    name: str  # folder/file of the patch
    gray: np.ndarray  # float32 (h, w): rows top..bottom, columns left..right of the car, both inclusive
    lights: np.ndarray  # float32 (h, w) 0..1: red tail-light pixels, brightened while braking
    median_gray: float  # of ``gray``: how light the car is (matched to a vehicle's shade)


def vehicle_extent(bgr: np.ndarray) -> tuple[int, int, int, int] | None:
    """The car's (left, top, right, bottom) pixel columns and rows (inclusive) in a rear-view patch, or None when
    the measurements disagree or the car is not wholly inside (rule in the module docstring)."""
    g = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY).astype(np.float32)
    h, w = g.shape
    rows = g[:, w // 4: 3 * w // 4].mean(axis=1)
    road, dark = rows[-2:].mean(), rows[h // 2: h - 2].min()
    if road - dark < MIN_CONTRAST:  # no road under the car: the car is cut at the bottom
        return None
    below = np.nonzero(rows[h // 2: h - 2] < 0.5 * (road + dark))[0]
    bottom = h // 2 + int(below[-1])
    run = _dark_run(g, bottom)
    edges = _symmetric_edges(g, bottom)
    if abs(run[0] - edges[0]) > SIDE_TOLERANCE_PX or abs(run[1] - edges[1]) > SIDE_TOLERANCE_PX:
        return None
    left, right = (run[0] + edges[0]) // 2, (run[1] + edges[1] + 1) // 2
    if left == 0 or right == w - 1:
        return None
    top = int(round(bottom + 1 - (right - left + 1) / CAR_ASPECT))
    return (left, top, right, bottom) if top >= 0 else None


def _dark_run(g: np.ndarray, bottom: int) -> tuple[int, int]:
    """Sides (a): the run of tyre-row columns darker than halfway to the road below them, through the centre."""
    h, w = g.shape
    band = g[max(0, bottom - 4): bottom + 1].mean(axis=0)
    centre = band[w // 2 - 4: w // 2 + 4].mean()
    inside = band < 0.5 * (centre + g[-2:].mean(axis=0))
    left, right = w // 2, w // 2 - 1
    while left > 0 and inside[left - 1]:
        left -= 1
    while right < w - 1 and inside[right + 1]:
        right += 1
    return left, right


def _symmetric_edges(g: np.ndarray, bottom: int) -> tuple[int, int]:
    """Sides (b): the pair of columns, mirror images about a centre within 4 px of the patch's, with the largest sum
    of mean |d/dx| over the car's lower half; at least 60 % of the patch apart."""
    h, w = g.shape
    gx = np.abs(cv2.Sobel(g, cv2.CV_32F, 1, 0, ksize=3))
    col = gx[max(0, bottom - h // 2): bottom + 1].mean(axis=0)
    col[0], col[-1] = col[1], col[-2]  # the Sobel response is 0 on the border: a car ending there takes its neighbour's
    best = (-1.0, 0, w - 1)
    for c2 in range(w - 8, w + 9):  # twice the centre column, so that half columns count
        for s2 in range(int(0.6 * w), w + 1):
            l2, r2 = c2 - s2, c2 + s2
            if l2 % 2 or l2 < 0 or r2 > 2 * (w - 1):
                continue
            score = float(col[l2 // 2] + col[r2 // 2])
            if score > best[0]:
                best = (score, l2 // 2, r2 // 2)
    return best[1], best[2]


def tail_lights(bgr: np.ndarray) -> np.ndarray:
    """0..1 mask of a car crop's tail lights, softened by one pixel: its red pixels, or, when there are none or the
    body itself is red, the two lamps where a car has them (``LAMPS``)."""
    b, g, r = (bgr[..., k].astype(np.float32) for k in range(3))
    red = ((r >= TAIL_MIN_RED) & (r > TAIL_RED_RATIO * g) & (r > TAIL_RED_RATIO * b)).astype(np.float32)
    if not 0.0 < red.mean() <= MAX_LIGHT_SHARE:
        h, w = red.shape
        red[:] = 0.0
        for (x0, x1), (y0, y1) in LAMPS:
            red[round(y0 * h): round(y1 * h) + 1, round(x0 * w): round(x1 * w) + 1] = 1.0
    return cv2.GaussianBlur(red, (3, 3), 0)


def missing_patches_message(folder: Path) -> str:
    return (f"vehicle_look: real draws vehicles from the vehicle patches in {folder} (../shared/data/patches/vehicles "
            f"beside the repository), which is missing or holds no usable patch; put the data there, or set "
            f"vehicle_look: plain in the scenario to draw plain rear faces")


def patches_problem(folder: str | Path | None = None) -> str:
    """Why ``vehicle_look: real`` cannot draw from ``folder`` (default ``PATCHES_DIR``), or "" when it can."""
    try:
        load_sprites(folder)
    except ScenarioError as exc:
        return str(exc)
    return ""


def load_sprites(folder: str | Path | None = None) -> tuple[Sprite, ...]:
    """Every usable patch of ``SPRITE_FOLDERS`` under ``folder`` (default ``PATCHES_DIR``), in file-name order;
    ScenarioError when there is none. Read once per folder and process."""
    return _load_sprites(Path(PATCHES_DIR if folder is None else folder).resolve())


@functools.lru_cache(maxsize=4)
def _load_sprites(folder: Path) -> tuple[Sprite, ...]:
    sprites = []
    for sub in SPRITE_FOLDERS:
        for path in sorted((folder / sub).glob("*.png")):
            bgr = cv2.imread(str(path), cv2.IMREAD_COLOR)
            extent = None if bgr is None else vehicle_extent(bgr)
            if extent is None:
                continue
            left, top, right, bottom = extent
            gray = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY).astype(np.float32)
            gain = REFERENCE_ROAD_GRAY / max(float(np.median(gray[bottom + 1:])), 1.0)
            car = np.ascontiguousarray(gray[top: bottom + 1, left: right + 1] * gain)
            lights = tail_lights(bgr[top: bottom + 1, left: right + 1])
            sprites.append(Sprite(f"{sub}/{path.name}", car, lights, float(np.median(car))))
    if not sprites:
        raise ScenarioError(missing_patches_message(folder))
    return tuple(sprites)


def pick_sprite(sprites: tuple[Sprite, ...], shade: float, seed: int, vehicle_id: int, candidates: int = 8) -> Sprite:
    """The sprite of one vehicle for the whole run: one of the ``candidates`` sprites whose median gray is nearest
    its shade, chosen by (seed, id), so a dark car stays dark and the same scenario draws the same cars."""
    order = np.argsort([abs(s.median_gray - shade) for s in sprites], kind="stable")
    pick = np.random.default_rng([seed, vehicle_id, 0x5B1]).integers(0, min(candidates, len(sprites)))
    return sprites[int(order[pick])]
