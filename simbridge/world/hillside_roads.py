"""The hillside village's roads: one along the valley floor (7 m of asphalt with a dashed centre line
and sidewalks both sides) and a few narrow ones (5 m, no markings) climbing the valley sides in
switchbacks, each cut level across its width into the relief with cuttings and embankments beside it;
cars on all of them, people on the sidewalks and along the edges of the climbing roads.

A road's height along its centre line (:attr:`HillRoad.heights_m`) is the relief under it smoothed
over some tens of metres; its lanes and walkways carry those heights point by point, so traffic and
people follow the ground (:mod:`simbridge.world.hillside`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from simbridge.world.city_parts import SIDEWALK_H, Range
from simbridge.world.model import Material, SurfaceClass
from simbridge.world.relief import Relief, level_strip
from simbridge.world.suburb_lots import SuburbLots
from simbridge.world.suburb_plan import MARK_W_M, STEP_M, Road, as_pts
from simbridge.world.world import Lane, Walkway

VALLEY_W_M, VALLEY_SIDEWALK_M = 7.0, 2.0
CLIMB_W_M = 5.0
CLIMB_EDGE_M = 1.0  # the strip along a climbing road's edge where people walk
VALLEY_SHOULDER_M, CLIMB_SHOULDER_M = 6.0, 5.0
CLIMB_GRADE = 0.09  # what a climbing road aims for, rise per metre
HAIRPIN_R_M = 12.0
LEG_M: Range = (70.0, 150.0)
CLIMB_LEGS = (3, 6)
SMOOTH_POINTS = 9  # the height profile's moving average along the centre line
VALLEY_SPEED_M_S: Range = (8.0, 14.0)
CLIMB_SPEED_M_S: Range = (5.0, 9.0)
ARRIVALS_PER_MIN: Range = (0.5, 3.0)


@dataclass(frozen=True, eq=False)
class HillRoad:
    """A road and its surface's height at each centre-line point (metres up, level across it)."""

    road: Road
    heights_m: np.ndarray  # float64 (k,)

    @property
    def core_m(self) -> float:
        """The width cut level: the carriageway and its sidewalks, or its edge strips."""
        return self.road.width_m + 2 * self.road.sidewalk_m


def _profile(relief: Relief, pts: np.ndarray) -> np.ndarray:
    """The relief under ``pts``, smoothed along them (the ends held)."""
    z = relief.sample(pts[:, 0], pts[:, 1])
    k = SMOOTH_POINTS // 2
    padded = np.concatenate([np.full(k, z[0]), z, np.full(k, z[-1])])
    return np.asarray(np.convolve(padded, np.ones(SMOOTH_POINTS) / SMOOTH_POINTS, mode="valid"))


