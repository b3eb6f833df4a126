"""Ray casting against the 2.5-D world grid, compiled with numba (one module over 600 lines: the
max-map pyramid and the casts that read it are one structure).

The grid stores, per cell (``res`` metres square), the height of the top surface in metres above
the scenario origin (up positive). Cell ``(i, j)`` spans north ``[n0 + i res, n0 + (i+1) res)``
and east ``[e0 + j res, e0 + (j+1) res)``. A ray is ``p(t) = o + t d`` in (north, east, up)
metres with ``|d| = 1``.

Empty space is skipped with centred max maps: on coarse cells of ``COARSE`` fine cells (0.8 m at
0.2 m resolution), level ``k`` holds the tallest fine cell within ``2**k`` coarse cells in every
direction. Wherever the ray is, if it stays above level ``k``'s value while moving ``2**k`` coarse
cells horizontally, it moves that far at once (in any direction: a sphere-tracing step with a
Chebyshev ball). When no level allows a jump the ray steps fine cells (2-D DDA) for one coarse cell
of travel and tries again. A ray hits a cell's *top* where it descends through the cell's height
inside the cell, or a *wall* where it enters a cell below that cell's height.

A camera image is cast in tiles (``cast_rays(..., row, tile)``): each tile's centre ray is
marched, and the tile's whole bundle of rays is then proven clear above the roof or street the
centre ray hit, or in front of the wall face it hit, with a few max-map lookups (or, beside an
edge, a few cells read one by one). After that each ray of the tile costs one cell lookup. Rays
the proofs leave open try their neighbour's plane and are marched. Every mode gives the march's
answer, ray for ray: a proof that cannot be made exactly is not used (tested equal on whole
images in both scenarios).

Hit kinds: 0 top, 1 wall crossed along north, 2 wall crossed along east, -1 miss.

Kept whole (about 700 lines): the pyramid and the numba casts that walk it share one memory layout
and one set of kernels; apart, neither reads without the other.
"""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np
from numba import njit

HIT_TOP, HIT_WALL_N, HIT_WALL_E, HIT_MISS = 0, 1, 2, -1
COARSE_SHIFT = 2  # coarse cells are 4 x 4 fine cells
COARSE = 1 << COARSE_SHIFT
LEVELS = 8  # jump radii of 1, 2, 4, ... 128 coarse cells (0.8 m ... 102.4 m at 0.2 m resolution)
_BIG = 1e30
FINE_SCAN_CELLS = 256  # a bundle layer's box up to this many cells is checked cell by cell
FLOOR_M = -50.0  # nothing in a world lies lower: a bundle's floor stops here
FINE_BACK_M = 2.4  # horizontal travel back from a plane hit proven cell by cell (``_plane_clear``)


