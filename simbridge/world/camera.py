"""The downward camera: a pinhole rendered by ray casting the world grid.

Camera frame (OpenCV): x right, y down, z along the optical axis. The camera looks straight down
the body +z axis with the image top toward the vehicle's nose, so the camera-to-body rotation is

    x_cam -> +y_body (right),  y_cam -> -x_body (image down = aft),  z_cam -> +z_body (down)

(``CAMERA_TO_BODY`` below, columns = camera axes in body FRD). Pixel centres are at
``(u + 0.5, v + 0.5)``; the principal point is the image centre; ``fx = fy = (W / 2) / tan(hfov / 2)``.

Depth maps hold the z-depth along the optical axis in metres (NaN where the ray found nothing).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import cv2
import numpy as np
from numba import njit

from simbridge.geo import Quat
from simbridge.world.model import Material, WorldGrid
from simbridge.world.raycast import HIT_MISS, HIT_TOP, HIT_WALL_N, Pyramid, cast_rays

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


# ---------------------------------------------------------------------------- palettes (RGB 0..1)
_MAT_RGB = np.zeros((32, 3), np.float32)
for _m, _rgb in {
    Material.NONE: (0.5, 0.5, 0.5),
    Material.GRAVEL: (0.62, 0.59, 0.53),
    Material.CONCRETE: (0.70, 0.69, 0.66),
    Material.TAR: (0.20, 0.20, 0.21),
    Material.MEMBRANE: (0.86, 0.86, 0.84),
    Material.TILES: (0.62, 0.30, 0.22),
    Material.ASPHALT: (0.27, 0.27, 0.28),
    Material.LANE_MARKING: (0.93, 0.93, 0.88),
    Material.PAVING: (0.66, 0.64, 0.60),
    Material.ZEBRA: (0.94, 0.94, 0.92),
    Material.GRASS: (0.33, 0.52, 0.22),
    Material.FOLIAGE: (0.16, 0.36, 0.14),
    Material.WATER: (0.12, 0.25, 0.36),
    Material.WOOD: (0.48, 0.35, 0.22),
    Material.METAL: (0.74, 0.76, 0.78),
    Material.SOLAR: (0.10, 0.14, 0.30),
    Material.RUBBLE: (0.50, 0.45, 0.38),
    Material.BRICK: (0.55, 0.30, 0.24),
    Material.SOIL: (0.47, 0.40, 0.30),
    Material.CAR_PAINT: (0.6, 0.6, 0.6),
    Material.CLOTH: (0.5, 0.3, 0.3),
    Material.PAINT_TEXT: (0.95, 0.85, 0.20),
    Material.CORRUGATED: (0.58, 0.60, 0.60),
    Material.SLATE: (0.30, 0.32, 0.35),
    Material.SHINGLE: (0.36, 0.33, 0.31),
    Material.SEAM_METAL: (0.52, 0.56, 0.58),
    Material.GLASS: (0.22, 0.28, 0.34),
    Material.POOL: (0.35, 0.70, 0.80),
}.items():
    _MAT_RGB[int(_m)] = _rgb


def default_palette() -> np.ndarray:
    """A copy of the built-in (32, 3) float32 RGB palette per ``Material`` (``render(..., palette=)``)."""
    return _MAT_RGB.copy()


_ACTOR_RGB = np.array(
    [(0.85, 0.85, 0.87), (0.08, 0.08, 0.09), (0.62, 0.08, 0.07), (0.10, 0.22, 0.55), (0.55, 0.56, 0.58),
     (0.90, 0.75, 0.10), (0.15, 0.40, 0.20), (0.75, 0.40, 0.10)],
    np.float32,
)  # fmt: skip
_FACADE_RGB = np.array(
    [(0.72, 0.70, 0.66), (0.60, 0.36, 0.28), (0.52, 0.55, 0.58), (0.80, 0.76, 0.66), (0.42, 0.44, 0.48)],
    np.float32,
)  # fmt: skip


@njit(cache=True, fastmath=True, inline="always")
def _hash2(a: int, b: int, salt: int) -> float:
    """Deterministic value in [0, 1) for an integer lattice point."""
    h = (a * 374761393 + b * 668265263 + salt * 2147483647) & 0xFFFFFFFF
    h = ((h ^ (h >> 13)) * 1274126177) & 0xFFFFFFFF
    h = h ^ (h >> 16)
    return (h & 0xFFFFFF) / 16777216.0


@njit(cache=True, fastmath=True, inline="always")
def _value_noise(x: float, y: float, salt: int) -> float:
    """Smooth value noise in [0, 1) at lattice spacing 1."""
    ix = math.floor(x)
    iy = math.floor(y)
    fx = x - ix
    fy = y - iy
    fx = fx * fx * (3 - 2 * fx)
    fy = fy * fy * (3 - 2 * fy)
    a = _hash2(ix, iy, salt)
    b = _hash2(ix + 1, iy, salt)
    c = _hash2(ix, iy + 1, salt)
    d = _hash2(ix + 1, iy + 1, salt)
    return (a * (1 - fx) + b * fx) * (1 - fy) + (c * (1 - fx) + d * fx) * fy


@njit(cache=True, fastmath=True, inline="always")
def _wrap(x: float, period: float) -> float:
    """``x % period`` for a positive period, without the float modulo's slow path."""
    return x - period * math.floor(x / period)


