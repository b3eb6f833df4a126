"""Cars and pedestrians, advanced by simulated time, deterministic for a seed.

Cars enter each lane by a Poisson process, drive at their own speed (keeping a gap to the car ahead)
and leave at the lane's end: traffic comes and goes. Pedestrians walk back and forth along their
walkways. Every actor is stamped into the grid as a box of its class, on top of the static world,
and removed again before the next stamp.

A city has thousands of actors and a frame stamps hundreds of them, so their state lives in flat
arrays (cars grouped by lane, front first; then pedestrians walkway by walkway), moved and placed by
numba kernels and stamped by :mod:`simbridge.world.stamping`, with no Python work per actor.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import cv2
import numpy as np
from numba import njit

from simbridge.world.model import Material, SurfaceClass, WorldGrid
from simbridge.world.raycast import COARSE
from simbridge.world.stamping import Boxes, Stamp, box_windows, paint_boxes
from simbridge.world.world import Lane, Walkway

CAR_LENGTH_M, CAR_WIDTH_M, CAR_HEIGHT_M = 4.5, 1.9, 1.5
PERSON_SIZE_M, PERSON_HEIGHT_M = 0.6, 1.75
_MIN_GAP_M = 6.0


@dataclass(frozen=True, slots=True)
class ActorPose:
    kind: SurfaceClass  # VEHICLE or PEDESTRIAN
    centre_ne: tuple[float, float]
    yaw_rad: float
    base_height_m: float
    colour: int  # index into the renderer's paint palette


def _polyline_lengths(points: tuple[tuple[float, float], ...]) -> np.ndarray:
    p = np.asarray(points, dtype=float)
    seg = np.hypot(np.diff(p[:, 0]), np.diff(p[:, 1]))
    return np.concatenate([[0.0], np.cumsum(seg)])


@dataclass(frozen=True, slots=True)
class _Paths:
    """Polylines (the lanes, then the walkways) packed into flat arrays, to place every actor in one
    kernel call. Per point: the arc length to it along its path, and the heading of the segment it
    starts with that heading's cosine and sine (by ``math``, as actors' yaws always were)."""

    start: np.ndarray  # int64 (paths + 1,): path p's points are [start[p], start[p + 1])
    points: np.ndarray  # float64 (points, 2): north, east
    cum: np.ndarray  # float64 (points,)
    yaw: np.ndarray  # float64 (points,); 0 at a path's last point
    cos: np.ndarray
    sin: np.ndarray
    length: np.ndarray  # float64 (paths,): each path's total length
    base: np.ndarray  # float64 (paths,): the height of the surface its actors stand on (a level path)
    sloped: np.ndarray  # bool (paths,): the path has a height per point (``z``), linear between them
    z: np.ndarray  # float64 (points,): the surface height at each point (``base`` on a level path)

    @staticmethod
    def pack(paths: list[tuple[tuple[tuple[float, float], ...], float, tuple[float, ...] | None]]) -> _Paths:
        """From (points, surface height, per-point heights or None) per path. A one-point path
        becomes that point twice: its actors stand on the point facing north, as they always did."""
        start, length, base, sloped = [0], [], [], []
        points: list[tuple[float, float]] = []
        z: list[float] = []
        cum: list[np.ndarray] = []
        yaw: list[float] = []
        for pts, height_m, heights in paths:
            zs = list(heights) if heights is not None else [height_m] * len(pts)
            if len(pts) == 1:
                pts, zs = pts * 2, zs * 2
            start.append(start[-1] + len(pts))
            points += pts
            z += zs
            cum.append(_polyline_lengths(pts))
            yaw += [math.atan2(e2 - e1, n2 - n1) for (n1, e1), (n2, e2) in itertools.pairwise(pts)] + [0.0]
            length.append(cum[-1][-1])
            base.append(height_m)
            sloped.append(heights is not None)
        return _Paths(
            start=np.asarray(start, np.int64),
            points=np.asarray(points, np.float64).reshape(-1, 2),
            cum=np.concatenate(cum) if cum else np.zeros(0),
            yaw=np.asarray(yaw, np.float64),
            cos=np.asarray([math.cos(y) for y in yaw], np.float64),
            sin=np.asarray([math.sin(y) for y in yaw], np.float64),
            length=np.asarray(length, np.float64),
            base=np.asarray(base, np.float64),
            sloped=np.asarray(sloped, bool),
            z=np.asarray(z, np.float64),
        )

    def surface(self, path: np.ndarray, seg: np.ndarray, frac: np.ndarray) -> np.ndarray:
        """The surface height under actors on ``path`` at fraction ``frac`` along segment ``seg``: the
        path's one height on a level path (exactly, as it always was), linear between the segment's
        ends on a sloped one."""
        base: np.ndarray = self.base[path]
        if not self.sloped.any():
            return base
        za, zb = self.z[seg], self.z[np.minimum(seg + 1, len(self.z) - 1)]
        return np.asarray(np.where(self.sloped[path], za + frac * (zb - za), base))


@njit(cache=True)
def _points_at(
    start: np.ndarray, points: np.ndarray, cum: np.ndarray, path: np.ndarray, s: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """North and east at arc length ``s[a]`` along path ``path[a]``, the segment (the index of its
    first point) that is on and the fraction along it, for every ``a``: the segment found as
    ``np.searchsorted(cum, s, side="right") - 1`` clipped to the path's segments, the point
    interpolated along it."""
    n, e, seg = np.empty(len(s)), np.empty(len(s)), np.empty(len(s), np.int64)
    frac = np.empty(len(s))
    for a in range(len(s)):
        first, end = start[path[a]], start[path[a] + 1]
        lo, hi = first, end
        while lo < hi:  # the first point past s
            mid = (lo + hi) // 2
            if cum[mid] <= s[a]:
                lo = mid + 1
            else:
                hi = mid
        k = min(max(lo - 1, first), end - 2)
        d = cum[k + 1] - cum[k]
        f = 0.0 if d == 0 else (s[a] - cum[k]) / d
        n[a] = points[k, 0] + f * (points[k + 1, 0] - points[k, 0])
        e[a] = points[k, 1] + f * (points[k + 1, 1] - points[k, 1])
        seg[a] = k
        frac[a] = f
    return n, e, seg, frac


@njit(cache=True)
def _drive(lane: np.ndarray, s: np.ndarray, speed: np.ndarray, dt: float) -> None:
    """Move each car (grouped by lane, front first) ``dt`` on at its speed, but no closer to the car
    ahead than a car's length and the minimum gap: in place."""
    ahead = math.inf
    for c in range(len(s)):
        if c == 0 or lane[c] != lane[c - 1]:
            ahead = math.inf
        s[c] = min(s[c] + speed[c] * dt, ahead - _MIN_GAP_M - CAR_LENGTH_M)
        ahead = s[c]