@njit(cache=True)
def max_pool(height: np.ndarray, block: int) -> np.ndarray:
    """Maximum over each ``block`` x ``block`` square (the last row/column may be partial)."""
    rows, cols = height.shape
    out = np.full(((rows + block - 1) // block, (cols + block - 1) // block), -1e9, dtype=np.float32)
    for i in range(rows):
        row = height[i]
        pooled = out[i // block]
        for bj in range(pooled.shape[0]):
            m = pooled[bj]
            for j in range(bj * block, min(bj * block + block, cols)):
                if row[j] > m:
                    m = row[j]
            pooled[bj] = m
    return out


@njit(cache=True)
def _dilate(a: np.ndarray, s: int) -> np.ndarray:
    """Max over offsets in {-s, 0, +s} along both axes, an offset past an edge taking the edge's
    value."""
    rows, cols = a.shape
    tmp = np.empty_like(a)
    for i in range(rows):
        up, down = max(i - s, 0), min(i + s, rows - 1)
        for j in range(cols):
            tmp[i, j] = max(a[up, j], a[i, j], a[down, j])
    out = np.empty_like(a)
    for i in range(rows):
        for j in range(cols):
            out[i, j] = max(tmp[i, max(j - s, 0)], tmp[i, j], tmp[i, min(j + s, cols - 1)])
    return out


def _max_levels(base: np.ndarray) -> Iterator[np.ndarray]:
    """Level ``k`` of the max maps over coarse cells ``base``: the maximum within ``2**k`` cells
    (Chebyshev), each level dilating the one before by half its radius."""
    level = _dilate(base, 1)
    yield level
    for k in range(1, LEVELS):
        level = _dilate(level, 1 << (k - 1))
        yield level


def check_maps(maps: np.ndarray, grid_shape: tuple[int, ...]) -> None:
    """Raises ValueError unless ``maps`` has the shape and type of :class:`Pyramid`'s max maps over
    a grid of ``grid_shape``."""
    rows, cols = grid_shape
    shape = (LEVELS, -(-rows // COARSE), -(-cols // COARSE))
    if maps.shape != shape or maps.dtype != np.float32:
        raise ValueError(f"max maps of shape {maps.shape} ({maps.dtype}) for a grid needing {shape}")


class Pyramid:
    """The max maps the march jumps with: ``maps[k, bi, bj]`` is the tallest cell within
    ``2**k`` coarse cells (Chebyshev) of coarse cell ``(bi, bj)``."""

    def __init__(self, height: np.ndarray, maps: np.ndarray | None = None) -> None:
        """The max maps over ``height``; or ``maps``, those maps computed before (a world kept on disk
        brings them, :mod:`simbridge.world.cache`), taken as they are (a view, written in place)."""
        if maps is not None:
            check_maps(maps, height.shape)
            self.maps = maps
            self.h_max = float(maps[-1].max())  # the widest level holds the tallest cell
            return
        base = max_pool(height, COARSE)
        self.maps = np.empty((LEVELS, *base.shape), np.float32)
        for k, level in enumerate(_max_levels(base)):
            self.maps[k] = level
        self.h_max = float(base.max())

    def raise_envelope(self, coarse_top: np.ndarray, from_level: int) -> None:
        """Raise maps ``from_level`` and up, once, over everything that may ever stand on the grid
        (``coarse_top``: per coarse cell, the top of the tallest actor that can come there; -1e9
        where none can). Those maps' windows span tens of metres: raising them for every actor at
        every frame would cost more than the frame, and an envelope along the roads bounds them."""
        base = np.asarray(coarse_top, np.float32)
        for k, level in enumerate(_max_levels(base)):
            if k >= from_level:
                np.maximum(self.maps[k], level, out=self.maps[k])
        self.h_max = max(self.h_max, float(base.max()))


@njit(cache=True, fastmath=True, nogil=True, inline="always")
def _plane_clear(
    height: np.ndarray, maps: np.ndarray, clear_above: float, res: float, coarse_m: float, inv_c: float,
    pn: float, pe: float, pi: int, pj: int, hp: float, tp: float, dn: float, de: float, sink: float,
) -> bool:  # fmt: skip
    """Whether a ray reaching height ``hp`` at grid point ``(pn, pe)`` (metres from the grid's
    corner, in cell ``(pi, pj)``) after ``tp`` of travel along ``(dn, de, -sink)`` passes over
    everything before it.

    Walked back from that point toward the origin. First, fine cell by fine cell for
    ``FINE_BACK_M`` of horizontal travel: each cell must be lower than the ray where the ray is
    lowest in it (the edge nearer the hit). Beside a wall, a parapet or a car that is the only
    proof that works, since every max map's window there holds the obstacle. Then in pieces that
    grow: max map ``k`` bounds every cell within ``R_k = 2**k`` coarse cells (Chebyshev) of its
    coarse cell, so one lookup at the middle of a piece ``2 R_k`` long bounds all of the piece,
    which is clear when that bound is below the ray's lowest point on it, the end nearer the hit.
    Each piece tries twice the last one's length and halves until its bound clears. No piece is
    needed past the origin or above ``clear_above``, a height above which the ray is known clear
    (the grid's top, or a tile bundle's floor). Any doubt is a ``False``: the march decides."""
    hd = math.sqrt(dn * dn + de * de)
    if hd < 1e-9:
        return True  # straight down: the ray is above hp everywhere before the hit
    un = dn / hd
    ue = de / hd
    slope = sink / hd
    travelled = tp * hd  # horizontal distance back to the origin
    brows, bcols = maps.shape[1], maps.shape[2]
    bi = min(int(pn * inv_c), brows - 1)
    bj = min(int(pe * inv_c), bcols - 1)
    fine = maps[0, bi, bj] > hp  # something near the hit stands above it: go cell by cell first
    s = coarse_m  # horizontal distance back from the hit proven clear so far
    while True:
        if fine:
            # beside a wall, a parapet or a car every max map's window holds it: prove the first
            # stretch cell by cell (each cell lower than the ray at its edge nearer the hit)
            rows, cols = height.shape
            i = pi
            j = pj
            step_i = -1 if un > 0.0 else 1
            step_j = -1 if ue > 0.0 else 1
            x_n = ((i * res if un > 0.0 else (i + 1) * res) - pn) / -un if abs(un) > 1e-12 else _BIG
            x_e = ((j * res if ue > 0.0 else (j + 1) * res) - pe) / -ue if abs(ue) > 1e-12 else _BIG
            dx_n = res / abs(un) if abs(un) > 1e-12 else _BIG
            dx_e = res / abs(ue) if abs(ue) > 1e-12 else _BIG
            s = min(travelled, FINE_BACK_M)
            while True:
                if x_n < x_e:
                    x = x_n
                    i += step_i
                    x_n += dx_n
                else:
                    x = x_e
                    j += step_j
                    x_e += dx_e
                if x >= s:
                    break
                if i < 0 or i >= rows or j < 0 or j >= cols:
                    return True  # left the grid walking back: nothing between it and the origin
                low = hp + x * slope
                if low > clear_above:
                    return True
                if height[i, j] >= low:
                    return False
        lvl = 0
        failed = False
        while s < travelled:
            low = hp + s * slope
            if low > clear_above:
                return True
            while True:  # the longest piece (up to twice the last) whose bound is below the ray
                r = coarse_m * (1 << lvl)
                back = s + r
                qi = min(max(int((pn - back * un) * inv_c), 0), brows - 1)
                qj = min(max(int((pe - back * ue) * inv_c), 0), bcols - 1)
                if maps[lvl, qi, qj] < low:
                    break
                if lvl == 0:
                    failed = True
                    break
                lvl -= 1
            if failed:
                break
            s = back + r
            if lvl < LEVELS - 1:
                lvl += 1
        if not failed:
            return True
        if fine or s >= FINE_BACK_M:
            return False
        fine = True  # the pieces failed near the hit: try the fine walk there once


@njit(cache=True, fastmath=True, nogil=True, inline="always")
def _bundle_runs(
    dirs: np.ndarray, c00: int, c01: int, c10: int, c11: int
) -> tuple[bool, float, float, float, float]:
    """Whether the corner rays all go down, and the box of their horizontal run per metre of
    descent (north low, high; east low, high): every ray of the tile runs within it."""
    wn_lo = _BIG
    wn_hi = -_BIG
    we_lo = _BIG
    we_hi = -_BIG
    for c in (c00, c01, c10, c11):
        du = dirs[c, 2]
        if du > -1e-9:
            return False, 0.0, 0.0, 0.0, 0.0
        wn = dirs[c, 0] / -du
        we = dirs[c, 1] / -du
        wn_lo = min(wn_lo, wn)
        wn_hi = max(wn_hi, wn)
        we_lo = min(we_lo, we)
        we_hi = max(we_hi, we)
    return True, wn_lo, wn_hi, we_lo, we_hi


@njit(cache=True, fastmath=True, nogil=True, inline="always")
def _layer_box(
    on: float, oe: float, ou: float, wn_lo: float, wn_hi: float, we_lo: float, we_hi: float,
    z_a: float, z_b: float,
) -> tuple[float, float, float, float]:  # fmt: skip
    """The box (metres from the grid's corner, a micrometre wider) every ray of a bundle stays in
    between levels ``z_a < z_b``: north low, high; east low, high."""
    s_hi = ou - z_a
    s_lo = ou - z_b
    return (
        on + min(s_hi * wn_lo, s_lo * wn_lo) - 1e-6,
        on + max(s_hi * wn_hi, s_lo * wn_hi) + 1e-6,
        oe + min(s_hi * we_lo, s_lo * we_lo) - 1e-6,
        oe + max(s_hi * we_hi, s_lo * we_hi) + 1e-6,
    )


@njit(cache=True, fastmath=True, nogil=True, inline="always")
def _box_bound(maps: np.ndarray, inv_c: float, n_lo: float, n_hi: float, e_lo: float, e_hi: float) -> float:
    """An upper bound of every cell in a box from one max-map lookup (the smallest window holding
    it): ``-_BIG`` when the box is off the grid, ``_BIG`` when no window is large enough."""
    brows, bcols = maps.shape[1], maps.shape[2]
    ci0 = max(math.floor(n_lo * inv_c), 0)
    ci1 = min(math.floor(n_hi * inv_c), brows - 1)
    cj0 = max(math.floor(e_lo * inv_c), 0)
    cj1 = min(math.floor(e_hi * inv_c), bcols - 1)
    if ci0 > ci1 or cj0 > cj1:
        return -_BIG
    ci = (ci0 + ci1) >> 1
    cj = (cj0 + cj1) >> 1
    reach = max(ci1 - ci, ci - ci0, cj1 - cj, cj - cj0)
    lvl = 0
    while (1 << lvl) < reach:
        lvl += 1
    return maps[lvl, ci, cj] if lvl < LEVELS else _BIG


@njit(cache=True, fastmath=True, nogil=True, inline="always")
def _bundle_floor(
    maps: np.ndarray, h_max: float, res: float, on: float, oe: float, ou: float, dirs: np.ndarray,
    c00: int, c01: int, c10: int, c11: int,
) -> float:  # fmt: skip
    """How low a tile's bundle of rays is proven clear, from the top down (layers that double
    while the max maps clear them): every ray of the tile may start its march at that level. The
    top of the grid (or the origin) when nothing below it is proven."""
    top = min(h_max, ou)
    down, wn_lo, wn_hi, we_lo, we_hi = _bundle_runs(dirs, c00, c01, c10, c11)
    if not down:
        return top
    coarse_m = COARSE * res
    inv_c = 1.0 / coarse_m
    run = max(abs(wn_lo), abs(wn_hi), abs(we_lo), abs(we_hi), 1e-3)
    dz0 = max(coarse_m, ou * max(wn_hi - wn_lo, we_hi - we_lo)) / run
    dz = dz0
    z_b = top
    while z_b > FLOOR_M:
        z_a = z_b - dz
        n_lo, n_hi, e_lo, e_hi = _layer_box(on, oe, ou, wn_lo, wn_hi, we_lo, we_hi, z_a, z_b)
        if _box_bound(maps, inv_c, n_lo, n_hi, e_lo, e_hi) < z_a:
            z_b = z_a
            dz *= 2.0
        elif dz <= dz0 * 0.25:
            break
        else:
            dz *= 0.5
    return max(z_b, FLOOR_M)


@njit(cache=True, fastmath=True, nogil=True, inline="always")
def _bundle_clear(
    height: np.ndarray, maps: np.ndarray, h_max: float, res: float, on: float, oe: float, ou: float,
    z0: float, touch: bool, dirs: np.ndarray, c00: int, c01: int, c10: int, c11: int,
    clip_axis: int, clip_lo: int, clip_hi: int,
) -> bool:  # fmt: skip
    """Whether every ray of a tile of image rays (``c00`` ... ``c11``: its corner rays) passes over
    everything it meets above height ``z0``, on cells whose index along ``clip_axis`` (0 rows,
    1 columns, -1 none) lies in ``[clip_lo, clip_hi]``; with ``touch``, cells exactly ``z0`` high
    are allowed (a plane at ``z0`` the rays end on).

    For a plane at ``z0`` (``touch``, no clip): a ray whose cell at the plane is that
    high hits its top there, and any other needs marching from the plane down only. For a wall
    face (``z0``: the lowest corner ray's crossing; the clip: the cells in front of the face): a
    ray that crosses the face where the cell behind stands above it hits the wall there.

    ``on, oe`` are the origin in metres from the grid's corner. The rays of a tile cross any level
    ``z`` in the quad ``O + (ou - z) W``, where ``W`` is the quad of the corner rays' horizontal
    run per metre of descent, so between two levels they stay in one box: the max map whose window
    holds that box bounds it in one lookup, and where that window reaches too far (beside a wall),
    a small box is read cell by cell, within the clip. The bundle is walked up from ``z0`` in
    layers that double while their bound clears (halved when it does not). No layer is needed above
    ``h_max``. The footprint must lie on the grid. Any doubt is a ``False``."""
    if ou <= z0:
        return False
    top = min(h_max, ou)
    if z0 >= top:
        return True
    down, wn_lo, wn_hi, we_lo, we_hi = _bundle_runs(dirs, c00, c01, c10, c11)
    if not down:
        return False
    s_hi = ou - z0
    if on + s_hi * wn_lo < 0.0 or on + s_hi * wn_hi >= height.shape[0] * res:
        return False
    if oe + s_hi * we_lo < 0.0 or oe + s_hi * we_hi >= height.shape[1] * res:
        return False
    rows, cols = height.shape
    coarse_m = COARSE * res
    inv_c = 1.0 / coarse_m
    inv_res = 1.0 / res
    run = max(abs(wn_lo), abs(wn_hi), abs(we_lo), abs(we_hi), 1e-3)
    dz0 = max(coarse_m, s_hi * max(wn_hi - wn_lo, we_hi - we_lo)) / run  # the box moves a footprint
    dz = dz0
    z_a = z0
    while z_a < top:
        while True:  # the thickest layer (up to twice the last) whose bound is below its bottom
            z_b = min(z_a + dz, top)
            n_lo, n_hi, e_lo, e_hi = _layer_box(on, oe, ou, wn_lo, wn_hi, we_lo, we_hi, z_a, z_b)
            bound = _box_bound(maps, inv_c, n_lo, n_hi, e_lo, e_hi)
            if bound < z_a or (touch and z_a == z0 and bound <= z0):
                break
            # the map's window reaches past the box: beside a wall or an edge, look at the cells
            fi0 = max(int(n_lo * inv_res), 0)
            fi1 = min(int(n_hi * inv_res), rows - 1)
            fj0 = max(int(e_lo * inv_res), 0)
            fj1 = min(int(e_hi * inv_res), cols - 1)
            if clip_axis == 0:
                fi0 = max(fi0, clip_lo)
                fi1 = min(fi1, clip_hi)
            elif clip_axis == 1:
                fj0 = max(fj0, clip_lo)
                fj1 = min(fj1, clip_hi)
            if (fi1 - fi0 + 1) * (fj1 - fj0 + 1) <= FINE_SCAN_CELLS:
                bound = -_BIG
                for fi in range(fi0, fi1 + 1):
                    for fj in range(fj0, fj1 + 1):
                        bound = max(bound, height[fi, fj])
                if bound < z_a or (touch and z_a == z0 and bound <= z0):
                    break
            if dz <= dz0 * 0.25:
                return False
            dz *= 0.5
        z_a = z_b
        dz *= 2.0
    return True


@njit(cache=True, fastmath=True, nogil=True)
def cast_rays(
    height: np.ndarray, maps: np.ndarray, h_max: float, res: float, n0: float, e0: float,
    origins: np.ndarray, dirs: np.ndarray, t_max: float, row: int = 0, tile: int = 0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
    """Cast rays; ``dirs`` is (N, 3) unit (north, east, up); ``origins`` is (N, 3), or (1, 3) for all.

    Returns per ray: distance (``t_max`` on a miss), cell row, cell column, hit kind and, for wall
    hits, the ray's step (+1/-1) across the boundary it crossed (the wall faces ``-step``).

    ``row`` > 0 (one origin only): the rays are an image, row-major with ``row`` rays per row, and
    each ray first tries the plane of its left or upper neighbour's top hit (``_plane_clear``):
    most pixels see the same roof or street as their neighbours, and proving that costs a few
    max-map lookups instead of a march.

    ``tile`` > 0 as well (a full image of ``row`` columns): the image is cut in ``tile`` x ``tile``
    tiles. Each tile's centre ray is marched; where it hit a top, the tile's whole bundle is proven
    clear above that plane at once (``_bundle_clear``), and then each of its rays costs one cell
    lookup if it lands on the plane, or a march from the plane down if the plane has a hole there.
    Tiles the proof fails for, and what is left, are marched ray by ray as above.

    The answer is the march's in every mode, ray for ray.
    """
    n = dirs.shape[0]
    ts = np.full(n, t_max, dtype=np.float32)
    ii = np.full(n, -1, dtype=np.int32)
    jj = np.full(n, -1, dtype=np.int32)
    kinds = np.full(n, HIT_MISS, dtype=np.int8)
    steps = np.zeros(n, dtype=np.int8)
    t_start = np.zeros(n, dtype=np.float64)
    out = (ts, ii, jj, kinds, steps, t_start)
    one_origin = origins.shape[0] == 1
    coherent = row > 0 and one_origin
    if not (coherent and tile > 0):
        _march(height, maps, h_max, res, n0, e0, origins, dirs, t_max, row if coherent else 0,
               np.arange(n), out)  # fmt: skip
        return ts, ii, jj, kinds, steps
    # ---- tiles: centres first, then the planes they prove, then the rest
    width = row
    height_px = n // width
    across = (width + tile - 1) // tile
    down = (height_px + tile - 1) // tile
    centres = np.empty(across * down, np.int64)
    for ti in range(down):
        for tj in range(across):
            r0, c0 = ti * tile, tj * tile
            centres[ti * across + tj] = ((r0 + min(r0 + tile, height_px) - 1) >> 1) * width + (
                (c0 + min(c0 + tile, width) - 1) >> 1
            )
    _march(height, maps, h_max, res, n0, e0, origins, dirs, t_max, 0, centres, out)
    rows, cols = height.shape
    on = origins[0, 0] - n0  # metres from the grid's corner
    oe = origins[0, 1] - e0
    ou = origins[0, 2]
    # per tile what was proven: 0 nothing, HIT_TOP + 1 the plane at ``level``, a wall kind + 1 the
    # face at ``level`` (its boundary) before cell row or column ``cell``, crossed with step ``st``
    proof = np.zeros(across * down, np.int8)
    level = np.zeros(across * down, np.float64)
    cell = np.zeros(across * down, np.int64)
    st = np.zeros(across * down, np.int8)
    for ti in range(down):
        r0 = ti * tile
        r1 = min(r0 + tile, height_px)
        for tj in range(across):
            c0 = tj * tile
            c1 = min(c0 + tile, width)
            t = ti * across + tj
            centre = centres[t]
            k00, k01 = r0 * width + c0, r0 * width + c1 - 1  # the corner rays
            k10, k11 = (r1 - 1) * width + c0, (r1 - 1) * width + c1 - 1
            kind = kinds[centre]
            if kind == HIT_TOP:
                hp = height[ii[centre], jj[centre]]
                if _bundle_clear(
                    height, maps, h_max, res, on, oe, ou, hp, True, dirs, k00, k01, k10, k11, -1, 0, 0
                ):
                    proof[t] = HIT_TOP + 1
                    level[t] = hp
            elif kind != HIT_MISS:  # a wall
                wall_n = kind == HIT_WALL_N
                step = steps[centre]
                c_w = ii[centre] if wall_n else jj[centre]
                bnd = (n0 if wall_n else e0) + (c_w + 1 if step < 0 else c_w) * res
                o_ax = origins[0, 0] if wall_n else origins[0, 1]
                z_lo = _BIG
                for c in (k00, k01, k10, k11):
                    d_ax = dirs[c, 0] if wall_n else dirs[c, 1]
                    if not ((d_ax > 1e-12 and step > 0) or (d_ax < -1e-12 and step < 0)):
                        z_lo = -_BIG  # a corner ray runs along or away from the face
                        break
                    z_lo = min(z_lo, ou + (bnd - o_ax) * (1.0 / d_ax) * dirs[c, 2])
                axis = 0 if wall_n else 1
                front_lo = 0 if step > 0 else c_w + 1  # the cells in front of the face
                front_hi = c_w - 1 if step > 0 else (rows if wall_n else cols) - 1
                if z_lo > -_BIG and _bundle_clear(
                    height, maps, h_max, res, on, oe, ou, z_lo, False, dirs, k00, k01, k10, k11,
                    axis, front_lo, front_hi,
                ):  # fmt: skip
                    proof[t] = kind + 1
                    level[t] = bnd
                    cell[t] = c_w
                    st[t] = step
            if proof[t] == 0:  # not proven: its rays march, from as low as the bundle is clear
                level[t] = _bundle_floor(maps, h_max, res, on, oe, ou, dirs, k00, k01, k10, k11)
    # ---- every ray by its tile's proof, in raster order (the arrays stream through the cache)
    tile_of_col = np.empty(width, np.int64)
    for c in range(width):
        tile_of_col[c] = c // tile
    left = np.zeros(n, np.bool_)
    inv_res = 1.0 / res
    for r in range(height_px):
        t_row = (r // tile) * across
        for c in range(width):
            k = r * width + c
            t = t_row + tile_of_col[c]
            if k == centres[t]:
                continue
            got = proof[t] - 1
            if got == HIT_TOP:
                hp = level[t]
                tp = (ou - hp) / -dirs[k, 2]
                pi = _cell(origins[0, 0] + tp * dirs[k, 0] - n0, inv_res, rows)
                pj = _cell(origins[0, 1] + tp * dirs[k, 1] - e0, inv_res, cols)
                if tp <= t_max and pi >= 0 and pj >= 0 and height[pi, pj] == hp:
                    ts[k] = tp
                    ii[k] = pi
                    jj[k] = pj
                    kinds[k] = HIT_TOP
                    continue
                if pi >= 0 and pj >= 0:
                    t_start[k] = tp  # a hole in the plane: march from it down
            elif got > HIT_TOP:  # a wall face
                wall_n = got == HIT_WALL_N
                tw = (level[t] - (origins[0, 0] if wall_n else origins[0, 1])) * (
                    1.0 / (dirs[k, 0] if wall_n else dirs[k, 1])
                )
                zw = ou + tw * dirs[k, 2]
                if wall_n:
                    pi = cell[t]
                    pj = _cell(origins[0, 1] + tw * dirs[k, 1] - e0, inv_res, cols)
                else:
                    pi = _cell(origins[0, 0] + tw * dirs[k, 0] - n0, inv_res, rows)
                    pj = cell[t]
                if tw <= t_max and pi >= 0 and pj >= 0 and height[pi, pj] >= zw:
                    ts[k] = tw
                    ii[k] = pi
                    jj[k] = pj
                    kinds[k] = got
                    steps[k] = st[t]
                    continue
            elif dirs[k, 2] < 0.0 and level[t] < ou:
                t_start[k] = (ou - level[t]) / -dirs[k, 2]  # the bundle is clear down to its floor
            left[k] = True  # not proven, a hole, over the wall's top or a tie: march
    _march(height, maps, h_max, res, n0, e0, origins, dirs, t_max, width, np.nonzero(left)[0], out)
    return ts, ii, jj, kinds, steps


@njit(cache=True, fastmath=True, nogil=True, inline="always")
def _cell(p: float, inv_res: float, cells: int) -> int:
    """The cell holding ``p`` (metres from the grid's corner) along one axis, or -1 when ``p`` is
    within a hundred-thousandth of a cell of a boundary: there the march's own sums decide which side it is on
    (rays through the corners of a regular grid are common, from a camera at a round position)."""
    x = p * inv_res
    c = int(x)
    f = x - c
    if f < 1e-5 or f > 1.0 - 1e-5 or c < 0 or c >= cells:
        return -1
    return c


@njit(cache=True, fastmath=True, nogil=True)
def _march(
    height: np.ndarray, maps: np.ndarray, h_max: float, res: float, n0: float, e0: float,
    origins: np.ndarray, dirs: np.ndarray, t_max: float, row: int, order: np.ndarray,
    out: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray],
) -> None:  # fmt: skip
    """March rays ``order`` (ascending when ``row`` > 0) into ``out`` = (distance, cell row, cell
    column, kind, step, start): each from its ``start`` distance, which the caller proved clear.
    ``row`` > 0: image rays, and each first tries its left or upper neighbour's plane.

    The march is written inside the loop on purpose: a numba call per ray that passes the arrays
    costs eight atomic reference-count updates, more than the whole march over open ground."""
    ts, ii, jj, kinds, steps, t_starts = out
    rows, cols = height.shape
    brows, bcols = maps.shape[1], maps.shape[2]
    one_origin = origins.shape[0] == 1
    size_n = rows * res
    size_e = cols * res
    coarse_m = COARSE * res
    inv_res = 1.0 / res
    inv_coarse = 1.0 / coarse_m
    coherent = row > 0 and one_origin
    for k in order:
        r = 0 if one_origin else k
        on = origins[r, 0]
        oe = origins[r, 1]
        ou = origins[r, 2]
        dn = dirs[k, 0]
        de = dirs[k, 1]
        du = dirs[k, 2]
        t_start = t_starts[k]
        if coherent and du < 0.0:
            clear_above = ou + t_start * du if t_start > 0.0 else h_max  # proven clear above this
            # ---- the plane of the left neighbour's hit, else the upper neighbour's: where this ray
            # meets it (a wall face: the cell behind standing above the ray; a top: as high), the
            # hit is the march's if the way there is clear
            g = k - 1 if k % row != 0 and kinds[k - 1] != HIT_MISS else k - row
            kind = kinds[g] if g >= 0 else HIT_MISS
            th = zh = pn = pe = 0.0  # where the ray meets the plane: distance, height, point
            pi = pj = -1
            if kind > HIT_TOP:
                wall_n = kind == HIT_WALL_N
                d_ax = dn if wall_n else de
                if (d_ax > 1e-12 and steps[g] > 0) or (d_ax < -1e-12 and steps[g] < 0):
                    cell = ii[g] if wall_n else jj[g]
                    bnd = (n0 if wall_n else e0) + (cell + 1 if steps[g] < 0 else cell) * res
                    th = (bnd - (on if wall_n else oe)) * (1.0 / d_ax)
                    zh = ou + th * du
                    pn = on + th * dn - n0
                    pe = oe + th * de - e0
                    if 0.0 < th <= t_max and 0.0 <= pn < size_n and 0.0 <= pe < size_e:
                        pi = ii[g] if wall_n else _cell(pn, inv_res, rows)
                        pj = _cell(pe, inv_res, cols) if wall_n else jj[g]
                        if pi >= 0 and pj >= 0 and height[pi, pj] < zh:
                            pi = -1
            elif kind == HIT_TOP:
                zh = height[ii[g], jj[g]]
                th = (ou - zh) / -du
                pn = on + th * dn - n0
                pe = oe + th * de - e0
                if 0.0 < th <= t_max and 0.0 <= pn < size_n and 0.0 <= pe < size_e:
                    pi = _cell(pn, inv_res, rows)
                    pj = _cell(pe, inv_res, cols)
                    if pi >= 0 and pj >= 0 and height[pi, pj] != zh:
                        pi = -1
            if pi >= 0 and pj >= 0 and _plane_clear(
                height, maps, clear_above, res, coarse_m, inv_coarse, pn, pe, pi, pj, zh, th, dn, de, -du,
            ):  # fmt: skip
                ts[k] = th
                ii[k] = pi
                jj[k] = pj
                kinds[k] = kind
                steps[k] = steps[g] if kind > HIT_TOP else 0
                continue
        # ---- clip to the grid's box and to the slab below h_max
        t0 = t_start
        t1 = t_max
        if ou > h_max:
            if du >= 0.0:
                continue
            t0 = max(t0, (ou - h_max) / -du)
        inside = True
        for axis in range(2):
            o = on - n0 if axis == 0 else oe - e0
            d = dn if axis == 0 else de
            size = size_n if axis == 0 else size_e
            if abs(d) < 1e-12:
                if o < 0.0 or o >= size:
                    inside = False
            else:
                ta = -o / d
                tb = (size - o) / d
                if ta > tb:
                    ta, tb = tb, ta
                t0 = max(t0, ta)
                t1 = min(t1, tb)
        if not inside or t0 >= t1:
            continue
        hd = math.sqrt(dn * dn + de * de)  # horizontal speed per unit t
        dt_per_coarse = coarse_m / hd if hd > 1e-6 else 0.0  # t to cross one coarse cell (no divides below)
        step_n = 1 if dn > 0.0 else -1
        step_e = 1 if de > 0.0 else -1
        has_n = abs(dn) > 1e-12
        has_e = abs(de) > 1e-12
        inv_dn = 1.0 / dn if has_n else 0.0
        inv_de = 1.0 / de if has_e else 0.0
        t = t0
        last_axis = -1
        jumping = hd > 1e-6
        top_lvl = LEVELS - 1  # largest jump worth trying: one above the last that worked
        if jumping and du < 0.0:
            # a jump of 2**lvl coarse cells drops the ray 2**lvl * coarse_m * |du| / hd: no use
            # trying one that would take it below the ground (height 0) from where it starts
            fit = (ou + t0 * du) * hd / (coarse_m * -du)
            if fit < 1.0:
                top_lvl = 0
            elif fit < 1 << (LEVELS - 1):
                top_lvl = int(math.log2(fit))
        fine_left = 0.0  # t at which to stop fine stepping and try jumping again
        i = 0
        j = 0
        placed = False
        while t < t1:
            z = ou + t * du
            if jumping:
                pn = on + t * dn - n0
                pe = oe + t * de - e0
                bi = min(max(int(pn * inv_coarse), 0), brows - 1)
                bj = min(max(int(pe * inv_coarse), 0), bcols - 1)
                jumped = False
                for lvl in range(top_lvl, -1, -1):
                    dt = (1 << lvl) * dt_per_coarse  # t for a jump of 2**lvl coarse cells
                    if maps[lvl, bi, bj] < min(z, z + dt * du):
                        t += dt
                        jumped = True
                        placed = False
                        last_axis = -1
                        top_lvl = min(lvl + 1, LEVELS - 1)
                        break
                if jumped:
                    continue
                jumping = False
                top_lvl = 1
                fine_left = t + dt_per_coarse
            if not placed:
                i = min(max(int((on + t * dn - n0) * inv_res), 0), rows - 1)
                j = min(max(int((oe + t * de - e0) * inv_res), 0), cols - 1)
                placed = True
            # ---- fine step through cell (i, j)
            h = height[i, j]
            if z <= h:
                ts[k] = t
                ii[k] = i
                jj[k] = j
                if last_axis == 0:
                    kinds[k] = HIT_WALL_N
                    steps[k] = step_n
                elif last_axis == 1:
                    kinds[k] = HIT_WALL_E
                    steps[k] = step_e
                else:
                    kinds[k] = HIT_TOP  # landed on (or started in) this cell from above
                break
            tn = (n0 + ((i + 1) * res if step_n > 0 else i * res) - on) * inv_dn if has_n else _BIG
            te = (e0 + ((j + 1) * res if step_e > 0 else j * res) - oe) * inv_de if has_e else _BIG
            t_exit = min(tn, te, t1)
            if du < 0.0 and ou + t_exit * du <= h:
                ts[k] = (ou - h) / -du
                ii[k] = i
                jj[k] = j
                kinds[k] = HIT_TOP
                break
            if t_exit >= t1:
                break
            t = t_exit
            if tn < te:
                i += step_n
                last_axis = 0
            else:
                j += step_e
                last_axis = 1
            if i < 0 or i >= rows or j < 0 or j >= cols:
                break
            if hd > 1e-6 and t >= fine_left:
                jumping = True
                # stay on the exact boundary we just crossed: (i, j) stays valid for a top test
