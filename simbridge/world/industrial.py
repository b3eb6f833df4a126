"""A procedural industrial estate, generated from a seed: big flat roofs, yards and a railway.

The plan is not the downtown grid's: north-south spine roads cross the whole estate 100-260 m apart,
and each strip between two spines has access roads of its own that end at the spines (T-junctions,
staggered from strip to strip); a railway runs north-south on its own corridor. The plots between the
roads are divided into one to three premises, each with

- a shed of 35-70 % of its ground, 7-16 m high, under one flat roof (membrane, seam metal or concrete)
  with rows of skylights, HVAC units, sometimes solar arrays over most of it, and now and then a low
  parapet; about a quarter of the roofs are left bare, the estate's clear landing sites;
- a yard of concrete: lorries at loading docks, shipping containers stacked one to three high, stacks of
  pallets and material (``MACHINERY``), a few parked vans;
- a car park with marked bays and parked cars (:meth:`~simbridge.world.city_props.Props._paint_bays`);
- grass verges along the roads, with trees now and then.

Lorries use the roads (``Lane``\\ s, slow and sparse); workers walk the footpaths and cross the yards
and car parks (``Walkway``\\ s on open ground). Everything comes from one ``np.random.default_rng(seed)``
threaded through the build, so a seed always gives identical rasters, lanes and walkways. The painting
helpers, the rooftop clutter and the car parks are the downtown city's (:mod:`simbridge.world.city_parts`,
:mod:`~simbridge.world.city_buildings`, :mod:`~simbridge.world.city_props`).
"""

from __future__ import annotations

import itertools
import math

import numpy as np

from simbridge.world.city_buildings import Buildings
from simbridge.world.city_parts import CityParams, Range, Roof, check_place_request
from simbridge.world.city_props import Props
from simbridge.world.model import Material, SurfaceClass
from simbridge.world.world import Lane, Walkway, World

__all__ = ["generate_industrial"]

ROAD_W_M: Range = (10.0, 14.0)  # carriageway, kerb to kerb
FOOTPATH_W_M = 2.0
RAIL_CORRIDOR_W_M = 14.0  # two tracks and their ballast
TRACK_GAUGE_M = 1.435
PLOT_M: Range = (100.0, 260.0)
CONTAINER_L_M = (6.06, 12.19)  # twenty- and forty-foot boxes
CONTAINER_W_M, CONTAINER_H_M = 2.44, 2.59
LORRY_L_M, LORRY_W_M, LORRY_H_M = 16.5, 2.55, 4.0
CLEAR_ROOF_FRACTION = 0.25
SOLAR_FRACTION = 0.3
PARAPET_FRACTION = 0.35


