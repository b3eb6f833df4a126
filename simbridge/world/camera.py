"""The downward camera: a pinhole rendered by ray casting the world grid (one module over 600 lines:
the frame's one pass from rays to shaded, weathered pixels, which its textures and variety feed).

Camera frame (OpenCV): x right, y down, z along the optical axis. The camera looks straight down
the body +z axis with the image top toward the vehicle's nose, so the camera-to-body rotation is

    x_cam -> +y_body (right),  y_cam -> -x_body (image down = aft),  z_cam -> +z_body (down)

(``CAMERA_TO_BODY`` below, columns = camera axes in body FRD). Pixel centres are at
``(u + 0.5, v + 0.5)``; the principal point is the image centre; ``fx = fy = (W / 2) / tan(hfov / 2)``.

Depth maps hold the z-depth along the optical axis in metres (NaN where the ray found nothing).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
from numba import njit

from simbridge.geo import Quat
from simbridge.world.camera_textures import (
    ACTOR_RGB,
    FACADE_RGB,
    MAT_RGB,
    default_palette,
    texture,
    texture_new,
    wrap,
)
from simbridge.world.camera_variety import (
    SOFT_SHADOW_M,
    VP_AMBIENT,
    VP_ON,
    VP_PX,
    VP_SHADOW_DEPTH,
    VP_SOFT,
    VP_SUN_GAIN,
    RenderVariety,
    variety_params,
    vary_albedo,
    vary_tint,
)
from simbridge.world.model import Material, WorldGrid
from simbridge.world.raycast import HIT_MISS, HIT_TOP, HIT_WALL_N, Pyramid, cast_rays
from simbridge.world.wire_sensing import draw_wires
from simbridge.world.world import Wire

__all__ = [
    "CAMERA_TO_BODY", "LABEL_SKY", "MAX_RANGE_M", "WEATHERS", "CameraModel", "Frame", "RenderVariety",
    "ShadowMap", "apply_weather", "body_to_neu", "default_palette", "quat_matrix", "render", "shade",
]  # fmt: skip

CAMERA_TO_BODY = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
_RAYS_BODY: dict[tuple[int, int, float], tuple[np.ndarray, np.ndarray]] = {}
_RAYS_CACHED = 16  # camera models whose rays are kept
MAX_RANGE_M = 600.0
SENSOR_NOISE = 0.008  # sigma of the sensor noise, in units of full scale
IMAGE_TILE = 8  # pixels a side of the tiles whose ray bundles ``cast_rays`` proves at once


@dataclass(frozen=True, slots=True)
class CameraModel:
    width_px: int = 960
    height_px: int = 540
    hfov_deg: float = 90.0

    def __post_init__(self) -> None:
        if not (16 <= self.width_px <= 8192 and 16 <= self.height_px <= 8192):
            raise ValueError(f"camera size {self.width_px}x{self.height_px} out of range 16..8192")
        if not 10.0 <= self.hfov_deg <= 150.0:
            raise ValueError(f"camera hfov_deg must be in [10, 150], got {self.hfov_deg}")

    @property
    def focal_px(self) -> float:
        return (self.width_px / 2) / math.tan(math.radians(self.hfov_deg) / 2)

    @property
    def principal_px(self) -> tuple[float, float]:
        return (self.width_px / 2, self.height_px / 2)

    def intrinsics(self) -> np.ndarray:
        f = self.focal_px
        cx, cy = self.principal_px
        return np.array([[f, 0.0, cx], [0.0, f, cy], [0.0, 0.0, 1.0]])

    def unit_rays_body(self) -> np.ndarray:
        """(H*W, 3) unit pixel rays in body FRD, row-major over pixels (cached per model)."""
        return self._rays()[0]

    def ray_norms(self) -> np.ndarray:
        """|(x, y, 1)| per pixel: z-depth = range / norm."""
        return self._rays()[1]

    def _rays(self) -> tuple[np.ndarray, np.ndarray]:
        key = (self.width_px, self.height_px, self.hfov_deg)
        cached = _RAYS_BODY.get(key)
        if cached is None:
            rays = self.rays_cam()
            norms = np.linalg.norm(rays, axis=1)
            cached = (np.ascontiguousarray((rays / norms[:, None]) @ CAMERA_TO_BODY.T), norms)
            if len(_RAYS_BODY) >= _RAYS_CACHED:  # bounded: training renders draw a new lens per view
                _RAYS_BODY.pop(next(iter(_RAYS_BODY)), None)
            _RAYS_BODY[key] = cached
        return cached

    def rays_cam(self) -> np.ndarray:
        """(H*W, 3) unnormalised rays (x, y, 1) in the camera frame, row-major over pixels."""
        f = self.focal_px
        cx, cy = self.principal_px
        u = (np.arange(self.width_px) + 0.5 - cx) / f
        v = (np.arange(self.height_px) + 0.5 - cy) / f
        uu, vv = np.meshgrid(u, v)
        return np.stack([uu, vv, np.ones_like(uu)], axis=-1).reshape(-1, 3)


def quat_matrix(q: Quat) -> np.ndarray:
    """Rotation matrix (body FRD -> NED) of a unit quaternion (w, x, y, z)."""
    w, x, y, z = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def body_to_neu(dirs_body: np.ndarray, q: Quat) -> np.ndarray:
    """Unit body FRD directions -> unit (north, east, up) directions."""
    m = quat_matrix(q) * np.array([[1.0], [1.0], [-1.0]])  # NED rows -> NEU rows
    return _rotate(np.ascontiguousarray(dirs_body, dtype=np.float64), m)


@njit(cache=True, nogil=True)
def _rotate(v: np.ndarray, m: np.ndarray) -> np.ndarray:
    """Rows of ``v`` times ``m`` transposed. (numpy's matmul with a 3-wide inner dimension goes
    through BLAS threads and is ~100x slower than this loop on a pinned core.)"""
    out = np.empty_like(v)
    for k in range(v.shape[0]):
        x, y, z = v[k, 0], v[k, 1], v[k, 2]
        out[k, 0] = m[0, 0] * x + m[0, 1] * y + m[0, 2] * z
        out[k, 1] = m[1, 0] * x + m[1, 1] * y + m[1, 2] * z
        out[k, 2] = m[2, 0] * x + m[2, 1] * y + m[2, 2] * z
    return out


@njit(cache=True, fastmath=True)
def _soft_shadow(
    shadow: np.ndarray, height: np.ndarray, pn: float, pe: float, n0: float, e0: float, res: float,
    i: int, j: int, radius_m: float,
) -> float:  # fmt: skip
    """Fraction in [0, 1] of the square of half-width ``radius_m`` around (pn, pe) in shadow: bilinear
    samples at most a cell apart, counting only cells within 1 m of the hit cell's height (no bleed
    across walls). Where the square's corners and centre agree (most pixels) that value is returned."""
    rows, cols = shadow.shape
    rad = radius_m / res
    r_i = math.ceil(rad)
    s0 = shadow[i, j]
    if (
        shadow[max(i - r_i, 0), max(j - r_i, 0)] == s0
        and shadow[max(i - r_i, 0), min(j + r_i, cols - 1)] == s0
        and shadow[min(i + r_i, rows - 1), max(j - r_i, 0)] == s0
        and shadow[min(i + r_i, rows - 1), min(j + r_i, cols - 1)] == s0
        and shadow[max(i - r_i, 0), j] == s0
        and shadow[min(i + r_i, rows - 1), j] == s0
        and shadow[i, max(j - r_i, 0)] == s0
        and shadow[i, min(j + r_i, cols - 1)] == s0
    ):
        return 1.0 if s0 else 0.0
    h0 = height[i, j]
    x0 = (pn - n0) / res - 0.5
    y0 = (pe - e0) / res - 0.5
    n = min(max(math.ceil(2.0 * rad) + 1, 3), 9)
    step = 2.0 * rad / (n - 1)
    acc = 0.0
    wsum = 0.0
    for sx in range(n):
        x = x0 - rad + sx * step
        ia = math.floor(x)
        tx = x - ia
        for sy in range(n):
            y = y0 - rad + sy * step
            ja = math.floor(y)
            ty = y - ja
            for di in range(2):
                a = min(max(ia + di, 0), rows - 1)
                wx = tx if di == 1 else 1.0 - tx
                for dj in range(2):
                    bb = min(max(ja + dj, 0), cols - 1)
                    if abs(height[a, bb] - h0) < 1.0:
                        w = wx * (ty if dj == 1 else 1.0 - ty)
                        if shadow[a, bb]:
                            acc += w
                        wsum += w
    return acc / wsum if wsum > 0.0 else (1.0 if s0 else 0.0)


