"""The waterfront's marina: pontoons out into the water with boats moored in their berths, and on the
hard standing behind the quay a boat yard (boats on trailers) and a car park.

Boats are ``VEHICLE``\\ s, afloat or on their trailers: vessels someone may be aboard, which the grader
refuses to land on and keeps a touchdown 5 m from (``GraderConfig.vehicle_m``), as it does cars. A
moored boat's hull stands 0.9-1.6 m above the water (``WATER_H``), its cabin 1-2 m higher.
"""

from __future__ import annotations

import math

import numpy as np

from simbridge.world.city_parts import PIER_H, WATER_H, Range
from simbridge.world.model import Material, SurfaceClass
from simbridge.world.waterfront_shore import QUAY_M, Pt, ShorePlan
from simbridge.world.world import Walkway

PONTOON_H = 0.3  # finger pontoons float lower than the main pier
PIER_W_M: Range = (2.5, 3.5)
PIER_GAP_M: Range = (38.0, 52.0)  # between neighbouring piers
FINGER_L_M: Range = (8.0, 11.0)
FINGER_W_M = 1.0
BERTH_M: Range = (4.5, 5.5)  # finger to finger
MOORED_FRACTION = 0.75


class MarinaParts(ShorePlan):
    """The marina's piers, boats, boat yard and car park."""

    def _paint_marina(self) -> int:
        """Everything in the marina's stretch of shore; the number of piers."""
        if self.marina is None:
            return 0
        m0, m1 = self.marina
        n_piers = 0
        s = m0 + self._u((12.0, 20.0))
        while s < m1 - 10.0:
            n_piers += self._pier(s)
            s += self._u(PIER_GAP_M)
        self._hard_standing(m0, m1)
        return n_piers

    def _along(self, root: Pt, yaw: float, u: float, v: float) -> Pt:
        """The point ``u`` metres along a heading ``yaw`` from ``root`` and ``v`` to its right."""
        c, s = math.cos(yaw), math.sin(yaw)
        return (root[0] + u * c - v * s, root[1] + u * s + v * c)

    def _pier(self, s: float) -> int:
        """A pier square to the shore with finger pontoons both sides and boats in the berths; 0 when
        there is not water enough off this stretch for one."""
        g = self.grid
        x0 = float(self._shore_x(s))
        room = self.half - x0  # water from the shore to the square's edge
        length = min(self._u((60.0, 120.0)) * min(1.0, self.size / 1200.0), 0.6 * room)
        if length < 25.0:
            return 0
        m = float(np.interp(s, self.s_tab, self.slope))
        out = self._out_yaw(m)
        root = self._ne(s, x0 - QUAY_M / 2)  # from the quay, over the water's edge
        width = self._u(PIER_W_M)
        total = length + QUAY_M / 2
        g.fill_rect(self._along(root, out, total / 2, 0.0), total, width, out, height_m=PIER_H,
                    cls=SurfaceClass.PIER, mat=Material.WOOD)  # fmt: skip
        head = self._along(root, out, total - 2.0, 0.0)
        g.fill_rect(head, 4.0, self._u((10.0, 16.0)), out, height_m=PIER_H, cls=SurfaceClass.PIER,
                    mat=Material.WOOD)  # fmt: skip
        finger, berth = self._u(FINGER_L_M), self._u(BERTH_M)
        u = QUAY_M / 2 + 8.0
        while u + berth < total - 5.0:
            for side in (-1.0, 1.0):
                v = side * (width / 2 + finger / 2)
                g.fill_rect(self._along(root, out, u, v), FINGER_W_M, finger, out, height_m=PONTOON_H,
                            cls=SurfaceClass.PIER, mat=Material.WOOD)  # fmt: skip
                if self.rng.random() < MOORED_FRACTION:
                    boat_l = min(self._u((6.0, 12.0)), finger + 2.0)
                    beam = min(self._u((2.2, 3.4)), berth - FINGER_W_M - 0.6)
                    centre = self._along(root, out, u + berth / 2, side * (width / 2 + 0.4 + boat_l / 2))
                    self._boat(centre, out + math.pi / 2, boat_l, beam, WATER_H)
            u += berth
        if self.rng.random() < 0.5:  # people walking out to their boats
            a, b = self._along(root, out, QUAY_M, 0.0), self._along(root, out, total - 3.0, 0.0)
            if all(abs(c) < self.half - 1.0 for c in (*a, *b)):
                self.walkways.append(Walkway((a, b), int(self.rng.integers(1, 3)), PIER_H, width * 0.6))
        return 1

    def _out_yaw(self, slope: float) -> float:
        """The heading square to the shoreline, out toward the water, where its slope is ``slope``."""
        # the water normal (-slope, 1) in the frame, as (north, east)
        dn = slope * self.we + self.wn
        de = -slope * self.wn + self.we
        return math.atan2(de, dn)

    def _boat(self, centre: Pt, yaw: float, length: float, beam: float, base: float) -> None:
        """A hull (its length along ``yaw``) with a cabin on it, standing on ``base``."""
        g = self.grid
        top = base + self._u((0.9, 1.6))
        g.fill_rect(centre, length, beam, yaw, height_m=top, cls=SurfaceClass.VEHICLE, mat=Material.CAR_PAINT,
                    mode="max")  # fmt: skip
        if self.rng.random() < 0.8:
            cabin = self._along(centre, yaw, self._u((-0.15, 0.05)) * length, 0.0)
            mat = Material.GLASS if self.rng.random() < 0.4 else Material.WOOD
            g.fill_rect(cabin, 0.4 * length, 0.7 * beam, yaw, height_m=top + self._u((1.0, 2.0)),
                        cls=SurfaceClass.VEHICLE, mat=mat, mode="max")  # fmt: skip

    def _hard_standing(self, m0: float, m1: float) -> None:
        """Behind the quay: the boat yard (boats on trailers in rows) and a car park at one end."""
        depth = self.front_m - QUAY_M
        park_len = min(self._u((45.0, 70.0)), 0.4 * (m1 - m0))
        at_start = self.rng.random() < 0.5
        p0, p1 = (m0, m0 + park_len) if at_start else (m1 - park_len, m1)
        y0, y1 = (p1 + 3.0, m1) if at_start else (m0, p0 - 3.0)
        # the car park: the largest frame box between the quay and the promenade over its stretch
        ss = np.linspace(p0, p1, 16)
        inner = self._inland(ss, self.front_m - 1.0)
        outer = self._inland(ss, QUAY_M + 1.0)
        _, xi = self._sx(inner[:, 0], inner[:, 1])
        _, xo = self._sx(outer[:, 0], outer[:, 1])
        x_lo, x_hi = float(xi.max()), float(xo.min())
        if x_hi - x_lo >= 18.0:
            box = self._ne_box(p0 + 2.0, p1 - 2.0, x_lo, x_hi)
            self._fill(*box, 0.0, SurfaceClass.PARKING_LOT, Material.ASPHALT)
            self._paint_bays(*box, 0.0, SurfaceClass.PARKING_LOT)
            mid = (p0 + p1) / 2
            pts = self._pts(self._inland(np.array([mid, mid]), np.array([QUAY_M + 2.0, self.front_m])), 1.0)
            if len(pts) == 2:
                self.walkways.append(Walkway(pts, int(self.rng.integers(1, 4)), 0.0, 2.0))
        # the boat yard: rows of boats on trailers square to the shore, a lane between rows
        s = y0 + 4.0
        while s < y1 - 4.0:
            yaw = self._out_yaw(float(np.interp(s, self.s_tab, self.slope)))
            length = min(self._u((6.0, 11.0)), depth - 6.0)
            if length >= 4.0 and self.rng.random() < 0.8:
                n, e = self._inland(np.array([s]), QUAY_M + 3.0 + length / 2)[0]
                self._boat((float(n), float(e)), yaw, length, self._u((2.0, 3.0)), self._u((0.6, 1.0)))
            s += self._u((4.0, 5.5))
        if y1 - y0 > 20.0:  # people working on the boats
            pts = self._pts(self._inland(np.array([y0 + 3.0, y1 - 3.0]), QUAY_M + 1.5), 1.0)
            if len(pts) == 2:
                self.walkways.append(Walkway(pts, int(self.rng.integers(1, 4)), 0.0, 2.0))