@njit(cache=True, fastmath=True, inline="always")
def _texture(mat: int, pn: float, pe: float, r: float, g: float, b: float) -> tuple[float, float, float]:
    """Procedural albedo of a material at world point (north, east), from its base colour."""
    k = 1.0
    if mat == 1:  # gravel: grains of 4 cm, varied tone
        k = 0.78 + 0.44 * _hash2(math.floor(pn * 25), math.floor(pe * 25), 1)
        k *= 0.9 + 0.2 * _value_noise(pn * 0.4, pe * 0.4, 2)
    elif mat == 2:  # concrete: slabs with joints and stains
        k = (
            0.9
            + 0.15 * _value_noise(pn * 0.3, pe * 0.3, 3)
            + 0.05 * _hash2(math.floor(pn * 20), math.floor(pe * 20), 4)
        )
        if _wrap(pn, 3.0) < 0.06 or _wrap(pe, 3.0) < 0.06:
            k *= 0.75
    elif mat == 3:  # tar
        k = (
            0.85
            + 0.3 * _value_noise(pn * 0.8, pe * 0.8, 5)
            + 0.1 * _hash2(math.floor(pn * 30), math.floor(pe * 30), 6)
        )
    elif mat == 4:  # membrane: seams every 1.5 m
        k = 0.95 + 0.05 * _value_noise(pn * 0.5, pe * 0.5, 7)
        if _wrap(pe, 1.5) < 0.04:
            k *= 0.85
    elif mat == 5:  # tiles
        row = math.floor(pn / 0.3)
        off = 0.15 if row % 2 == 0 else 0.0
        k = 0.82 + 0.3 * _hash2(row, math.floor((pe + off) / 0.3), 8)
        if _wrap(pn, 0.3) < 0.04 or _wrap(pe + off, 0.3) < 0.03:
            k *= 0.6
    elif mat == 6:  # asphalt
        k = (
            0.85
            + 0.25 * _hash2(math.floor(pn * 20), math.floor(pe * 20), 9)
            + 0.15 * _value_noise(pn * 0.2, pe * 0.2, 10)
        )
    elif mat == 8:  # paving stones 0.5 m
        k = 0.88 + 0.2 * _hash2(math.floor(pn * 2), math.floor(pe * 2), 11)
        if _wrap(pn, 0.5) < 0.03 or _wrap(pe, 0.5) < 0.03:
            k *= 0.7
    elif mat == 10:  # grass
        k = (
            0.75
            + 0.35 * _value_noise(pn * 0.7, pe * 0.7, 12)
            + 0.15 * _hash2(math.floor(pn * 15), math.floor(pe * 15), 13)
        )
    elif mat == 11:  # foliage: clumps
        k = 0.6 + 0.7 * _value_noise(pn * 1.5, pe * 1.5, 14)
    elif mat == 12:  # water: ripples
        k = 0.85 + 0.3 * _value_noise(pn * 1.2 + pe * 0.3, pe * 0.9, 15)
    elif mat == 13:  # wood planks 0.2 m
        k = 0.8 + 0.3 * _hash2(math.floor(pe / 0.2), math.floor(pn / 2.0), 16)
        if _wrap(pe, 0.2) < 0.02:
            k *= 0.6
    elif mat == 14:  # metal: brushed panels
        k = 0.9 + 0.12 * _hash2(math.floor(pn * 2), math.floor(pe * 2), 17)
    elif mat == 15:  # solar cells
        if _wrap(pn, 1.0) < 0.05 or _wrap(pe, 1.7) < 0.05:
            k = 2.4
        else:
            k = 0.9 + 0.2 * _hash2(math.floor(pn * 6), math.floor(pe * 6), 18)
    elif mat == 16:  # rubble
        k = 0.55 + 0.8 * _hash2(math.floor(pn * 6), math.floor(pe * 6), 19)
    elif mat == 18:  # soil
        k = 0.8 + 0.35 * _value_noise(pn * 0.5, pe * 0.5, 20)
    return (r * k, g * k, b * k)


