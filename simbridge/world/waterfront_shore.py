"""The waterfront's shore: where the water is, and the bands that follow the shoreline inland (a sand
beach, lawns behind a rock revetment or the marina's quay, then the promenade, the shore road and its
sidewalk), with the beach's umbrellas, kiosks and people, the promenade's benches, lamps and strollers
and the shore road's traffic.

The plan works in a shore frame: ``s`` metres along the shore and ``x`` metres across it, toward the
water. The water side is one of the four compass directions (drawn from the seed), so the frame's boxes
are the grid's boxes; the shoreline ``x = shore(s)`` is two long gentle waves and a wide bay that brings
the water to 20-40 m from the launch point, its depth set so that the water covers 33-42 % of the
square. The bands are cut by each cell's exact distance from the water (a Euclidean distance transform
at 1 m, interpolated to the grid), so they run parallel to the shore however it curves.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from simbridge.world.city_parts import SIDEWALK_H, WATER_H, CityParams, Range
from simbridge.world.city_props import Props
from simbridge.world.model import Material, SurfaceClass
from simbridge.world.world import Lane, Walkway

Pt = tuple[float, float]
STEP_M = 2.0  # spacing of the shoreline's samples
WATER_SHARE: Range = (0.33, 0.42)  # of the square
LAUNCH_TO_WATER_M: Range = (20.0, 40.0)  # from the launch point (0, 0) across to the shoreline
MIN_RADIUS_M = 300.0  # the smallest radius of curvature each of the shore's waves may have
FRONT_M: Range = (35.0, 50.0)  # beach, lawn or marina hard standing between the water and the promenade
PROMENADE_M: Range = (8.0, 12.0)
SHORE_ROAD_M: Range = (9.0, 11.0)
TOWN_WALK_M = 3.0  # the shore road's sidewalk on the town side
ROCKS_M, ROCKS_H = 5.0, 0.3  # rock revetment along the shore where there is no beach
QUAY_M, QUAY_H = 6.0, 0.5
UMBRELLA_PER_M2 = 1.0 / 300.0
SUNBATHERS_PER_M2 = 1.0 / 260.0  # groups of one to four lying or standing still
CHUNK_ROWS = 500  # rows painted at a time (bounds the temporary arrays)


class ShorePlan(Props):
    """The shore frame, the water and the shore's bands; :class:`Props` brings the grid, rng and painters."""

    def __init__(self, seed: int, size_m: float, res: float, params: CityParams) -> None:
        super().__init__(seed, size_m, res, params)
        side = int(self.rng.integers(0, 4))
        self.wn, self.we = ((1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0))[side]  # toward the water
        self.s_tab = np.arange(-self.half - 60.0, self.half + 60.0 + 1e-6, STEP_M)
        self.shore = self._draw_shore()
        self.slope = np.gradient(self.shore, STEP_M)
        self.front_m = self._u(FRONT_M)
        self.prom_m = self._u(PROMENADE_M)
        self.road_m = self._u(SHORE_ROAD_M)
        self.town_d = self.front_m + self.prom_m + self.road_m + TOWN_WALK_M  # where the town begins
        k = self.size / 1200.0
        self.beach: Range = (-self._u((0.15, 0.27)) * self.size, self._u((0.15, 0.27)) * self.size)
        self.marina: Range | None = self._marina_span(k)

    # ------------------------------------------------------------------ the frame
    def _ne(self, s: float, x: float) -> Pt:
        """Scenario (north, east) of the shore frame's (along, across) point."""
        return (-s * self.we + x * self.wn, s * self.wn + x * self.we)

    def _ne_box(self, s0: float, s1: float, x0: float, x1: float) -> tuple[float, float, float, float]:
        """A frame box as the (n_lo, n_hi, e_lo, e_hi) box it is on the grid."""
        (na, ea), (nb, eb) = self._ne(s0, x0), self._ne(s1, x1)
        return (min(na, nb), max(na, nb), min(ea, eb), max(ea, eb))

    def _sx(self, n: np.ndarray, e: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Frame (along, across) of scenario points (broadcasting)."""
        return -n * self.we + e * self.wn, n * self.wn + e * self.we

    def _shore_x(self, s: np.ndarray | float) -> np.ndarray:
        return np.asarray(np.interp(s, self.s_tab, self.shore))

    def _inland(self, s: np.ndarray, d_m: float | np.ndarray) -> np.ndarray:
        """(k, 2) scenario points ``d_m`` metres inland of the shoreline at ``s``, square to it."""
        x = self._shore_x(s)
        m = np.interp(s, self.s_tab, self.slope)
        norm = np.hypot(1.0, m)
        fs, fx = s + d_m * m / norm, x - d_m / norm
        return np.stack([-fs * self.we + fx * self.wn, fs * self.wn + fx * self.we], axis=1)

    def _yaw_along(self, s: float) -> float:
        """The heading (0 north, toward east positive) of the shoreline at ``s``, toward growing ``s``."""
        m = float(np.interp(s, self.s_tab, self.slope))
        return math.atan2(self.wn + m * self.we, -self.we + m * self.wn)

    def _pts(self, a: np.ndarray, margin: float = 0.5) -> tuple[Pt, ...]:
        """The points of ``a`` inside the grid (``margin`` from its edges) as a path."""
        keep = (np.abs(a) <= self.half - margin).all(axis=1)
        return tuple((float(n), float(e)) for n, e in a[keep])

    # ------------------------------------------------------------------ the plan
    def _draw_shore(self) -> np.ndarray:
        """The shoreline's across coordinate at ``s_tab``: waves, a bay off the launch point, and an
        offset found by bisection so that the water covers the drawn share of the square."""
        s = self.s_tab
        wave = np.zeros_like(s)
        for _ in range(2):
            lam = self._u((350.0, 900.0))
            amp = self._u((0.3, 1.0)) * min(40.0, lam**2 / (4 * math.pi**2 * MIN_RADIUS_M))
            wave += amp * np.sin(2 * math.pi * s / lam + self._u((0.0, 2 * math.pi)))
        k = min(1.0, self.size / 1200.0)
        bay = np.exp(-0.5 * ((s - self._u((-0.07, 0.07)) * self.size) / (self._u((230.0, 320.0)) * k)) ** 2)
        at0 = self._u(LAUNCH_TO_WATER_M)
        bay0, wave0 = float(np.interp(0.0, s, bay)), float(np.interp(0.0, s, wave))
        inside = np.abs(s) <= self.half
        target = self._u(WATER_SHARE)

        def line(c0: float) -> np.ndarray:
            return np.asarray(c0 + wave + (at0 - c0 - wave0) / bay0 * bay)

        def share(c0: float) -> float:
            return float(np.clip(self.half - line(c0)[inside], 0.0, self.size).mean()) / self.size

        lo, hi = -self.half, self.half
        for _ in range(40):  # the share falls as c0 moves the shore out toward the water
            mid = (lo + hi) / 2
            lo, hi = (mid, hi) if share(mid) > target else (lo, mid)
        return line((lo + hi) / 2)

    def _marina_span(self, k: float) -> Range | None:
        """The stretch of shore beside the beach that the marina takes, on one side or the other."""
        length = self._u((0.17, 0.22)) * self.size
        first = 1.0 if self.rng.random() < 0.5 else -1.0
        for side in (first, -first):
            start = (self.beach[1] if side > 0 else -self.beach[0]) + self._u((15.0, 30.0))
            end = min(start + length, self.half - 15.0)
            if end - start >= 60.0 * k:
                return (start, end) if side > 0 else (-end, -start)
        return None

    def _zone_of(self, s: np.ndarray) -> np.ndarray:
        """Per ``s``: 0 lawn behind rocks, 1 beach, 2 marina."""
        zone = np.where((s >= self.beach[0]) & (s <= self.beach[1]), 1, 0)
        if self.marina is not None:
            zone = np.where((s >= self.marina[0]) & (s <= self.marina[1]), 2, zone)
        return zone

    # ------------------------------------------------------------------ painting the bands
    def _paint_shore(self) -> None:
        """Water beyond the shoreline; inland of it, by distance: beach / lawn / quay, promenade, shore
        road, sidewalk (the town's land beyond is left as it is)."""
        g = self.grid
        rows, cols = g.shape
        coarse = 1.0
        m = round(self.size / coarse)
        c = -self.half + (np.arange(m) + 0.5) * coarse
        s, x = self._sx(c[:, None], c[None, :])
        land = (x <= self._shore_x(s)).astype(np.uint8)
        near = cv2.distanceTransform(land, cv2.DIST_L2, cv2.DIST_MASK_PRECISE) * coarse - coarse / 2
        dist = np.asarray(cv2.resize(near, (cols, rows), interpolation=cv2.INTER_LINEAR), np.float32)
        f, p, r = self.front_m, self.prom_m, self.road_m
        e = g.e0 + (np.arange(cols) + 0.5) * g.res
        for i0 in range(0, rows, CHUNK_ROWS):
            i1 = min(i0 + CHUNK_ROWS, rows)
            n = g.n0 + (np.arange(i0, i1) + 0.5) * g.res
            cs, cx = self._sx(n[:, None], e[None, :])
            water = cx > self._shore_x(cs)
            d = dist[i0:i1]
            zone = self._zone_of(cs)
            conds = [
                water,
                (d < f) & (zone == 1),
                (d < QUAY_M) & (zone == 2),
                (d < f) & (zone == 2),
                (d < ROCKS_M),
                (d < f),
                (d < f + p),
                (d < f + p + r),
                (d < self.town_d),
            ]
            table = [
                (WATER_H, SurfaceClass.WATER, Material.WATER),
                (0.0, SurfaceClass.GROUND, Material.SAND),
                (QUAY_H, SurfaceClass.GROUND, Material.CONCRETE),
                (0.0, SurfaceClass.GROUND, Material.CONCRETE),
                (ROCKS_H, SurfaceClass.GROUND, Material.GRAVEL),
                (0.05, SurfaceClass.GRASS, Material.GRASS),
                (SIDEWALK_H, SurfaceClass.SIDEWALK, Material.PAVING),
                (0.0, SurfaceClass.ROAD, Material.ASPHALT),
                (SIDEWALK_H, SurfaceClass.SIDEWALK, Material.PAVING),
            ]
            which = np.select(conds, list(range(len(conds))), default=-1)
            on = which >= 0
            k = which[on]
            g.height[i0:i1][on] = np.array([t[0] for t in table], np.float32)[k]
            g.cls[i0:i1][on] = np.array([int(t[1]) for t in table], np.uint8)[k]
            g.mat[i0:i1][on] = np.array([int(t[2]) for t in table], np.uint8)[k]
        self._shore_road()

    def _shore_road(self) -> None:
        """The shore road's dashed centre line, a lane each way and people on the promenade."""
        s = np.arange(-self.half - 10.0, self.half + 10.0, 4.0)
        mid = self.front_m + self.prom_m + self.road_m / 2
        centre = self._inland(s, mid)
        for a, b in zip(centre[:-1:2], centre[1::2], strict=False):  # 2 m dashes every 8 m
            self.grid.fill_polyline([(a[0], a[1]), ((a[0] + b[0]) / 2, (a[1] + b[1]) / 2)], 0.25,
                                    cls=SurfaceClass.ROAD, mat=Material.LANE_MARKING)  # fmt: skip
        for sign in (1.0, -1.0):
            pts = self._pts(self._inland(s, mid + sign * self.road_m / 4))
            if len(pts) >= 2:
                lane = pts if sign > 0 else pts[::-1]
                self.lanes.append(Lane(lane, (8.0, 13.0), self._u((3.0, 8.0))))
        at = -self.half + self._u((0.0, 60.0))
        while at < self.half - 20.0:  # strollers on the promenade, in stretches of about 100 m
            stretch = np.arange(at, at + self._u((80.0, 120.0)), 4.0)
            pts = self._pts(self._inland(stretch, self.front_m + self.prom_m / 2), 1.0)
            if len(pts) >= 2 and self.rng.random() < 0.8:
                self.walkways.append(
                    Walkway(pts, int(self.rng.integers(3, 8)), SIDEWALK_H, 0.8 * self.prom_m)
                )
            at = float(stretch[-1]) + 4.0
        self._promenade_furniture()

    def _promenade_furniture(self) -> None:
        """Benches facing the water along the promenade's town side, lamp posts along its water side."""
        g = self.grid
        s = -self.half + self._u((5.0, 15.0))
        while s < self.half - 5.0:
            (bn, be), yaw = (
                self._inland(np.array([s]), self.front_m + self.prom_m - 1.0)[0],
                self._yaw_along(s),
            )
            g.fill_rect((float(bn), float(be)), 1.8, 0.6, yaw, height_m=SIDEWALK_H + 0.45,
                        cls=SurfaceClass.GROUND, mat=Material.WOOD)  # fmt: skip
            s += self._u((12.0, 22.0))
        lamp = self._line_w(0.25)
        for s in np.arange(-self.half + self._u((0.0, 25.0)), self.half, 25.0):
            (ln, le) = self._inland(np.array([s]), self.front_m + 0.6)[0]
            g.fill_rect((float(ln), float(le)), lamp, lamp, 0.0, height_m=4.5, cls=SurfaceClass.GROUND,
                        mat=Material.METAL)  # fmt: skip

    # ------------------------------------------------------------------ the beach and the lawns
    def _paint_beach(self) -> None:
        """Umbrellas, sunbathers, kiosks; people along the waterline, paddling and crossing the sand."""
        g = self.grid
        b0, b1 = self.beach
        f = self.front_m
        area = (b1 - b0) * f

        def spot(d_lo: float, d_hi: float) -> tuple[float, float, float]:
            s = self._u((b0 + 4.0, b1 - 4.0))
            n, e = self._inland(np.array([s]), self._u((d_lo, d_hi)))[0]
            return float(n), float(e), s

        for _ in range(round(area * UMBRELLA_PER_M2)):
            n, e, _s = spot(8.0, f - 6.0)
            r = self._u((1.0, 1.4))
            g.fill_disc((n, e), r, height_m=self._u((2.0, 2.4)), cls=SurfaceClass.GROUND, mat=Material.CLOTH,
                        mode="max")  # fmt: skip
            if self.rng.random() < 0.7:  # its owners, lying or standing beside it
                beside = self._clip_pt((n + r + 0.8, e), 1.0)
                self.walkways.append(Walkway((beside,), int(self.rng.integers(1, 4)), 0.0, 2.5))
        for _ in range(round(area * SUNBATHERS_PER_M2)):
            n, e, _s = spot(4.0, f - 4.0)
            width = self._u((2.0, 4.0))
            self.walkways.append(
                Walkway((self._clip_pt((n, e), 1.0),), int(self.rng.integers(1, 5)), 0.0, width)
            )
        for _ in range(int(self.rng.integers(2, 5))):  # kiosks and beach huts by the promenade
            _n, _e, s = spot(0.0, 0.0)
            n, e = self._inland(np.array([s]), f - 4.0)[0]
            yaw, rid = self._yaw_along(s), self._new_region()
            g.fill_rect((float(n), float(e)), 4.4, 3.4, yaw, height_m=2.4, cls=SurfaceClass.ROOF_PITCHED,
                        mat=Material.WOOD, region=rid)  # fmt: skip
            g.fill_pitched((float(n), float(e)), 4.4, 3.4, yaw, 2.4, 3.3, region=rid,
                           mat=Material.CORRUGATED)  # fmt: skip
        at = b0
        while at < b1 - 20.0:  # walkers along the waterline, on the wet sand
            stretch = np.arange(at, min(at + self._u((80.0, 120.0)), b1), 4.0)
            pts = self._pts(self._inland(stretch, self._u((1.5, 3.5))), 1.0)
            if len(pts) >= 2:
                self.walkways.append(Walkway(pts, int(self.rng.integers(2, 6)), 0.0, 3.0))
            at = float(stretch[-1]) + 4.0
        for _ in range(max(1, round((b1 - b0) / 60.0))):  # paddlers pottering at the water's edge
            s = self._u((b0 + 5.0, b1 - 10.0))
            pts = self._pts(self._inland(np.array([s, s + self._u((4.0, 8.0))]), self._u((0.8, 2.5))), 1.0)
            if len(pts) == 2:
                self.walkways.append(Walkway(pts, int(self.rng.integers(1, 3)), 0.0, 2.0))
        for s in np.arange(b0 + self._u((10.0, 40.0)), b1 - 5.0, self._u((40.0, 70.0))):  # down to the water
            pts = self._pts(self._inland(np.array([s, s]), np.array([f - 1.0, 2.0])), 1.0)
            if len(pts) == 2:
                self.walkways.append(Walkway(pts, int(self.rng.integers(1, 3)), 0.0, 2.0))

    def _paint_lawns(self) -> None:
        """The lawns behind the rocks, off the beach and the marina: trees, and people crossing them."""
        zones = self._zone_of(self.s_tab)
        for s in np.arange(-self.half + self._u((5.0, 30.0)), self.half, self._u((25.0, 40.0))):
            if zones[int(np.searchsorted(self.s_tab, s))] != 0:
                continue
            if self.rng.random() < 0.6:
                n, e = self._inland(np.array([s]), self._u((ROCKS_M + 5.0, self.front_m - 5.0)))[0]
                self.grid.fill_disc((float(n), float(e)), self._u((2.0, 4.0)), height_m=self._u((5.0, 10.0)),
                                    dome=True, cls=SurfaceClass.TREE, mat=Material.FOLIAGE,
                                    mode="max")  # fmt: skip
            if self.rng.random() < 0.35:  # from the promenade to the rocks and back
                pts = self._pts(self._inland(np.array([s, s + self._u((-15.0, 15.0))]),
                                             np.array([self.front_m, ROCKS_M + 1.0])), 1.0)  # fmt: skip
                if len(pts) == 2:
                    self.walkways.append(Walkway(pts, int(self.rng.integers(1, 4)), 0.05, 2.0))