@njit(cache=True, inline="always")
def _lcg_noise(state: np.uint64) -> tuple[np.uint64, float]:
    """Next state of the sensor-noise LCG and a triangular value in about [0, 2) (mean 1)."""
    state = state * np.uint64(6364136223846793005) + np.uint64(1442695040888963407)
    r = (
        float((state >> np.uint64(33)) & np.uint64(0xFFFF))
        + float((state >> np.uint64(49)) & np.uint64(0x7FFF)) * 2.0
    ) / 65535.0
    return state, r


@njit(cache=True, inline="always")
def _quantise(value: np.float32, v: np.float32, r: float, sigma: float) -> np.uint8:
    val = (value * v + sigma * 2.45 * (r - 1.0)) * 255.0
    return np.uint8(0) if val < 0.0 else np.uint8(255) if val > 255.0 else np.uint8(val)


@njit(cache=True, fastmath=True, nogil=True)
def shade(
    ts: np.ndarray, ii: np.ndarray, jj: np.ndarray, kinds: np.ndarray, steps: np.ndarray, dirs: np.ndarray,
    origin: np.ndarray, height: np.ndarray, mat: np.ndarray, region: np.ndarray, shadow: np.ndarray,
    res: float, n0: float, e0: float, sun: np.ndarray, mat_rgb: np.ndarray, actor_rgb: np.ndarray,
    facade_rgb: np.ndarray, ray_len: np.ndarray, cls_grid: np.ndarray, depth: np.ndarray, cls: np.ndarray,
    out_u8: np.ndarray, vignette: np.ndarray, seed: int, sigma: float, vp: np.ndarray,
) -> np.ndarray:  # fmt: skip
    """Colour every ray's hit: albedo x (ambient + sun x lit), RGB float32 in [0, 1+]; and per pixel
    the z-depth along the optical axis (``ray_len``: |(x, y, 1)|) and the class seen (255: sky).

    With an ``out_u8`` of one row per ray (clear weather: nothing comes between shading and the
    sensor), the same pass also applies the vignette and the seeded sensor noise and quantises into
    it (what ``_to_uint8`` does, in the same order); the float image is then not kept (empty).

    ``vp``: the ``RenderVariety`` parameter vector (``_VP_*``); with ``vp[VP_ON]`` 0 the fixed look,
    byte for byte as before varieties existed."""
    n = ts.shape[0]
    rows, cols = height.shape
    direct = out_u8.shape[0] == n
    out = np.empty((0 if direct else n, 3), np.float32)
    state = np.uint64(seed) * np.uint64(6364136223846793005) + np.uint64(1442695040888963407)
    ambient = 0.38
    cam_up = origin[2]
    vary = vp[VP_ON] > 0.5
    amb_v = vp[VP_AMBIENT]
    gain_v = vp[VP_SUN_GAIN]
    px = vp[VP_PX]
    soft_m = vp[VP_SOFT] * SOFT_SHADOW_M
    shadow_depth = vp[VP_SHADOW_DEPTH]
    for k in range(n):
        dn, de, du = dirs[k, 0], dirs[k, 1], dirs[k, 2]
        t = ts[k]
        kind = kinds[k]
        if kind == HIT_MISS:
            if du < -1e-6:  # open ground beyond the modelled area
                t = origin[2] / -du
                pn = origin[0] + t * dn
                pe = origin[1] + t * de
                if vary:
                    r, g, b = vary_albedo(
                        18, pn, pe, 0, t * px, 0.0, 0.0, vp, mat_rgb[18, 0], mat_rgb[18, 1], mat_rgb[18, 2]
                    )
                    light = amb_v + gain_v * (0.8 / 0.85) * max(sun[2], 0.0)
                else:
                    r, g, b = texture(18, pn, pe, mat_rgb[18, 0], mat_rgb[18, 1], mat_rgb[18, 2])
                    light = ambient + 0.8 * max(sun[2], 0.0)
                depth[k] = (cam_up / -du) / ray_len[k]
                cls[k] = 1
            else:  # sky
                r, g, b, light = 0.62, 0.72, 0.85, 1.0
                depth[k] = np.nan
                cls[k] = 255
        else:
            depth[k] = t / ray_len[k]
            cls[k] = cls_grid[ii[k], jj[k]]
            i = ii[k]
            j = jj[k]
            pn = origin[0] + t * dn
            pe = origin[1] + t * de
            pu = origin[2] + t * du
            reg = region[i, j]
            m = mat[i, j]
            top = kind == HIT_TOP
            if vary and not top and m != 19 and m != 20:  # a low riser of a sloped top: shade it as the top
                if kind == HIT_WALL_N:
                    low = min(height[max(i - 1, 0), j], height[min(i + 1, rows - 1), j])
                else:
                    low = min(height[i, max(j - 1, 0)], height[i, min(j + 1, cols - 1)])
                top = height[i, j] - low < 0.6
            if top:
                # normal from the height gradient (domes, trees, pitched roofs)
                gn = 0.0
                ge = 0.0
                i0 = max(i - 1, 0)
                i1 = min(i + 1, rows - 1)
                j0 = max(j - 1, 0)
                j1 = min(j + 1, cols - 1)
                dh_n = height[i1, j] - height[i0, j]
                dh_e = height[i, j1] - height[i, j0]
                if dh_n == 0.0 and dh_e == 0.0:  # level (most pixels): the normal is straight up
                    cos_sun = sun[2]
                else:
                    gn = dh_n / ((i1 - i0) * res + 1e-9)
                    ge = dh_e / ((j1 - j0) * res + 1e-9)
                    if abs(gn) > 3.0 or abs(ge) > 3.0:  # an edge, not a slope
                        gn = 0.0
                        ge = 0.0
                    nn, ne_, nu = -gn, -ge, 1.0
                    norm = math.sqrt(nn * nn + ne_ * ne_ + nu * nu)
                    cos_sun = (nn * sun[0] + ne_ * sun[1] + nu * sun[2]) / norm
                if reg < 0 and (m == 19 or m == 20):  # actor: its own paint
                    a = (-reg - 1) % actor_rgb.shape[0]
                    r, g, b = actor_rgb[a, 0], actor_rgb[a, 1], actor_rgb[a, 2]
                elif vary:
                    r, g, b = vary_albedo(
                        m, pn, pe, reg, t * px, gn, ge, vp, mat_rgb[m, 0], mat_rgb[m, 1], mat_rgb[m, 2]
                    )
                elif m >= 22:  # the roof materials without a fixed look to keep: axis-aligned
                    r, g, b = texture_new(m, pn, pe, mat_rgb[m, 0], mat_rgb[m, 1], mat_rgb[m, 2], t * px, 0)
                else:
                    r, g, b = texture(m, pn, pe, mat_rgb[m, 0], mat_rgb[m, 1], mat_rgb[m, 2])
                if vary:
                    if soft_m > 0.0:
                        sf = _soft_shadow(shadow, height, pn, pe, n0, e0, res, i, j, soft_m)
                    else:
                        sf = 1.0 if shadow[i, j] else 0.0
                    lit = max(cos_sun, 0.0) * (1.0 - shadow_depth * sf)
                else:
                    lit = 0.0 if shadow[i, j] else max(cos_sun, 0.0)
            else:
                # facade: a tint per building, floors every 3 m, windows every 1.6 m
                fc = (reg if reg > 0 else i // 7 + j // 11) % facade_rgb.shape[0]
                r, g, b = facade_rgb[fc, 0], facade_rgb[fc, 1], facade_rgb[fc, 2]
                along = pe if kind == HIT_WALL_N else pn
                if reg > 0 and 1.0 < wrap(pu, 3.0) < 2.4 and wrap(along, 1.6) > 0.4:
                    r, g, b = 0.16, 0.2, 0.26  # glass
                elif vary:
                    r, g, b = vary_tint(r, g, b, reg, pn, pe, vp)
                st = steps[k]
                if kind == HIT_WALL_N:
                    cos_sun = -st * sun[0]
                else:
                    cos_sun = -st * sun[1]
                lit = max(cos_sun, 0.0)
            light = amb_v + gain_v * lit if vary else ambient + 0.85 * lit
        c0 = np.float32(r * light)
        c1 = np.float32(g * light)
        c2 = np.float32(b * light)
        if direct:
            v = vignette[k]
            state, x = _lcg_noise(state)
            out_u8[k, 0] = _quantise(c0, v, x, sigma)
            state, x = _lcg_noise(state)
            out_u8[k, 1] = _quantise(c1, v, x, sigma)
            state, x = _lcg_noise(state)
            out_u8[k, 2] = _quantise(c2, v, x, sigma)
        else:
            out[k, 0] = c0
            out[k, 1] = c1
            out[k, 2] = c2
    return out


@njit(cache=True, nogil=True)
def _tiles_needed(ii: np.ndarray, jj: np.ndarray, done: np.ndarray, shift: int) -> np.ndarray:
    """Which shadow tiles (``2**shift`` cells a side) cells ``(ii, jj)`` lie in that are not done
    (a shift, not a division: this runs over every pixel of every frame)."""
    need = np.zeros(done.shape, np.bool_)
    for k in range(ii.shape[0]):
        if ii[k] >= 0:
            ti = ii[k] >> shift
            tj = jj[k] >> shift
            if not done[ti, tj]:
                need[ti, tj] = True
    return need


@njit(cache=True, nogil=True)
def _to_uint8(img: np.ndarray, vignette: np.ndarray, seed: int, sigma: float) -> np.ndarray:
    """Vignetting, sensor noise (seeded, approximately Gaussian) and quantisation to uint8."""
    h, w, c = img.shape
    out = np.empty((h, w, c), np.uint8)
    state = np.uint64(seed) * np.uint64(6364136223846793005) + np.uint64(1442695040888963407)
    for y in range(h):
        for x in range(w):
            v = vignette[y, x, 0]
            for ch in range(c):
                # sum of two 16-bit uniforms from an LCG: triangular noise with the given sigma
                state, r = _lcg_noise(state)
                out[y, x, ch] = _quantise(img[y, x, ch], v, r, sigma)
    return out


class ShadowMap:
    """Which cell tops lie in the shadow of something toward the sun, computed tile by tile on demand.

    A shadow ray leaves each cell top toward the sun; a cell is shadowed when the ray hits anything.
    Tiles of ``TILE`` x ``TILE`` cells are computed the first time a camera sees them, so a large
    city costs only what is looked at. Moving actors add their own shadows (``stamp``/``unstamp``).
    """

    TILE_SHIFT = 8
    TILE = 1 << TILE_SHIFT

    def __init__(self, grid: WorldGrid, pyramid: Pyramid, sun_neu: tuple[float, float, float]) -> None:
        self.grid = grid
        self.pyramid = pyramid
        self.sun = np.asarray(sun_neu, dtype=np.float64)
        rows, cols = grid.shape
        self.shadow = np.zeros((rows, cols), np.bool_)
        self._done = np.zeros(
            ((rows + self.TILE - 1) // self.TILE, (cols + self.TILE - 1) // self.TILE), bool
        )
        self._stamped: list[tuple[tuple[int, int, int, int], np.ndarray, np.ndarray]] = []

    def ensure(self, ii: np.ndarray, jj: np.ndarray) -> None:
        """Compute the tiles containing cells ``(ii, jj)`` (negative indices ignored)."""
        for ti, tj in zip(*np.nonzero(_tiles_needed(ii, jj, self._done, self.TILE_SHIFT)), strict=True):
            self._compute_tile(int(ti), int(tj))

    def ensure_all(self) -> None:
        for ti in range(self._done.shape[0]):
            for tj in range(self._done.shape[1]):
                if not self._done[ti, tj]:
                    self._compute_tile(ti, tj)

    def _compute_tile(self, ti: int, tj: int) -> None:
        grid, pyr = self.grid, self.pyramid
        rows, cols = grid.shape
        i0, i1 = ti * self.TILE, min((ti + 1) * self.TILE, rows)
        j0, j1 = tj * self.TILE, min((tj + 1) * self.TILE, cols)
        n, e = grid.cell_centres(i0, i1, j0, j1)
        h = grid.height[i0:i1, j0:j1].astype(np.float64) + 0.05
        origins = np.stack([n.ravel(), e.ravel(), h.ravel()], axis=1)
        dirs = np.ascontiguousarray(np.broadcast_to(self.sun, origins.shape))
        origins += dirs * (grid.res * 0.75)  # leave the cell's own top behind
        _, _, _, kinds, _ = cast_rays(
            grid.height, pyr.maps, pyr.h_max,
            grid.res, grid.n0, grid.e0, origins, dirs, MAX_RANGE_M,
        )  # fmt: skip
        self.shadow[i0:i1, j0:j1] = (kinds != HIT_MISS).reshape(i1 - i0, j1 - j0)
        self._done[ti, tj] = True

    def stamp(self, window: tuple[int, int, int, int], mask: np.ndarray) -> None:
        """Darken cells under ``mask`` (an actor's shadow) until the next ``unstamp``."""
        i0, i1, j0, j1 = window
        self._stamped.append((window, mask, self.shadow[i0:i1, j0:j1][mask].copy()))
        self.shadow[i0:i1, j0:j1][mask] = True

    def unstamp(self) -> None:
        for (i0, i1, j0, j1), mask, saved in reversed(self._stamped):
            self.shadow[i0:i1, j0:j1][mask] = saved
        self._stamped = []


@dataclass(frozen=True, slots=True)
class Frame:
    """One rendered camera frame."""

    rgb: np.ndarray  # (H, W, 3) uint8
    depth_m: np.ndarray  # (H, W) float32 z-depth along the optical axis, NaN for sky
    hit_class: np.ndarray  # (H, W) uint8 SurfaceClass of the surface each pixel sees (255: sky)
    # Per-pixel labels, only with ``render(..., labels=True)`` (training data; the flight path skips them):
    hit_material: np.ndarray | None = None  # (H, W) uint8 Material of the cell each pixel sees (0: sky)
    hit_kind: np.ndarray | None = None  # (H, W) uint8: HIT_TOP, HIT_WALL_N, HIT_WALL_E, or LABEL_SKY


LABEL_SKY = 255  # ``Frame.hit_kind`` of a pixel that sees the sky


def render(
    grid: WorldGrid,
    pyramid: Pyramid,
    shadow: ShadowMap,
    camera: CameraModel,
    pos_ned_m: tuple[float, float, float],
    quat: Quat,
    sun_neu: tuple[float, float, float],
    weather: str = "clear",
    rng: np.random.Generator | None = None,
    *,
    labels: bool = False,
    palette: np.ndarray | None = None,
    variety: RenderVariety | None = None,
    wires: tuple[Wire, ...] = (),
) -> Frame:
    """Render the camera at a pose (position NED, attitude body->NED).

    Args:
        labels: also fill ``Frame.hit_material`` and ``Frame.hit_kind`` (per-pixel training labels).
        palette: (32, 3) float32 RGB in [0, 1] per ``Material`` in place of the built-in one (domain
            randomisation for training data); None keeps the built-in palette.
        variety: lighting, tint, texture, stain and shadow randomisation for training data
            (``RenderVariety``); None (or a neutral variety) renders the fixed look, byte for byte.
    """
    if variety is not None and not isinstance(variety, RenderVariety):
        raise ValueError(f"variety must be a RenderVariety or None, got {type(variety).__name__}")
    if palette is not None and (palette.shape != MAT_RGB.shape or palette.dtype != np.float32):
        raise ValueError(
            f"palette must be float32 of shape {MAT_RGB.shape}, got {palette.dtype} {palette.shape}"
        )
    ray_len = camera.ray_norms()
    dirs = body_to_neu(camera.unit_rays_body(), quat)
    origin = np.array([[pos_ned_m[0], pos_ned_m[1], -pos_ned_m[2]]])
    ts, ii, jj, kinds, steps = cast_rays(
        grid.height, pyramid.maps, pyramid.h_max,
        grid.res, grid.n0, grid.e0, origin, dirs, MAX_RANGE_M, camera.width_px, IMAGE_TILE,
    )  # fmt: skip
    sun = np.asarray(sun_neu, dtype=np.float64)
    shadow.ensure(ii, jj)
    if weather not in WEATHERS:
        raise ValueError(f"unknown weather {weather!r}; expected one of {', '.join(WEATHERS)}")
    rng = rng if rng is not None else np.random.default_rng(0)
    h, w = camera.height_px, camera.width_px
    n = ts.shape[0]
    depth = np.empty(n, np.float32)
    cls = np.empty(n, np.uint8)
    vignette = _vignette(h, w)
    clear = weather == "clear"  # nothing between shading and the sensor: one pass does both
    out = np.empty((n if clear else 0, 3), np.uint8)
    seed = int(rng.integers(1, 2**62)) if clear else 0
    rgb = shade(
        ts, ii, jj, kinds, steps, dirs, origin[0], grid.height, grid.mat, grid.region, shadow.shadow,
        grid.res, grid.n0, grid.e0, sun, MAT_RGB if palette is None else palette, ACTOR_RGB, FACADE_RGB,
        ray_len, grid.cls, depth, cls, out, vignette.reshape(-1), seed, SENSOR_NOISE,
        variety_params(variety, 1.0 / camera.focal_px),
    )  # fmt: skip
    depth_img = depth.reshape(h, w)
    hit_material, hit_kind = _hit_labels(grid, ii, jj, kinds, dirs, (h, w)) if labels else (None, None)
    if clear:
        image = out.reshape(h, w, 3)
    else:
        img = apply_weather(rgb.reshape(h, w, 3), depth_img, weather, rng)
        image = _to_uint8(
            np.ascontiguousarray(img, np.float32), vignette, int(rng.integers(1, 2**62)), SENSOR_NOISE
        )
    if wires:
        r_neu_cam = (quat_matrix(quat) * np.array([[1.0], [1.0], [-1.0]])) @ CAMERA_TO_BODY
        image = draw_wires(image, depth_img, wires, r_neu_cam, origin[0], camera.focal_px)
    return Frame(image, depth_img, cls.reshape(h, w), hit_material, hit_kind)


def _hit_labels(
    grid: WorldGrid,
    ii: np.ndarray,
    jj: np.ndarray,
    kinds: np.ndarray,
    dirs: np.ndarray,
    shape: tuple[int, int],
) -> tuple[np.ndarray, np.ndarray]:
    """Per-pixel material and hit kind (``Frame.hit_material``, ``Frame.hit_kind``) of one render's rays.
    A ray that leaves the modelled area downward sees open ground (soil, a top), as ``shade`` draws it."""
    hit = kinds != HIT_MISS
    material = np.zeros(kinds.shape[0], np.uint8)
    material[hit] = grid.mat[ii[hit], jj[hit]]
    kind = np.full(kinds.shape[0], LABEL_SKY, np.uint8)
    kind[hit] = kinds[hit]
    ground = ~hit & (dirs[:, 2] < -1e-6)
    material[ground] = int(Material.SOIL)
    kind[ground] = HIT_TOP
    return material.reshape(shape), kind.reshape(shape)


_VIGNETTE: dict[tuple[int, int], np.ndarray] = {}


def _vignette(h: int, w: int) -> np.ndarray:
    if (h, w) not in _VIGNETTE:
        y, x = np.mgrid[0:h, 0:w].astype(np.float32)
        r2 = ((x - w / 2) / (w / 2)) ** 2 + ((y - h / 2) / (h / 2)) ** 2
        _VIGNETTE[(h, w)] = (1.0 - 0.12 * r2)[..., None].astype(np.float32)
    return _VIGNETTE[(h, w)]


WEATHERS = ("clear", "fog", "rain")


def apply_weather(img: np.ndarray, depth_m: np.ndarray, weather: str, rng: np.random.Generator) -> np.ndarray:
    """Fog: haze growing with distance. Rain: wet darkening, contrast loss, streaks."""
    if weather == "clear":
        return img
    d = np.nan_to_num(depth_m, nan=MAX_RANGE_M)[..., None]
    if weather == "fog":
        visibility_m = 220.0
        transmit = np.exp(-3.0 * d / visibility_m).astype(np.float32)
        fog = np.array([0.78, 0.80, 0.82], np.float32)
        return np.asarray(img * transmit + fog * (1.0 - transmit), np.float32)
    if weather == "rain":
        grey = img.mean(axis=2, keepdims=True)
        wet = img * 0.72 + 0.1 * (img - grey)  # darker, a little more saturated
        transmit = np.exp(-d / 900.0).astype(np.float32)
        hazed = wet * transmit + np.float32(0.45) * (1.0 - transmit)
        flat = 0.8 * hazed + 0.2 * hazed.mean()  # contrast loss
        h, w = img.shape[:2]
        streaks: np.ndarray = np.zeros((h, w), np.float32)
        count = int(h * w / 900)
        x0 = rng.integers(0, w, count)
        y0 = rng.integers(0, h, count)
        length = rng.integers(8, 30, count)
        for x, y, ln in zip(x0.tolist(), y0.tolist(), length.tolist(), strict=True):
            cv2.line(streaks, (x, y), (x + ln // 6, y + ln), 1.0, 1)
        blurred = np.asarray(cv2.GaussianBlur(streaks, (3, 3), 0), np.float32)[..., None]
        return np.asarray(flat * (1 - 0.35 * blurred) + 0.85 * 0.35 * blurred, np.float32)
    raise ValueError(f"unknown weather {weather!r}; expected one of {', '.join(WEATHERS)}")
