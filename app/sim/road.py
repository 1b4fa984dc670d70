"""The road plane and the sky: world-fixed asphalt texture, lane markings, cast shadows, haze.

Everything on the road is a function of the world position (X, Z + odometer), so between two
frames road pixels move exactly by the road-plane homography (what the parallax detector
relies on). The texture is a sum of periodic noise layers, each sampled with ``cv2.remap`` at
the ground point of every pixel and faded out where one pixel covers more road than the
layer's texel (no aliasing shimmer near the horizon). Markings and shadows are projected
ground rectangles; far road blends into haze.
"""
from __future__ import annotations

import dataclasses
import math

import cv2
import numpy as np

from .camera import Camera
from .polygons import fill, project_quads, rect_xz
from .road_shape import pieces
from .scenario import Scenario

# Beyond this range the road is one haze-blended gray, and markings are not drawn (sub-pixel).
FAR_M = 3000.0
MARKING_RANGE_M = 220.0
HAZE_M = 900.0  # e-folding distance of the blend towards the horizon gray
TEXTURE_HALF_WIDTH_M = 60.0  # a bent road's asphalt texture is sampled within this lateral distance
FADE_CUT = 2.15  # texel/footprint ratio where a layer's weight exp(-r^2) falls below 1 %


@dataclasses.dataclass
class TextureLayer:
    """Periodic noise: ``tile[z_index, x_index]`` with texel sizes (texel_x_m, texel_z_m)."""

    tile: np.ndarray  # float32, zero mean, unit std, periodic in both axes
    texel_x_m: float
    texel_z_m: float
    amplitude: float  # relative brightness modulation (fraction of the albedo)
    step_px: int = 1  # sampled every step_px pixels and interpolated (coarse layers vary slowly)
    padded: np.ndarray | None = None
    pad_left: int = 0

    @property
    def period_z_m(self) -> float:
        return self.tile.shape[0] * self.texel_z_m

    def max_range_m(self, camera: Camera) -> float:
        """Range beyond which a sample covers too much road for this layer to show (fade < 1 %)."""
        along = math.sqrt(FADE_CUT * self.texel_z_m * camera.fy * camera.height_m / self.step_px)
        across = FADE_CUT * self.texel_x_m * camera.fx / self.step_px
        return min(along, across)

    def sampler(self, x_extent_m: float, z_extent_m: float) -> tuple[np.ndarray, int]:
        """The tile padded (by wrapping) so that |X| <= x_extent and Z + odometer phase fit without a modulo."""
        need_left = int(math.ceil(x_extent_m / self.texel_x_m)) + 2
        need_bottom = int(math.ceil(z_extent_m / self.texel_z_m)) + 2
        if self.padded is None or need_left > self.pad_left or need_bottom > self.padded.shape[0] - self.tile.shape[0]:
            self.pad_left = need_left
            self.padded = np.pad(self.tile, ((0, need_bottom), (need_left, need_left)), mode="wrap")
        return self.padded, self.pad_left


def periodic_noise(rng: np.random.Generator, shape: tuple[int, int], sigma_texels: tuple[float, float]) -> np.ndarray:
    """Gaussian-smoothed white noise that wraps around (smoothing done in the Fourier domain)."""
    white = rng.standard_normal(shape)
    fz = np.fft.fftfreq(shape[0])[:, None]
    fx = np.fft.fftfreq(shape[1])[None, :]
    kernel = np.exp(-2.0 * math.pi ** 2 * ((fz * sigma_texels[0]) ** 2 + (fx * sigma_texels[1]) ** 2))
    smooth = np.real(np.fft.ifft2(np.fft.fft2(white) * kernel))
    return ((smooth - smooth.mean()) / smooth.std()).astype(np.float32)


def make_layers(rng: np.random.Generator, contrast: float) -> list[TextureLayer]:
    """Asphalt: fine grain (near), streaks along the driving direction, large blotches (to ~50 m)."""
    grain = periodic_noise(rng, (256, 256), (0.7, 0.7))
    streaks = periodic_noise(rng, (256, 256), (1.0, 1.2))
    blotches = periodic_noise(rng, (128, 256), (1.5, 1.5))
    # Repair patches and stains: a few darker blobs with sharp-ish borders.
    blotches = blotches - 1.2 * np.clip(periodic_noise(rng, (128, 256), (3.0, 3.0)) - 1.3, 0.0, None)
    blotches = (blotches - blotches.mean()) / blotches.std()
    return [
        TextureLayer(grain, 0.025, 0.025, 0.10 * contrast),
        TextureLayer(streaks, 0.06, 0.4, 0.035 * contrast, step_px=2),
        TextureLayer(blotches.astype(np.float32), 0.3, 1.2, 0.05 * contrast, step_px=2),
    ]


