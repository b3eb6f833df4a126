"""Cars and pedestrians, advanced by simulated time, deterministic for a seed.

Cars enter each lane by a Poisson process, drive at their own speed (keeping a gap to the car ahead)
and leave at the lane's end: traffic comes and goes. Pedestrians walk back and forth along their
walkways. Every actor is stamped into the grid as a box of its class, on top of the static world,
and removed again before the next stamp.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from simbridge.world.model import Material, SurfaceClass, WorldGrid
from simbridge.world.raycast import COARSE
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


def _point_at(
    points: tuple[tuple[float, float], ...], cum: np.ndarray, s: float
) -> tuple[float, float, float]:
    """Position and heading at arc length ``s`` along a polyline."""
    k = int(np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(points) - 2))
    (n1, e1), (n2, e2) = points[k], points[k + 1]
    seg = cum[k + 1] - cum[k]
    f = 0.0 if seg == 0 else (s - cum[k]) / seg
    return n1 + f * (n2 - n1), e1 + f * (e2 - e1), math.atan2(e2 - e1, n2 - n1)


class Actors:
    """All moving actors of a world; ``advance(t_s)`` then ``poses()`` or ``stamp(grid)``."""

    def __init__(self, lanes: tuple[Lane, ...], walkways: tuple[Walkway, ...], seed: int) -> None:
        self._rng = np.random.default_rng(seed + 7919)
        self._lanes = lanes
        self._lane_len = [_polyline_lengths(ln.points_ne) for ln in lanes]
        self._cars: list[list[list[float]]] = [[] for _ in lanes]  # per lane: [s, speed, colour]
        self._next_arrival = [self._rng.exponential(60.0 / max(ln.arrivals_per_min, 1e-6)) for ln in lanes]
        self._walkways = walkways
        self._walk_len = [_polyline_lengths(w.points_ne) for w in walkways]
        self._people: list[list[list[float]]] = []
        for w, cum in zip(walkways, self._walk_len, strict=True):
            group = []
            for _ in range(w.count):
                s0 = float(self._rng.uniform(0, cum[-1]))
                speed = float(self._rng.uniform(1.0, 1.6)) * float(self._rng.choice([-1, 1]))
                offset = float(self._rng.uniform(-0.4, 0.4)) * w.width_m
                group.append([s0, speed, offset, float(self._rng.integers(0, 8))])
            self._people.append(group)
        self.t_s = 0.0
        # warm the roads up so the first frame already has traffic
        self._prefill()
        # per stamped actor: window, mask, then the saved height, class, material and region
        self._stamped: list[tuple[tuple[int, int, int, int], np.ndarray, *tuple[np.ndarray, ...]]] = []

    def _prefill(self) -> None:
        for k, ln in enumerate(self._lanes):
            cum = self._lane_len[k]
            s = float(self._rng.exponential(60.0 / max(ln.arrivals_per_min, 1e-6)) * np.mean(ln.speed_m_s))
            while s < cum[-1]:
                self._cars[k].append(
                    [s, float(self._rng.uniform(*ln.speed_m_s)), float(self._rng.integers(0, 8))]
                )
                s += max(
                    _MIN_GAP_M + CAR_LENGTH_M,
                    float(self._rng.exponential(60.0 / ln.arrivals_per_min) * np.mean(ln.speed_m_s)),
                )
            self._cars[k].sort(key=lambda c: -c[0])

    def advance(self, t_s: float) -> None:
        """Move every actor to simulated time ``t_s`` (monotonic; earlier times are ignored)."""
        dt = t_s - self.t_s
        if dt <= 0:
            return
        for k, ln in enumerate(self._lanes):
            cars = self._cars[k]
            end = self._lane_len[k][-1]
            ahead = math.inf
            for car in cars:  # sorted front (largest s) first
                car[0] = min(car[0] + car[1] * dt, ahead - _MIN_GAP_M - CAR_LENGTH_M)
                ahead = car[0]
            self._cars[k] = [c for c in cars if c[0] < end]
            self._next_arrival[k] -= dt
            while self._next_arrival[k] <= 0:
                last = self._cars[k][-1][0] if self._cars[k] else math.inf
                if last > _MIN_GAP_M + CAR_LENGTH_M:
                    self._cars[k].append(
                        [0.0, float(self._rng.uniform(*ln.speed_m_s)), float(self._rng.integers(0, 8))]
                    )
                self._next_arrival[k] += float(self._rng.exponential(60.0 / max(ln.arrivals_per_min, 1e-6)))
        for _w, cum, group in zip(self._walkways, self._walk_len, self._people, strict=True):
            for p in group:
                p[0] += p[1] * dt
                if p[0] < 0 or p[0] > cum[-1]:
                    p[1] = -p[1]
                    p[0] = min(max(p[0], 0.0), cum[-1])
        self.t_s = t_s

    def poses(self) -> list[ActorPose]:
        out = []
        for k, ln in enumerate(self._lanes):
            for s, _, colour in self._cars[k]:
                n, e, yaw = _point_at(ln.points_ne, self._lane_len[k], s)
                out.append(ActorPose(SurfaceClass.VEHICLE, (n, e), yaw, ln.deck_height_m, int(colour)))
        for w, cum, group in zip(self._walkways, self._walk_len, self._people, strict=True):
            for s, _, offset, colour in group:
                n, e, yaw = _point_at(w.points_ne, cum, s)
                n, e = n - math.sin(yaw) * offset, e + math.cos(yaw) * offset
                out.append(ActorPose(SurfaceClass.PEDESTRIAN, (n, e), yaw, w.surface_height_m, int(colour)))
        return out

    # ------------------------------------------------------------------ grid stamping
    def unstamp(self, grid: WorldGrid) -> None:
        """Restore the cells the last stamp covered (last stamped first)."""
        for (i0, i1, j0, j1), mask, h, c, m, r in reversed(self._stamped):
            grid.height[i0:i1, j0:j1][mask] = h
            grid.cls[i0:i1, j0:j1][mask] = c
            grid.mat[i0:i1, j0:j1][mask] = m
            grid.region[i0:i1, j0:j1][mask] = r
        self._stamped = []

    def envelope(self, grid: WorldGrid) -> np.ndarray:
        """Per coarse cell of ``grid`` (``COARSE`` fine cells square), at least the top of the
        tallest actor that can ever stand in it: cars on their lanes, people on their walkways;
        -1e9 where none can."""
        rows, cols = grid.shape
        out = np.full((-(-rows // COARSE), -(-cols // COARSE)), -1e9, np.float32)
        coarse_m = grid.res * COARSE
        paths = [(ln.points_ne, ln.deck_height_m + CAR_HEIGHT_M, CAR_LENGTH_M / 2) for ln in self._lanes]
        paths += [
            (w.points_ne, w.surface_height_m + PERSON_HEIGHT_M, 0.4 * w.width_m + PERSON_SIZE_M)
            for w in self._walkways
        ]
        cells, tops, reach_m = [], [], 0.0
        for points, top, reach in paths:
            p = np.asarray(points, float)
            if len(p) < 2:
                continue
            seg = np.diff(p, axis=0)
            steps = np.maximum(np.ceil(np.hypot(seg[:, 0], seg[:, 1]) / (coarse_m / 2)), 1).astype(int)
            pts = np.concatenate(
                [p[k] + seg[k] * (np.arange(steps[k] + 1)[:, None] / steps[k]) for k in range(len(seg))]
            )
            cells.append(np.floor((pts - (grid.n0, grid.e0)) / coarse_m).astype(np.int64))
            tops.append(np.full(len(pts), top, np.float32))
            reach_m = max(reach_m, reach)
        if not cells:
            return out
        ij = np.concatenate(cells)
        ok = (ij[:, 0] >= 0) & (ij[:, 0] < out.shape[0]) & (ij[:, 1] >= 0) & (ij[:, 1] < out.shape[1])
        np.maximum.at(out, (ij[ok, 0], ij[ok, 1]), np.concatenate(tops)[ok])
        r = math.ceil(reach_m / coarse_m) + 1  # an actor's reach from its path point, and a cell
        return np.asarray(cv2.dilate(out, np.ones((2 * r + 1, 2 * r + 1), np.uint8)), np.float32)

    def stamp(
        self, grid: WorldGrid, near: tuple[float, float, float] | None = None
    ) -> list[tuple[ActorPose, tuple[int, int, int, int]]]:
        """Put the actors into the grid at the current time: all, or those within ``near``'s radius
        of its north and east. Returns each one stamped with its grid window."""
        self.unstamp(grid)
        poses = self.poses()
        if near is not None:
            n0, e0, radius = near
            poses = [a for a in poses if math.hypot(a.centre_ne[0] - n0, a.centre_ne[1] - e0) <= radius]
        out = []
        for a in poses:
            if a.kind is SurfaceClass.VEHICLE:
                size, height, mat = (CAR_LENGTH_M, CAR_WIDTH_M), CAR_HEIGHT_M, Material.CAR_PAINT
            else:
                size, height, mat = (PERSON_SIZE_M, PERSON_SIZE_M), PERSON_HEIGHT_M, Material.CLOTH
            got = grid.rect_mask(a.centre_ne, size[0], size[1], a.yaw_rad)
            if got is None:
                continue
            win, mask, _, _ = got
            i0, i1, j0, j1 = win
            saved: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] = (
                grid.height[i0:i1, j0:j1][mask].copy(),
                grid.cls[i0:i1, j0:j1][mask].copy(),
                grid.mat[i0:i1, j0:j1][mask].copy(),
                grid.region[i0:i1, j0:j1][mask].copy(),
            )
            self._stamped.append((win, mask, *saved))
            # actors carry their paint colour as a negative region id: -(colour + 1)
            grid.paint(win, mask, a.base_height_m + height, a.kind, mat, -(a.colour + 1), "set")
            out.append((a, win))
        return out
