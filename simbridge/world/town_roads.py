"""The town's arterial roads along the seams between its districts: their band, what is painted across
it, and the traffic and pedestrians on them (:mod:`simbridge.world.town` composes the districts).

Across a seam's band, from its centre line out: a carriageway of four 3.5 m lanes (two each way, a
double solid centre line, dashed lane lines), a 3 m sidewalk each side, and grass verges to the band's
edge. Where two arterials cross, the carriageways meet in one square of asphalt with zebra crossings on
every arm. Wherever a district's street reaches the band's edge, its mouth is cut through the verge to the
carriageway, with a zebra where it crosses the sidewalk.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from simbridge.world.model import Material, SurfaceClass, WorldGrid
from simbridge.world.world import Lane, Walkway

__all__ = ["CARRIAGEWAY_M", "SIDEWALK_M", "Seam", "paint_seams", "seam_band_mask"]

LANE_W_M = 3.5
LANES_EACH_WAY = 2
CARRIAGEWAY_M = 2 * LANES_EACH_WAY * LANE_W_M
SIDEWALK_M = 3.0
SIDEWALK_H_M = 0.15
VERGE_H_M = 0.05
MOUTH_M = (3.0, 40.0)  # a district street's width where it meets the band; longer runs lie alongside
SPEED_M_S = (10.0, 16.0)
ARRIVALS_PER_MIN = (4.0, 10.0)
WALK_PIECE_M = (150.0, 300.0)


@dataclass(frozen=True, slots=True)
class Seam:
    """An arterial along a seam: ``axis`` "ns" runs north at east ``centre``, "ew" runs east at north
    ``centre``, from ``lo`` to ``hi`` along it; its band reaches ``band_half_m`` either side (metres)."""

    axis: Literal["ns", "ew"]
    centre: float
    lo: float
    hi: float
    band_half_m: float

    def point(self, along: float, across: float) -> tuple[float, float]:
        """(north, east) of a point ``along`` the seam and ``across`` it (east of a "ns" seam, north of
        an "ew" one)."""
        return (along, self.centre + across) if self.axis == "ns" else (self.centre + across, along)


def _cells(lo: float, hi: float, origin: float, res: float, count: int) -> tuple[int, int]:
    a = max(math.ceil((lo - origin) / res - 0.5), 0)
    b = min(math.ceil((hi - origin) / res - 0.5), count)
    return a, b


def _frame(
    grid: WorldGrid, seam: Seam, reach_m: float
) -> tuple[tuple[int, int, int, int], np.ndarray, np.ndarray] | None:
    """The window of the cells within ``reach_m`` of the seam's centre line, with each cell's along and
    across coordinate (arrays broadcast to the window's shape)."""
    rows, cols = grid.shape
    if seam.axis == "ns":
        i0, i1 = _cells(seam.lo, seam.hi, grid.n0, grid.res, rows)
        j0, j1 = _cells(seam.centre - reach_m, seam.centre + reach_m, grid.e0, grid.res, cols)
    else:
        i0, i1 = _cells(seam.centre - reach_m, seam.centre + reach_m, grid.n0, grid.res, rows)
        j0, j1 = _cells(seam.lo, seam.hi, grid.e0, grid.res, cols)
    if i0 >= i1 or j0 >= j1:
        return None
    n = (grid.n0 + (np.arange(i0, i1) + 0.5) * grid.res)[:, None]
    e = (grid.e0 + (np.arange(j0, j1) + 0.5) * grid.res)[None, :]
    shape = (i1 - i0, j1 - j0)
    along, across = (n, e - seam.centre) if seam.axis == "ns" else (e, n - seam.centre)
    return (i0, i1, j0, j1), np.broadcast_to(along, shape), np.broadcast_to(across, shape)


def seam_band_mask(grid: WorldGrid, seams: tuple[Seam, ...], pad_m: float = 0.0) -> np.ndarray:
    """The grid's cells in any seam's band (grown by ``pad_m`` each side), as a boolean raster."""
    mask = np.zeros(grid.shape, bool)
    for seam in seams:
        fr = _frame(grid, seam, seam.band_half_m + pad_m)
        if fr is not None:
            i0, i1, j0, j1 = fr[0]
            mask[i0:i1, j0:j1] = True
    return mask


def _near_crossing(along: np.ndarray, seam: Seam, seams: tuple[Seam, ...], reach_m: float) -> np.ndarray:
    """Where ``along`` this seam lies within ``reach_m`` of another seam's centre line."""
    near = np.zeros(along.shape, bool)
    for other in seams:
        if other.axis != seam.axis:
            near |= np.abs(along - other.centre) < reach_m
    return near


def paint_seams(
    grid: WorldGrid, seams: tuple[Seam, ...], rng: np.random.Generator
) -> tuple[list[Lane], list[Walkway]]:
    """Paint every seam's arterial (verges, sidewalks, carriageway, markings, crossings, street mouths)
    and return its traffic lanes and sidewalk walkways."""
    frames = [(seam, _frame(grid, seam, seam.band_half_m)) for seam in seams]
    cw = CARRIAGEWAY_M / 2
    layers = (
        (lambda a: np.ones(a.shape, bool), VERGE_H_M, SurfaceClass.GRASS, Material.GRASS),
        (lambda a: np.abs(a) < cw + SIDEWALK_M, SIDEWALK_H_M, SurfaceClass.SIDEWALK, Material.PAVING),
        (lambda a: np.abs(a) < cw, 0.0, SurfaceClass.ROAD, Material.ASPHALT),
    )
    for inside, height, cls, mat in layers:  # each layer on every seam first: crossings come out clean
        for _seam, fr in frames:
            if fr is not None:
                win, _along, across = fr
                grid.paint(win, inside(across), height, cls, mat, 0, "set")
    for seam, fr in frames:
        if fr is None:
            continue
        win, along, across = fr
        junction = _near_crossing(along, seam, seams, cw + SIDEWALK_M)
        lw = max(0.15, grid.res * 1.01) / 2
        solid = (np.abs(np.abs(across) - 0.2) <= lw) & ~junction
        dashed = (np.abs(np.abs(across) - LANE_W_M) <= lw) & (np.mod(along, 9.0) < 3.0) & ~junction
        grid.paint(win, solid | dashed, None, SurfaceClass.ROAD, Material.LANE_MARKING)
        crossing = (np.abs(across) < cw) & junction & ~_near_crossing(along, seam, seams, cw + 0.3)
        grid.paint(win, crossing, 0.0, SurfaceClass.CROSSWALK, Material.ASPHALT)
        grid.paint(win, crossing & (np.mod(across + cw, 1.0) < 0.5), None, None, Material.ZEBRA)
    for seam in seams:
        _street_mouths(grid, seam, seams)
    lanes: list[Lane] = []
    walkways: list[Walkway] = []
    for seam in seams:
        lanes += _lanes(seam, rng)
        walkways += _walkways(seam, rng)
    return lanes, walkways


def _street_mouths(grid: WorldGrid, seam: Seam, seams: tuple[Seam, ...]) -> None:
    """Cut each district street that reaches the band through the verge (asphalt) and the sidewalk (a
    zebra), so it meets the carriageway."""
    res = grid.res
    rows, cols = grid.shape
    for side in (1.0, -1.0):
        n, e = seam.point(seam.lo, side * (seam.band_half_m + res / 2))  # the first cell past the band
        if seam.axis == "ns":
            j = math.floor((e - grid.e0) / res)
            i0, i1 = _cells(seam.lo, seam.hi, grid.n0, res, rows)
            if not 0 <= j < cols:
                continue
            line, first, origin = grid.cls[i0:i1, j], i0, grid.n0
        else:
            i = math.floor((n - grid.n0) / res)
            j0, j1 = _cells(seam.lo, seam.hi, grid.e0, res, cols)
            if not 0 <= i < rows:
                continue
            line, first, origin = grid.cls[i, j0:j1], j0, grid.e0
        road = np.concatenate(([False], line == SurfaceClass.ROAD, [False]))
        edges = np.flatnonzero(np.diff(road.astype(np.int8)))
        for a, b in zip(edges[::2], edges[1::2], strict=True):
            lo = origin + (first + a) * res
            hi = origin + (first + b) * res
            if not MOUTH_M[0] <= hi - lo <= MOUTH_M[1]:
                continue
            if _near_crossing(np.array([lo, hi]), seam, seams, seam.band_half_m + 1.0).any():
                continue  # the crossroads: its own zebras
            _paint_mouth(grid, seam, side, lo, hi)


def _paint_mouth(grid: WorldGrid, seam: Seam, side: float, lo: float, hi: float) -> None:
    """A street's mouth on one side of the seam, ``lo..hi`` along it."""
    part = Seam(seam.axis, seam.centre, lo, hi, seam.band_half_m)
    fr = _frame(grid, part, seam.band_half_m)
    if fr is None:
        return
    win, along, across = fr
    out = across * side
    cw = CARRIAGEWAY_M / 2
    verge = out >= cw + SIDEWALK_M
    walk = (out >= cw) & ~verge
    grid.paint(win, verge, 0.0, SurfaceClass.ROAD, Material.ASPHALT, 0)
    grid.paint(win, walk, 0.0, SurfaceClass.CROSSWALK, Material.ASPHALT, 0)
    grid.paint(win, walk & (np.mod(along - lo, 1.0) < 0.5), None, None, Material.ZEBRA)


def _lanes(seam: Seam, rng: np.random.Generator) -> list[Lane]:
    """Two lanes each way, traffic on the right: north- or eastbound on the side of larger ``across``
    for a "ns" seam (east), of smaller for an "ew" one (south)."""
    right = 1.0 if seam.axis == "ns" else -1.0
    out = []
    for k in range(LANES_EACH_WAY):
        off = (k + 0.5) * LANE_W_M
        forward = (seam.point(seam.lo + 1.0, right * off), seam.point(seam.hi - 1.0, right * off))
        back = (seam.point(seam.hi - 1.0, -right * off), seam.point(seam.lo + 1.0, -right * off))
        for pts in (forward, back):
            out.append(Lane(pts, SPEED_M_S, float(rng.uniform(*ARRIVALS_PER_MIN))))
    return out


def _walkways(seam: Seam, rng: np.random.Generator) -> list[Walkway]:
    """People on both sidewalks, in stretches of ``WALK_PIECE_M``."""
    across = CARRIAGEWAY_M / 2 + SIDEWALK_M / 2
    out = []
    for side in (1.0, -1.0):
        cuts = [seam.lo + 1.0]
        while cuts[-1] < seam.hi - 1.0:
            cuts.append(min(cuts[-1] + float(rng.uniform(*WALK_PIECE_M)), seam.hi - 1.0))
        for a, b in itertools.pairwise(cuts):
            if b - a < 20.0:
                continue
            pts = (seam.point(a, side * across), seam.point(b, side * across))
            out.append(Walkway(pts, int(rng.integers(1, 5)), SIDEWALK_H_M, 2.0))
    return out