@njit(cache=True, fastmath=True, inline="always")
def _line(x: float, period: float, width: float, fw: float) -> float:
    """Coverage in [0, 1] of a thin periodic line (``width`` m every ``period`` m) at ``x``, box-filtered
    over a pixel footprint of ``fw`` m: a line thinner than the footprint widens and fades instead of
    aliasing into dots."""
    eff = max(width, fw)
    return width / eff if _wrap(x, period) < eff else 0.0


@njit(cache=True, fastmath=True)
def _texture_new(
    mat: int, u: float, v: float, r: float, g: float, b: float, fw: float, salt: int
) -> tuple[float, float, float]:
    """Procedural albedo of the roof materials 22..27 (``Material.CORRUGATED`` .. ``POOL``) at local
    coordinates (u, v) in metres: u runs across the rows (down the slope), v along them (the eave).
    ``fw`` is the pixel footprint in metres (fine ridges and lines fade as it grows); ``salt`` varies
    the per-sheet / per-slate tones."""
    k = 1.0
    if mat == 22:  # corrugated sheet: 12 cm ridges down the slope, 1 m x 2.5 m sheets, weathering
        period = 0.12
        s = math.sin(6.283185307179586 * v / period)
        fade = max(0.0, 1.0 - 1.2 * fw / period)  # fades out before it would alias
        k = 1.0 + fade * (0.2 * s + 0.1 * s * s - 0.05)  # lit flank, dark flank, bright crest
        k *= 0.94 + 0.12 * _hash2(math.floor(u / 2.5), math.floor(v / 1.0), salt + 40)
        k *= 1.0 - 0.35 * _line(u, 2.5, 0.05, fw)  # end lap: the upper sheet's edge casts a line
        k *= 1.0 - 0.15 * _line(v, 1.0, 0.03, fw)  # side lap
        k *= 0.86 + 0.24 * _value_noise(u * 0.7, v * 0.7, salt + 41)
        k *= 0.96 + 0.08 * _hash2(math.floor(u * 10.0), math.floor(v * 10.0), salt + 42)
    elif mat == 23:  # slate: 23 cm rows of 30 cm slates, half-bond, thin dark gaps
        row = math.floor(u / 0.23)
        off = 0.15 if row % 2 == 0 else 0.0
        col = math.floor((v + off) / 0.3)
        h = _hash2(row, col, salt + 50)
        k = 0.7 + 0.45 * h
        k *= 0.9 + 0.12 * (u / 0.23 - row)  # the exposed lower edge is lighter than the lap
        k *= 1.0 - 0.45 * _line(u, 0.23, 0.02, fw)
        k *= 1.0 - 0.35 * _line(v + off, 0.3, 0.012, fw)
        b *= 0.95 + 0.1 * _hash2(col, row, salt + 51)  # blue-grey to purple-grey slates
    elif mat == 24:  # asphalt shingle: 14 cm rows of 33 cm staggered tabs, granules
        row = math.floor(u / 0.14)
        off = 0.165 if row % 2 == 0 else 0.0
        tab = math.floor((v + off) / 0.33)
        k = 0.82 + 0.26 * _hash2(row, tab, salt + 60)
        k *= 0.9 + 0.2 * _hash2(math.floor(u * 40.0), math.floor(v * 40.0), salt + 62)
        k *= 1.0 - 0.4 * _line(u, 0.14, 0.015, fw)
        k *= 1.0 - 0.3 * _line(v + off, 0.33, 0.01, fw)
        k *= 0.92 + 0.16 * _value_noise(u * 0.5, v * 0.5, salt + 63)
    elif mat == 25:  # standing-seam metal: a bright/dark seam pair every 0.5 m, slightly varied panels
        k = 0.93 + 0.1 * _hash2(math.floor(v / 0.5), math.floor(u / 6.0), salt + 70)
        k *= 1.0 + 0.4 * _line(v, 0.5, 0.025, fw)
        k *= 1.0 - 0.4 * _line(v - 0.025, 0.5, 0.03, fw)
        k *= 0.95 + 0.1 * _value_noise(u * 0.8, v * 3.0, salt + 71)  # oil canning
    elif mat == 26:  # glass: dark panes reflecting the sky in a gradient, 1 m panels in a light frame
        pu = _wrap(u, 1.0)
        pv = _wrap(v, 1.0)
        refl = 0.15 + 0.45 * (0.6 * pu + 0.4 * pv) + 0.3 * _value_noise(u * 0.3, v * 0.3, salt + 80)
        pane = 0.8 + 0.3 * _hash2(math.floor(u), math.floor(v), salt + 81)
        r = r * pane * (1.0 - 0.5 * refl) + 0.62 * 0.5 * refl
        g = g * pane * (1.0 - 0.5 * refl) + 0.72 * 0.5 * refl
        b = b * pane * (1.0 - 0.5 * refl) + 0.85 * 0.5 * refl
        frame = max(_line(u + 0.03, 1.0, 0.06, fw), _line(v + 0.03, 1.0, 0.06, fw))
        r += (0.56 - r) * frame
        g += (0.57 - g) * frame
        b += (0.59 - b) * frame
    elif mat == 27:  # pool: caustic ripple network, lighter / cyan variation over the basin
        n1 = 1.0 - abs(2.0 * _value_noise(u * 1.3, v * 1.3, salt + 90) - 1.0)
        n2 = 1.0 - abs(2.0 * _value_noise(u * 2.9 + 3.1, v * 2.9, salt + 91) - 1.0)
        c = (0.6 * n1**4 + 0.4 * n2**4) * max(0.0, 1.0 - fw / 0.8)
        d = 0.88 + 0.2 * _value_noise(u * 0.12, v * 0.12, salt + 92)
        return (r * d + 0.22 * c, g * d + 0.28 * c, b * d + 0.24 * c)
    return (r * k, g * k, b * k)