def _within(n: np.ndarray, e: np.ndarray, near: tuple[float, float, float]) -> np.ndarray:
    """Indices of the points within ``near``'s radius of its north and east. ``math.hypot`` decides,
    as it always has; numpy's hypot, which may round the last bit differently, only preselects."""
    n0, e0, radius = near
    maybe = np.flatnonzero(np.hypot(n - n0, e - e0) <= radius + abs(radius) * 1e-12)
    dn, de = (n[maybe] - n0).tolist(), (e[maybe] - e0).tolist()
    inside = np.asarray([math.hypot(a, b) <= radius for a, b in zip(dn, de, strict=True)], bool)
    return np.asarray(maybe[inside])


def _columns(rows: list[tuple[float, ...]], dtypes: tuple[type, ...]) -> list[np.ndarray]:
    """The columns of a table given as rows (possibly none), each as an array of its dtype."""
    table = np.asarray(rows, np.float64).reshape(-1, len(dtypes))
    return [np.ascontiguousarray(table[:, k], dtype) for k, dtype in enumerate(dtypes)]


class Actors:
    """All moving actors of a world; ``advance(t_s)`` then ``poses()`` or ``stamp(grid)``."""

    def __init__(self, lanes: tuple[Lane, ...], walkways: tuple[Walkway, ...], seed: int) -> None:
        self._rng = np.random.default_rng(seed + 7919)
        self._lanes = lanes
        self._walkways = walkways
        self._paths = _Paths.pack(
            [(ln.points_ne, ln.deck_height_m, ln.heights_m) for ln in lanes]
            + [(w.points_ne, w.surface_height_m, w.heights_m) for w in walkways]
        )
        self._next_arrival = np.asarray(
            [self._rng.exponential(60.0 / max(ln.arrivals_per_min, 1e-6)) for ln in lanes], np.float64
        )
        people: list[tuple[float, ...]] = []  # path, s, speed, offset (to the walkway's left), colour
        for k, w in enumerate(walkways, start=len(lanes)):
            for _ in range(w.count):
                s0 = float(self._rng.uniform(0, self._paths.length[k]))
                speed = float(self._rng.uniform(1.0, 1.6)) * float(self._rng.choice([-1, 1]))
                offset = float(self._rng.uniform(-0.4, 0.4)) * w.width_m
                people.append((k, s0, speed, offset, int(self._rng.integers(0, 8))))
        self._person_path, self._person_s, self._person_speed, self._person_offset, self._person_colour = (
            _columns(people, (np.int64, np.float64, np.float64, np.float64, np.int64))
        )
        self.t_s = 0.0
        # warm the roads up so the first frame already has traffic
        self._car_lane, self._car_s, self._car_speed, self._car_colour = self._prefill()
        self._stamped: Boxes | None = None  # the boxes in the grid now
        self._saved: Stamp | None = None  # and what they overwrote

    def _prefill(self) -> list[np.ndarray]:
        """Cars all along every lane, as if traffic had been flowing: lane, position, speed and
        colour per car, lane by lane, front first."""
        cars: list[tuple[float, ...]] = []
        for k, ln in enumerate(self._lanes):
            lane: list[tuple[float, ...]] = []
            s = float(self._rng.exponential(60.0 / max(ln.arrivals_per_min, 1e-6)) * np.mean(ln.speed_m_s))
            while s < self._paths.length[k]:
                lane.append((k, s, float(self._rng.uniform(*ln.speed_m_s)), int(self._rng.integers(0, 8))))
                s += max(
                    _MIN_GAP_M + CAR_LENGTH_M,
                    float(self._rng.exponential(60.0 / ln.arrivals_per_min) * np.mean(ln.speed_m_s)),
                )
            cars += sorted(lane, key=lambda c: -c[1])
        return _columns(cars, (np.int64, np.float64, np.float64, np.int64))

    def advance(self, t_s: float) -> None:
        """Move every actor to simulated time ``t_s`` (monotonic; earlier times are ignored)."""
        dt = t_s - self.t_s
        if dt <= 0:
            return
        _drive(self._car_lane, self._car_s, self._car_speed, float(dt))
        stay = self._car_s < self._paths.length[self._car_lane]
        if not stay.all():
            self._car_lane, self._car_s, self._car_speed, self._car_colour = (
                a[stay] for a in (self._car_lane, self._car_s, self._car_speed, self._car_colour)
            )
        self._arrive(dt)
        s = self._person_s + self._person_speed * dt
        end = self._paths.length[self._person_path]
        turn = (s < 0) | (s > end)  # walked off an end: back the other way, from that end
        self._person_speed[turn] = -self._person_speed[turn]
        s[turn] = np.minimum(np.maximum(s[turn], 0.0), end[turn])
        self._person_s = s
        self.t_s = t_s

    def _arrive(self, dt: float) -> None:
        """Count every lane's next arrival ``dt`` down; a car due enters at the lane's start, unless
        the last car is still within a car's length and the gap of it (then that arrival is lost)."""
        self._next_arrival -= dt
        due = np.flatnonzero(self._next_arrival <= 0).tolist()
        if not due:
            return
        at: list[int] = []  # per new car: where it goes (after its lane's last), lane, speed, colour
        lane: list[int] = []
        speed: list[float] = []
        colour: list[int] = []
        for k, end in zip(due, np.searchsorted(self._car_lane, due, side="right").tolist(), strict=True):
            ln = self._lanes[k]
            last = self._car_s[end - 1] if end > 0 and self._car_lane[end - 1] == k else math.inf
            while self._next_arrival[k] <= 0:
                if last > _MIN_GAP_M + CAR_LENGTH_M:
                    at.append(end)
                    lane.append(k)
                    speed.append(float(self._rng.uniform(*ln.speed_m_s)))
                    colour.append(int(self._rng.integers(0, 8)))
                    last = 0.0
                self._next_arrival[k] += float(self._rng.exponential(60.0 / max(ln.arrivals_per_min, 1e-6)))
        if at:
            self._car_lane = np.insert(self._car_lane, at, lane)
            self._car_s = np.insert(self._car_s, at, 0.0)
            self._car_speed = np.insert(self._car_speed, at, speed)
            self._car_colour = np.insert(self._car_colour, at, colour)

    def _place(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Every actor's north, east, segment (its first point's index) and the height of the surface
        it stands on: the cars, then the pedestrians, each their offset to the left of their
        walkway's line."""
        p = self._paths
        path = np.concatenate([self._car_lane, self._person_path])
        s = np.concatenate([self._car_s, self._person_s])
        n, e, seg, frac = _points_at(p.start, p.points, p.cum, path, s)
        cars = len(self._car_s)
        n[cars:] -= p.sin[seg[cars:]] * self._person_offset
        e[cars:] += p.cos[seg[cars:]] * self._person_offset
        return n, e, seg, p.surface(path, seg, frac)

    def people_at(self, t_s: float) -> np.ndarray:
        """(people, 3) north, east and the height of the surface under each pedestrian at ``t_s`` (not
        before now), without moving anyone: what an observer measures, leaving the episode's actors
        exactly as the sensors will find them."""
        p = self._paths
        dt = max(t_s - self.t_s, 0.0)
        end = p.length[self._person_path]
        s = np.clip(self._person_s + self._person_speed * dt, 0.0, end)  # at an end, as advance turns there
        n, e, seg, frac = _points_at(p.start, p.points, p.cum, self._person_path, s)
        n = n - p.sin[seg] * self._person_offset
        e = e + p.cos[seg] * self._person_offset
        base = p.surface(self._person_path, seg, frac)
        return np.stack([n, e, base], axis=1) if len(s) else np.zeros((0, 3))

    def poses(self) -> list[ActorPose]:
        """Every actor now: the cars lane by lane (front first), then the pedestrians."""
        n, e, seg, base_m = self._place()
        kinds = [SurfaceClass.VEHICLE] * len(self._car_s) + [SurfaceClass.PEDESTRIAN] * len(self._person_s)
        return [
            ActorPose(kind, (cn, ce), yaw, base, colour)
            for kind, cn, ce, yaw, base, colour in zip(
                kinds, n.tolist(), e.tolist(), self._paths.yaw[seg].tolist(), base_m.tolist(),
                np.concatenate([self._car_colour, self._person_colour]).tolist(), strict=True,
            )
        ]  # fmt: skip

    # ------------------------------------------------------------------ grid stamping
    def unstamp(self, grid: WorldGrid) -> None:
        """Restore the cells the last stamp covered (last stamped first)."""
        if self._saved is not None:
            self._saved.restore(grid)
        self._stamped = self._saved = None

    def envelope(self, grid: WorldGrid) -> np.ndarray:
        """Per coarse cell of ``grid`` (``COARSE`` fine cells square), at least the top of the
        tallest actor that can ever stand in it: cars on their lanes, people on their walkways;
        -1e9 where none can."""
        rows, cols = grid.shape
        out = np.full((-(-rows // COARSE), -(-cols // COARSE)), -1e9, np.float32)
        coarse_m = grid.res * COARSE
        paths = [
            (ln.points_ne, ln.deck_height_m, ln.heights_m, CAR_HEIGHT_M, CAR_LENGTH_M / 2)
            for ln in self._lanes
        ]
        paths += [
            (w.points_ne, w.surface_height_m, w.heights_m, PERSON_HEIGHT_M, 0.4 * w.width_m + PERSON_SIZE_M)
            for w in self._walkways
        ]
        cells, tops, reach_m = [], [], 0.0
        for points, level_m, heights, tall, reach in paths:
            p = np.asarray(points, float)
            if len(p) < 2:
                continue
            seg = np.diff(p, axis=0)
            steps = np.maximum(np.ceil(np.hypot(seg[:, 0], seg[:, 1]) / (coarse_m / 2)), 1).astype(int)
            frac = [np.arange(steps[k] + 1) / steps[k] for k in range(len(seg))]
            pts = np.concatenate([p[k] + seg[k] * frac[k][:, None] for k in range(len(seg))])
            cells.append(np.floor((pts - (grid.n0, grid.e0)) / coarse_m).astype(np.int64))
            if heights is None:
                tops.append(np.full(len(pts), level_m + tall, np.float32))
            else:
                z = np.asarray(heights, float)
                under = np.concatenate([z[k] + (z[k + 1] - z[k]) * frac[k] for k in range(len(seg))])
                tops.append((under + tall).astype(np.float32))
            reach_m = max(reach_m, reach)
        if not cells:
            return out
        ij = np.concatenate(cells)
        ok = (ij[:, 0] >= 0) & (ij[:, 0] < out.shape[0]) & (ij[:, 1] >= 0) & (ij[:, 1] < out.shape[1])
        np.maximum.at(out, (ij[ok, 0], ij[ok, 1]), np.concatenate(tops)[ok])
        r = math.ceil(reach_m / coarse_m) + 1  # an actor's reach from its path point, and a cell
        return np.asarray(cv2.dilate(out, np.ones((2 * r + 1, 2 * r + 1), np.uint8)), np.float32)

    def _boxes(self, near: tuple[float, float, float] | None) -> Boxes:
        """The actors' boxes now, in ``poses()`` order: all, or those within ``near``'s radius."""
        n, e, seg, base_m = self._place()
        which = np.arange(len(n)) if near is None else _within(n, e, near)
        car = which < len(self._car_s)
        colour = np.concatenate([self._car_colour, self._person_colour])[which]
        return Boxes(
            centre_n=n[which],
            centre_e=e[which],
            cos=self._paths.cos[seg[which]],
            sin=self._paths.sin[seg[which]],
            length=np.where(car, CAR_LENGTH_M, PERSON_SIZE_M),
            width=np.where(car, CAR_WIDTH_M, PERSON_SIZE_M),
            base=base_m[which],
            tall=np.where(car, CAR_HEIGHT_M, PERSON_HEIGHT_M),
            cls=np.where(car, SurfaceClass.VEHICLE, SurfaceClass.PEDESTRIAN).astype(np.uint8),
            mat=np.where(car, Material.CAR_PAINT, Material.CLOTH).astype(np.uint8),
            region=(-(colour + 1)).astype(np.int32),  # actors carry their paint colour as a negative id
        )

    def stamp(
        self, grid: WorldGrid, near: tuple[float, float, float] | None = None
    ) -> tuple[Boxes, np.ndarray]:
        """Put the actors into the grid at the current time: all, or those within ``near``'s radius
        of its north and east. Returns the boxes stamped (those on the grid) and their grid windows
        ((N, 4): i0, i1, j0, j1)."""
        self.unstamp(grid)
        boxes = self._boxes(near)
        windows = box_windows(grid, boxes)
        on = (windows[:, 0] < windows[:, 1]) & (windows[:, 2] < windows[:, 3])
        boxes, windows = boxes.take(on), windows[on]
        self._stamped, self._saved = boxes, paint_boxes(grid, boxes, windows)
        return boxes, windows
