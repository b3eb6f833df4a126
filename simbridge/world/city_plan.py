"""The city's plan: its street grid (lanes, markings, crosswalks, sidewalks' walkways), the river and
the elevated highway, and the blocks between the streets."""

from __future__ import annotations

import math
from typing import Literal

import numpy as np

from simbridge.world.city_parts import (
    FRONTAGE_W,
    HW_LANE_W,
    PIER_H,
    RAIL_H,
    RAIL_W,
    RAMP_W,
    SIDEWALK_H,
    WATER_H,
    CityError,
    CityParts,
    Range,
    Street,
    Window,
)
from simbridge.world.model import Material, SurfaceClass
from simbridge.world.world import Lane, Walkway


class CityPlan(CityParts):
    """The city's plan: its street grid, the river, the elevated highway and the blocks."""

    def _street_frame(
        self, st: Street, across_lo: float, across_hi: float
    ) -> tuple[Window, np.ndarray, np.ndarray] | None:
        """Window over a strip of a street, offsets ``[across_lo, across_hi)`` from its centre line.

        Returns the window with broadcastable along (east or north, metres) and across-offset arrays.
        """
        a_lo, a_hi = -self.half, self.half
        if st.axis == "ew":
            got = self._box(st.centre + across_lo, st.centre + across_hi, a_lo, a_hi)
            if got is None:
                return None
            win, n, e = got
            return win, e, n - st.centre
        got = self._box(a_lo, a_hi, st.centre + across_lo, st.centre + across_hi)
        if got is None:
            return None
        win, n, e = got
        return win, n, e - st.centre

    def _street_point(self, st: Street, along: float, across: float) -> tuple[float, float]:
        if st.axis == "ew":
            return (st.centre + across, along)
        return (along, st.centre + across)

    # ------------------------------------------------------------------ layout
    def _street_size(self) -> tuple[float, float, int]:
        """Carriageway width, sidewalk width and lane count of a new street (more lanes, wider)."""
        p = self.p
        lanes = int(self.rng.integers(p.street_lanes[0], p.street_lanes[1] + 1))
        nbands = p.street_lanes[1] - p.street_lanes[0] + 1
        frac = (lanes - p.street_lanes[0] + float(self.rng.uniform())) / nbands
        width = p.street_width_m[0] + frac * (p.street_width_m[1] - p.street_width_m[0])
        return width, self._u(p.sidewalk_m), lanes

    def _layout_axis(
        self, axis: Literal["ew", "ns"], special_w: float, special_is_street: bool
    ) -> tuple[list[Street], list[Range], Range]:
        """Streets and blocks along one axis, with one special span (river column or highway corridor)."""
        p = self.p
        x = -self.half - float(self.rng.uniform(0.3, 0.9)) * p.block_m[0]
        target = float(self.rng.uniform(-0.2, 0.2)) * self.size
        streets: list[Street] = []
        blocks: list[Range] = []
        special: Range | None = None

        def due() -> bool:
            return special is None and (x >= target or x + 2 * p.block_m[1] >= self.half)

        while x < self.half:
            if not special_is_street and due():
                special = (x, x + special_w)
                x += special_w
            else:
                b = self._u(p.block_m)
                blocks.append((x, x + b))
                x += b
            if x >= self.half:
                break
            if special_is_street and due():
                st = Street(axis, x + special_w / 2, special_w - 6.0, 3.0, 2, corridor=True)
                special = (x, x + special_w)
            else:
                width, sidewalk, lanes = self._street_size()
                st = Street(axis, x + width / 2 + sidewalk, width, sidewalk, lanes)
            streets.append(st)
            x += 2 * st.half_total
        if special is None:  # pragma: no cover - the loop always places it for size_m >= 300
            raise CityError("city too small to hold the river and the highway")
        return streets, blocks, special

    # ------------------------------------------------------------------ streets
    def _paint_streets(self, ew: list[Street], ns: list[Street]) -> None:
        for st in ew + ns:  # sidewalks first: carriageways then cut through them at crossings
            fr = self._street_frame(st, -st.half_total, st.half_total)
            if fr is not None:
                self._paint_mask(
                    fr[0], np.ones((1, 1), bool), SIDEWALK_H, SurfaceClass.SIDEWALK, Material.PAVING
                )
        for st in ew + ns:
            fr = self._street_frame(st, -st.width / 2, st.width / 2)
            if fr is not None:
                self._paint_mask(fr[0], np.ones((1, 1), bool), 0.0, SurfaceClass.ROAD, Material.ASPHALT)
        for st in ew:
            self._paint_markings(st, ns)
        for st in ns:
            self._paint_markings(st, ew)
        for st in ew:
            self._paint_crosswalks(st, ns)
        for st in ns:
            self._paint_crosswalks(st, ew)

    def _marking_offsets(self, st: Street) -> tuple[list[float], list[float]]:
        """Solid and dashed line offsets across a street (metres from its centre line)."""
        half = st.width / 2
        s = st.right_sign
        solid = [-(half - 0.35), half - 0.35]
        dashed: list[float] = []
        if st.corridor:
            solid += [-(half - 6.0), half - 6.0]
            return solid, dashed
        lw = st.width / st.lanes
        fwd = math.ceil(st.lanes / 2)
        centre = s * (half - fwd * lw)
        if st.lanes == 2:
            dashed.append(centre)
        else:
            solid += [centre - 0.2, centre + 0.2]
        dashed += [s * (half - k * lw) for k in range(1, st.lanes) if k != fwd]
        return solid, dashed

    def _paint_markings(self, st: Street, crossing: list[Street]) -> None:
        fr = self._street_frame(st, -st.width / 2, st.width / 2)
        if fr is None:
            return
        win, along, across = fr
        clear = np.ones(along.shape, bool)
        for t in crossing:
            clear &= np.abs(along - t.centre) > t.width / 2 + 0.5
        lw = self._line_w(0.15)
        solid, dashed = self._marking_offsets(st)
        on_solid = np.zeros(across.shape, bool)
        for off in solid:
            on_solid |= np.abs(across - off) <= lw / 2
        on_dash = np.zeros(across.shape, bool)
        for off in dashed:
            on_dash |= np.abs(across - off) <= lw / 2
        dash = np.mod(along, 9.0) < 3.0
        mask = (on_solid & clear) | (on_dash & clear & dash)
        self._paint_mask(win, mask, None, SurfaceClass.ROAD, Material.LANE_MARKING)

    def _paint_crosswalks(self, st: Street, crossing: list[Street]) -> None:
        fr = self._street_frame(st, -st.width / 2, st.width / 2)
        if fr is None:
            return
        win, along, across = fr
        band = np.zeros(along.shape, bool)
        for t in crossing:
            depth = max(t.sidewalk, 3.0)
            d = np.abs(along - t.centre) - t.width / 2
            band |= (d >= 0.3) & (d <= 0.3 + depth)
        stripes = np.mod(across + st.width / 2, 1.0) < 0.5
        self._paint_mask(win, band, None, SurfaceClass.CROSSWALK, Material.ASPHALT)
        self._paint_mask(win, band & stripes, None, None, Material.ZEBRA)

    def _street_lanes(self, st: Street, cuts: list[Range]) -> None:
        """Lanes both ways along a street, broken where ``cuts`` (along ranges) block it."""
        p = self.p
        spans: list[Range] = []
        a = -self.half + 0.5
        for lo, hi in sorted(cuts):
            spans.append((a, lo))
            a = hi
        spans.append((a, self.half - 0.5))
        spans = [(lo, hi) for lo, hi in spans if hi - lo >= 30.0]
        half = st.width / 2
        s = st.right_sign
        if st.corridor:
            centres = [(s * (half - 3.0), True), (-s * (half - 3.0), False)]
        else:
            lw = st.width / st.lanes
            fwd = math.ceil(st.lanes / 2)
            centres = [(s * (half - (k + 0.5) * lw), k < fwd) for k in range(st.lanes)]
        for off, forward in centres:
            if not self._in_grid(st.centre + off):
                continue
            mid = 0.5 * (p.street_speed_m_s[0] + p.street_speed_m_s[1])
            speed = (self._u((p.street_speed_m_s[0], mid)), self._u((mid, p.street_speed_m_s[1])))
            rate = self._u(p.arrivals_per_min)
            for lo, hi in spans:
                pts = [self._street_point(st, lo, off), self._street_point(st, hi, off)]
                if not forward:
                    pts.reverse()
                self.lanes.append(Lane(tuple(pts), speed, rate, 0.0))

    def _between(self, crossing: list[Street]) -> list[Range]:
        """Spans (>= 10 m, inside the grid) between the carriageways of the crossing streets."""
        edges = sorted((t.centre - t.width / 2, t.centre + t.width / 2) for t in crossing)
        spans: list[Range] = []
        a = -self.half + 0.5
        for lo, hi in edges:
            spans.append((a, lo - 0.5))
            a = hi + 0.5
        spans.append((a, self.half - 0.5))
        clipped = [(max(lo, -self.half + 0.5), min(hi, self.half - 0.5)) for lo, hi in spans]
        return [(lo, hi) for lo, hi in clipped if hi - lo >= 10.0]

    def _maybe_walkway(
        self, a: tuple[float, float], b: tuple[float, float], surface_m: float, width_m: float
    ) -> None:
        """With probability ``walkway_fraction``, pedestrians walking between two points."""
        p = self.p
        if self.rng.random() < p.walkway_fraction:
            count = int(self.rng.integers(p.walkway_count[0], p.walkway_count[1] + 1))
            self.walkways.append(Walkway((a, b), count, surface_m, width_m))

    def _sidewalk_walkways(self, st: Street, crossing: list[Street]) -> None:
        for lo, hi in self._between(crossing):
            for side in (-1.0, 1.0):
                off = side * (st.width / 2 + st.sidewalk / 2)
                if self._in_grid(st.centre + off):
                    a, b = self._street_point(st, lo, off), self._street_point(st, hi, off)
                    self._maybe_walkway(a, b, SIDEWALK_H, st.sidewalk)

    # ------------------------------------------------------------------ river
    def _paint_river(self, col: Range, ew: list[Street]) -> None:
        p = self.p
        e_lo, e_hi = col
        prom = self._u(p.promenade_m)
        self._fill(-self.half, self.half, e_lo, e_hi, SIDEWALK_H, SurfaceClass.SIDEWALK, Material.PAVING)
        w_lo, w_hi = e_lo + prom, e_hi - prom
        self._fill(-self.half, self.half, w_lo, w_hi, WATER_H, SurfaceClass.WATER, Material.WATER)
        for lo, hi in self._between(ew):  # people strolling along the waterfront
            for e in (e_lo + prom / 2, e_hi - prom / 2):
                if self._in_grid(e):
                    self._maybe_walkway((lo, e), (hi, e), SIDEWALK_H, prom)
        for side, bank in ((1.0, w_lo), (-1.0, w_hi)):  # pier decks stick out from each bank
            n_piers = max(1, round(p.piers_per_km * self.size / 1000.0))
            placed: list[float] = []
            for _ in range(n_piers * 6):
                if len(placed) >= n_piers:
                    break
                width = float(self.rng.uniform(4.0, 8.0))
                length = float(self.rng.uniform(12.0, max(12.5, 0.4 * (w_hi - w_lo))))
                tee = self.rng.random() < 0.4
                head = width * 2.5 if tee else width
                c = float(self.rng.uniform(-self.half + head, self.half - head))
                if any(abs(c - st.centre) < st.half_total + head / 2 + 4.0 for st in ew):
                    continue  # keep clear of bridges
                if any(abs(c - q) < head + 6.0 for q in placed):
                    continue
                placed.append(c)
                e_a, e_b = sorted((bank - side * 0.5, bank + side * length))
                self._fill(c - width / 2, c + width / 2, e_a, e_b, PIER_H, SurfaceClass.PIER, Material.WOOD)
                if tee:
                    t_a, t_b = sorted((bank + side * (length - 4.0), bank + side * length))
                    self._fill(c - head / 2, c + head / 2, t_a, t_b, PIER_H, SurfaceClass.PIER, Material.WOOD)

    # ------------------------------------------------------------------ highway
    def _paint_highway(self, cor: Street, river: Range) -> None:
        p = self.p
        deck_w = cor.width - 2 * FRONTAGE_W
        h = self._u(p.highway_height_m)
        c = cor.centre
        half = deck_w / 2
        self._fill(c - half, c + half, -self.half, self.half, h, SurfaceClass.HIGHWAY, Material.ASPHALT)
        usable = half - RAIL_W - 0.3
        n_dir = max(2, math.floor((usable - 1.0) / HW_LANE_W))
        inner = 0.3 + 0.5
        # markings on the deck
        hw = Street("ew", c, deck_w, 0.0, 2 * n_dir)
        fr = self._street_frame(hw, -half, half)
        if fr is not None:
            win, along, across = fr
            lw = self._line_w(0.15)
            solid = np.zeros(across.shape, bool)
            dashed = np.zeros(across.shape, bool)
            for sgn in (-1.0, 1.0):
                for off in (inner, inner + n_dir * HW_LANE_W):
                    solid |= np.abs(across - sgn * off) <= lw / 2
                for k in range(1, n_dir):
                    dashed |= np.abs(across - sgn * (inner + k * HW_LANE_W)) <= lw / 2
            mask = solid | (dashed & (np.mod(along, 12.0) < 3.0))
            self._paint_mask(win, mask, None, SurfaceClass.HIGHWAY, Material.LANE_MARKING)
        # median barrier
        med = self._line_w(0.6) / 2
        self._fill(
            c - med, c + med, -self.half, self.half, h + RAIL_H, SurfaceClass.GUARD_RAIL, Material.CONCRETE
        )
        # ramps (both sides), then the edge rails with gaps where a ramp merges
        gaps: dict[float, list[Range]] = {-1.0: [], 1.0: []}
        n_ramps = max(1, round(self.size / 600.0))
        for sgn in (-1.0, 1.0):
            taken: list[Range] = [(river[0] - 15.0, river[1] + 15.0)]
            placed = 0
            for _ in range(40):
                if placed >= n_ramps:
                    break
                length = h / self._u(p.highway_ramp_grade)
                if length > self.size - 60.0:
                    continue
                a0 = float(self.rng.uniform(-self.half + 5.0, self.half - 5.0 - length))
                a1 = a0 + length
                if any(a0 < hi + 20.0 and a1 > lo - 20.0 for lo, hi in taken):
                    continue
                taken.append((a0, a1))
                placed += 1
                # the high end joins the deck; the low end meets the frontage road at street level
                descend_east = bool(self.rng.random() < 0.5)
                high_a, low_a = (a0, a1) if descend_east else (a1, a0)
                rc = c + sgn * (half + RAMP_W / 2)
                self.grid.fill_ramp((rc, high_a), (rc, low_a), RAMP_W, h, 0.0)
                rail = c + sgn * (half + RAMP_W - RAIL_W / 2)
                self.grid.fill_ramp(
                    (rail, high_a), (rail, low_a), self._line_w(RAIL_W), h + RAIL_H, RAIL_H,
                    cls=SurfaceClass.GUARD_RAIL, mat=Material.METAL,
                )  # fmt: skip
                gore = 0.3 * length
                gaps[sgn].append((a0, a0 + gore) if descend_east else (a1 - gore, a1))
        rail_w = self._line_w(RAIL_W)
        for sgn in (-1.0, 1.0):
            lo_v, hi_v = sorted((sgn * half, sgn * (half - rail_w)))
            fr = self._street_frame(hw, lo_v, hi_v)
            if fr is None:
                continue
            win, along, _ = fr
            keep = np.ones(along.shape, bool)
            for lo, hi in gaps[sgn]:
                keep &= (along < lo) | (along > hi)
            self._paint_mask(win, keep, h + RAIL_H, SurfaceClass.GUARD_RAIL, Material.METAL)
        # highway traffic: eastbound south of the median
        for sgn, forward in ((-1.0, True), (1.0, False)):
            for k in range(n_dir):
                off = sgn * (inner + (k + 0.5) * HW_LANE_W)
                if not self._in_grid(c + off):
                    continue
                pts = [(c + off, -self.half + 0.5), (c + off, self.half - 0.5)]
                if not forward:
                    pts.reverse()
                lo_s, hi_s = p.highway_speed_m_s
                mid = 0.5 * (lo_s + hi_s)
                speed = (self._u((lo_s, mid)), self._u((mid, hi_s)))
                self.lanes.append(Lane(tuple(pts), speed, self._u(p.arrivals_per_min), h))

    # ------------------------------------------------------------------ blocks
    def _paint_blocks(self, n_blocks: list[Range], e_blocks: list[Range]) -> None:
        p = self.p
        cells = [(nb, eb) for nb in n_blocks for eb in e_blocks]
        u = self.rng.random(len(cells))
        kinds: list[str] = []
        for x in u:
            if x < p.park_fraction:
                kinds.append("park")
            elif x < p.park_fraction + p.plaza_fraction:
                kinds.append("plaza")
            elif x < p.park_fraction + p.plaza_fraction + p.parking_lot_fraction:
                kinds.append("lot")
            else:
                kinds.append("buildings")

        def inside(k: int) -> bool:  # mostly within the grid
            (n0, n1), (e0, e1) = cells[k]
            return (
                n0 > -self.half - 10 and n1 < self.half + 10 and e0 > -self.half - 10 and e1 < self.half + 10
            )

        order = self.rng.permutation(len(cells))
        for need in ("park", "lot"):  # every city has at least one inside the grid
            if not any(kinds[k] == need and inside(k) for k in range(len(cells))) and len(cells) >= 6:
                for k in order:
                    if kinds[k] == "buildings" and inside(int(k)):
                        kinds[k] = need
                        break
        n_garages = max(1, round(p.parking_structures_per_km2 * (self.size / 1000.0) ** 2))
        for k in order:
            if n_garages == 0:
                break
            if kinds[k] == "buildings" and inside(int(k)):
                kinds[k] = "garage"
                n_garages -= 1
        for ((n0, n1), (e0, e1)), kind in zip(cells, kinds, strict=True):
            if kind == "park":
                self._paint_park(n0, n1, e0, e1)
            elif kind == "plaza":
                self._paint_plaza(n0, n1, e0, e1)
            elif kind == "lot":
                self._fill(
                    n0 + 0.5, n1 - 0.5, e0 + 0.5, e1 - 0.5, 0.0, SurfaceClass.PARKING_LOT, Material.ASPHALT
                )
                self._paint_bays(n0 + 0.5, n1 - 0.5, e0 + 0.5, e1 - 0.5, 0.0, SurfaceClass.PARKING_LOT)
            elif kind == "garage":
                self._paint_garage_block(n0, n1, e0, e1)
            else:
                self._paint_building_block(n0, n1, e0, e1)
