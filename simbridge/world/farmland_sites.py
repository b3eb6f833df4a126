"""Farmland's buildings: the village where the first two roads cross (detached houses under pitched
roofs, gardens, driveways) and the farmsteads beside the roads (a yard with barns, sheds, a farmhouse
and machinery). Each site is laid out in its own frame, ``u`` along the road and ``v`` away from it,
and painted rotated with the road (:mod:`simbridge.world.farmland`)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from simbridge.world.city_parts import CAR_H, CAR_L, CAR_W, Range
from simbridge.world.farmland_plan import BUILT_CLASSES, FarmPlan, Pt
from simbridge.world.model import Material, SurfaceClass
from simbridge.world.suburb_plan import Road
from simbridge.world.world import Walkway

Box = tuple[float, float, float, float]  # u_lo, u_hi, v_lo, v_hi in a site's frame

VILLAGE_REACH_M: Range = (70.0, 120.0)  # along each road from the crossing
LOT_FRONT_M: Range = (18.0, 28.0)
LOT_DEPTH_M: Range = (25.0, 35.0)
HOUSE_MATS = (Material.TILES, Material.SLATE, Material.SHINGLE)
YARD_L_M: Range = (60.0, 90.0)
YARD_D_M: Range = (45.0, 70.0)
YARD_SETBACK_M = 10.0  # from the road's verge to the yard
FARM_GAP_M = 180.0  # between farmsteads, and from the village
YARD_OPEN_M = 6.0  # the yard's strip along the road kept open (the way across it)
# machinery: (length, width, height, material, weight)
MACHINES = (
    (4.2, 2.4, 2.9, Material.CAR_PAINT, 0.3),  # tractor
    (7.0, 2.5, 2.6, Material.METAL, 0.25),  # trailer
    (10.0, 3.8, 3.8, Material.CAR_PAINT, 0.08),  # combine harvester
    (6.0, 2.4, 2.4, Material.CROP, 0.37),  # a stack of bales
)


@dataclass(frozen=True, slots=True)
class Site:
    """A frame beside a road: ``origin`` at the road's verge, ``along`` the road, ``out`` away from it."""

    origin: Pt
    along: Pt
    out: Pt

    def pt(self, u: float, v: float) -> Pt:
        return (
            self.origin[0] + self.along[0] * u + self.out[0] * v,
            self.origin[1] + self.along[1] * u + self.out[1] * v,
        )

    @property
    def yaw_u(self) -> float:
        return math.atan2(self.along[1], self.along[0])


def _overlaps(a: Box, b: Box, gap_m: float) -> bool:
    return a[0] < b[1] + gap_m and b[0] < a[1] + gap_m and a[2] < b[3] + gap_m and b[2] < a[3] + gap_m


