"""Ray casting against the 2.5-D world grid, compiled with numba.

The grid stores, per cell (``res`` metres square), the height of the top surface in metres above
the scenario origin (up positive). Cell ``(i, j)`` spans north ``[n0 + i res, n0 + (i+1) res)``
and east ``[e0 + j res, e0 + (j+1) res)``. A ray is ``p(t) = o + t d`` in (north, east, up)
metres with ``|d| = 1``.

The march descends a max-height pyramid (blocks of 4, 16 and 64 cells): a block whose tallest cell
stays below the ray for the ray's whole crossing is skipped at once; otherwise the ray steps one
fine cell at a time (2-D DDA). A ray hits a cell's *top* where it descends through the cell's height
inside the cell, or a *wall* where it enters a cell below that cell's height.

Hit kinds: 0 top, 1 wall crossed along north, 2 wall crossed along east, -1 miss.
"""

from __future__ import annotations

import numpy as np
from numba import njit

HIT_TOP, HIT_WALL_N, HIT_WALL_E, HIT_MISS = 0, 1, 2, -1
PYRAMID_BLOCKS = (4, 16, 64)
_SHIFTS = (2, 4, 6)  # log2 of the block sizes: block indices are shifts, never divisions
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


class Pyramid:
    """The max-height levels the march uses, flattened into one array.

    ``flat[offset[l] + bi * ncols[l] + bj]`` is the tallest cell of block ``(bi, bj)`` at level
    ``l`` (blocks of ``PYRAMID_BLOCKS[l]`` cells); one array and two small tables keep the march's
    inner loop free of per-level branches.
    """

    def __init__(self, height: np.ndarray) -> None:
        l1 = max_pool(height, PYRAMID_BLOCKS[0])
        l2 = max_pool(l1, PYRAMID_BLOCKS[1] // PYRAMID_BLOCKS[0])
        l3 = max_pool(l2, PYRAMID_BLOCKS[2] // PYRAMID_BLOCKS[1])
        self.flat = np.concatenate([lv.ravel() for lv in (l1, l2, l3)]).astype(np.float32)
        sizes = [lv.size for lv in (l1, l2, l3)]
        self.offset = np.array([0, sizes[0], sizes[0] + sizes[1]], dtype=np.int64)
        self.ncols = np.array([lv.shape[1] for lv in (l1, l2, l3)], dtype=np.int64)
        # views into ``flat``: writing a level writes the array the march reads
        self.levels = tuple(
            self.flat[o : o + lv.size].reshape(lv.shape)
            for o, lv in zip(self.offset, (l1, l2, l3), strict=True)
        )
        self.h_max = float(l3.max())

    def raise_window(self, i0: int, i1: int, j0: int, j1: int, top_m: float) -> None:
        """Make every block overlapping cells ``[i0, i1) x [j0, j1)`` at least ``top_m`` high.

        The pyramid only has to bound the grid from above, so moving actors raise it where they
        are stamped and never lower it: the march stays exact, only a little less quick.
        """
        for level, shift in zip(self.levels, _SHIFTS, strict=True):
            blk = level[i0 >> shift : ((i1 - 1) >> shift) + 1, j0 >> shift : ((j1 - 1) >> shift) + 1]
            np.maximum(blk, top_m, out=blk)
        self.h_max = max(self.h_max, top_m)


@njit(cache=True, fastmath=True, nogil=True)
def cast_rays(
    height: np.ndarray, pyr: np.ndarray, pyr_offset: np.ndarray, pyr_ncols: np.ndarray, h_max: float,
    res: float, n0: float, e0: float, origins: np.ndarray, dirs: np.ndarray, t_max: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
    """Cast rays; ``dirs`` is (N, 3) unit (north, east, up); ``origins`` is (N, 3), or (1, 3) for all.

    Returns per ray: distance (``t_max`` on a miss), cell row, cell column, hit kind and, for wall
    hits, the ray's step (+1/-1) across the boundary it crossed (the wall faces ``-step``).

    The march is written inside the loop on purpose: a numba call per ray that passes the arrays
    costs eight atomic reference-count updates, more than the whole march over open ground.
    """
    n = dirs.shape[0]
    rows, cols = height.shape
    one_origin = origins.shape[0] == 1
    ts = np.full(n, t_max, dtype=np.float32)
    ii = np.full(n, -1, dtype=np.int32)
    jj = np.full(n, -1, dtype=np.int32)
    kinds = np.full(n, HIT_MISS, dtype=np.int8)
    steps = np.zeros(n, dtype=np.int8)
    size_n = rows * res
    size_e = cols * res
    for k in range(n):
        r = 0 if one_origin else k
        on = origins[r, 0]
        oe = origins[r, 1]
        ou = origins[r, 2]
        dn = dirs[k, 0]
        de = dirs[k, 1]
        du = dirs[k, 2]
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
        step_n = 1 if dn > 0.0 else -1
        step_e = 1 if de > 0.0 else -1
        has_n = abs(dn) > 1e-12
        has_e = abs(de) > 1e-12
        inv_dn = 1.0 / dn if has_n else 0.0
        inv_de = 1.0 / de if has_e else 0.0
        t = t0
        last_axis = -1
        i = min(max(int((on + t * dn - n0) / res), 0), rows - 1)
        j = min(max(int((oe + t * de - e0) / res), 0), cols - 1)
        lvl = 2  # pyramid level to try next; -1: fine stepping inside one level-0 block
        b0i = i >> _SHIFTS[0]
        b0j = j >> _SHIFTS[0]
        while t < t1:
            z = ou + t * du
            if lvl >= 0:
                sh = 2 + 2 * lvl  # _SHIFTS[lvl]
                bi = i >> sh
                bj = j >> sh
                hb = pyr[pyr_offset[lvl] + bi * pyr_ncols[lvl] + bj]
                if z > hb:
                    blk = 1 << sh
                    bsize = blk * res
                    tbn = (
                        (n0 + ((bi + 1) * bsize if step_n > 0 else bi * bsize) - on) * inv_dn
                        if has_n
                        else _BIG
                    )
                    tbe = (
                        (e0 + ((bj + 1) * bsize if step_e > 0 else bj * bsize) - oe) * inv_de
                        if has_e
                        else _BIG
                    )
                    tb = min(tbn, tbe)
                    if tb >= t1:
                        if ou + t1 * du > hb:
                            break  # stays above everything until it leaves: miss
                    elif ou + tb * du > hb:
                        # the whole crossing of this block stays above its tallest cell: skip it
                        t = tb
                        if tbn < tbe:
                            last_axis = 0
                            i = (bi + 1) * blk if step_n > 0 else bi * blk - 1
                            j = min(max(int((oe + t * de - e0) / res), bj * blk), bj * blk + blk - 1)
                        else:
                            last_axis = 1
                            j = (bj + 1) * blk if step_e > 0 else bj * blk - 1
                            i = min(max(int((on + t * dn - n0) / res), bi * blk), bi * blk + blk - 1)
                        if i < 0 or i >= rows or j < 0 or j >= cols:
                            break
                        lvl = 2 if lvl >= 1 else 1
                        continue
                lvl -= 1
                if lvl < 0:
                    b0i = i >> _SHIFTS[0]
                    b0j = j >> _SHIFTS[0]
                continue
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
                    kinds[k] = HIT_TOP  # started inside a structure
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
            if (i >> _SHIFTS[0]) != b0i or (j >> _SHIFTS[0]) != b0j:
                lvl = 0  # entered another 4 x 4 block: try skipping again
    return ts, ii, jj, kinds, steps
