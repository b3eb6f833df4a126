"""The camera's materials: the palette per material, actor and facade colours, and the procedural
textures (value noise, gravel, tiles, markings, water...) the shader samples (numba, inlined)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from simbridge.world.model import Material

MAT_RGB = np.zeros((32, 3), np.float32)
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
    Material.SAND: (0.80, 0.72, 0.55),
    Material.CROP: (0.42, 0.52, 0.20),
}.items():
    MAT_RGB[int(_m)] = _rgb


def default_palette() -> np.ndarray:
    """A copy of the built-in (32, 3) float32 RGB palette per ``Material`` (``render(..., palette=)``)."""
    return MAT_RGB.copy()


ACTOR_RGB = np.array(
    [(0.85, 0.85, 0.87), (0.08, 0.08, 0.09), (0.62, 0.08, 0.07), (0.10, 0.22, 0.55), (0.55, 0.56, 0.58),
     (0.90, 0.75, 0.10), (0.15, 0.40, 0.20), (0.75, 0.40, 0.10)],
    np.float32,
)  # fmt: skip
FACADE_RGB = np.array(
    [(0.72, 0.70, 0.66), (0.60, 0.36, 0.28), (0.52, 0.55, 0.58), (0.80, 0.76, 0.66), (0.42, 0.44, 0.48)],
    np.float32,
)  # fmt: skip


@njit(cache=True, fastmath=True, inline="always")
def hash2(a: int, b: int, salt: int) -> float:
    """Deterministic value in [0, 1) for an integer lattice point."""
    h = (a * 374761393 + b * 668265263 + salt * 2147483647) & 0xFFFFFFFF
    h = ((h ^ (h >> 13)) * 1274126177) & 0xFFFFFFFF
    h = h ^ (h >> 16)
    return (h & 0xFFFFFF) / 16777216.0


@njit(cache=True, fastmath=True, inline="always")
def value_noise(x: float, y: float, salt: int) -> float:
    """Smooth value noise in [0, 1) at lattice spacing 1."""
    ix = math.floor(x)
    iy = math.floor(y)
    fx = x - ix
    fy = y - iy
    fx = fx * fx * (3 - 2 * fx)
    fy = fy * fy * (3 - 2 * fy)
    a = hash2(ix, iy, salt)
    b = hash2(ix + 1, iy, salt)
    c = hash2(ix, iy + 1, salt)
    d = hash2(ix + 1, iy + 1, salt)
    return (a * (1 - fx) + b * fx) * (1 - fy) + (c * (1 - fx) + d * fx) * fy


@njit(cache=True, fastmath=True, inline="always")
def wrap(x: float, period: float) -> float:
    """``x % period`` for a positive period, without the float modulo's slow path."""
    return x - period * math.floor(x / period)


@njit(cache=True, fastmath=True, inline="always")
def texture(mat: int, pn: float, pe: float, r: float, g: float, b: float) -> tuple[float, float, float]:
    """Procedural albedo of a material at world point (north, east), from its base colour."""
    k = 1.0
    if mat == 1:  # gravel: grains of 4 cm, varied tone
        k = 0.78 + 0.44 * hash2(math.floor(pn * 25), math.floor(pe * 25), 1)
        k *= 0.9 + 0.2 * value_noise(pn * 0.4, pe * 0.4, 2)
    elif mat == 2:  # concrete: slabs with joints and stains
        k = (
            0.9
            + 0.15 * value_noise(pn * 0.3, pe * 0.3, 3)
            + 0.05 * hash2(math.floor(pn * 20), math.floor(pe * 20), 4)
        )
        if wrap(pn, 3.0) < 0.06 or wrap(pe, 3.0) < 0.06:
            k *= 0.75
    elif mat == 3:  # tar
        k = (
            0.85
            + 0.3 * value_noise(pn * 0.8, pe * 0.8, 5)
            + 0.1 * hash2(math.floor(pn * 30), math.floor(pe * 30), 6)
        )
    elif mat == 4:  # membrane: seams every 1.5 m
        k = 0.95 + 0.05 * value_noise(pn * 0.5, pe * 0.5, 7)
        if wrap(pe, 1.5) < 0.04:
            k *= 0.85
    elif mat == 5:  # tiles
        row = math.floor(pn / 0.3)
        off = 0.15 if row % 2 == 0 else 0.0
        k = 0.82 + 0.3 * hash2(row, math.floor((pe + off) / 0.3), 8)
        if wrap(pn, 0.3) < 0.04 or wrap(pe + off, 0.3) < 0.03:
            k *= 0.6
    elif mat == 6:  # asphalt
        k = (
            0.85
            + 0.25 * hash2(math.floor(pn * 20), math.floor(pe * 20), 9)
            + 0.15 * value_noise(pn * 0.2, pe * 0.2, 10)
        )
    elif mat == 8:  # paving stones 0.5 m
        k = 0.88 + 0.2 * hash2(math.floor(pn * 2), math.floor(pe * 2), 11)
        if wrap(pn, 0.5) < 0.03 or wrap(pe, 0.5) < 0.03:
            k *= 0.7
    elif mat == 10:  # grass
        k = (
            0.75
            + 0.35 * value_noise(pn * 0.7, pe * 0.7, 12)
            + 0.15 * hash2(math.floor(pn * 15), math.floor(pe * 15), 13)
        )
    elif mat == 11:  # foliage: clumps
        k = 0.6 + 0.7 * value_noise(pn * 1.5, pe * 1.5, 14)
    elif mat == 12:  # water: ripples
        k = 0.85 + 0.3 * value_noise(pn * 1.2 + pe * 0.3, pe * 0.9, 15)
    elif mat == 13:  # wood planks 0.2 m
        k = 0.8 + 0.3 * hash2(math.floor(pe / 0.2), math.floor(pn / 2.0), 16)
        if wrap(pe, 0.2) < 0.02:
            k *= 0.6
    elif mat == 14:  # metal: brushed panels
        k = 0.9 + 0.12 * hash2(math.floor(pn * 2), math.floor(pe * 2), 17)
    elif mat == 15:  # solar cells
        if wrap(pn, 1.0) < 0.05 or wrap(pe, 1.7) < 0.05:
            k = 2.4
        else:
            k = 0.9 + 0.2 * hash2(math.floor(pn * 6), math.floor(pe * 6), 18)
    elif mat == 16:  # rubble
        k = 0.55 + 0.8 * hash2(math.floor(pn * 6), math.floor(pe * 6), 19)
    elif mat == 18:  # soil
        k = 0.8 + 0.35 * value_noise(pn * 0.5, pe * 0.5, 20)
    return (r * k, g * k, b * k)


