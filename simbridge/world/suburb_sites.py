"""The suburb's open places, claimed before the residential streets: a school with its sports field (a
marked pitch, a running track round it on a large place, the school building and its car park), a park
with trees and paths, and a few open lawns and small playing fields. They are the open ground a drone
could land on, and people walk across them."""

from __future__ import annotations

import math

import numpy as np

from simbridge.world.model import Material, SurfaceClass
from simbridge.world.suburb_plan import MARK_W_M, Pt, SuburbPlan, as_pts
from simbridge.world.world import Walkway

Frame = tuple[Pt, float]  # a site's centre and yaw (0: its length along north, pi/2: along east)
TRACK_LANES, TRACK_LANE_M = 6, 1.22
SCHOOL_STRIP_M = 50.0  # beside the field: the school building, its forecourt and car park
SITE_GAP_M = 4.0  # claimed around a site, so that lots and streets keep off its edge


class SuburbSites(SuburbPlan):
    """The school, the park and the open lawns."""

    def _site(self, length_m: float, width_m: float, near_m: float | None = None) -> Frame | None:
        """A free place for a ``length_m`` x ``width_m`` site (within ``near_m`` of the launch point if
        given), claimed; None when none turns up in a few dozen tries."""
        for _ in range(60):
            yaw = 0.0 if self.rng.random() < 0.5 else math.pi / 2
            lim = self.half - max(length_m, width_m) / 2 - 2.0
            reach = lim if near_m is None else min(lim, near_m)
            if reach <= 0:
                return None
            centre = (self._u((-reach, reach)), self._u((-reach, reach)))
            grown = (length_m + 2 * SITE_GAP_M, width_m + 2 * SITE_GAP_M)
            if self._rect_free(centre, *grown, yaw):
                self._claim_rect(centre, *grown, yaw)
                return centre, yaw
        return None

    def _local(self, frame: Frame, u: float, v: float) -> Pt:
        """A point given in a site's frame (``u`` along its length, ``v`` across)."""
        (cn, ce), yaw = frame
        c, s = math.cos(yaw), math.sin(yaw)
        return (cn + u * c - v * s, ce + u * s + v * c)

    def _site_box(
        self, frame: Frame, u0: float, u1: float, v0: float, v1: float
    ) -> tuple[float, float, float, float]:
        """A box in a site's frame as a north/east box (sites are turned by multiples of 90 degrees)."""
        corners = np.array([self._local(frame, u, v) for u in (u0, u1) for v in (v0, v1)])
        return (
            float(corners[:, 0].min()),
            float(corners[:, 0].max()),
            float(corners[:, 1].min()),
            float(corners[:, 1].max()),
        )

    def _site_paint(self, frame: Frame, length_m: float, width_m: float, mask_of: str, height_m: float | None,
                    cls: SurfaceClass | None, mat: Material | None, **shape: float) -> None:  # fmt: skip
        """Paint the cells of a shape in a site's frame: ``mask_of`` names it (all of the rectangle, the
        lines of a pitch ``pl`` x ``pw``, a running track round a straight ``half_straight`` x 2 at
        ``r_in`` from it, or the lines between its lanes)."""
        got = self.grid.rect_mask(frame[0], length_m, width_m, frame[1])
        if got is None:
            return
        win, inside, u, v = got
        lw = MARK_W_M / 2
        if mask_of == "all":
            on = np.ones(u.shape, bool)
        elif mask_of == "pitch_lines":
            pl, pw = shape["pl"], shape["pw"]
            k = pl / 105.0  # penalty areas scale with the pitch
            box_u, box_v = pl / 2 - 16.5 * k, 20.15 * k
            au, av = np.abs(u), np.abs(v)
            on = (
                ((np.abs(au - pl / 2) <= lw) & (av <= pw / 2 + lw))
                | ((np.abs(av - pw / 2) <= lw) & (au <= pl / 2 + lw))
                | ((au <= lw) & (av <= pw / 2))
                | (np.abs(np.hypot(u, v) - 9.15 * k) <= lw)
                | ((np.abs(au - box_u) <= lw) & (av <= box_v))
                | ((np.abs(av - box_v) <= lw) & (au >= box_u) & (au <= pl / 2))
            )
        else:
            d = np.hypot(np.maximum(np.abs(u) - shape["half_straight"], 0.0), v)
            r_in = shape["r_in"]
            if mask_of == "track":
                on = (d >= r_in) & (d <= r_in + TRACK_LANES * TRACK_LANE_M)
            else:
                on = np.zeros(d.shape, bool)
                for k_lane in range(TRACK_LANES + 1):
                    on |= np.abs(d - r_in - k_lane * TRACK_LANE_M) <= lw
        self.grid.paint(win, inside & on, height_m, cls, mat)

    # ------------------------------------------------------------------ the school
    def _school(self) -> Pt | None:
        """The school: try the largest layout first (with a track, on a large place), then smaller ones.
        Returns the centre spot of its pitch."""
        pl, pw = self._u((90.0, 105.0)), self._u((55.0, 68.0))
        options = [(True, 1.0), (False, 1.0), (False, 0.8), (False, 0.65)]
        for track, scale in options if self.size >= 700.0 else options[1:]:
            l_p, w_p = pl * scale, pw * scale
            r_in = w_p / 2 + 3.0
            field_l = l_p + 2 * (r_in + TRACK_LANES * TRACK_LANE_M) + 4.0 if track else l_p + 12.0
            field_w = 2 * (r_in + TRACK_LANES * TRACK_LANE_M) + 4.0 if track else w_p + 12.0
            frame = self._site(field_l, field_w + SCHOOL_STRIP_M, near_m=None)
            if frame is None:
                continue
            # the field across one part of the site, the building strip across the rest
            f_v = -(field_w + SCHOOL_STRIP_M) / 2 + field_w / 2
            fc = self._local(frame, 0.0, f_v)
            field = (fc, frame[1])
            self._site_paint(field, field_l, field_w, "all", 0.0, SurfaceClass.GRASS, Material.GRASS)
            if track:
                shape = {"half_straight": l_p / 2, "r_in": r_in}
                self._site_paint(
                    field, field_l, field_w, "track", 0.02, SurfaceClass.GROUND, Material.SOIL, **shape
                )
                self._site_paint(
                    field, field_l, field_w, "track_lines", None, None, Material.LANE_MARKING, **shape
                )
                ring = [
                    self._local(
                        field,
                        (l_p / 2) * math.copysign(1.0, math.cos(t)) + (r_in + 3.0) * math.cos(t),
                        (r_in + 3.0) * math.sin(t),
                    )
                    for t in np.linspace(0.0, 2 * math.pi, 41)
                ]  # joggers on the track: the centre line of its middle lanes
                self.walkways.append(Walkway(tuple(ring), int(self.rng.integers(2, 7)), 0.02, 3.0))
            self._site_paint(
                field, l_p, w_p, "pitch_lines", None, None, Material.LANE_MARKING, pl=l_p, pw=w_p
            )
            for end in (-1.0, 1.0):  # goals: a crossbar 2.4 m up behind each goal line
                u = end * (l_p / 2 + 0.8)
                a, b = self._local(field, u, -3.66 * scale), self._local(field, u, 3.66 * scale)
                self.grid.fill_polyline(
                    [a, b], 0.3, height_m=2.44, cls=SurfaceClass.GUARD_RAIL, mat=Material.METAL
                )
            corners = [
                self._local(field, su * l_p / 2 * 0.9, sv * w_p / 2 * 0.9)
                for su, sv in ((-1, -1), (1, 1), (-1, 1), (1, -1))
            ]
            for a, b in ((corners[0], corners[1]), (corners[2], corners[3])):  # people across the field
                self.walkways.append(Walkway((a, b), int(self.rng.integers(2, 6)), 0.0, 2.0))
            self._school_building(frame, field_l, field_w)
            return fc
        return None

    def _school_building(self, frame: Frame, site_l: float, field_w: float) -> None:
        """A flat-roofed building with a parapet and a few roof units, its forecourt and its car park."""
        v0 = -(field_w + SCHOOL_STRIP_M) / 2 + field_w + 3.0
        v1 = v0 + SCHOOL_STRIP_M - 6.0
        self._fill(
            *self._site_box(frame, -site_l / 2, site_l / 2, v0, v1),
            0.05,
            SurfaceClass.GROUND,
            Material.CONCRETE,
        )
        bl = min(self._u((45.0, 70.0)), 0.55 * site_l)
        bw = self._u((16.0, 24.0))
        h = self._u((7.0, 10.0))
        rid = self._new_region()
        self.n_buildings += 1
        b_lo = -site_l / 2 + 4.0
        bv0 = v0 + 6.0
        self._fill(
            *self._site_box(frame, b_lo, b_lo + bl, bv0, bv0 + bw),
            h + 0.8,
            SurfaceClass.PARAPET,
            Material.CONCRETE,
            rid,
        )
        self._fill(*self._site_box(frame, b_lo + 0.4, b_lo + bl - 0.4, bv0 + 0.4, bv0 + bw - 0.4), h,
                   SurfaceClass.ROOF_FLAT, Material.MEMBRANE, rid)  # fmt: skip
        for _ in range(int(self.rng.integers(2, 5))):
            u = self._u((b_lo + 3.0, b_lo + bl - 3.0))
            v = self._u((bv0 + 3.0, bv0 + bw - 3.0))
            self._fill(*self._site_box(frame, u - 1.2, u + 1.2, v - 0.9, v + 0.9), h + 1.5,
                       SurfaceClass.ROOF_CLUTTER, Material.METAL)  # fmt: skip
        lot = self._site_box(frame, b_lo + bl + 4.0, site_l / 2 - 2.0, v0 + 2.0, v1 - 2.0)
        self._fill(*lot, 0.0, SurfaceClass.PARKING_LOT, Material.ASPHALT)
        self._paint_bays(*lot, 0.0, SurfaceClass.PARKING_LOT)

    # ------------------------------------------------------------------ park and lawns
    def _park(self) -> None:
        """A park (Props' painter: lawn, paths, maybe a pond, trees), and people across its grass."""
        length, width = self._u((80.0, 140.0)), self._u((80.0, 140.0))
        frame = self._site(length, width)
        if frame is None:
            return
        n0, n1, e0, e1 = self._site_box(frame, -length / 2, length / 2, -width / 2, width / 2)
        self._paint_park(n0, n1, e0, e1)
        a, b = (n0 + 4.0, e0 + 0.3 * (e1 - e0)), (n1 - 4.0, e0 + 0.75 * (e1 - e0))
        self.walkways.append(Walkway((a, b), int(self.rng.integers(1, 4)), 0.05, 2.0))

    def _lawn(self, near_m: float | None) -> None:
        """An open lawn (half of them marked out as a small playing field), trees along its edges and
        people crossing it."""
        length, width = self._u((40.0, 80.0)), self._u((35.0, 70.0))
        frame = self._site(length, width, near_m)
        if frame is None:
            return
        self._site_paint(frame, length, width, "all", 0.0, SurfaceClass.GRASS, Material.GRASS)
        if self.rng.random() < 0.5:
            pl, pw = length - 10.0, min(width - 10.0, 0.65 * (length - 10.0))
            self._site_paint(frame, pl, pw, "pitch_lines", None, None, Material.LANE_MARKING, pl=pl, pw=pw)
        for _ in range(int(self.rng.integers(3, 9))):
            side = float(self.rng.choice([-1.0, 1.0]))
            r = self._u((2.0, 4.0))
            u, v = self._u((-length / 2 + r, length / 2 - r)), side * (width / 2 - r)
            self.grid.fill_disc(self._local(frame, u, v), r, height_m=self._u((6.0, 12.0)), dome=True,
                                cls=SurfaceClass.TREE, mat=Material.FOLIAGE, mode="max")  # fmt: skip
        ends = [
            (-length / 2 + 2.0, self._u((-0.4, 0.4)) * width),
            (length / 2 - 2.0, self._u((-0.4, 0.4)) * width),
        ]
        if self.rng.random() < 0.5:
            ends = [(u, -v) for u, v in ends]
        pts = tuple(as_pts(np.array([self._local(frame, u, v) for u, v in ends])))
        self.walkways.append(Walkway(pts, int(self.rng.integers(1, 4)), 0.0, 2.0))

    def _open_ground(self) -> Pt | None:
        """The school first (it needs the most room), then the park, then the lawns, one near the launch
        point. Returns the school's pitch centre."""
        pitch = self._school()
        self._park()
        self._lawn(near_m=130.0)
        for _ in range(round(self.size / 400.0)):
            self._lawn(near_m=None)
        return pitch
