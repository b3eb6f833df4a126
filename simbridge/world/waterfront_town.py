"""The seaside town behind the shore road: terrace streets that follow the shoreline (their curves
flattening the farther inland they lie), cross streets square to the shore that end at the shore road,
and blocks between them of mixed buildings (flat roofs clear or cluttered, pitched roofs), hotels with
big flat roofs and garden pools on the first row, a park and a car park.
"""

from __future__ import annotations

import itertools

import numpy as np

from simbridge.world.city_buildings import Buildings
from simbridge.world.city_parts import SIDEWALK_H, Range, Roof
from simbridge.world.model import Material, SurfaceClass
from simbridge.world.waterfront_marina import MarinaParts
from simbridge.world.world import Lane, Walkway

TERRACE_DEPTH_M: Range = (55.0, 85.0)  # lots between two terrace streets
STREET_W_M: Range = (7.0, 9.0)
TOWN_SIDEWALK_M = 2.5
CROSS_GAP_M: Range = (90.0, 150.0)
FLATTEN = 0.6  # each terrace street keeps this share of the curve of the one in front of it
LOT_W_M: Range = (12.0, 28.0)
HOTEL_FRACTION = 0.35  # of first-row blocks
HOTEL_H_M: Range = (18.0, 40.0)


class TownParts(MarinaParts, Buildings):
    """The town's streets, blocks and buildings; :class:`Buildings` paints the buildings."""

    def _paint_town(self) -> tuple[int, int]:
        """Every street and block behind the shore road; (terrace streets, cross streets)."""
        s = np.arange(-self.half - 20.0, self.half + 20.0 + 1e-6, 2.0)
        front = self._inland(self.s_tab, self.town_d + 1.0)
        fs, fx = self._sx(front[:, 0], front[:, 1])
        front_x = np.interp(s, fs, fx)  # where the town's land begins, across the shore
        dev = front_x - float(np.median(front_x))
        lines: list[tuple[np.ndarray, float]] = [(front_x, 0.0)]  # (across per s, half the street's width)
        base = float(np.median(front_x))
        k = 1
        while True:
            width = self._u(STREET_W_M)
            base -= self._u(TERRACE_DEPTH_M) + width + 2 * TOWN_SIDEWALK_M
            centre = base + FLATTEN**k * dev
            if centre.max() < -self.half + 10.0:
                break
            lines.append((centre, width / 2 + TOWN_SIDEWALK_M))
            self._street([self._ne(a, b) for a, b in zip(s, centre, strict=True)], width)
            k += 1
        cross: list[tuple[float, float]] = []
        at = -self.half + self._u((40.0, 120.0))
        while at < self.half - 40.0:
            cross.append((at, self._u(STREET_W_M)))
            at += self._u(CROSS_GAP_M)
        for c, width in cross:
            top = float(np.interp(c, s, front_x)) + TOWN_SIDEWALK_M + 1.0  # through the sidewalk
            self._street([self._ne(c, top), self._ne(c, -self.half - 5.0)], width, traffic=False)
        edges = [(-self.half, 0.0), *((c, w / 2 + TOWN_SIDEWALK_M) for c, w in cross), (self.half, 0.0)]
        park_budget, car_park_budget = 2, 2
        for row in range(len(lines)):
            hi_x, hi_off = lines[row]
            lo_x, lo_off = lines[row + 1] if row + 1 < len(lines) else (np.full_like(s, -self.half), 0.0)
            for (a, a_off), (b, b_off) in itertools.pairwise(edges):
                s0, s1 = a + a_off, b - b_off
                if s1 - s0 < 15.0:
                    continue
                span = (s >= s0) & (s <= s1)
                hi, lo = hi_x - hi_off, lo_x + lo_off
                x_hi, x_lo = float(hi[span].min()), float(lo[span].max())
                if x_hi - x_lo < 12.0:
                    continue
                x = self.rng.random()
                if row == 0 and x < HOTEL_FRACTION:
                    self._hotels(s0, s1, x_lo, x_hi)
                elif row > 0 and park_budget and x < 0.12:
                    park_budget -= 1
                    self._paint_park(*self._ne_box(s0, s1, x_lo, x_hi))
                elif car_park_budget and x > 0.93:
                    car_park_budget -= 1
                    box = self._ne_box(s0, s1, x_lo, x_hi)
                    self._fill(*box, 0.0, SurfaceClass.PARKING_LOT, Material.ASPHALT)
                    self._paint_bays(*box, 0.0, SurfaceClass.PARKING_LOT)
                else:
                    self._lots(s, s0, s1, hi, lo)
        return len(lines) - 1, len(cross)

    def _street(self, pts: list[tuple[float, float]], width: float, traffic: bool = True) -> None:
        """A town street: sidewalks both sides, light traffic each way, people here and there."""
        g = self.grid
        g.fill_polyline(pts, width + 2 * TOWN_SIDEWALK_M, height_m=SIDEWALK_H, cls=SurfaceClass.SIDEWALK,
                        mat=Material.PAVING)  # fmt: skip
        g.fill_polyline(pts, width, height_m=0.0, cls=SurfaceClass.ROAD, mat=Material.ASPHALT)
        arr = np.asarray(pts)
        d = np.gradient(arr, axis=0)
        nrm = np.stack([-d[:, 1], d[:, 0]], axis=1) / np.hypot(d[:, 0], d[:, 1])[:, None]
        if traffic:
            for sign in (1.0, -1.0):
                lane = self._pts(arr + nrm * (sign * width / 4))
                if len(lane) >= 2:
                    self.lanes.append(
                        Lane(lane if sign > 0 else lane[::-1], (5.0, 10.0), self._u((0.5, 2.0)))
                    )
        for sign in (1.0, -1.0):
            walk = arr + nrm * (sign * (width / 2 + TOWN_SIDEWALK_M / 2))
            for k in range(0, len(walk) - 5, 50):  # stretches of about 100 m
                chunk = self._pts(walk[k : k + 51], 1.0)
                if len(chunk) >= 2 and self.rng.random() < 0.3:
                    count = int(self.rng.integers(1, 5))
                    self.walkways.append(Walkway(chunk, count, SIDEWALK_H, TOWN_SIDEWALK_M))

    def _lots(self, s: np.ndarray, s0: float, s1: float, hi: np.ndarray, lo: np.ndarray) -> None:
        """Lots side by side along the block, each as deep as the streets on either side allow: a
        building (two, one behind the other, on a deep lot), now and then a garden."""
        a = s0
        while a < s1 - 8.0:
            b = min(a + self._u(LOT_W_M), s1)
            if s1 - b < 8.0:
                b = s1
            span = (s >= a - 2.0) & (s <= b + 2.0)
            x_hi = float(hi[span].min()) - self._u((0.5, 4.0))
            x_lo = float(lo[span].max()) + self._u((0.5, 3.0))
            gap = self._u((0.0, 2.0))
            if x_hi - x_lo >= 10.0:
                if self.rng.random() < 0.08:
                    self._garden(*self._ne_box(a + gap, b - gap, x_lo, x_hi))
                elif x_hi - x_lo > 45.0:
                    cut = x_hi - self._u((14.0, 25.0))
                    self._paint_building(*self._ne_box(a + gap, b - gap, cut, x_hi))
                    if self.rng.random() < 0.5:
                        self._paint_building(
                            *self._ne_box(a + gap, b - gap, x_lo, cut - self._u((4.0, 12.0)))
                        )
                    else:
                        self._garden(*self._ne_box(a + gap, b - gap, x_lo, cut - 1.0))
                else:
                    self._paint_building(*self._ne_box(a + gap, b - gap, x_lo, x_hi))
            a = b

    def _garden(self, n0: float, n1: float, e0: float, e1: float) -> None:
        self._fill(n0, n1, e0, e1, 0.05, SurfaceClass.GRASS, Material.GRASS)
        if min(n1 - n0, e1 - e0) > 8.0 and self.rng.random() < 0.6:
            centre = ((n0 + n1) / 2, (e0 + e1) / 2)
            self.grid.fill_disc(centre, self._u((2.0, 3.5)), height_m=self._u((5.0, 10.0)), dome=True,
                                cls=SurfaceClass.TREE, mat=Material.FOLIAGE, mode="max")  # fmt: skip

    def _hotels(self, s0: float, s1: float, x_lo: float, x_hi: float) -> None:
        """One or two hotels facing the sea: tall, flat-roofed (about half the roofs bare), a paved
        forecourt in front and a garden with a pool behind."""
        self._fill(*self._ne_box(s0, s1, x_lo, x_hi), SIDEWALK_H, SurfaceClass.SIDEWALK, Material.PAVING)
        depth = min(self._u((15.0, 25.0)), x_hi - x_lo - 4.0)
        a = s0 + 2.0
        while a < s1 - 20.0:
            b = min(a + self._u((30.0, 60.0)), s1 - 2.0)
            h = self._u(HOTEL_H_M)
            rid = self._new_region()
            self.n_buildings += 1
            top = x_hi - 3.0
            n0, n1, e0, e1 = self._ne_box(a, b, top - depth, top)
            self._fill(n0, n1, e0, e1, h + 1.0, SurfaceClass.PARAPET, Material.CONCRETE, rid)
            pw = self._line_w(0.4)
            self._fill(n0 + pw, n1 - pw, e0 + pw, e1 - pw, h, SurfaceClass.ROOF_FLAT, Material.MEMBRANE, rid)
            roof = Roof(rid, n0, n1, e0, e1, h, pw + 0.5)
            zone = (n0 + roof.margin, n1 - roof.margin, e0 + roof.margin, e1 - roof.margin)
            if self.rng.random() < 0.5:
                self.clear_roofs.append(roof)
            else:
                self._paint_clutter(roof, zone, 0.01)
            garden = top - depth - 2.0
            if garden - x_lo > 12.0:
                self._fill(*self._ne_box(a, b, x_lo, garden), 0.05, SurfaceClass.GRASS, Material.GRASS)
                if self.rng.random() < 0.6 and b - a > 16.0:
                    pn0, pn1, pe0, pe1 = self._ne_box(
                        a + 4.0, min(a + 16.0, b - 4.0), garden - 10.0, garden - 3.0
                    )
                    self._fill(pn0, pn1, pe0, pe1, -1.2, SurfaceClass.WATER, Material.POOL)
            a = b + self._u((6.0, 15.0))
