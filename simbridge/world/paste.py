"""Pasting one built world into a larger grid: its rasters at an offset, its routes, zones and wires
shifted with them and cut to the part that was kept.

A place made of districts (:mod:`simbridge.world.town`) builds each district as a world of its own,
centred on its own origin, and pastes it where it belongs. Every :class:`~simbridge.world.model.WorldGrid`
raster is copied (height, class, material, region id); positive region ids are shifted by
``region_base`` so that the buildings of two districts never share an id. Lanes, walkways and wires are
clipped to a box: a route that leaves the box and comes back becomes two routes, pieces too short to use
are dropped. Safe zones are kept only when they lie wholly inside the box.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from simbridge.world.model import WorldError, WorldGrid
from simbridge.world.world import Lane, SafeZone, Walkway, Wire, World

__all__ = ["Box", "Pasted", "clip_polyline", "paste_world"]

MIN_LANE_M = 10.0  # shorter pieces of a cut lane carry no traffic worth the name
MIN_WALKWAY_M = 4.0
MIN_WIRE_M = 1.0


@dataclass(frozen=True, slots=True)
class Box:
    """An axis-aligned box in scenario (north, east) metres: ``[n_lo, n_hi] x [e_lo, e_hi]``."""

    n_lo: float
    n_hi: float
    e_lo: float
    e_hi: float

    def __post_init__(self) -> None:
        if not (self.n_lo < self.n_hi and self.e_lo < self.e_hi):
            raise WorldError(f"empty box: north {self.n_lo}..{self.n_hi}, east {self.e_lo}..{self.e_hi}")

    @property
    def centre_ne(self) -> tuple[float, float]:
        return ((self.n_lo + self.n_hi) / 2, (self.e_lo + self.e_hi) / 2)

    @property
    def size_ne(self) -> tuple[float, float]:
        return (self.n_hi - self.n_lo, self.e_hi - self.e_lo)

    def contains(self, north_m: float, east_m: float) -> bool:
        return self.n_lo <= north_m <= self.n_hi and self.e_lo <= east_m <= self.e_hi

    def shifted(self, offset_ne: tuple[float, float]) -> Box:
        dn, de = offset_ne
        return Box(self.n_lo + dn, self.n_hi + dn, self.e_lo + de, self.e_hi + de)

    def intersect(self, other: Box) -> Box | None:
        n_lo, n_hi = max(self.n_lo, other.n_lo), min(self.n_hi, other.n_hi)
        e_lo, e_hi = max(self.e_lo, other.e_lo), min(self.e_hi, other.e_hi)
        return Box(n_lo, n_hi, e_lo, e_hi) if n_lo < n_hi and e_lo < e_hi else None


@dataclass(frozen=True, slots=True)
class Pasted:
    """What :func:`paste_world` carried over, in the target's coordinates.

    ``window`` is the target's cells written, ``(i0, i1, j0, j1)``; ``next_region`` the first region id
    free after the pasted ones (hand it to the next paste as its ``region_base``).
    """

    lanes: tuple[Lane, ...]
    walkways: tuple[Walkway, ...]
    safe_zones: tuple[SafeZone, ...]
    wires: tuple[Wire, ...]
    window: tuple[int, int, int, int]
    next_region: int


Point = tuple[float, ...]


def _clip_segment(a: Point, b: Point, box: Box) -> tuple[float, float] | None:
    """Liang-Barsky: the parameters ``t0 <= t1`` in [0, 1] of the part of ``a -> b`` (north, east
    first) inside ``box``, or None when none is."""
    t0, t1 = 0.0, 1.0
    dn, de = b[0] - a[0], b[1] - a[1]
    for p, q in (
        (-dn, a[0] - box.n_lo),
        (dn, box.n_hi - a[0]),
        (-de, a[1] - box.e_lo),
        (de, box.e_hi - a[1]),
    ):
        if p == 0.0:
            if q < 0.0:
                return None
            continue
        t = q / p
        if p < 0.0:
            t0 = max(t0, t)
        else:
            t1 = min(t1, t)
        if t0 > t1:
            return None
    return t0, t1


def _lerp(a: Point, b: Point, t: float) -> Point:
    return tuple(float(x + t * (y - x)) for x, y in zip(a, b, strict=True))


def _length(points: Sequence[Point]) -> float:
    return sum(math.hypot(b[0] - a[0], b[1] - a[1]) for a, b in itertools.pairwise(points))


def clip_polyline(points: Sequence[Point], box: Box, min_length_m: float = 0.0) -> list[tuple[Point, ...]]:
    """The pieces of a polyline inside ``box``, in order, each at least ``min_length_m`` long.

    Points are ``(north, east, ...)``: any further coordinates (a wire's height) are interpolated where
    a segment is cut. A single point is kept when it lies in the box.
    """
    if len(points) == 1:
        return [tuple(points)] if box.contains(points[0][0], points[0][1]) else []
    pieces: list[tuple[Point, ...]] = []
    cur: list[Point] = []

    def flush() -> None:
        if len(cur) >= 2 and _length(cur) >= min_length_m:
            pieces.append(tuple(cur))
        cur.clear()

    for a, b in itertools.pairwise(points):
        got = _clip_segment(a, b, box)
        if got is None:
            flush()
            continue
        t0, t1 = got
        if t0 > 0.0 or not cur:
            flush()
            cur.append(_lerp(a, b, t0) if t0 > 0.0 else tuple(float(x) for x in a))
        end = _lerp(a, b, t1) if t1 < 1.0 else tuple(float(x) for x in b)
        if end != cur[-1]:
            cur.append(end)
        if t1 < 1.0:
            flush()
    flush()
    return pieces


def _ne(points: tuple[Point, ...]) -> tuple[tuple[float, float], ...]:
    return tuple((p[0], p[1]) for p in points)


def _neh(points: tuple[Point, ...]) -> tuple[tuple[float, float, float], ...]:
    return tuple((p[0], p[1], p[2]) for p in points)


def _cells(lo: float, hi: float, origin: float, res: float, count: int) -> tuple[int, int]:
    """Cells ``[a, b)`` whose centres lie in ``[lo, hi)``, clipped to ``[0, count)``."""
    a = max(math.ceil((lo - origin) / res - 0.5), 0)
    b = min(math.ceil((hi - origin) / res - 0.5), count)
    return a, b


def _cell_shift(src_origin: float, offset: float, dst_origin: float, res: float, axis: str) -> int:
    shift = (src_origin + offset - dst_origin) / res
    k = round(shift)
    if abs(shift - k) > 1e-6:
        raise WorldError(
            f"paste offset puts the source's {axis} cell edges {abs(shift - k) * res:.3g} m off the "
            f"target's: the offset must be a whole number of {res} m cells"
        )
    return k


def paste_world(
    target: WorldGrid,
    world: World,
    offset_ne: tuple[float, float],
    keep: Box | None = None,
    *,
    keep_routes: Box | None = None,
    region_base: int = 0,
) -> Pasted:
    """Copy ``world``'s grid into ``target`` moved by ``offset_ne``, and its routes with it.

    Args:
        target: the grid written into (same resolution, cell edges aligned with the moved source's).
        world: the world pasted; its grid is read, never changed.
        offset_ne: (north, east) metres added to every source coordinate.
        keep: the target's box that is written (cells whose centres lie in it); default the whole moved
            source grid. Cells outside the moved source are never written.
        keep_routes: the target's box the lanes, walkways, wires and safe zones are cut to; default ``keep``
            (pass a smaller one where something will be painted over the edge of the pasted part).
        region_base: added to every positive region id pasted.

    Returns:
        The carried-over routes, zones and wires in target coordinates, the window written and the next
        free region id.

    Raises:
        WorldError: a different resolution, an offset that is not a whole number of cells, or a ``keep``
            box that misses both grids.
    """
    src = world.grid
    if abs(src.res - target.res) > 1e-9:
        raise WorldError(f"paste needs one resolution: source {src.res} m, target {target.res} m")
    res = target.res
    dn, de = offset_ne
    di = _cell_shift(src.n0, dn, target.n0, res, "north")
    dj = _cell_shift(src.e0, de, target.e0, res, "east")
    sn_lo, sn_hi, se_lo, se_hi = src.extent_m
    moved = Box(sn_lo + dn, sn_hi + dn, se_lo + de, se_hi + de)
    area = moved if keep is None else moved.intersect(keep)
    if area is None:
        raise WorldError(f"paste keeps nothing: box {keep} misses the moved source {moved}")
    rows, cols = target.shape
    i0, i1 = _cells(area.n_lo, area.n_hi, target.n0, res, rows)
    j0, j1 = _cells(area.e_lo, area.e_hi, target.e0, res, cols)
    if i0 >= i1 or j0 >= j1:
        raise WorldError(f"paste keeps nothing: box {area} misses the target's extent {target.extent_m}")
    s = (slice(i0 - di, i1 - di), slice(j0 - dj, j1 - dj))
    t = (slice(i0, i1), slice(j0, j1))
    target.height[t] = src.height[s]
    target.cls[t] = src.cls[s]
    target.mat[t] = src.mat[s]
    region = src.region[s]
    target.region[t] = np.where(region > 0, region + np.int32(region_base), region)
    top = int(region.max(initial=0))

    box = area if keep_routes is None else keep_routes

    def moved_pts(points: Sequence[Point]) -> list[Point]:
        return [(p[0] + dn, p[1] + de, *p[2:]) for p in points]

    lanes = [
        dataclasses.replace(lane, points_ne=_ne(piece))
        for lane in world.lanes
        for piece in clip_polyline(moved_pts(lane.points_ne), box, MIN_LANE_M)
    ]
    walkways = [
        dataclasses.replace(walk, points_ne=_ne(piece))
        for walk in world.walkways
        for piece in clip_polyline(moved_pts(walk.points_ne), box, MIN_WALKWAY_M)
    ]
    wires = [
        dataclasses.replace(wire, points_neh=_neh(piece))
        for wire in world.wires
        for piece in clip_polyline(moved_pts(wire.points_neh), box, MIN_WIRE_M)
    ]
    zones = []
    for zone in world.safe_zones:
        centre = (zone.centre_ne[0] + dn, zone.centre_ne[1] + de)
        zone = dataclasses.replace(zone, centre_ne=centre)
        if all(box.contains(float(n), float(e)) for n, e in zone.corners_ne()):
            zones.append(zone)
    return Pasted(
        lanes=tuple(lanes),
        walkways=tuple(walkways),
        safe_zones=tuple(zones),
        wires=tuple(wires),
        window=(i0, i1, j0, j1),
        next_region=region_base + top + 1,
    )