class _EstateBuilder(Props, Buildings):
    """Builds one estate from its seed; the downtown parts lend their painting helpers."""

    def build(self, seed: int) -> World:
        spines = self._road_lines()  # north-south, across the whole estate
        rail_e = self._rail_line(spines)
        for centre, width in spines:
            self._road((-self.half, centre), (self.half, centre), width)
        self._rail((-self.half, rail_e), (self.half, rail_e))
        n_roads = len(spines)
        # each strip between the spines has access roads of its own, staggered against its neighbours'
        # (T-junctions, not a grid): east-west roads that end at the spines on either side
        for e0, e1 in self._gaps(spines, [(rail_e, RAIL_CORRIDOR_W_M)]):
            access = self._road_lines()
            n_roads += len(access)
            for centre, width in access:
                self._road((centre, e0), (centre, e1), width)
            for n0, n1 in self._gaps(access, []):
                self._plot(n0, n1, e0, e1)
        sun = self._sun((30.0, 65.0))
        desc = (
            f"procedural industrial estate (seed {seed}): {n_roads} roads, a railway, "
            f"{self.n_buildings} sheds, {len(self.clear_roofs)} clear roofs"
        )
        return self._world("industrial", seed, sun, desc)

    # ------------------------------------------------------------------ the plan
    def _road_lines(self) -> list[tuple[float, float]]:
        """(centre, carriageway width) of the roads along one axis, plots of ``PLOT_M`` between them."""
        out = []
        x = -self.half + self._u(PLOT_M) / 2
        while x < self.half - 40.0:
            out.append((x, self._u(ROAD_W_M)))
            x += self._u(PLOT_M)
        return out

    def _rail_line(self, roads: list[tuple[float, float]]) -> float:
        """The railway's east coordinate: inside a plot, away from the roads running beside it."""
        for _ in range(50):
            e = float(self.rng.uniform(-0.35, 0.35)) * self.size
            if all(abs(e - c) > w / 2 + RAIL_CORRIDOR_W_M + 20.0 for c, w in roads):
                return e
        return float(roads[0][0] + roads[0][1] / 2 + RAIL_CORRIDOR_W_M + 20.0)

    def _gaps(self, lines: list[tuple[float, float]], extra: list[tuple[float, float]]) -> list[Range]:
        """The stretches between the roads (and the railway's corridor) across the estate."""
        cuts = sorted((c - w / 2 - FOOTPATH_W_M, c + w / 2 + FOOTPATH_W_M) for c, w in [*lines, *extra])
        edges = [-self.half, *[v for cut in cuts for v in cut], self.half]
        return [(a, b) for a, b in zip(edges[::2], edges[1::2], strict=True) if b - a >= 30.0]

    def _road(self, a: tuple[float, float], b: tuple[float, float], width: float) -> None:
        """A two-lane road with a dashed centre line, footpaths and lorries in both directions."""
        g = self.grid
        g.fill_polyline([a, b], width + 2 * FOOTPATH_W_M, height_m=0.15, cls=SurfaceClass.SIDEWALK,
                        mat=Material.PAVING)  # fmt: skip
        g.fill_polyline([a, b], width, height_m=0.0, cls=SurfaceClass.ROAD, mat=Material.ASPHALT)
        along_n = abs(b[0] - a[0]) > abs(b[1] - a[1])
        length = math.dist(a, b)
        for k in range(int(length // 9.0)):  # 3 m dashes, 6 m gaps
            t0, t1 = k * 9.0 / length, (k * 9.0 + 3.0) / length
            p0 = (a[0] + (b[0] - a[0]) * t0, a[1] + (b[1] - a[1]) * t0)
            p1 = (a[0] + (b[0] - a[0]) * t1, a[1] + (b[1] - a[1]) * t1)
            g.fill_polyline([p0, p1], self._line_w(0.15), mat=Material.LANE_MARKING)
        off = width / 4
        for sign in (1.0, -1.0):
            shift = (0.0, sign * off) if along_n else (sign * off, 0.0)
            ends = [self._clip_pt((p[0] + shift[0], p[1] + shift[1]), 1.0) for p in (a, b)]
            pts = tuple(ends if sign > 0 else ends[::-1])
            self.lanes.append(Lane(pts, (6.0, 12.0), self._u((1.0, 4.0))))
        side = (width / 2 + FOOTPATH_W_M / 2) * (1.0 if self.rng.random() < 0.5 else -1.0)
        shift = (0.0, side) if along_n else (side, 0.0)
        walk = tuple(self._clip_pt((p[0] + shift[0], p[1] + shift[1]), 1.0) for p in (a, b))
        self.walkways.append(Walkway(walk, int(self.rng.integers(2, 6)), 0.15, FOOTPATH_W_M))

    def _rail(self, a: tuple[float, float], b: tuple[float, float]) -> None:
        """Two tracks on ballast in a fenced-off gravel corridor."""
        g = self.grid
        g.fill_polyline([a, b], RAIL_CORRIDOR_W_M, height_m=0.0, cls=SurfaceClass.GROUND, mat=Material.SOIL)
        for track in (-2.25, 2.25):
            pa, pb = ((p[0], p[1] + track) for p in (a, b))
            g.fill_polyline([pa, pb], 3.2, height_m=0.3, cls=SurfaceClass.RAIL, mat=Material.GRAVEL)
            for rail in (-TRACK_GAUGE_M / 2, TRACK_GAUGE_M / 2):
                ra, rb = ((p[0], p[1] + rail) for p in (pa, pb))
                g.fill_polyline([ra, rb], self._line_w(0.1), height_m=0.45, cls=SurfaceClass.RAIL,
                                mat=Material.METAL)  # fmt: skip

    # ------------------------------------------------------------------ premises
    def _plot(self, n0: float, n1: float, e0: float, e1: float) -> None:
        """A plot between the roads: one to three premises side by side along its longer side."""
        along_n = (n1 - n0) >= (e1 - e0)
        span = (n1 - n0) if along_n else (e1 - e0)
        parts = max(1, min(3, int(span // 70.0), int(self.rng.integers(1, 4))))
        cuts = np.sort(self.rng.uniform(0.3, 0.7, parts - 1)) if parts > 1 else np.array([])
        edges = [0.0, *cuts.tolist(), 1.0]
        for a, b in itertools.pairwise(edges):
            if along_n:
                self._premises(n0 + a * span, n0 + b * span, e0, e1)
            else:
                self._premises(n0, n1, e0 + a * span, e0 + b * span)

    def _premises(self, n0: float, n1: float, e0: float, e1: float) -> None:
        """Verge, shed, yard and car park of one business, fenced off from its neighbours."""
        if min(n1 - n0, e1 - e0) < 25.0:
            self._fill(n0, n1, e0, e1, 0.05, SurfaceClass.GRASS, Material.GRASS)
            return
        verge = self._u((3.0, 6.0))
        self._fill(n0, n1, e0, e1, 0.05, SurfaceClass.GRASS, Material.GRASS)
        for _ in range(int(self.rng.integers(0, 4))):  # trees on the verge
            cn, ce = self._edge_point(n0, n1, e0, e1, verge / 2)
            self.grid.fill_disc((cn, ce), self._u((2.0, 4.0)), height_m=self._u((6.0, 11.0)), dome=True,
                                cls=SurfaceClass.TREE, mat=Material.FOLIAGE, mode="max")  # fmt: skip
        n0, n1, e0, e1 = n0 + verge, n1 - verge, e0 + verge, e1 - verge
        self._fill(n0, n1, e0, e1, 0.0, SurfaceClass.GROUND, Material.CONCRETE)
        along_n = (n1 - n0) >= (e1 - e0)
        span = (n1 - n0) if along_n else (e1 - e0)
        shed = self._u((0.35, 0.7)) * span
        park = min(self._u((0.12, 0.25)) * span, 40.0)

        def band(a: float, b: float) -> tuple[float, float, float, float]:
            return (n0 + a, n0 + b, e0, e1) if along_n else (n0, n1, e0 + a, e0 + b)

        self._shed(*band(0.0, shed))
        if span - shed - park >= 15.0:
            self._yard(*band(shed, span - park))
            self._car_park(*band(span - park, span))
        else:
            self._yard(*band(shed, span))

    def _edge_point(self, n0: float, n1: float, e0: float, e1: float, inset: float) -> tuple[float, float]:
        """A point ``inset`` in from a random side of the box."""
        side = int(self.rng.integers(0, 4))
        t = float(self.rng.uniform(0.1, 0.9))
        if side < 2:
            return (n0 + inset if side == 0 else n1 - inset, e0 + t * (e1 - e0))
        return (n0 + t * (n1 - n0), e0 + inset if side == 2 else e1 - inset)

    def _shed(self, n0: float, n1: float, e0: float, e1: float) -> None:
        """A flat-roofed shed: skylights and HVAC, solar arrays or a bare roof."""
        inset = 2.0
        n0, n1, e0, e1 = n0 + inset, n1 - inset, e0 + inset, e1 - inset
        if min(n1 - n0, e1 - e0) < 10.0:
            return
        h = self._u((7.0, 16.0))
        rid = self._new_region()
        self.n_buildings += 1
        mat = (Material.MEMBRANE, Material.SEAM_METAL, Material.CONCRETE)[int(self.rng.integers(0, 3))]
        self._fill(n0, n1, e0, e1, h, SurfaceClass.ROOF_FLAT, mat, rid)
        margin = 0.5
        if self.rng.random() < PARAPET_FRACTION:
            pw = 0.4
            sides = ((n0, n0 + pw, e0, e1), (n1 - pw, n1, e0, e1))
            for box in (*sides, (n0, n1, e0, e0 + pw), (n0, n1, e1 - pw, e1)):
                self._fill(*box, h + 0.6, SurfaceClass.PARAPET, Material.CONCRETE)
            margin = pw + 1.0
        roof = Roof(rid, n0, n1, e0, e1, h, margin)
        x = self.rng.random()
        if x < CLEAR_ROOF_FRACTION:
            self.clear_roofs.append(roof)
            return
        zone = (n0 + margin, n1 - margin, e0 + margin, e1 - margin)
        if x < CLEAR_ROOF_FRACTION + SOLAR_FRACTION:
            f = self._u((0.5, 0.9))
            self._solar(zone[0], zone[0] + f * (zone[1] - zone[0]), zone[2], zone[3], h)
        self._skylights(zone, h)
        self._paint_clutter(roof, zone, 0.004)

    def _skylights(self, zone: tuple[float, float, float, float], h: float) -> None:
        """Rows of glazed roof lights, 1.5-2.5 m wide, every 8-14 m across the roof."""
        zn0, zn1, ze0, ze1 = zone
        if self.rng.random() < 0.4:
            return
        pitch, w = self._u((8.0, 14.0)), self._u((1.5, 2.5))
        along_n = (zn1 - zn0) >= (ze1 - ze0)
        x = (ze0 if along_n else zn0) + pitch / 2
        stop = ze1 if along_n else zn1
        while x + w < stop:
            box = (zn0 + 2.0, zn1 - 2.0, x, x + w) if along_n else (x, x + w, ze0 + 2.0, ze1 - 2.0)
            self._fill(*box, h + 0.4, SurfaceClass.ROOF_CLUTTER, Material.GLASS)
            x += pitch

    def _yard(self, n0: float, n1: float, e0: float, e1: float) -> None:
        """Lorries, container stacks and material on concrete; workers crossing it."""
        area = (n1 - n0) * (e1 - e0)
        g = self.grid
        for _ in range(int(area // 900.0) + int(self.rng.integers(0, 3))):
            kind = self.rng.random()
            yaw = 0.0 if self.rng.random() < 0.5 else math.pi / 2
            if kind < 0.35:
                length, width, height, cls, mat = (
                    LORRY_L_M, LORRY_W_M, LORRY_H_M, SurfaceClass.VEHICLE, Material.CAR_PAINT
                )  # fmt: skip
            elif kind < 0.75:
                tiers = int(self.rng.integers(1, 4))
                length = CONTAINER_L_M[int(self.rng.integers(0, 2))]
                width, height, cls, mat = (
                    CONTAINER_W_M, tiers * CONTAINER_H_M, SurfaceClass.MACHINERY, Material.CORRUGATED
                )  # fmt: skip
            else:
                length, width = self._u((2.0, 8.0)), self._u((1.2, 4.0))
                height, cls, mat = self._u((1.0, 3.0)), SurfaceClass.MACHINERY, Material.WOOD
            half = max(length, width) / 2 + 1.0
            if n1 - n0 <= 2 * half or e1 - e0 <= 2 * half:
                continue
            cn = float(self.rng.uniform(n0 + half, n1 - half))
            ce = float(self.rng.uniform(e0 + half, e1 - half))
            g.fill_rect((cn, ce), length, width, yaw, height_m=height, cls=cls, mat=mat, mode="max")
        if self.rng.random() < 0.6:  # a worker's way across the yard
            a = self._clip_pt((n0 + 2.0, e0 + 2.0), 1.0)
            b = self._clip_pt((n1 - 2.0, e1 - 2.0), 1.0)
            self.walkways.append(Walkway((a, b), int(self.rng.integers(1, 4)), 0.0, 2.0))

    def _car_park(self, n0: float, n1: float, e0: float, e1: float) -> None:
        """Marked bays with parked cars, and people walking between them and the shed."""
        self._fill(n0, n1, e0, e1, 0.0, SurfaceClass.PARKING_LOT, Material.ASPHALT)
        self._paint_bays(n0, n1, e0, e1, 0.0, SurfaceClass.PARKING_LOT)
        cn, ce = (n0 + n1) / 2, (e0 + e1) / 2
        a, b = self._clip_pt((n0 + 1.0, ce), 1.0), self._clip_pt((n1 - 1.0, ce), 1.0)
        if (n1 - n0) < (e1 - e0):
            a, b = self._clip_pt((cn, e0 + 1.0), 1.0), self._clip_pt((cn, e1 - 1.0), 1.0)
        self.walkways.append(Walkway((a, b), int(self.rng.integers(1, 4)), 0.0, 2.0))


def generate_industrial(seed: int, size_m: float = 1200.0, res: float = 0.2) -> World:
    """Build a procedural industrial estate, identical for identical arguments.

    Args:
        seed: non-negative integer seeding the one ``np.random.Generator`` used for everything.
        size_m: side of the square estate in metres; the grid spans north and east ``[-size_m/2, size_m/2]``.
        res: grid resolution in metres per cell.

    Returns:
        A :class:`World` named ``"industrial"``: the painted grid, lorry lanes along the roads and
        walkways on the footpaths, across yards and car parks.

    Raises:
        CityError: a negative seed or an estate smaller than 300 m.
    """
    check_place_request("estate", seed, size_m)
    params = CityParams(parked_occupancy=(0.3, 0.7))
    return _EstateBuilder(int(seed), float(size_m), res, params).build(int(seed))
