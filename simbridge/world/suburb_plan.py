"""The suburb's streets and the land they take: gently curving collector roads across the whole place
and the residential streets off them (crescents that loop back to the road they leave, cul-de-sacs that
end in a turning circle), with traffic on the collectors and people on their sidewalks.

Every street, site and lot claims its land on a coarse claim raster (:attr:`SuburbPlan.claim`) before it
is painted, so what is placed later never overlaps what came first (:mod:`simbridge.world.suburb`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from simbridge.world.city_parts import SIDEWALK_H, CityParams, Range
from simbridge.world.city_props import Props
from simbridge.world.model import Material, SurfaceClass, WorldGrid
from simbridge.world.world import Lane, Walkway

STEP_M = 4.0  # spacing of a street's centre-line points
CLAIM_RES_M = 1.0  # cell size of the claim raster
COLLECTOR_W_M: Range = (7.0, 8.0)
COLLECTOR_GAP_M: Range = (280.0, 340.0)  # between east-west collectors
LOCAL_W_M: Range = (6.0, 7.0)
SIDEWALK_W_M: Range = (1.8, 2.5)
VERGE_M = 1.5  # grass between a residential street and its lots
TURN_R_M: Range = (9.0, 11.0)  # cul-de-sac turning circle
STREET_CLEAR_M = 14.0  # a new residential street keeps this far (beyond its verge) from claimed land
COLLECTOR_SPEED_M_S: Range = (6.0, 12.0)
COLLECTOR_ARRIVALS_PER_MIN: Range = (1.0, 4.0)
MARK_W_M = 0.25  # painted lines: wider than a cell, so a diagonal line never breaks up

Pt = tuple[float, float]


@dataclass(frozen=True, eq=False)
class Road:
    """A street's centre line (points every ~``STEP_M``), its carriageway and what borders it."""

    points: np.ndarray  # (k, 2) north, east
    width_m: float
    sidewalk_m: float = 0.0  # each side; 0 for residential streets (a grass verge instead)
    turn_r_m: float = 0.0  # turning circle at the last point (a cul-de-sac); 0 for none
    depth: int = 0  # 0: collector, 1: off a collector, 2: off a residential street

    @property
    def edge_m(self) -> float:
        """From the centre line to where the street's land ends and lots may begin."""
        return self.width_m / 2 + (self.sidewalk_m if self.sidewalk_m > 0 else VERGE_M)

    def arclength(self) -> np.ndarray:
        seg = np.hypot(*np.diff(self.points, axis=0).T)
        return np.concatenate([[0.0], np.cumsum(seg)])

    def normals(self) -> np.ndarray:
        """Unit normals to the right of the direction of travel, per point."""
        d = np.gradient(self.points, axis=0)
        t = d / np.hypot(d[:, 0], d[:, 1])[:, None]
        return np.stack([-t[:, 1], t[:, 0]], axis=1)

    def at(self, s_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Points and right normals at arc lengths ``s_m`` (interpolated between the samples)."""
        s = self.arclength()
        nrm = self.normals()
        pts = np.stack([np.interp(s_m, s, self.points[:, k]) for k in (0, 1)], axis=1)
        nv = np.stack([np.interp(s_m, s, nrm[:, k]) for k in (0, 1)], axis=1)
        return pts, nv / np.hypot(nv[:, 0], nv[:, 1])[:, None]

    def offset(self, d_m: float) -> np.ndarray:
        """The centre line moved ``d_m`` metres to the right (left if negative)."""
        return np.asarray(self.points + self.normals() * d_m)


def as_pts(a: np.ndarray) -> list[Pt]:
    """(k, 2) points as the (north, east) tuples the painters, lanes and walkways take."""
    return [(float(n), float(e)) for n, e in a]


class SuburbPlan(Props):
    """The suburb's streets on a claim raster; :class:`Props` brings the grid, rng and park painter."""

    def __init__(self, seed: int, size_m: float, res: float) -> None:
        super().__init__(seed, size_m, res, CityParams())
        self.grid.cls.fill(int(SurfaceClass.GRASS))  # unbuilt land is grass (fields, verges, lawns)
        self.grid.mat.fill(int(Material.GRASS))
        h = self.half
        self.claim = WorldGrid.empty((-h, h), (-h, h), CLAIM_RES_M, ground_cls=SurfaceClass.UNKNOWN)

    # ------------------------------------------------------------------ land claims
    def _inside(self, pts: np.ndarray, margin_m: float) -> np.ndarray:
        lim = self.half - margin_m
        return np.asarray((np.abs(pts) <= lim).all(axis=1))

    def _rect_free(self, centre: Pt, length_m: float, width_m: float, yaw_rad: float) -> bool:
        """Whether a rotated rectangle lies in the grid and on land nothing has claimed."""
        c, s = math.cos(yaw_rad), math.sin(yaw_rad)
        hl, hw = length_m / 2, width_m / 2
        corners = np.array(
            [
                (centre[0] + a * hl * c - b * hw * s, centre[1] + a * hl * s + b * hw * c)
                for a in (-1, 1)
                for b in (-1, 1)
            ]
        )
        if not self._inside(corners, 1.0).all():
            return False
        got = self.claim.rect_mask(centre, length_m, width_m, yaw_rad)
        if got is None:
            return False
        (i0, i1, j0, j1), mask, _, _ = got
        return not bool(self.claim.cls[i0:i1, j0:j1][mask].any())

    def _claim_rect(self, centre: Pt, length_m: float, width_m: float, yaw_rad: float) -> None:
        self.claim.fill_rect(centre, length_m, width_m, yaw_rad, cls=SurfaceClass.GROUND)

    def _claim_road(self, road: Road) -> None:
        self.claim.fill_polyline(as_pts(road.points), 2 * road.edge_m + 1.0, cls=SurfaceClass.GROUND)
        if road.turn_r_m > 0:
            end = (float(road.points[-1, 0]), float(road.points[-1, 1]))
            self.claim.fill_disc(end, road.turn_r_m + VERGE_M, cls=SurfaceClass.GROUND)

    # ------------------------------------------------------------------ the streets
    def _collectors(self) -> list[Road]:
        """A spine east-west past the launch point and others ~300 m on either side of it, crossed by
        north-south ones ~400 m apart: long sine curves, a few hundred metres from crest to crest."""
        size, h = self.size, self.half
        spine = self._u((-40.0, 40.0))
        ew = [spine]
        for side in (-1.0, 1.0):
            at = spine + side * self._u(COLLECTOR_GAP_M)
            while abs(at) < h - 80.0:
                ew.append(at)
                at += side * self._u(COLLECTOR_GAP_M)
        n_ns = max(1, round(size / 400.0))
        ns = [-h + (k + 0.5) * size / n_ns + self._u((-0.08, 0.08)) * size / n_ns for k in range(n_ns)]
        along = np.arange(-h - 2 * STEP_M, h + 2 * STEP_M + 1e-6, STEP_M)
        roads: list[Road] = []
        for axis, centres in (("ew", ew), ("ns", ns)):
            for c in centres:
                amp = min(self._u((8.0, 25.0)), 0.05 * size)
                wave = self._u((350.0, 800.0))
                phase = self._u((0.0, 2 * math.pi))
                across = c + amp * np.sin(2 * math.pi * along / wave + phase)
                pts = np.stack([across, along] if axis == "ew" else [along, across], axis=1)
                roads.append(Road(pts, self._u(COLLECTOR_W_M), self._u(SIDEWALK_W_M)))
        for road in roads:
            self._claim_road(road)
        return roads

    def _local_streets(self, collectors: list[Road]) -> list[Road]:
        """Crescents and cul-de-sacs off the collectors, and off those again, wherever the land is free."""
        queue = list(collectors)
        out: list[Road] = []
        while queue:
            parent = queue.pop(0)
            s = parent.arclength()
            at = self._u((15.0, 50.0))
            while at < s[-1] - 40.0:
                side = float(self.rng.choice([-1.0, 1.0]))
                crescent = bool(self.rng.random() < 0.4)
                road = self._crescent(parent, at, side) if crescent else self._cul_de_sac(parent, at, side)
                if road is None:
                    at += self._u((10.0, 20.0))
                    continue
                self._claim_road(road)
                out.append(road)
                if road.depth < 3:
                    queue.append(road)
                at += (road.arclength()[-1] * 0.6 if crescent else 0.0) + self._u((55.0, 100.0))
        return out

    def _accept(
        self, parent: Road, pts: np.ndarray, d_from_parent: np.ndarray, width_m: float, turn_r_m: float
    ) -> Road | None:
        """The street if it stays in the grid and clear of claimed land (but where it meets its parent)."""
        if not self._inside(pts, turn_r_m + 25.0).all():  # room for a lot between it and the edge
            return None
        road = Road(pts, width_m, 0.0, turn_r_m, parent.depth + 1)
        clear = road.edge_m + STREET_CLEAR_M
        for pt in pts[d_from_parent > parent.edge_m + clear + STEP_M]:  # the junction itself is not checked
            if not self._rect_free((float(pt[0]), float(pt[1])), 2 * clear, 2 * clear, 0.0):
                return None
        if turn_r_m > 0:
            end = (float(pts[-1, 0]), float(pts[-1, 1]))
            if not self._rect_free(end, 2 * (turn_r_m + clear), 2 * (turn_r_m + clear), 0.0):
                return None
        return road

    def _cul_de_sac(self, parent: Road, at_m: float, side: float) -> Road | None:
        """Out from the parent at right angles, bending gently, to a turning circle 60-170 m on."""
        at, nrm = parent.at(np.array([at_m]))
        p0, n0 = at[0], nrm[0]
        heading = math.atan2(side * n0[1], side * n0[0])
        turn = self._u((-1.0, 1.0)) / 110.0  # radians per metre
        steps = round(self._u((60.0, 170.0)) / STEP_M)
        path = [p0]
        for _ in range(steps):
            heading += turn * STEP_M
            path.append(path[-1] + STEP_M * np.array([math.cos(heading), math.sin(heading)]))
        arr = np.array(path)
        d = np.arange(len(path)) * STEP_M
        return self._accept(parent, arr, d, self._u(LOCAL_W_M), self._u(TURN_R_M))

    def _crescent(self, parent: Road, at_m: float, side: float) -> Road | None:
        """A half-ellipse 45-80 m deep that leaves the parent and joins it again 90-160 m further on."""
        span, depth = self._u((90.0, 160.0)), self._u((45.0, 80.0))
        if at_m + span > parent.arclength()[-1] - 10.0:
            return None
        t = np.linspace(0.0, math.pi, max(8, round(math.pi * (span + depth) / 2 / STEP_M)))
        base, nrm = parent.at(at_m + span * (1.0 - np.cos(t)) / 2)
        d = depth * np.sin(t)
        return self._accept(parent, base + nrm * (side * d)[:, None], d, self._u(LOCAL_W_M), 0.0)

    # ------------------------------------------------------------------ painting them
    def _paint_roads(self, collectors: list[Road], local: list[Road]) -> None:
        """Sidewalks first, then carriageways cut through them (residential streets through the
        collectors' sidewalks), then the collectors' dashed centre lines, cleared where two cross."""
        g = self.grid
        for road in collectors:
            w = road.width_m + 2 * road.sidewalk_m
            g.fill_polyline(
                as_pts(road.points), w, height_m=SIDEWALK_H, cls=SurfaceClass.SIDEWALK, mat=Material.PAVING
            )
        for road in local + collectors:
            g.fill_polyline(
                as_pts(road.points), road.width_m, height_m=0.0, cls=SurfaceClass.ROAD, mat=Material.ASPHALT
            )
            if road.turn_r_m > 0:
                end = (float(road.points[-1, 0]), float(road.points[-1, 1]))
                g.fill_disc(end, road.turn_r_m, height_m=0.0, cls=SurfaceClass.ROAD, mat=Material.ASPHALT)
                if self.rng.random() < 0.5:  # a planted island in the turning circle
                    g.fill_disc(
                        end, road.turn_r_m - 6.0, height_m=0.15, cls=SurfaceClass.GRASS, mat=Material.GRASS
                    )
        for road in collectors:
            pts = road.points
            for a, b in zip(pts[:-1:2], pts[1::2], strict=False):  # 2 m dashes every 8 m
                g.fill_polyline(
                    as_pts(np.array([a, (a + b) / 2])),
                    MARK_W_M,
                    cls=SurfaceClass.ROAD,
                    mat=Material.LANE_MARKING,
                )
        for k, a in enumerate(collectors):
            for b in collectors[k + 1 :]:
                d = np.hypot(*(a.points[:, None, :] - b.points[None, :, :]).transpose(2, 0, 1))
                i, j = np.unravel_index(int(np.argmin(d)), d.shape)
                if d[i, j] < STEP_M:
                    mid = (a.points[i] + b.points[j]) / 2
                    r = max(a.width_m, b.width_m) * 0.75
                    g.fill_disc(
                        (float(mid[0]), float(mid[1])),
                        r,
                        height_m=0.0,
                        cls=SurfaceClass.ROAD,
                        mat=Material.ASPHALT,
                    )

    # ------------------------------------------------------------------ traffic and people
    def _collector_traffic(self, road: Road) -> None:
        """A lane each way (keeping right) and, here and there, people on the sidewalks."""
        lo, hi = COLLECTOR_SPEED_M_S
        mid = (lo + hi) / 2
        for fwd in (True, False):
            pts = road.offset(road.width_m / 4 if fwd else -road.width_m / 4)
            pts = pts[self._inside(pts, 0.5)]
            if len(pts) < 2:
                continue
            speed = (self._u((lo, mid)), self._u((mid, hi)))
            lane = as_pts(pts if fwd else pts[::-1])
            self.lanes.append(Lane(tuple(lane), speed, self._u(COLLECTOR_ARRIVALS_PER_MIN), 0.0))
        for side in (-1.0, 1.0):
            pts = road.offset(side * (road.width_m / 2 + road.sidewalk_m / 2))
            pts = pts[self._inside(pts, 1.0)]
            for k in range(0, len(pts) - 5, 25):  # stretches of ~100 m
                if self.rng.random() < 0.35:
                    count = int(self.rng.integers(1, 5))
                    chunk = tuple(as_pts(pts[k : k + 26]))
                    self.walkways.append(Walkway(chunk, count, SIDEWALK_H, road.sidewalk_m))
