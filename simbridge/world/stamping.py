"""Moving boxes (cars, pedestrians) stamped into a :class:`WorldGrid` in numba kernels.

A frame stamps a few hundred actors, each a handful of cells: done one numpy call at a time that is
all Python overhead. These kernels paint every box, save what they overwrote, raise the max maps
over them and find their shadows in one call each, with the same float operations in the same
order as ``WorldGrid.rect_mask`` and ``WorldGrid.paint``: the grid and the shadows come out bit
for bit as those would leave them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from simbridge.world.model import WorldGrid
from simbridge.world.raycast import COARSE_SHIFT, Pyramid

SHADE_MARGIN_M = 0.5  # a cell this much below a box's top is under it, not the box itself


@dataclass(frozen=True, slots=True)
class Boxes:
    """Upright boxes, one per array element: footprint centre, heading (cos and sin of the yaw, as
    ``rect_mask`` takes it), length along the heading and width across it; the surface height they
    stand on and their own height; and the class, material and region id their cells take."""

    centre_n: np.ndarray  # float64
    centre_e: np.ndarray
    cos: np.ndarray
    sin: np.ndarray
    length: np.ndarray
    width: np.ndarray
    base: np.ndarray
    tall: np.ndarray
    cls: np.ndarray  # uint8 SurfaceClass
    mat: np.ndarray  # uint8 Material
    region: np.ndarray  # int32

    def __len__(self) -> int:
        return len(self.centre_n)

    @property
    def top(self) -> np.ndarray:
        """Height of each box's top (float64, as the painting and the max maps round it)."""
        top: np.ndarray = self.base + self.tall
        return top

    def take(self, which: np.ndarray) -> Boxes:
        """The boxes ``which`` selects (an index or boolean array), in its order."""
        return Boxes(
            self.centre_n[which], self.centre_e[which], self.cos[which], self.sin[which],
            self.length[which], self.width[which], self.base[which], self.tall[which],
            self.cls[which], self.mat[which], self.region[which],
        )  # fmt: skip


@dataclass(frozen=True, slots=True)
class Stamp:
    """What painting boxes overwrote: per cell (flat index), in painting order, the old values."""

    cells: np.ndarray  # int64
    height: np.ndarray
    cls: np.ndarray
    mat: np.ndarray
    region: np.ndarray

    def restore(self, grid: WorldGrid) -> None:
        """Put the old values back, last painted first (boxes overlap: the first save is the original)."""
        _restore(
            grid.height,
            grid.cls,
            grid.mat,
            grid.region,
            self.cells,
            self.height,
            self.cls,
            self.mat,
            self.region,
        )


# ---------------------------------------------------------------------- rect_mask, cell by cell
# ``WorldGrid.rect_mask`` computes its window and cell test with numpy on float64 arrays; these two
# repeat its expressions scalar by scalar in the same order (no fastmath: no reassociation, no fused
# multiply-add), so a box covers exactly the cells rect_mask would give it.
@njit(cache=True, inline="always")
def _rect_window(
    n0: float, e0: float, res: float, rows: int, cols: int,
    cn: float, ce: float, c: float, s: float, length: float, width: float,
) -> tuple[int, int, int, int]:  # fmt: skip
    """``rect_mask``'s window (i0, i1, j0, j1), clipped to the grid; empty when i0 >= i1 or j0 >= j1."""
    half_n = abs(c) * length / 2 + abs(s) * width / 2
    half_e = abs(s) * length / 2 + abs(c) * width / 2
    i0 = max(math.floor((cn - half_n - n0) / res), 0)
    i1 = min(math.ceil((cn + half_n - n0) / res), rows)
    j0 = max(math.floor((ce - half_e - e0) / res), 0)
    j1 = min(math.ceil((ce + half_e - e0) / res), cols)
    return i0, i1, j0, j1


@njit(cache=True, inline="always")
def _in_rect(
    n0: float, e0: float, res: float, i: int, j: int,
    cn: float, ce: float, c: float, s: float, length: float, width: float,
) -> bool:  # fmt: skip
    """``rect_mask``'s test: whether the centre of cell ``(i, j)`` falls in the rectangle."""
    n = n0 + (i + 0.5) * res
    e = e0 + (j + 0.5) * res
    u = (n - cn) * c + (e - ce) * s
    v = -(n - cn) * s + (e - ce) * c
    return abs(u) <= length / 2 and abs(v) <= width / 2