# ------------------------------------------------------------------ domain randomisation (training only)
# Layout of the float64 parameter vector ``shade`` takes (``RenderVariety._params``). With ``_VP_ON`` 0
# ``shade`` takes exactly the fixed look's path (byte-identical frames); only ``_VP_PX`` is read then.
_VP_ON, _VP_AMBIENT, _VP_SUN_GAIN, _VP_TINT, _VP_SCALE_LO, _VP_SCALE_HI = 0, 1, 2, 3, 4, 5
_VP_ORIENT, _VP_STAIN, _VP_SOFT, _VP_SHADOW_DEPTH, _VP_SALT, _VP_PX = 6, 7, 8, 9, 10, 11
_VP_SIZE = 12
_SOFT_SHADOW_M = 0.6  # penumbra half-width at ``soft_shadow`` 1


@dataclass(frozen=True, slots=True)
class RenderVariety:
    """Opt-in domain randomisation of the camera's look, for training data (``render(..., variety=)``).

    The defaults are the fixed look the flight simulator renders (``render`` then takes exactly the
    path it takes without a variety, byte for byte). Per-region effects key on ``WorldGrid.region``
    (> 0: one building or object) hashed with ``salt``; open ground varies smoothly over tens of metres.

    Attributes:
        ambient: light every surface gets, in [0, 1] (0.38; overcast ~0.6-0.8).
        sun_gain: direct sunlight on a surface facing the sun, in [0, 2] (0.85; overcast ~0.2-0.4).
        tint: strength in [0, 1] (useful up to ~0.35) of a per-region colour tint: brightness, a
            red/blue hue shift, a green shift and desaturation (red, brown, orange or grey tiles).
        texture_scale: (low, high) range in [0.25, 4] of a per-region, log-uniform scale on texture
            periods (ridges, rows, slabs, seams).
        orient: rotate each region's textures: rows run across the slope of a pitched roof (parallel
            to the eave), at a hashed angle on flat roofs.
        stain: amount in [0, 1] of value-noise stains at 0.5-5 m: darkening streaks down the slope,
            moss on tiles / slate / shingle / concrete, rust on metal, dry patches on grass.
        soft_shadow: penumbra in [0, 1]: the shadow is averaged over up to ``_SOFT_SHADOW_M`` metres
            around the hit point (cells at a similar height only) instead of read per cell.
        shadow_depth: fraction in [0, 1] of the direct light a shadow removes (1: all of it).
        salt: seed in [0, 2**31) of every hash and noise.
    """

    ambient: float = 0.38
    sun_gain: float = 0.85
    tint: float = 0.0
    texture_scale: tuple[float, float] = (1.0, 1.0)
    orient: bool = False
    stain: float = 0.0
    soft_shadow: float = 0.0
    shadow_depth: float = 1.0
    salt: int = 0

    def __post_init__(self) -> None:
        for name, lo, hi in (
            ("ambient", 0.0, 1.0), ("sun_gain", 0.0, 2.0), ("tint", 0.0, 1.0), ("stain", 0.0, 1.0),
            ("soft_shadow", 0.0, 1.0), ("shadow_depth", 0.0, 1.0),
        ):  # fmt: skip
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value) and lo <= value <= hi):
                raise ValueError(f"RenderVariety.{name} must be a number in [{lo}, {hi}], got {value!r}")
        scale = self.texture_scale
        if not (
            len(scale) == 2
            and all(isinstance(s, int | float) and math.isfinite(s) for s in scale)
            and 0.25 <= scale[0] <= scale[1] <= 4.0
        ):
            raise ValueError(
                "RenderVariety.texture_scale must be (low, high) with 0.25 <= low <= high <= 4, "
                f"got {scale!r}"
            )
        if not isinstance(self.orient, bool):
            raise ValueError(f"RenderVariety.orient must be a bool, got {self.orient!r}")
        if not (isinstance(self.salt, int) and not isinstance(self.salt, bool) and 0 <= self.salt < 2**31):
            raise ValueError(f"RenderVariety.salt must be an int in [0, 2**31), got {self.salt!r}")

    @property
    def is_neutral(self) -> bool:
        """True when this is the fixed look (the defaults; the salt then changes nothing)."""
        return replace(self, salt=0) == RenderVariety()

    @staticmethod
    def sample(rng: np.random.Generator) -> RenderVariety:
        """A random variety for one training frame: hard sun (70%) or overcast light, tints, scales,
        orientations, stains and penumbras drawn from ranges that cover real aerial photographs."""
        if rng.random() < 0.3:  # overcast: flat light, faint soft shadows
            ambient, gain = rng.uniform(0.55, 0.8), rng.uniform(0.1, 0.4)
            depth, soft = rng.uniform(0.2, 0.6), rng.uniform(0.5, 1.0)
        else:
            ambient, gain = rng.uniform(0.28, 0.5), rng.uniform(0.7, 1.05)
            depth, soft = rng.uniform(0.75, 1.0), rng.uniform(0.0, 0.7)
        return RenderVariety(
            ambient=float(ambient), sun_gain=float(gain), tint=float(rng.uniform(0.1, 0.35)),
            texture_scale=(0.7, 1.5), orient=True, stain=float(rng.uniform(0.0, 0.8)),
            soft_shadow=float(soft), shadow_depth=float(depth), salt=int(rng.integers(0, 2**31)),
        )  # fmt: skip


