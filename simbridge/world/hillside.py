"""A procedural hillside village, generated from a seed: houses, gardens and terraced fields on the
sides of a valley, where the ground itself is not level and "ground level" is not one height.

The relief (:func:`~simbridge.world.relief.make_relief`) is a valley across the square, its floor near
0 m, its sides rising 30-80 m on either hand in slopes of 5-30 degrees broken by flatter benches, with
bumps, spurs and gullies on them. A road runs along the valley floor beside a stream, and a few narrow
roads climb the sides in switchbacks; every road is cut level across its width, with cuttings and
embankments beside it. The village lies round the launch point: a square and a sports ground on
levelled benches, a few larger buildings (hall, school, church: pitched or flat roofs) on platforms,
and lots along the roads, each levelled into a platform with retaining walls at its edges, holding a
house under a pitched roof with its garden, driveway, cars, now and then a pool or a shed. Terraced
fields and gardens (level strips behind retaining walls of 1-3 m) climb the moderate slopes; woods
cover the steep upper ones; meadow and scattered trees are the rest. Cars drive every road and people
walk the valley road's sidewalks, the climbing roads' edges, the square and the sports ground, all
standing on the sloped ground (:class:`~simbridge.world.world.Lane` and
:class:`~simbridge.world.world.Walkway` ``heights_m``).

Everything is painted as if flat (heights up from the local ground, as in the suburb) while the ground
raster is shaped beside it; :func:`~simbridge.world.relief.lay_over` sets the one on the other at the
end. One ``np.random.default_rng(seed)`` is threaded through the whole build.
"""

from __future__ import annotations

import math

import numpy as np

from simbridge.world.city_buildings import Buildings
from simbridge.world.city_parts import SIDEWALK_H, CityError, CityParams, check_place_request
from simbridge.world.farmland_plan import CROP_H_M, crop_canopy
from simbridge.world.hillside_roads import HillRoad, HillsideRoads
from simbridge.world.model import Material, SurfaceClass
from simbridge.world.relief import ReliefParams, lay_over, level_rect, make_relief
from simbridge.world.suburb_lots import Lot
from simbridge.world.suburb_plan import Pt, as_pts
from simbridge.world.world import Walkway, World

__all__ = ["CityError", "generate_hillside"]

VILLAGE_R_M = 380.0  # lots and the village's sites lie this close to the village centre
LOT_RISE_M = 6.0  # a lot is taken where the relief under it varies by at most this much
SITE_RISE_M = 6.0
TERRACE_WALL_M = (1.0, 3.0)
TERRACE_SLOPE_DEG = (8.0, 26.0)
WOODS_SLOPE_DEG = 15.0
WOODS_ABOVE_M = 25.0  # woods on slopes steeper than WOODS_SLOPE_DEG this high above the floor
TREES_PER_M2_WOODS = 1.0 / 35.0
CLUMPS_PER_M2 = 1.0 / 3000.0