class Ground:
    """Draws the image rows below the horizon."""

    def __init__(self, scenario: Scenario, rng: np.random.Generator):
        self.road = scenario.road
        self.light = scenario.lighting
        self.layers = make_layers(rng, scenario.lighting.texture_contrast)
        self.haze_gray = 0.7 * scenario.lighting.sky_gray + 0.3 * scenario.lighting.asphalt_gray
        lw = scenario.road.lane_width_m
        self.boundaries_m = [self.road.left_edge_m + k * lw for k in range(self.road.lanes + 1)]
        self.paved_m = (self.road.left_edge_m - self.road.shoulder_m, self.road.right_edge_m + self.road.shoulder_m)

    def draw(self, camera: Camera, odometer_m: float, shadows: list[tuple[np.ndarray, float]], r0: int) -> np.ndarray:
        """Gray levels (float32) of rows r0..H-1. ``shadows``: (ground polygon corners (k, 3), light factor)."""
        height = camera.height - r0
        rows = np.arange(r0, camera.height, dtype=np.float64)
        z_near = self._nearest_visible_m(camera)
        albedo = np.full((height, camera.width), self.light.grass_gray, np.uint8)
        fill(albedo, project_quads(camera, [rect_xz(*self.paved_m, z_near, FAR_M)], r0), self.light.asphalt_gray)
        marking_gray = min(235.0, self.light.asphalt_gray + 105.0)
        if self.road.markings == "painted":
            fill(albedo, project_quads(camera, self._markings(odometer_m, z_near), r0), marking_gray)

        shadows = [(corners, factor) for corners, factor in shadows if len(corners) >= 3]
        if shadows:
            light = np.full((height, camera.width), 255, np.uint8)
            for corners, factor in shadows:
                fill(light, project_quads(camera, [corners], r0), 255.0 * factor)
            lit = cv2.multiply(albedo, light, scale=1.0 / 255.0, dtype=cv2.CV_32F)
        else:
            lit = albedo.astype(np.float32)

        range_m = np.nan_to_num(camera.range_of_row(rows), nan=FAR_M)
        lit *= self._texture(camera, odometer_m, r0, np.minimum(range_m, FAR_M))
        # Haze: far road fades to the horizon gray (row-wise, ranges measured below the camera).
        haze = (1.0 - np.exp(-np.clip(range_m, 0.0, None) / HAZE_M)).astype(np.float32)[:, None]
        lit *= 1.0 - haze
        lit += haze * np.float32(self.haze_gray)
        return lit

    def draw_bent(self, camera, odometer_m: float, shadows: list[tuple[np.ndarray, float]]) -> tuple[np.ndarray, np.ndarray]:
        """The road on a bent road (road_shape.BentCamera): gray levels (float32, whole image) and where the
        ground is (bool). Polygons follow the bend; the texture and the haze take each pixel's road
        coordinates from thin slabs across the road (the road within a slab is planar to well below a
        pixel), drawn far to near so that a crest's far side stays hidden."""
        shape = (camera.height, camera.width)
        z_near = self._nearest_visible_m(camera)
        far = min(FAR_M, camera.view_m)
        x_m, z_m, ground = self._road_coordinates(camera, pieces(z_near, far))
        albedo = np.full(shape, self.light.grass_gray, np.uint8)
        fill(albedo, project_quads(camera, [rect_xz(*self.paved_m, z_near, far)]), self.light.asphalt_gray)
        if self.road.markings == "painted":
            marking_gray = min(235.0, self.light.asphalt_gray + 105.0)
            fill(albedo, project_quads(camera, self._markings(odometer_m, z_near)), marking_gray)
        lit = albedo.astype(np.float32)
        shadows = [(corners, factor) for corners, factor in shadows if len(corners) >= 3]
        if shadows:
            light = np.full(shape, 255, np.uint8)
            for corners, factor in shadows:
                fill(light, project_quads(camera, [corners]), 255.0 * factor)
            lit = cv2.multiply(albedo, light, scale=1.0 / 255.0, dtype=cv2.CV_32F)
        texture = np.ones(shape, np.float32)
        for layer in self.layers:
            # |X| bounded: a slab seen edge-on (a crest's top) maps a few pixels far sideways; the verge there is
            # texture-free anyway
            near = ground & (z_m < layer.max_range_m(camera)) & (np.abs(x_m) < TEXTURE_HALF_WIDTH_M)
            if not near.any():
                continue
            x, z = x_m[near], z_m[near]
            tile, left = layer.sampler(float(np.abs(x).max()), float(z.max()) + layer.period_z_m)
            phase = (odometer_m % layer.period_z_m) / layer.texel_z_m
            # cv2.remap takes maps under 32767 columns: the pixels' samples as rows of 1024
            pad = -len(x) % 1024
            map_x = np.pad(x / layer.texel_x_m + left, (0, pad)).astype(np.float32).reshape(-1, 1024)
            map_z = np.pad(z / layer.texel_z_m + phase, (0, pad)).astype(np.float32).reshape(-1, 1024)
            sample = cv2.remap(tile, map_x, map_z, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT).ravel()[:len(x)]
            ratio = np.maximum(z / camera.fx / layer.texel_x_m, z * z / (camera.fy * camera.height_m) / layer.texel_z_m)
            texture[near] += sample * (layer.amplitude * np.exp(-ratio * ratio)).astype(np.float32)
        lit *= texture
        haze = np.where(ground, 1.0 - np.exp(-np.clip(z_m, 0.0, None) / HAZE_M), 0.0).astype(np.float32)
        lit *= 1.0 - haze
        lit += haze * np.float32(self.haze_gray)
        return lit, ground

    @staticmethod
    def _road_coordinates(camera, zs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per pixel: road X and Z (NaN off the ground) and whether the ground is seen there.

        Slab k (zs[k]..zs[k+1], across +-1 km) is filled with k + 1 far to near; within a slab the pixel
        goes back to the road through the homography of the slab's four corners at +-20 m, exact there."""
        ids = np.zeros((camera.height, camera.width), np.float32)
        slabs = np.array([rect_xz(-1000.0, 1000.0, zs[k], zs[k + 1]) for k in range(len(zs) - 1)])
        order = np.arange(len(slabs))[::-1]
        for k, polygon in zip(order, project_quads(camera, slabs[order])):
            fill(ids, [polygon], float(k + 1), antialias=False)
        corners = np.array([rect_xz(-20.0, 20.0, zs[k], zs[k + 1]) for k in range(len(zs) - 1)])
        u, v = camera.project(corners.reshape(-1, 3))
        image_pts = np.stack([u, v], 1).reshape(-1, 4, 2).astype(np.float32)
        inverse = np.full((len(slabs) + 1, 3, 3), np.nan)
        for k in range(len(slabs)):
            if np.isfinite(image_pts[k]).all():
                inverse[k + 1] = cv2.getPerspectiveTransform(image_pts[k], corners[k][:, [0, 2]].astype(np.float32))
        index = ids.astype(np.int32)
        ground = index > 0
        rows, cols = np.nonzero(ground)
        h = inverse[index[ground]]
        pts = np.stack([cols, rows, np.ones(len(rows))], 1).astype(np.float64)
        mapped = np.einsum("nij,nj->ni", h, pts)
        x_m = np.full(ids.shape, np.nan)
        z_m = np.full(ids.shape, np.nan)
        x_m[ground] = mapped[:, 0] / mapped[:, 2]
        z_m[ground] = mapped[:, 1] / mapped[:, 2]
        ground &= np.isfinite(z_m)
        return x_m, z_m, ground

    def _nearest_visible_m(self, camera: Camera) -> float:
        _, z = camera.ground_from_pixel(np.array([0.0, camera.width - 1.0]), np.full(2, camera.height - 1.0))
        z = z[np.isfinite(z)]
        return max(0.3, 0.8 * float(z.min())) if z.size else 0.3

    def _markings(self, odometer_m: float, z_near: float) -> np.ndarray:
        """Ground rectangles of the painted lines: solid edges, dashed separators in world-fixed phase."""
        mw = self.road.marking_width_m
        rects = [rect_xz(self.boundaries_m[0], self.boundaries_m[0] + mw, z_near, FAR_M),
                 rect_xz(self.boundaries_m[-1] - mw, self.boundaries_m[-1], z_near, FAR_M)]
        cycle = self.road.dash_length_m + self.road.dash_gap_m
        first = math.floor((odometer_m + z_near) / cycle) - 1
        last = math.ceil((odometer_m + MARKING_RANGE_M) / cycle)
        for j in range(first, last + 1):
            z0 = j * cycle - odometer_m
            z1 = max(z0 + self.road.dash_length_m, z_near)
            if z1 <= z_near:
                continue
            z0 = max(z0, z_near)
            rects.extend(rect_xz(x - 0.5 * mw, x + 0.5 * mw, z0, z1) for x in self.boundaries_m[1:-1])
        return np.array(rects)

    def _texture(self, camera: Camera, odometer_m: float, r0: int, range_m: np.ndarray) -> np.ndarray:
        """1 + sum of faded noise layers at each pixel's ground point, rows r0..H-1 (float32).

        ``range_m``: road range below the camera at rows r0..H-1 (decreasing down the image).
        """
        out = np.ones((camera.height - r0, camera.width), np.float32)
        image_to_ground = np.linalg.inv(camera.ground_to_image())
        # Road covered by one pixel of each row: across Z / fx, along |dZ/dv| ~ Z^2 / (fy h) (small angles;
        # only the fade uses it).
        across_m = range_m / camera.fx
        along_m = range_m * range_m / (camera.fy * camera.height_m)
        for layer in self.layers:
            first = r0 + int(np.searchsorted(-range_m, -layer.max_range_m(camera)))  # first row nearer than its reach
            if first >= camera.height:
                continue
            step = layer.step_px
            n_rows, n_cols = -(-(camera.height - first) // step), -(-camera.width // step)
            # Sample at the centres of step x step pixel blocks (what cv2.resize interpolates between).
            u = (np.arange(n_cols, dtype=np.float32) * step + 0.5 * (step - 1))[None, :]
            v = (np.arange(n_rows, dtype=np.float64) * step + 0.5 * (step - 1) + first)[:, None]
            # Ground point (X, Z) -> padded-tile index: scale by texel, shift by odometer phase and pad.
            x_extent, z_max = _ground_extent(image_to_ground, u[0, [0, -1]], v[[0, -1], 0])
            tile, left = layer.sampler(x_extent, z_max + layer.period_z_m)
            phase = (odometer_m % layer.period_z_m) / layer.texel_z_m
            h = np.array([[1.0 / layer.texel_x_m, 0.0, left], [0.0, 1.0 / layer.texel_z_m, phase], [0.0, 0.0, 1.0]])
            h = h @ image_to_ground
            inv_w = 1.0 / (np.float32(h[2, 0]) * u + (h[2, 1] * v + h[2, 2]).astype(np.float32))
            map_x = (np.float32(h[0, 0]) * u + (h[0, 1] * v + h[0, 2]).astype(np.float32)) * inv_w
            map_z = (np.float32(h[1, 0]) * u + (h[1, 1] * v + h[1, 2]).astype(np.float32)) * inv_w
            sample = cv2.remap(tile, map_x, map_z, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
            # Fade by the footprint of a sample (step pixels), taken at the block's first row.
            rows = np.arange(first, camera.height, step) - r0
            ratio = step * np.maximum(across_m[rows] / layer.texel_x_m, along_m[rows] / layer.texel_z_m)
            sample *= (layer.amplitude * np.exp(-ratio * ratio)).astype(np.float32)[:, None]
            if step > 1:
                sample = cv2.resize(sample, (n_cols * step, n_rows * step), interpolation=cv2.INTER_LINEAR)
            out[first - r0:] += sample[:camera.height - first, :camera.width]
        return out


def _ground_extent(image_to_ground: np.ndarray, us: np.ndarray, vs: np.ndarray) -> tuple[float, float]:
    """Largest |X| and Z of the road seen in an image rectangle (extremes are at its corners)."""
    corners = np.array([[u, v, 1.0] for u in us for v in vs]) @ image_to_ground.T
    x = corners[:, 0] / corners[:, 2]
    z = corners[:, 1] / corners[:, 2]
    return float(np.abs(x).max()), float(z.max())


class Sky:
    """Sky gradient and a distant tree line; both at infinity (shift with yaw, not with travel)."""

    def __init__(self, scenario: Scenario, rng: np.random.Generator):
        self.sky_gray = scenario.lighting.sky_gray
        # Tree-line height (rad above the horizon) sampled every 0.05 deg over +-90 deg of azimuth.
        self.step_rad = math.radians(0.05)
        n = int(round(math.pi / self.step_rad)) + 1
        hills = periodic_noise(rng, (1, n), (0.0, 60.0))[0]
        crowns = periodic_noise(rng, (1, n), (0.0, 4.0))[0]
        height_deg = np.clip(0.9 + 0.5 * hills + 0.25 * crowns, 0.0, None)
        height_deg[hills < -1.0] = 0.0  # open fields: gaps in the tree line
        self.height_rad = np.radians(height_deg)
        tree_gray = 80.0 + 10.0 * crowns
        self.tree_gray = (0.55 * tree_gray + 0.45 * self.sky_gray).astype(np.float32)  # seen through haze

    def draw(self, camera: Camera, r0: int) -> np.ndarray:
        """Gray levels (float32) of rows 0..r0-1."""
        v_h = camera.horizon_row
        rows = np.arange(r0, dtype=np.float32)
        # Brightest at the horizon, darker towards the zenith.
        column = self.sky_gray - 45.0 * np.clip((v_h - rows) / (2.0 * camera.fy * 0.35), 0.0, 1.0)
        azimuth = np.arctan((np.arange(camera.width) - camera.cx) / camera.fx) + math.radians(camera.yaw_deg)
        index = np.clip(np.round(azimuth / self.step_rad).astype(int) + len(self.height_rad) // 2, 0,
                        len(self.height_rad) - 1)
        top_rows = v_h - camera.fy * np.tan(self.height_rad[index])
        trees = rows[:, None] > top_rows[None, :]
        return np.where(trees, self.tree_gray[index][None, :], column[:, None].astype(np.float32))
