"""Domain randomisation of the camera (training renders only): :class:`RenderVariety` and the tint and
albedo changes the shader applies with it."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numba import njit

from simbridge.world.camera_textures import hash2, texture, texture_new, value_noise

# Layout of the float64 parameter vector ``shade`` takes (``RenderVariety._params``). With ``VP_ON`` 0
# ``shade`` takes exactly the fixed look's path (byte-identical frames); only ``VP_PX`` is read then.
VP_ON, VP_AMBIENT, VP_SUN_GAIN, VP_TINT, VP_SCALE_LO, VP_SCALE_HI = 0, 1, 2, 3, 4, 5
VP_ORIENT, VP_STAIN, VP_SOFT, VP_SHADOW_DEPTH, VP_SALT, VP_PX = 6, 7, 8, 9, 10, 11
VP_SIZE = 12
SOFT_SHADOW_M = 0.6  # penumbra half-width at ``soft_shadow`` 1


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
        soft_shadow: penumbra in [0, 1]: the shadow is averaged over up to ``SOFT_SHADOW_M`` metres
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


def variety_params(variety: RenderVariety | None, px_angle: float) -> np.ndarray:
    """``shade``'s parameter vector: off (the fixed look) for None or a neutral variety."""
    vp = np.zeros(VP_SIZE, np.float64)
    vp[VP_PX] = px_angle
    if variety is not None and not variety.is_neutral:
        vp[VP_ON] = 1.0
        vp[VP_AMBIENT] = variety.ambient
        vp[VP_SUN_GAIN] = variety.sun_gain
        vp[VP_TINT] = variety.tint
        vp[VP_SCALE_LO], vp[VP_SCALE_HI] = variety.texture_scale
        vp[VP_ORIENT] = 1.0 if variety.orient else 0.0
        vp[VP_STAIN] = variety.stain
        vp[VP_SOFT] = variety.soft_shadow
        vp[VP_SHADOW_DEPTH] = variety.shadow_depth
        vp[VP_SALT] = float(variety.salt)
    return vp


@njit(cache=True, fastmath=True)
def vary_tint(
    r: float, g: float, b: float, reg: int, pn: float, pe: float, vp: np.ndarray
) -> tuple[float, float, float]:
    """Per-region colour tint (``RenderVariety.tint``): hashed per building, smooth noise on open ground."""
    tint = vp[VP_TINT]
    if tint <= 0.0:
        return (r, g, b)
    salt = int(vp[VP_SALT])
    if reg > 0:
        h1 = hash2(reg, 21, salt)
        h2 = hash2(reg, 22, salt)
        h3 = hash2(reg, 23, salt)
        desat = min(0.8, 2.0 * tint * hash2(reg, 24, salt))
    else:
        h1 = value_noise(pn / 30.0, pe / 30.0, salt + 5)
        h2 = value_noise(pn / 45.0 + 7.0, pe / 45.0, salt + 6)
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
def vary_albedo(
    m: int, pn: float, pe: float, reg: int, fw: float, gn: float, ge: float, vp: np.ndarray,
    r: float, g: float, b: float,
) -> tuple[float, float, float]:  # fmt: skip
    """Albedo under a ``RenderVariety``: the material's texture in per-region rotated, scaled and
    shifted coordinates, then the region's tint and stains. ``(gn, ge)``: the surface's height gradient
    (0 where level), ``fw``: the pixel footprint in metres."""
    salt = int(vp[VP_SALT])
    lo = vp[VP_SCALE_LO]
    key = reg if reg > 0 else 0
    scale = lo * (vp[VP_SCALE_HI] / lo) ** hash2(key, 12, salt)
    ang = 0.0
    ou = 0.0
    ov = 0.0
    if reg > 0:
        if vp[VP_ORIENT] > 0.5:
            ang = math.atan2(ge, gn) if (gn != 0.0 or ge != 0.0) else math.pi * hash2(reg, 13, salt)
        ou = 37.0 * hash2(reg, 14, salt)
        ov = 37.0 * hash2(reg, 15, salt)
    c = math.cos(ang)
    s = math.sin(ang)
    u = (pn * c + pe * s) / scale + ou
    v = (pe * c - pn * s) / scale + ov
    if m >= 22:
        r, g, b = texture_new(m, u, v, r, g, b, fw / scale, (key * 7919 + salt) & 0x3FFFFFFF)
    else:
        r, g, b = texture(m, u, v, r, g, b)
    r, g, b = vary_tint(r, g, b, reg, pn, pe, vp)
    stain = vp[VP_STAIN]
    if stain > 0.0 and m != 11 and m != 12 and m != 27:
        x = (
            0.5 * value_noise(pn * 0.22, pe * 0.22, salt + 31)
            + 0.25 * value_noise(pn * 0.9, pe * 0.9, salt + 32)
            + 0.25 * value_noise(u * 0.25, v * 2.0, salt + 33)  # streaks down the slope
        )
        a = min(max((x - 0.72 + 0.3 * stain) / 0.2, 0.0), 1.0) * min(1.0, 1.5 * stain)
        kind = hash2(key, 25, salt) if reg > 0 else 1.0
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