class FarmSites(FarmPlan):
    """The village and the farmsteads."""

    # ------------------------------------------------------------------ frames and boxes
    def _site(self, road: Road, s_m: float, side: float) -> Site:
        pts, nrm = road.at(np.array([s_m]))
        out = (float(side * nrm[0, 0]), float(side * nrm[0, 1]))
        edge = road.width_m / 2 + 1.5
        return Site(
            (float(pts[0, 0]) + out[0] * edge, float(pts[0, 1]) + out[1] * edge), (out[1], -out[0]), out
        )

    def _box_clear(self, site: Site, box: Box) -> bool:
        """Whether a box lies inside the place and holds no road, building or machine yet."""
        u0, u1, v0, v1 = box
        corners = np.array([site.pt(u, v) for u in (u0, u1) for v in (v0, v1)])
        if (np.abs(corners) > self.half - 2.0).any():
            return False
        got = self.grid.rect_mask(site.pt((u0 + u1) / 2, (v0 + v1) / 2), u1 - u0, v1 - v0, site.yaw_u)
        if got is None:
            return False
        (i0, i1, j0, j1), mask, _, _ = got
        return not bool(np.isin(self.grid.cls[i0:i1, j0:j1][mask], [int(c) for c in BUILT_CLASSES]).any())

    def _site_rect(
        self, site: Site, box: Box, height: float, cls: SurfaceClass, mat: Material, region: int | None = None
    ) -> None:
        u0, u1, v0, v1 = box
        self.grid.fill_rect(site.pt((u0 + u1) / 2, (v0 + v1) / 2), u1 - u0, v1 - v0, site.yaw_u,
                            height_m=height, cls=cls, mat=mat, region=region)  # fmt: skip

    def _place_in(self, area: Box, su: float, sv: float, keep: list[Box], gap_m: float) -> Box | None:
        """A free ``su`` x ``sv`` box inside ``area``, clear of ``keep`` by ``gap_m``; None after 25 tries."""
        a0, a1, b0, b1 = area
        if a1 - a0 < su or b1 - b0 < sv:
            return None
        for _ in range(25):
            u = self._u((a0, a1 - su)) if a1 - a0 > su else a0
            v = self._u((b0, b1 - sv)) if b1 - b0 > sv else b0
            box = (u, u + su, v, v + sv)
            if not any(_overlaps(box, k, gap_m) for k in keep):
                return box
        return None

    def _gabled(self, site: Site, box: Box, eave: float, pitch_deg: float, mat: Material) -> None:
        """A building under a gable roof, the ridge along its longer side."""
        u0, u1, v0, v1 = box
        rid = self._new_region()
        self.n_buildings += 1
        along_u = (u1 - u0) >= (v1 - v0)
        length, width = (u1 - u0, v1 - v0) if along_u else (v1 - v0, u1 - u0)
        yaw = site.yaw_u if along_u else site.yaw_u + math.pi / 2
        ridge = eave + math.tan(math.radians(pitch_deg)) * width / 2
        centre = site.pt((u0 + u1) / 2, (v0 + v1) / 2)
        self._site_rect(site, box, eave, SurfaceClass.ROOF_PITCHED, mat, rid)  # the rectangle's edge cells
        self.grid.fill_pitched(centre, length, width, yaw, eave, ridge, region=rid, mat=mat)

    def _flat(self, site: Site, box: Box, height: float, mat: Material) -> None:
        self.n_buildings += 1
        self._site_rect(site, box, height, SurfaceClass.ROOF_FLAT, mat, self._new_region())

    # ------------------------------------------------------------------ the village
    def _village(self, roads: list[Road]) -> Pt | None:
        """Houses on lots along both roads either side of where they cross; None when they do not."""
        a, b = roads[0], roads[1]
        d = np.hypot(a.points[:, None, 0] - b.points[None, :, 0], a.points[:, None, 1] - b.points[None, :, 1])
        ia, ib = np.unravel_index(int(np.argmin(d)), d.shape)
        if d[ia, ib] > 10.0:
            return None
        centre = (float(a.points[ia, 0]), float(a.points[ia, 1]))
        for road, i in ((a, int(ia)), (b, int(ib))):
            s = road.arclength()
            other = b if road is a else a
            for direction in (1.0, -1.0):
                reach = self._u(VILLAGE_REACH_M)
                for side in (-1.0, 1.0):
                    at = other.width_m / 2 + 8.0
                    while at < reach:
                        front = self._u(LOT_FRONT_M)
                        s_m = s[i] + direction * (at + front / 2)
                        if not 0.0 < s_m < s[-1]:
                            break
                        self._house_lot(self._site(road, s_m, side), front)
                        at += front + self._u((0.0, 6.0))
                walk = road.offset(float(self.rng.choice([-1.0, 1.0])) * (road.width_m / 2 + 0.75))
                lo, hi = sorted((s[i] + direction * (other.width_m / 2 + 4.0), s[i] + direction * reach))
                keep = (s >= lo) & (s <= hi) & (np.abs(walk) <= self.half - 1.0).all(axis=1)
                if keep.sum() >= 2 and self.rng.random() < 0.7:
                    pts = tuple((float(p[0]), float(p[1])) for p in walk[keep])
                    self.walkways.append(Walkway(pts, int(self.rng.integers(1, 4)), 0.05, 1.5))
        return centre

    def _house_lot(self, site: Site, front: float) -> None:
        """A garden with a house under a pitched roof, a driveway, maybe a car and a tree."""
        depth = self._u(LOT_DEPTH_M)
        lot = (-front / 2, front / 2, 0.5, depth)
        if not self._box_clear(site, lot):
            return
        self._site_rect(site, lot, 0.05, SurfaceClass.GRASS, Material.GRASS)
        hl, hw = min(self._u((9.0, 14.0)), front - 5.0), self._u((8.0, 11.0))
        u0 = self._u((-front / 2 + 1.0, front / 2 - 4.0 - hl)) if front - 5.0 - hl > 0 else -front / 2 + 1.0
        v0 = self._u((4.0, 7.0))
        self._gabled(site, (u0, u0 + hl, v0, v0 + hw), self._u((3.0, 5.5)), self._u((30.0, 45.0)),
                     HOUSE_MATS[int(self.rng.integers(0, len(HOUSE_MATS)))])  # fmt: skip
        self.n_houses += 1
        drive = (u0 + hl + 0.5, min(u0 + hl + 3.5, front / 2 - 0.3), 0.0, v0 + hw)
        if drive[1] - drive[0] >= 2.5:
            self._site_rect(site, drive, 0.02, SurfaceClass.GROUND, Material.CONCRETE)
            if self.rng.random() < 0.5:
                cu, cv = (drive[0] + drive[1]) / 2, self._u((1.0 + CAR_L / 2, 2.0 + CAR_L / 2))
                self._site_rect(site, (cu - CAR_W / 2, cu + CAR_W / 2, cv - CAR_L / 2, cv + CAR_L / 2),
                          0.02 + CAR_H, SurfaceClass.VEHICLE, Material.CAR_PAINT)  # fmt: skip
        if self.rng.random() < 0.6 and depth - v0 - hw > 8.0:  # a garden tree at the back
            tc = site.pt(self._u((-front / 2 + 3.0, front / 2 - 3.0)), self._u((v0 + hw + 4.0, depth - 3.0)))
            self.grid.fill_disc(tc, self._u((2.0, 3.5)), height_m=self._u((5.0, 10.0)), dome=True,
                                cls=SurfaceClass.TREE, mat=Material.FOLIAGE, mode="max")  # fmt: skip

    # ------------------------------------------------------------------ farmsteads
    def _farmsteads(self, roads: list[Road], village: Pt | None) -> int:
        """Farmsteads beside the roads, away from the village and from each other."""
        want = max(1, round(self.size**2 / 5e5))
        placed: list[Pt] = [] if village is None else [village]
        n = 0
        for _ in range(40):
            if n == want:
                break
            road = roads[int(self.rng.integers(0, len(roads)))]
            s = road.arclength()
            if s[-1] < 200.0:
                continue
            length, depth = self._u(YARD_L_M), self._u(YARD_D_M)
            site = self._site(road, self._u((100.0, s[-1] - 100.0)), float(self.rng.choice([-1.0, 1.0])))
            yard = (-length / 2, length / 2, YARD_SETBACK_M, YARD_SETBACK_M + depth)
            middle = site.pt(0.0, YARD_SETBACK_M + depth / 2)
            if any(math.dist(middle, p) < FARM_GAP_M for p in placed) or not self._box_clear(site, yard):
                continue
            self._farmstead(site, length, depth)
            placed.append(middle)
            n += 1
        return n

    def _farmstead(self, site: Site, length: float, depth: float) -> None:
        """Yard, access track, barns and sheds at the back, the farmhouse, machinery, a worker or two."""
        v0 = YARD_SETBACK_M
        mat = Material.GRAVEL if self.rng.random() < 0.6 else Material.CONCRETE
        self._site_rect(site, (-length / 2, length / 2, v0, v0 + depth), 0.0, SurfaceClass.GROUND, mat)
        self._site_rect(site, (-2.0, 2.0, -1.5, v0), 0.0, SurfaceClass.GROUND, Material.GRAVEL)  # the way in
        keep: list[Box] = []
        inner = (-length / 2 + 1.5, length / 2 - 1.5, v0 + YARD_OPEN_M, v0 + depth - 1.5)
        # the farmhouse in its garden at one end of the yard
        hl, hw = self._u((10.0, 14.0)), self._u((8.0, 11.0))
        end = -1.0 if self.rng.random() < 0.5 else 1.0
        gu0 = -length / 2 + 1.0 if end < 0 else length / 2 - hl - 9.0
        garden = (gu0, gu0 + hl + 8.0, inner[2], min(inner[2] + hw + 8.0, inner[3]))
        if garden[3] - garden[2] >= hw + 2.0:
            self._site_rect(site, garden, 0.05, SurfaceClass.GRASS, Material.GRASS)
            self._gabled(site, (gu0 + 4.0, gu0 + 4.0 + hl, garden[2] + 3.0, garden[2] + 3.0 + hw),
                         self._u((4.0, 6.0)), self._u((30.0, 45.0)), Material.TILES)  # fmt: skip
            keep.append(garden)
        for k in range(int(self.rng.integers(1, 3)) + int(self.rng.integers(1, 3))):  # barns, then sheds
            barn = k == 0 or (k == 1 and self.rng.random() < 0.4)
            su, sv = (
                (self._u((20.0, 36.0)), self._u((12.0, 20.0)))
                if barn
                else (self._u((8.0, 16.0)), self._u((6.0, 10.0)))
            )
            box = self._place_in(inner, su, sv, keep, 3.0)
            if box is None:
                continue
            keep.append(box)
            roof = (Material.CORRUGATED, Material.SEAM_METAL)[int(self.rng.integers(0, 2))]
            if self.rng.random() < 0.65:
                eave = self._u((5.0, 8.0)) if barn else self._u((3.0, 4.5))
                self._gabled(site, box, eave, self._u((15.0, 25.0)), roof)
            else:
                self._flat(site, box, self._u((6.0, 9.0)) if barn else self._u((3.5, 5.0)), roof)
        self._machinery(site, inner, keep)
        walk = (site.pt(-length / 2 + 2.0, v0 + 3.0), site.pt(length / 2 - 2.0, v0 + 3.0))
        self.walkways.append(Walkway(walk, int(self.rng.integers(1, 3)), 0.0, 2.0))

    def _machinery(self, site: Site, area: Box, keep: list[Box]) -> None:
        """Tractors, trailers, now and then a combine, stacks of bales: ``MACHINERY`` in the yard."""
        weights = np.array([m[4] for m in MACHINES])
        for _ in range(int(self.rng.integers(3, 8))):
            length, width, height, mat, _w = MACHINES[int(self.rng.choice(len(MACHINES), p=weights))]
            su, sv = (length, width) if self.rng.random() < 0.5 else (width, length)
            box = self._place_in(area, su, sv, keep, 1.0)
            if box is None:
                continue
            keep.append(box)
            h = height if mat != Material.CROP else 1.2 * int(self.rng.integers(1, 4))
            self._site_rect(site, box, h, SurfaceClass.MACHINERY, mat)