@njit(cache=True, fastmath=True, inline="always")
def _line(x: float, period: float, width: float, fw: float) -> float:
    """Coverage in [0, 1] of a thin periodic line (``width`` m every ``period`` m) at ``x``, box-filtered
    over a pixel footprint of ``fw`` m: a line thinner than the footprint widens and fades instead of
    aliasing into dots."""
    eff = max(width, fw)
    return width / eff if wrap(x, period) < eff else 0.0


@njit(cache=True, fastmath=True)
def texture_new(
    mat: int, u: float, v: float, r: float, g: float, b: float, fw: float, salt: int
) -> tuple[float, float, float]:
    """Procedural albedo of the materials 22..29 (``Material.CORRUGATED`` .. ``CROP``) at local
    coordinates (u, v) in metres: u runs across the rows (down the slope), v along them (the eave).
    ``fw`` is the pixel footprint in metres (fine ridges and lines fade as it grows); ``salt`` varies
    the per-sheet / per-slate tones."""
    k = 1.0
    if mat == 22:  # corrugated sheet: 12 cm ridges down the slope, 1 m x 2.5 m sheets, weathering
        period = 0.12
        s = math.sin(6.283185307179586 * v / period)
        fade = max(0.0, 1.0 - 1.2 * fw / period)  # fades out before it would alias
        k = 1.0 + fade * (0.2 * s + 0.1 * s * s - 0.05)  # lit flank, dark flank, bright crest
        k *= 0.94 + 0.12 * hash2(math.floor(u / 2.5), math.floor(v / 1.0), salt + 40)
        k *= 1.0 - 0.35 * _line(u, 2.5, 0.05, fw)  # end lap: the upper sheet's edge casts a line
        k *= 1.0 - 0.15 * _line(v, 1.0, 0.03, fw)  # side lap
        k *= 0.86 + 0.24 * value_noise(u * 0.7, v * 0.7, salt + 41)
        k *= 0.96 + 0.08 * hash2(math.floor(u * 10.0), math.floor(v * 10.0), salt + 42)
    elif mat == 23:  # slate: 23 cm rows of 30 cm slates, half-bond, thin dark gaps
        row = math.floor(u / 0.23)
        off = 0.15 if row % 2 == 0 else 0.0
        col = math.floor((v + off) / 0.3)
        h = hash2(row, col, salt + 50)
        k = 0.7 + 0.45 * h
        k *= 0.9 + 0.12 * (u / 0.23 - row)  # the exposed lower edge is lighter than the lap
        k *= 1.0 - 0.45 * _line(u, 0.23, 0.02, fw)
        k *= 1.0 - 0.35 * _line(v + off, 0.3, 0.012, fw)
        b *= 0.95 + 0.1 * hash2(col, row, salt + 51)  # blue-grey to purple-grey slates
    elif mat == 24:  # asphalt shingle: 14 cm rows of 33 cm staggered tabs, granules
        row = math.floor(u / 0.14)
        off = 0.165 if row % 2 == 0 else 0.0
        tab = math.floor((v + off) / 0.33)
        k = 0.82 + 0.26 * hash2(row, tab, salt + 60)
        k *= 0.9 + 0.2 * hash2(math.floor(u * 40.0), math.floor(v * 40.0), salt + 62)
        k *= 1.0 - 0.4 * _line(u, 0.14, 0.015, fw)
        k *= 1.0 - 0.3 * _line(v + off, 0.33, 0.01, fw)
        k *= 0.92 + 0.16 * value_noise(u * 0.5, v * 0.5, salt + 63)
    elif mat == 25:  # standing-seam metal: a bright/dark seam pair every 0.5 m, slightly varied panels
        k = 0.93 + 0.1 * hash2(math.floor(v / 0.5), math.floor(u / 6.0), salt + 70)
        k *= 1.0 + 0.4 * _line(v, 0.5, 0.025, fw)
        k *= 1.0 - 0.4 * _line(v - 0.025, 0.5, 0.03, fw)
        k *= 0.95 + 0.1 * value_noise(u * 0.8, v * 3.0, salt + 71)  # oil canning
    elif mat == 26:  # glass: dark panes reflecting the sky in a gradient, 1 m panels in a light frame
        pu = wrap(u, 1.0)
        pv = wrap(v, 1.0)
        refl = 0.15 + 0.45 * (0.6 * pu + 0.4 * pv) + 0.3 * value_noise(u * 0.3, v * 0.3, salt + 80)
        pane = 0.8 + 0.3 * hash2(math.floor(u), math.floor(v), salt + 81)
        r = r * pane * (1.0 - 0.5 * refl) + 0.62 * 0.5 * refl
        g = g * pane * (1.0 - 0.5 * refl) + 0.72 * 0.5 * refl
        b = b * pane * (1.0 - 0.5 * refl) + 0.85 * 0.5 * refl
        frame = max(_line(u + 0.03, 1.0, 0.06, fw), _line(v + 0.03, 1.0, 0.06, fw))
        r += (0.56 - r) * frame
        g += (0.57 - g) * frame
        b += (0.59 - b) * frame
    elif mat == 27:  # pool: caustic ripple network, lighter / cyan variation over the basin
        n1 = 1.0 - abs(2.0 * value_noise(u * 1.3, v * 1.3, salt + 90) - 1.0)
        n2 = 1.0 - abs(2.0 * value_noise(u * 2.9 + 3.1, v * 2.9, salt + 91) - 1.0)
        c = (0.6 * n1**4 + 0.4 * n2**4) * max(0.0, 1.0 - fw / 0.8)
        d = 0.88 + 0.2 * value_noise(u * 0.12, v * 0.12, salt + 92)
        return (r * d + 0.22 * c, g * d + 0.28 * c, b * d + 0.24 * c)
    elif mat == 28:  # sand: fine grain, wind ripples 8-12 cm apart, damp and dry patches
        k = 0.9 + 0.12 * hash2(math.floor(u * 30.0), math.floor(v * 30.0), salt + 100)
        ripple = math.sin(6.283185307179586 * (u + 0.3 * value_noise(u * 0.5, v * 0.5, salt + 101)) / 0.1)
        k *= 1.0 + 0.05 * ripple * max(0.0, 1.0 - fw / 0.1)
        k *= 0.82 + 0.26 * value_noise(u * 0.08, v * 0.08, salt + 102)
    elif mat == 29:  # standing crops: rows 0.75 m apart (green plants over soil), tramlines every 24 m
        leaf = 0.5 + 0.5 * math.cos(6.283185307179586 * u / 0.75)  # 1 on a row, 0 between two
        cover = 0.55 + 0.45 * max(0.0, 1.0 - fw / 0.75) * (leaf - 0.5) * 2.0
        cover = min(1.0, max(0.0, cover)) * (0.85 + 0.3 * value_noise(u * 0.6, v * 0.6, salt + 110))
        cover *= 1.0 - 0.6 * _line(u, 24.0, 0.5, fw)  # the sprayer's tramlines: bare soil
        cover = min(1.0, cover)
        tint = 0.85 + 0.3 * value_noise(u * 0.05, v * 0.05, salt + 111)  # ripening unevenly
        r = cover * r * tint + (1.0 - cover) * 0.47
        g = cover * g * (0.9 + 0.1 * tint) + (1.0 - cover) * 0.40
        b = cover * b + (1.0 - cover) * 0.30
        k = 0.93 + 0.14 * hash2(math.floor(u * 8.0), math.floor(v * 8.0), salt + 112)
    return (r * k, g * k, b * k)