def _variety_params(variety: RenderVariety | None, px_angle: float) -> np.ndarray:
    """``shade``'s parameter vector: off (the fixed look) for None or a neutral variety."""
    vp = np.zeros(_VP_SIZE, np.float64)
    vp[_VP_PX] = px_angle
    if variety is not None and not variety.is_neutral:
        vp[_VP_ON] = 1.0
        vp[_VP_AMBIENT] = variety.ambient
        vp[_VP_SUN_GAIN] = variety.sun_gain
        vp[_VP_TINT] = variety.tint
        vp[_VP_SCALE_LO], vp[_VP_SCALE_HI] = variety.texture_scale
        vp[_VP_ORIENT] = 1.0 if variety.orient else 0.0
        vp[_VP_STAIN] = variety.stain
        vp[_VP_SOFT] = variety.soft_shadow
        vp[_VP_SHADOW_DEPTH] = variety.shadow_depth
        vp[_VP_SALT] = float(variety.salt)
    return vp


@njit(cache=True, fastmath=True)
def _vary_tint(
    r: float, g: float, b: float, reg: int, pn: float, pe: float, vp: np.ndarray
) -> tuple[float, float, float]:
    """Per-region colour tint (``RenderVariety.tint``): hashed per building, smooth noise on open ground."""
    tint = vp[_VP_TINT]
    if tint <= 0.0:
        return (r, g, b)
    salt = int(vp[_VP_SALT])
    if reg > 0:
        h1 = _hash2(reg, 21, salt)
        h2 = _hash2(reg, 22, salt)
        h3 = _hash2(reg, 23, salt)
        desat = min(0.8, 2.0 * tint * _hash2(reg, 24, salt))
    else:
        h1 = _value_noise(pn / 30.0, pe / 30.0, salt + 5)
        h2 = _value_noise(pn / 45.0 + 7.0, pe / 45.0, salt + 6)
        h3 = 0.5
        desat = 0.0
        tint *= 0.6
    bright = 1.0 + tint * (2.0 * h1 - 1.0)
    hue = tint * (2.0 * h2 - 1.0)
    r *= bright * (1.0 + hue)
    g *= bright * (1.0 + 0.5 * tint * (2.0 * h3 - 1.0))
    b *= bright * (1.0 - 0.8 * hue)
    lum = 0.3 * r + 0.59 * g + 0.11 * b
    return (r + (lum - r) * desat, g + (lum - g) * desat, b + (lum - b) * desat)