# ---------------------------------------------------------------------- kernels
@njit(cache=True)
def _windows(
    n0: float, e0: float, res: float, rows: int, cols: int, cn: np.ndarray, ce: np.ndarray,
    c: np.ndarray, s: np.ndarray, length: np.ndarray, width: np.ndarray,
) -> np.ndarray:  # fmt: skip
    """``_rect_window`` of each rectangle."""
    out = np.empty((len(cn), 4), np.int64)
    for a in range(len(cn)):
        out[a] = _rect_window(n0, e0, res, rows, cols, cn[a], ce[a], c[a], s[a], length[a], width[a])
    return out


@njit(cache=True)
def _paint(
    height: np.ndarray, cls: np.ndarray, mat: np.ndarray, region: np.ndarray, n0: float, e0: float,
    res: float, windows: np.ndarray, cn: np.ndarray, ce: np.ndarray, c: np.ndarray, s: np.ndarray,
    length: np.ndarray, width: np.ndarray, top: np.ndarray, new_cls: np.ndarray, new_mat: np.ndarray,
    new_region: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
    """Each box in turn: save, then set its cells (``paint``'s "set": the top, rounded to float32)."""
    cols = height.shape[1]
    size = 0
    for a in range(len(windows)):
        size += (windows[a, 1] - windows[a, 0]) * (windows[a, 3] - windows[a, 2])
    cells = np.empty(size, np.int64)
    old_h = np.empty(size, height.dtype)
    old_c = np.empty(size, cls.dtype)
    old_m = np.empty(size, mat.dtype)
    old_r = np.empty(size, region.dtype)
    k = 0
    for a in range(len(windows)):
        h = np.float32(top[a])
        for i in range(windows[a, 0], windows[a, 1]):
            for j in range(windows[a, 2], windows[a, 3]):
                if _in_rect(n0, e0, res, i, j, cn[a], ce[a], c[a], s[a], length[a], width[a]):
                    cells[k] = i * cols + j
                    old_h[k], old_c[k], old_m[k], old_r[k] = height[i, j], cls[i, j], mat[i, j], region[i, j]
                    height[i, j], cls[i, j], mat[i, j], region[i, j] = (
                        h,
                        new_cls[a],
                        new_mat[a],
                        new_region[a],
                    )
                    k += 1
    return cells[:k], old_h[:k], old_c[:k], old_m[:k], old_r[:k]


@njit(cache=True)
def _restore(
    height: np.ndarray, cls: np.ndarray, mat: np.ndarray, region: np.ndarray, cells: np.ndarray,
    old_h: np.ndarray, old_c: np.ndarray, old_m: np.ndarray, old_r: np.ndarray,
) -> None:  # fmt: skip
    """Write the saved values back into their cells, last saved first."""
    cols = height.shape[1]
    for k in range(len(cells) - 1, -1, -1):
        i, j = cells[k] // cols, cells[k] % cols
        height[i, j], cls[i, j], mat[i, j], region[i, j] = old_h[k], old_c[k], old_m[k], old_r[k]


@njit(cache=True)
def _raise(maps: np.ndarray, windows: np.ndarray, top: np.ndarray, levels: int) -> None:
    """Make the first ``levels`` maps cover each box's ``top`` (rounded to float32) on its fine-cell
    window: map ``k``'s coarse cells within ``2**k`` of the window. The maps only have to bound
    the grid from above, so moving actors raise them where they are stamped and never lower them:
    the march stays exact, only a little less quick."""
    rows, cols = maps.shape[1], maps.shape[2]
    for a in range(len(windows)):
        b_i0, b_i1 = windows[a, 0] >> COARSE_SHIFT, ((windows[a, 1] - 1) >> COARSE_SHIFT) + 1
        b_j0, b_j1 = windows[a, 2] >> COARSE_SHIFT, ((windows[a, 3] - 1) >> COARSE_SHIFT) + 1
        h = np.float32(top[a])
        for k in range(levels):
            r = 1 << k
            for bi in range(max(b_i0 - r, 0), min(b_i1 + r, rows)):
                for bj in range(max(b_j0 - r, 0), min(b_j1 + r, cols)):
                    if maps[k, bi, bj] < h:
                        maps[k, bi, bj] = h


@njit(cache=True)
def _shades(
    height: np.ndarray, n0: float, e0: float, res: float, windows: np.ndarray, cn: np.ndarray,
    ce: np.ndarray, length: np.ndarray, width: np.ndarray, under: np.ndarray,
) -> np.ndarray:  # fmt: skip
    """Per axis-aligned rectangle, one after another, flat: the mask over its window of the cells in
    it lower than ``under`` (float32: numpy compares the float32 heights with a Python float so)."""
    size = 0
    for a in range(len(windows)):
        size += max(windows[a, 1] - windows[a, 0], 0) * max(windows[a, 3] - windows[a, 2], 0)
    masks = np.zeros(size, np.bool_)
    k = 0
    for a in range(len(windows)):
        for i in range(windows[a, 0], windows[a, 1]):
            for j in range(windows[a, 2], windows[a, 3]):
                inside = _in_rect(n0, e0, res, i, j, cn[a], ce[a], 1.0, 0.0, length[a], width[a])
                masks[k] = inside and height[i, j] < under[a]
                k += 1
    return masks


# ---------------------------------------------------------------------- entry points
def box_windows(grid: WorldGrid, boxes: Boxes) -> np.ndarray:
    """(N, 4) int64: each box's grid window (i0, i1, j0, j1); empty where it lies off the grid."""
    rows, cols = grid.shape
    return _windows(
        grid.n0, grid.e0, grid.res, rows, cols,
        boxes.centre_n, boxes.centre_e, boxes.cos, boxes.sin, boxes.length, boxes.width,
    )  # fmt: skip


def paint_boxes(grid: WorldGrid, boxes: Boxes, windows: np.ndarray) -> Stamp:
    """Paint the boxes into their windows, in order (a later box wins where boxes overlap), and
    return what they overwrote."""
    return Stamp(
        *_paint(
            grid.height, grid.cls, grid.mat, grid.region, grid.n0, grid.e0, grid.res, windows,
            boxes.centre_n, boxes.centre_e, boxes.cos, boxes.sin, boxes.length, boxes.width, boxes.top,
            boxes.cls, boxes.mat, boxes.region,
        )
    )  # fmt: skip


def raise_pyramid(pyramid: Pyramid, windows: np.ndarray, top: np.ndarray, levels: int) -> None:
    """Raise the first ``levels`` max maps of ``pyramid`` over every stamped window to its top."""
    _raise(pyramid.maps, windows, top, levels)
    if len(top):
        pyramid.h_max = max(pyramid.h_max, float(top.max()))


def shadows(
    grid: WorldGrid, boxes: Boxes, sun_neu: tuple[float, float, float]
) -> list[tuple[tuple[int, int, int, int], np.ndarray]]:
    """Each box's shadow on the grid as painted (so boxes shade each other), for
    ``ShadowMap.stamp``: the window and mask of the cells under the sun's shadow of the box, drawn as
    the box's footprint stretched away from the sun by its height over the sun's slope (an
    axis-aligned rectangle), less the cells as high as the box's top (the box itself). Boxes whose
    shadow falls off the grid have none."""
    sn, se, su = sun_neu
    shadow_len = 1.0 / max(math.tan(math.asin(min(su, 1.0))), 0.05)
    horiz = math.hypot(sn, se) or 1.0
    off = boxes.tall * shadow_len  # how far the shadow reaches beyond the box, away from the sun
    cn = boxes.centre_n - sn / horiz * off / 2
    ce = boxes.centre_e - se / horiz * off / 2
    length = boxes.length + off * abs(sn / horiz)
    width = boxes.width + off * abs(se / horiz)
    rows, cols = grid.shape
    one, zero = np.ones(len(boxes)), np.zeros(len(boxes))
    windows = _windows(grid.n0, grid.e0, grid.res, rows, cols, cn, ce, one, zero, length, width)
    under = (boxes.top - SHADE_MARGIN_M).astype(np.float32)
    masks = _shades(grid.height, grid.n0, grid.e0, grid.res, windows, cn, ce, length, width, under)
    out = []
    at = 0
    for i0, i1, j0, j1 in windows.tolist():
        if i0 < i1 and j0 < j1:
            size = (i1 - i0) * (j1 - j0)
            out.append(((i0, i1, j0, j1), masks[at : at + size].reshape(i1 - i0, j1 - j0)))
            at += size
    return out
