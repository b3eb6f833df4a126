"""Ray casting against the 2.5-D world grid, compiled with numba.

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

Hit kinds: 0 top, 1 wall crossed along north, 2 wall crossed along east, -1 miss.
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


@njit(cache=True)
def max_pool(height: np.ndarray, block: int) -> np.ndarray:
    """Maximum over each ``block`` x ``block`` square (the last row/column may be partial)."""
    rows, cols = height.shape
    out = np.full(((rows + block - 1) // block, (cols + block - 1) // block), -1e9, dtype=np.float32)
    for i in range(rows):
        bi = i // block
        for j in range(cols):
            v = height[i, j]
            bj = j // block
            if v > out[bi, bj]:
                out[bi, bj] = v
    return out


def _dilate(a: np.ndarray, s: int) -> np.ndarray:
    """Max over offsets in {-s, 0, +s} along both axes (edges padded with the edge value)."""
    p = np.pad(a, ((s, s), (0, 0)), mode="edge")
    a = np.maximum(np.maximum(p[: -2 * s], p[s:-s]), p[2 * s :])
    p = np.pad(a, ((0, 0), (s, s)), mode="edge")
    return np.asarray(np.maximum(np.maximum(p[:, : -2 * s], p[:, s:-s]), p[:, 2 * s :]))


def _max_levels(base: np.ndarray) -> Iterator[np.ndarray]:
    """Level ``k`` of the max maps over coarse cells ``base``: the maximum within ``2**k`` cells
    (Chebyshev), each level dilating the one before by half its radius."""
    level = _dilate(base, 1)
    yield level
    for k in range(1, LEVELS):
        level = _dilate(level, 1 << (k - 1))
        yield level


class Pyramid:
    """The max maps the march jumps with: ``maps[k, bi, bj]`` is the tallest cell within
    ``2**k`` coarse cells (Chebyshev) of coarse cell ``(bi, bj)``."""

    def __init__(self, height: np.ndarray) -> None:
        base = max_pool(height, COARSE)
        self.maps = np.ascontiguousarray(np.stack(list(_max_levels(base))).astype(np.float32))
        self.h_max = float(base.max())

    def raise_window(self, i0: int, i1: int, j0: int, j1: int, top_m: float, levels: int = LEVELS) -> None:
        """Make the first ``levels`` maps cover something ``top_m`` high on fine cells
        ``[i0, i1) x [j0, j1)``.

        The maps only have to bound the grid from above, so moving actors raise them where they
        are stamped and never lower them: the march stays exact, only a little less quick.
        """
        rows, cols = self.maps.shape[1:]
        b_i0, b_i1 = i0 >> COARSE_SHIFT, ((i1 - 1) >> COARSE_SHIFT) + 1
        b_j0, b_j1 = j0 >> COARSE_SHIFT, ((j1 - 1) >> COARSE_SHIFT) + 1
        for k in range(levels):
            r = 1 << k
            blk = self.maps[k, max(b_i0 - r, 0) : min(b_i1 + r, rows), max(b_j0 - r, 0) : min(b_j1 + r, cols)]
            np.maximum(blk, top_m, out=blk)
        self.h_max = max(self.h_max, top_m)

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
    maps: np.ndarray, h_max: float, coarse_m: float, inv_c: float, pn: float, pe: float, hp: float,
    tp: float, dn: float, de: float, sink: float,
) -> bool:  # fmt: skip
    """Whether a ray reaching height ``hp`` at grid point ``(pn, pe)`` (metres from the grid's
    corner) after ``tp`` of travel along ``(dn, de, -sink)`` passes over everything before it.

    Walked back from that point toward the origin in pieces that double: max map ``k`` bounds every
    cell within ``R_k = 2**k`` coarse cells (Chebyshev) of its coarse cell, so one lookup at the
    middle of a piece ``2 R_k`` long bounds all of the piece; the piece is clear when that bound
    is below the ray's lowest point on it, the end nearer the hit. The first piece, within ``R_0``
    of the hit, must hold nothing above ``hp``. No piece is needed past the origin or above
    ``h_max``. Any doubt is a ``False``: the march decides."""
    brows, bcols = maps.shape[1], maps.shape[2]
    bi = min(int(pn * inv_c), brows - 1)
    bj = min(int(pe * inv_c), bcols - 1)
    if maps[0, bi, bj] > hp:
        return False
    hd = math.sqrt(dn * dn + de * de)
    if hd < 1e-9:
        return True  # straight down: the ray is above hp everywhere before the hit
    un = dn / hd
    ue = de / hd
    slope = sink / hd
    travelled = tp * hd  # horizontal distance back to the origin
    s = coarse_m  # horizontal distance back from the hit proven clear so far
    lvl = 0
    while s < travelled:
        low = hp + s * slope
        if low > h_max:
            return True
        r = coarse_m * (1 << lvl)
        back = s + r
        qi = min(max(int((pn - back * un) * inv_c), 0), brows - 1)
        qj = min(max(int((pe - back * ue) * inv_c), 0), bcols - 1)
        if maps[lvl, qi, qj] >= low:
            return False
        s = back + r
        if lvl < LEVELS - 1:
            lvl += 1
    return True


@njit(cache=True, fastmath=True, nogil=True)
def cast_rays(
    height: np.ndarray, maps: np.ndarray, h_max: float, res: float, n0: float, e0: float,
    origins: np.ndarray, dirs: np.ndarray, t_max: float, row: int = 0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
    """Cast rays; ``dirs`` is (N, 3) unit (north, east, up); ``origins`` is (N, 3), or (1, 3) for all.

    Returns per ray: distance (``t_max`` on a miss), cell row, cell column, hit kind and, for wall
    hits, the ray's step (+1/-1) across the boundary it crossed (the wall faces ``-step``).

    ``row`` > 0 (one origin only): the rays are an image, row-major with ``row`` rays per row, and
    each ray first tries the plane of its left or upper neighbour's top hit (``_plane_hit``): most
    pixels see the same roof or street as their neighbours, and proving that costs a few max-map
    lookups instead of a march. The answer is the march's either way.

    The march is written inside the loop on purpose: a numba call per ray that passes the arrays
    costs eight atomic reference-count updates, more than the whole march over open ground.
    """
    n = dirs.shape[0]
    rows, cols = height.shape
    brows, bcols = maps.shape[1], maps.shape[2]
    one_origin = origins.shape[0] == 1
    ts = np.full(n, t_max, dtype=np.float32)
    ii = np.full(n, -1, dtype=np.int32)
    jj = np.full(n, -1, dtype=np.int32)
    kinds = np.full(n, HIT_MISS, dtype=np.int8)
    steps = np.zeros(n, dtype=np.int8)
    size_n = rows * res
    size_e = cols * res
    coarse_m = COARSE * res
    inv_res = 1.0 / res
    inv_coarse = 1.0 / coarse_m
    coherent = row > 0 and one_origin
    for k in range(n):
        r = 0 if one_origin else k
        on = origins[r, 0]
        oe = origins[r, 1]
        ou = origins[r, 2]
        dn = dirs[k, 0]
        de = dirs[k, 1]
        du = dirs[k, 2]
        if coherent and du < 0.0:
            # ---- the plane of the left neighbour's top hit, else the upper neighbour's
            g = k - 1 if k % row != 0 and kinds[k - 1] == HIT_TOP else k - row
            if g >= 0 and kinds[g] == HIT_TOP:
                hp = height[ii[g], jj[g]]
                tp = (ou - hp) / -du
                pn = on + tp * dn - n0
                pe = oe + tp * de - e0
                if 0.0 < tp <= t_max and 0.0 <= pn < size_n and 0.0 <= pe < size_e:
                    pi = min(int(pn * inv_res), rows - 1)
                    pj = min(int(pe * inv_res), cols - 1)
                    if height[pi, pj] == hp and _plane_clear(
                        maps, h_max, coarse_m, inv_coarse, pn, pe, hp, tp, dn, de, -du
                    ):
                        ts[k] = tp
                        ii[k] = pi
                        jj[k] = pj
                        kinds[k] = HIT_TOP
                        continue
        # ---- clip to the grid's box and to the slab below h_max
        t0 = 0.0
        t1 = t_max
        if ou > h_max:
            if du >= 0.0:
                continue
            t0 = (ou - h_max) / -du
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
    return ts, ii, jj, kinds, steps