# Buildings._place (roof clutter) and SuburbLots._place (a lot's boxes) share a name: the halls' roofs
# are kept clear (no clutter), so Buildings' never runs here
class _HillsideBuilder(HillsideRoads, Buildings):  # type: ignore[misc]
    """Builds one hillside village from its seed: relief, roads, sites, lots, terraces, woods."""

    def __init__(self, seed: int, size_m: float, res: float) -> None:
        super().__init__(seed, size_m, res)
        # the halls' flat roofs are clear: the city's clutter painter would reach the suburb lots' _place
        self.p = CityParams(
            height_mix=((7.0, 13.0, 1.0),), pitched_fraction=0.6, parapet_fraction=0.5,
            clear_roof_fraction=1.0, heavy_clutter_fraction=0.0,
        )  # fmt: skip
        h = self.half
        cells = max(2, round(size_m / 2.0))  # a coarse relief cell of about 2 m that fits the square
        self.relief = make_relief(self.rng, (-h, h), (-h, h), ReliefParams(res_m=size_m / cells))
        self.ground = self.relief.raster(self.grid)
        self.village: Pt = (0.0, 0.0)
        self.benches: list[tuple[Pt, float]] = []  # the levelled sites: centre and surface height
        self._lots_here = False
        self.pitch_centre: Pt | None = None  # the sports ground's centre, where there is one

    def build(self, seed: int) -> World:
        valley = self._valley_road()
        self.village = (float(self.relief.valley_at(0.0)), 0.0)
        self._stream()
        climbing = self._climbing_roads(valley, max(2, round(self.size / 300.0)))
        roads = [valley, *climbing]
        self._cut_roads(roads, "shoulders")
        self._square_and_pitch(valley)
        self._halls()
        self._lots_here = True
        self._paint_lots([r.road for r in roads])
        self._lots_here = False
        terraces = self._terraces()
        self._cut_roads(roads, "core")
        self._paint_hill_roads(valley, climbing)
        self._woods()
        for r in roads:
            self._road_traffic(r)
        lay_over(self.grid, self.ground)
        sun = self._sun((30.0, 65.0))
        z = self.relief.z
        desc = (
            f"procedural hillside village {self.size:.0f} m square, seed {seed}: relief "
            f"{float(z.min()):.0f} to {float(z.max()):.0f} m, {self.n_buildings} buildings, a valley road "
            f"and {len(climbing)} climbing roads, {terraces} terraced fields, woods on the steep slopes"
        )
        return self._world("hillside", seed, sun, desc)

    # ------------------------------------------------------------------ land
    def _rise(self, centre: Pt, length_m: float, width_m: float, yaw_rad: float) -> tuple[float, float]:
        """The relief's range and mean over a rotated rectangle (its corners, edge midpoints, centre)."""
        c, s = math.cos(yaw_rad), math.sin(yaw_rad)
        a = np.array([-0.5, 0.0, 0.5])
        uu, vv = np.meshgrid(a * length_m, a * width_m)
        z = self.relief.sample(centre[0] + uu * c - vv * s, centre[1] + uu * s + vv * c)
        return float(z.max() - z.min()), float(z.mean())

    def _rect_free(self, centre: Pt, length_m: float, width_m: float, yaw_rad: float) -> bool:
        """Free land (:meth:`SuburbPlan._rect_free`); for a lot, also near the village and on ground
        that varies by at most ``LOT_RISE_M`` under it."""
        if self._lots_here:
            if math.hypot(centre[0] - self.village[0], centre[1] - self.village[1]) > VILLAGE_R_M:
                return False
            if self._rise(centre, length_m, width_m, yaw_rad)[0] > LOT_RISE_M:
                return False
        return super()._rect_free(centre, length_m, width_m, yaw_rad)

    def _site_near(self, road: HillRoad, length_m: float, width_m: float, tries: int = 40) -> Pt | None:
        """A free axis-aligned site off ``road`` near the village whose ground varies least."""
        best: tuple[float, Pt] | None = None
        pts = road.road.points
        for _ in range(tries):
            i = int(np.argmin(np.abs(pts[:, 1] - self.village[1] - self._u((-220.0, 220.0)))))
            side = float(self.rng.choice([-1.0, 1.0]))
            centre = (float(pts[i, 0]) + side * (road.road.edge_m + 6.0 + width_m / 2), float(pts[i, 1]))
            if not super()._rect_free(centre, width_m + 8.0, length_m + 8.0, 0.0):
                continue
            rise, _ = self._rise(centre, width_m, length_m, 0.0)
            if rise <= SITE_RISE_M and (best is None or rise < best[0]):
                best = (rise, centre)
        return None if best is None else best[1]

    def _bench(self, centre: Pt, length_n: float, width_e: float, shoulder_m: float) -> float:
        """Level a site (north ``length_n`` by east ``width_e``) at the relief's mean under it, claim
        it with its shoulder; returns its height."""
        _, z = self._rise(centre, length_n, width_e, 0.0)
        level_rect(self.ground, self.grid, centre, length_n, width_e, 0.0, z, shoulder_m)
        self._claim_rect(centre, length_n + 2 * shoulder_m, width_e + 2 * shoulder_m, 0.0)
        self.benches.append((centre, z))
        return z

    # ------------------------------------------------------------------ the village
    def _stream(self) -> None:
        """A stream 3-5 m wide down the valley's lowest line, its bed 0.6 m below the banks."""
        e = np.arange(-self.half - 8.0, self.half + 8.0 + 1e-6, 4.0)
        pts = np.stack([self.relief.valley_at(e), e], axis=1)
        w = self._u((3.0, 5.0))
        self.grid.fill_polyline(as_pts(pts), w, height_m=-0.6, cls=SurfaceClass.WATER, mat=Material.WATER)
        self.claim.fill_polyline(as_pts(pts), w + 4.0, cls=SurfaceClass.GROUND)

    def _square_and_pitch(self, valley: HillRoad) -> None:
        """A paved square and a sports ground (a marked pitch) on benches off the valley road, with
        people walking on both."""
        sq = self._site_near(valley, 34.0, 30.0)
        if sq is not None:
            z = self._bench(sq, 34.0, 30.0, 4.0)
            self._fill(sq[0] - 17, sq[0] + 17, sq[1] - 15, sq[1] + 15, SIDEWALK_H, SurfaceClass.SIDEWALK,
                       Material.PAVING)  # fmt: skip
            self.grid.fill_disc(
                sq, 2.5, height_m=SIDEWALK_H + 0.5, cls=SurfaceClass.GROUND, mat=Material.BRICK
            )
            for k in range(3):
                n = sq[0] - 12.0 + 12.0 * k
                path = ((n, sq[1] - 13.0), (n, sq[1] - 4.0), (n + 2.0, sq[1] + 4.0), (n, sq[1] + 13.0))
                self.walkways.append(Walkway(path, int(self.rng.integers(2, 6)), z + SIDEWALK_H, 4.0))
        pitch = self._site_near(valley, 70.0, 46.0)
        if pitch is None:
            return
        z = self._bench(pitch, 70.0, 46.0, 5.0)
        self._fill(pitch[0] - 35, pitch[0] + 35, pitch[1] - 23, pitch[1] + 23, 0.0, SurfaceClass.GRASS,
                   Material.GRASS)  # fmt: skip
        lw = self._line_w(0.12)
        for dn, de, ln, we in ((0.0, -20.0, 60.0, lw), (0.0, 20.0, 60.0, lw), (-30.0, 0.0, lw, 40.0),
                               (30.0, 0.0, lw, 40.0), (0.0, 0.0, lw, 40.0)):  # fmt: skip
            self._fill(pitch[0] + dn - ln / 2, pitch[0] + dn + ln / 2, pitch[1] + de - we / 2,
                       pitch[1] + de + we / 2, None, None, Material.LANE_MARKING)  # fmt: skip
        pn, pe = pitch
        ring = (
            (pn - 33, pe - 22),
            (pn + 33, pe - 22),
            (pn + 33, pe + 22),
            (pn - 33, pe + 22),
            (pn - 33, pe - 22),
        )
        self.walkways.append(Walkway(ring, int(self.rng.integers(2, 8)), z, 2.0))
        self.pitch_centre = pitch

    def _halls(self) -> None:
        """Two to four larger buildings (hall, school, church) on platforms near the village centre."""
        for _ in range(int(self.rng.integers(2, 5))):
            for _try in range(30):
                dn, de = self._u((14.0, 28.0)), self._u((14.0, 26.0))
                c = (self.village[0] + self._u((-180.0, 180.0)), self.village[1] + self._u((-220.0, 220.0)))
                if (
                    super()._rect_free(c, dn + 10.0, de + 10.0, 0.0)
                    and self._rise(c, dn, de, 0.0)[0] < SITE_RISE_M
                ):
                    self._bench(c, dn + 4.0, de + 4.0, 3.0)
                    n0, n1, e0, e1 = c[0] - dn / 2, c[0] + dn / 2, c[1] - de / 2, c[1] + de / 2
                    self._fill(n0 - 2, n1 + 2, e0 - 2, e1 + 2, 0.02, SurfaceClass.GROUND, Material.CONCRETE)
                    self._paint_building(c[0] - dn / 2, c[0] + dn / 2, c[1] - de / 2, c[1] + de / 2)
                    break

    def _paint_lot(self, lot: Lot) -> None:
        """The lot's platform (level at the relief's mean under it, retaining walls at its edges),
        then the suburb's lot on it."""
        _, z = self._rise(lot.centre, lot.front_m, lot.depth_m, lot.yaw_u)
        level_rect(self.ground, self.grid, lot.centre, lot.front_m, lot.depth_m, lot.yaw_u, z, 0.0)
        super()._paint_lot(lot)

    # ------------------------------------------------------------------ terraces and woods
    def _terraces(self) -> int:
        """Terraced fields and gardens on moderate slopes: level strips along the contour, each a wall
        of 1-3 m above the one below. Returns how many were laid."""
        laid = 0
        for _ in range(int(self.rng.integers(8, 14)) * 6):
            if laid >= 10:
                break
            c = (self.village[0] + self._u((-420.0, 420.0)), self.village[1] + self._u((-500.0, 500.0)))
            g = self._gradient(np.asarray(c))
            slope = math.hypot(g[0], g[1])
            if (
                not math.tan(math.radians(TERRACE_SLOPE_DEG[0]))
                <= slope
                <= math.tan(math.radians(TERRACE_SLOPE_DEG[1]))
            ):
                continue
            up = g / slope
            yaw_up = math.atan2(up[1], up[0])
            along, depth = self._u((50.0, 110.0)), self._u((30.0, 60.0))
            if not super()._rect_free(c, depth + 4.0, along + 4.0, yaw_up):
                continue
            self._claim_rect(c, depth + 4.0, along + 4.0, yaw_up)
            step = self._u(TERRACE_WALL_M) / slope  # each strip's depth up the slope
            strips = max(2, math.floor(depth / step))
            crop = self.rng.random() < 0.6
            for k in range(strips):
                v = -depth / 2 + (k + 0.5) * depth / strips
                sc = (c[0] + up[0] * v, c[1] + up[1] * v)
                zc = float(self.relief.sample(sc[0], sc[1]))
                level_rect(self.ground, self.grid, sc, depth / strips, along, yaw_up, zc, 0.0)
                cls, mat = (
                    (SurfaceClass.CROP, Material.CROP) if crop else (SurfaceClass.GRASS, Material.GRASS)
                )
                if not crop and self.rng.random() < 0.3:
                    cls, mat = SurfaceClass.GROUND, Material.SOIL
                got = self.grid.rect_mask(sc, depth / strips - 0.5, along, yaw_up) if crop else None
                if got is not None:  # rows along the terrace, rough to a LiDAR (farmland_plan.crop_canopy)
                    win, mask, up_m, _along_m = got
                    tall = float(np.random.default_rng([*win, 1]).uniform(*CROP_H_M))
                    self.grid.paint(win, mask, crop_canopy(up_m, tall, win), cls, mat)
                else:
                    self.grid.fill_rect(
                        sc, depth / strips - 0.5, along, yaw_up, height_m=0.0, cls=cls, mat=mat
                    )
                wall = (
                    c[0] + up[0] * (v - depth / strips / 2 + 0.2),
                    c[1] + up[1] * (v - depth / strips / 2 + 0.2),
                )
                self.grid.fill_rect(wall, 0.4, along, yaw_up, height_m=0.0, cls=SurfaceClass.GROUND,
                                    mat=Material.BRICK)  # fmt: skip
            laid += 1
        return laid

    def _woods(self) -> None:
        """Dense trees where the slope is steep high up; clumps of trees on the meadows elsewhere."""
        steep = self.relief.slope_deg()
        floor = float(np.percentile(self.relief.z, 5))
        n = round(self.size**2 * TREES_PER_M2_WOODS)
        rows, cols = steep.shape
        cn = self.rng.uniform(-self.half, self.half, n)
        ce = self.rng.uniform(-self.half, self.half, n)
        i = np.clip(((cn + self.half) / self.relief.res).astype(int), 0, rows - 1)
        j = np.clip(((ce + self.half) / self.relief.res).astype(int), 0, cols - 1)
        wood = (steep[i, j] > WOODS_SLOPE_DEG) & (self.relief.z[i, j] > floor + WOODS_ABOVE_M)
        wood |= self.relief.z[i, j] > floor + 0.8 * float(np.ptp(self.relief.z))
        meadow = self.rng.random(n) < CLUMPS_PER_M2 / TREES_PER_M2_WOODS
        radius = self.rng.uniform(2.0, 4.5, n)
        tall = self.rng.uniform(7.0, 18.0, n)
        for k in np.flatnonzero(wood | meadow).tolist():
            pt = (float(cn[k]), float(ce[k]))
            r = float(radius[k])
            if self._rect_free(pt, 2 * r, 2 * r, 0.0):
                self.grid.fill_disc(pt, r, height_m=float(tall[k]), dome=True, cls=SurfaceClass.TREE,
                                    mat=Material.FOLIAGE, mode="max")  # fmt: skip


def generate_hillside(seed: int, size_m: float = 1200.0, res: float = 0.2) -> World:
    """Build a procedural hillside village, identical for identical arguments.

    Args:
        seed: non-negative integer seeding the one ``np.random.Generator`` used for everything.
        size_m: side of the square place in metres; the grid spans north and east ``[-size_m/2, size_m/2]``.
        res: grid resolution in metres per cell.

    Returns:
        A :class:`World` named ``"hillside"`` launching 100 m above the ground at (0, 0), with the
        painted grid on its relief, traffic lanes and walkways that follow the relief, and the sun; no
        safe zones (landings are graded from the grid's classes and slopes).

    Raises:
        CityError: a negative or non-integer seed, or a place smaller than 300 m.
    """
    return build_hillside(seed, size_m, res)[0]


def build_hillside(seed: int, size_m: float = 1200.0, res: float = 0.2) -> tuple[World, np.ndarray]:
    """:func:`generate_hillside`, and the ground raster under it (float32, the grid's shape: the relief
    as the roads, platforms and terraces left it, metres up)."""
    check_place_request("hillside", seed, size_m)
    builder = _HillsideBuilder(int(seed), float(size_m), res)
    return builder.build(int(seed)), builder.ground