class HillsideRoads(SuburbLots):
    """The roads of the hillside on the relief; the builder provides ``relief`` and ``ground``."""

    relief: Relief
    ground: np.ndarray

    def _valley_road(self) -> HillRoad:
        """East-west along the valley floor, 30-45 m to one side of its lowest line (the stream)."""
        h = self.half
        e = np.arange(-h - 2 * STEP_M, h + 2 * STEP_M + 1e-6, STEP_M)
        side = float(self.rng.choice([-1.0, 1.0]))
        n = self.relief.valley_at(e) + side * self._u((30.0, 45.0))
        pts = np.stack([n, e], axis=1)
        road = HillRoad(Road(pts, VALLEY_W_M, VALLEY_SIDEWALK_M), _profile(self.relief, pts))
        self._claim_road(road.road)
        return road

    def _climbing_roads(self, valley: HillRoad, count: int) -> list[HillRoad]:
        """``count`` roads leaving the valley road about evenly spaced along it, alternately north and
        south, each climbing the side in switchbacks."""
        out: list[HillRoad] = []
        side = float(self.rng.choice([-1.0, 1.0]))
        pts_v = valley.road.points
        for k in range(count):
            at_e = -self.half + (k + 0.5) * self.size / count + self._u((-40.0, 40.0))
            i = int(np.argmin(np.abs(pts_v[:, 1] - at_e)))
            road = self._switchbacks(pts_v[i], side)
            if road is not None:
                self._claim_road(road.road)
                out.append(road)
            side = -side
        return out

    def _switchbacks(self, start: np.ndarray, side: float) -> HillRoad | None:
        """From ``start`` straight out to ``side`` (north +1, south -1), then up the slope at about
        ``CLIMB_GRADE``, turning back in a hairpin of ``HAIRPIN_R_M`` after each leg."""
        heading = math.atan2(0.0, side)  # due north or south
        leg_sign = float(self.rng.choice([-1.0, 1.0]))
        legs, leg_left = int(self.rng.integers(*CLIMB_LEGS)), self._u(LEG_M)
        max_turn = STEP_M / HAIRPIN_R_M
        path = [np.asarray(start, np.float64)]
        walked = 0.0
        while legs > 0 and walked < 900.0:
            p = path[-1]
            g = self._gradient(p)
            slope = math.hypot(g[0], g[1])
            if walked < 20.0 or slope < 0.02:
                target = heading
            else:
                up = g / slope
                along = leg_sign * np.array([-up[1], up[0]])
                rise = min(1.0, CLIMB_GRADE / slope)
                d = along * math.sqrt(1.0 - rise * rise) + up * rise
                target = math.atan2(d[1], d[0])
            diff = (target - heading + math.pi) % (2 * math.pi) - math.pi
            if abs(diff) > math.pi / 2 and slope >= 0.02:  # a hairpin: turn through the uphill side
                up_h = math.atan2(g[1], g[0])
                sign = 1.0 if ((up_h - heading + math.pi) % (2 * math.pi) - math.pi) > 0 else -1.0
                heading += sign * max_turn
            else:
                heading += max(-max_turn, min(max_turn, diff))
            nxt = p + STEP_M * np.array([math.cos(heading), math.sin(heading)])
            if not self._inside(nxt[None, :], 30.0)[0]:
                break
            if walked > 40.0 and self.claim.class_at(float(nxt[0]), float(nxt[1])) != SurfaceClass.UNKNOWN:
                break  # another road, or land already taken
            path.append(nxt)
            walked += STEP_M
            leg_left -= STEP_M
            if leg_left <= 0 and walked > 20.0:
                leg_sign, leg_left, legs = -leg_sign, self._u(LEG_M), legs - 1
        if walked < 80.0:
            return None
        pts = np.asarray(path)
        return HillRoad(Road(pts, CLIMB_W_M, CLIMB_EDGE_M, depth=1), _profile(self.relief, pts))

    def _gradient(self, p: np.ndarray) -> np.ndarray:
        """The relief's gradient (north, east; metres per metre) at ``p``, over 4 m."""
        d = 2.0
        s = self.relief.sample(
            np.array([p[0] + d, p[0] - d, p[0], p[0]]), np.array([p[1], p[1], p[1] + d, p[1] - d])
        )
        return np.array([(s[0] - s[1]) / (2 * d), (s[2] - s[3]) / (2 * d)])

    # ------------------------------------------------------------------ cutting and painting
    def _cut_roads(self, roads: list[HillRoad], part: str) -> None:
        for r in roads:
            shoulder = VALLEY_SHOULDER_M if r.road.depth == 0 else CLIMB_SHOULDER_M
            level_strip(self.ground, self.grid, r.road.points, r.heights_m, r.core_m, shoulder, part=part)

    def _paint_hill_roads(self, valley: HillRoad, climbing: list[HillRoad]) -> None:
        """The valley road's sidewalks, then every carriageway (the climbing roads' edge strips are
        carriageway too), then the valley road's dashed centre line."""
        g = self.grid
        g.fill_polyline(as_pts(valley.road.points), valley.core_m, height_m=SIDEWALK_H,
                        cls=SurfaceClass.SIDEWALK, mat=Material.PAVING)  # fmt: skip
        for r in [*climbing, valley]:
            w = r.road.width_m if r is valley else r.core_m
            g.fill_polyline(
                as_pts(r.road.points), w, height_m=0.0, cls=SurfaceClass.ROAD, mat=Material.ASPHALT
            )
        pts = valley.road.points
        for a, b in zip(pts[:-1:2], pts[1::2], strict=False):  # 2 m dashes every 8 m
            g.fill_polyline(as_pts(np.array([a, (a + b) / 2])), MARK_W_M, cls=SurfaceClass.ROAD,
                            mat=Material.LANE_MARKING)  # fmt: skip

    def _road_traffic(self, r: HillRoad) -> None:
        """A lane each way and, here and there, people: on the valley road's sidewalks, along the
        climbing roads' edges; every lane and walkway carries the road's heights."""
        road = r.road
        speed_r = VALLEY_SPEED_M_S if road.depth == 0 else CLIMB_SPEED_M_S
        lo, hi = speed_r
        for fwd in (True, False):
            keep = self._inside(road.offset(road.width_m / 4 if fwd else -road.width_m / 4), 0.5)
            pts, z = road.offset(road.width_m / 4 if fwd else -road.width_m / 4)[keep], r.heights_m[keep]
            if len(pts) < 2:
                continue
            if not fwd:
                pts, z = pts[::-1], z[::-1]
            speed = (self._u((lo, (lo + hi) / 2)), self._u(((lo + hi) / 2, hi)))
            self.lanes.append(Lane(tuple(as_pts(pts)), speed, self._u(ARRIVALS_PER_MIN), 0.0,
                                   tuple(float(v) for v in z)))  # fmt: skip
        lift = SIDEWALK_H if road.depth == 0 else 0.0
        for side in (-1.0, 1.0):
            keep = self._inside(road.offset(side * (road.width_m / 2 + road.sidewalk_m / 2)), 1.0)
            pts = road.offset(side * (road.width_m / 2 + road.sidewalk_m / 2))[keep]
            z = r.heights_m[keep] + lift
            for k in range(0, len(pts) - 5, 25):  # stretches of ~100 m
                if self.rng.random() < 0.4:
                    self.walkways.append(
                        Walkway(tuple(as_pts(pts[k : k + 26])), int(self.rng.integers(1, 5)), 0.0,
                                road.sidewalk_m, tuple(float(v) for v in z[k : k + 26]))
                    )  # fmt: skip