@njit(cache=True, fastmath=True)
def _vary_albedo(
    m: int, pn: float, pe: float, reg: int, fw: float, gn: float, ge: float, vp: np.ndarray,
    r: float, g: float, b: float,
) -> tuple[float, float, float]:  # fmt: skip
    """Albedo under a ``RenderVariety``: the material's texture in per-region rotated, scaled and
    shifted coordinates, then the region's tint and stains. ``(gn, ge)``: the surface's height gradient
    (0 where level), ``fw``: the pixel footprint in metres."""
    salt = int(vp[_VP_SALT])
    lo = vp[_VP_SCALE_LO]
    key = reg if reg > 0 else 0
    scale = lo * (vp[_VP_SCALE_HI] / lo) ** _hash2(key, 12, salt)
    ang = 0.0
    ou = 0.0
    ov = 0.0
    if reg > 0:
        if vp[_VP_ORIENT] > 0.5:
            ang = math.atan2(ge, gn) if (gn != 0.0 or ge != 0.0) else math.pi * _hash2(reg, 13, salt)
        ou = 37.0 * _hash2(reg, 14, salt)
        ov = 37.0 * _hash2(reg, 15, salt)
    c = math.cos(ang)
    s = math.sin(ang)
    u = (pn * c + pe * s) / scale + ou
    v = (pe * c - pn * s) / scale + ov
    if m >= 22:
        r, g, b = _texture_new(m, u, v, r, g, b, fw / scale, (key * 7919 + salt) & 0x3FFFFFFF)
    else:
        r, g, b = _texture(m, u, v, r, g, b)
    r, g, b = _vary_tint(r, g, b, reg, pn, pe, vp)
    stain = vp[_VP_STAIN]
    if stain > 0.0 and m != 11 and m != 12 and m != 27:
        x = (
            0.5 * _value_noise(pn * 0.22, pe * 0.22, salt + 31)
            + 0.25 * _value_noise(pn * 0.9, pe * 0.9, salt + 32)
            + 0.25 * _value_noise(u * 0.25, v * 2.0, salt + 33)  # streaks down the slope
        )
        a = min(max((x - 0.72 + 0.3 * stain) / 0.2, 0.0), 1.0) * min(1.0, 1.5 * stain)
        kind = _hash2(key, 25, salt) if reg > 0 else 1.0
        if m == 14 or m == 22 or m == 25:  # metal: rust or grime
            if kind < 0.6:
                w = 0.75 * a
                r += (0.42 - r) * w
                g += (0.22 - g) * w
                b += (0.10 - b) * w
            else:
                r *= 1.0 - 0.45 * a
                g *= 1.0 - 0.45 * a
                b *= 1.0 - 0.45 * a
        elif m == 10:  # grass: dry patches
            w = 0.5 * a
            r += (0.55 - r) * w
            g += (0.50 - g) * w
            b += (0.30 - b) * w
        elif kind < 0.4 and (m == 1 or m == 2 or m == 3 or m == 4 or m == 5 or m == 23 or m == 24):
            w = 0.6 * a  # moss / lichen
            r += (0.22 - r) * w
            g += (0.30 - g) * w
            b += (0.12 - b) * w
        else:  # darkening streaks, dirt
            r *= 1.0 - 0.45 * a
            g *= 1.0 - 0.42 * a
            b *= 1.0 - 0.38 * a
    return (r, g, b)


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

    ``vp``: the ``RenderVariety`` parameter vector (``_VP_*``); with ``vp[_VP_ON]`` 0 the fixed look,
    byte for byte as before varieties existed."""
    n = ts.shape[0]
    rows, cols = height.shape
    direct = out_u8.shape[0] == n
    out = np.empty((0 if direct else n, 3), np.float32)
    state = np.uint64(seed) * np.uint64(6364136223846793005) + np.uint64(1442695040888963407)
    ambient = 0.38
    cam_up = origin[2]
    vary = vp[_VP_ON] > 0.5
    amb_v = vp[_VP_AMBIENT]
    gain_v = vp[_VP_SUN_GAIN]
    px = vp[_VP_PX]
    soft_m = vp[_VP_SOFT] * _SOFT_SHADOW_M
    shadow_depth = vp[_VP_SHADOW_DEPTH]
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
                    r, g, b = _vary_albedo(
                        18, pn, pe, 0, t * px, 0.0, 0.0, vp, mat_rgb[18, 0], mat_rgb[18, 1], mat_rgb[18, 2]
                    )
                    light = amb_v + gain_v * (0.8 / 0.85) * max(sun[2], 0.0)
                else:
                    r, g, b = _texture(18, pn, pe, mat_rgb[18, 0], mat_rgb[18, 1], mat_rgb[18, 2])
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
                    r, g, b = _vary_albedo(
                        m, pn, pe, reg, t * px, gn, ge, vp, mat_rgb[m, 0], mat_rgb[m, 1], mat_rgb[m, 2]
                    )
                elif m >= 22:  # the roof materials without a fixed look to keep: axis-aligned
                    r, g, b = _texture_new(m, pn, pe, mat_rgb[m, 0], mat_rgb[m, 1], mat_rgb[m, 2], t * px, 0)
                else:
                    r, g, b = _texture(m, pn, pe, mat_rgb[m, 0], mat_rgb[m, 1], mat_rgb[m, 2])
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
                if reg > 0 and 1.0 < _wrap(pu, 3.0) < 2.4 and _wrap(along, 1.6) > 0.4:
                    r, g, b = 0.16, 0.2, 0.26  # glass
                elif vary:
                    r, g, b = _vary_tint(r, g, b, reg, pn, pe, vp)
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
    if palette is not None and (palette.shape != _MAT_RGB.shape or palette.dtype != np.float32):
        raise ValueError(
            f"palette must be float32 of shape {_MAT_RGB.shape}, got {palette.dtype} {palette.shape}"
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
        grid.res, grid.n0, grid.e0, sun, _MAT_RGB if palette is None else palette, _ACTOR_RGB, _FACADE_RGB,
        ray_len, grid.cls, depth, cls, out, vignette.reshape(-1), seed, SENSOR_NOISE,
        _variety_params(variety, 1.0 / camera.focal_px),
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
