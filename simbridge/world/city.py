"""A procedural city, generated from a seed: the decisions a landing-site chooser meets in a real one.

The city is a street grid (slightly irregular blocks, 2-4 lane streets with markings, sidewalks and
zebra crossings) whose blocks hold buildings (flat roofs with parapets and rooftop clutter from none to
heavy, some pitched roofs), parking lots and parking structures, parks with trees and plazas. A river
with piers and street bridges crosses it north-south and an elevated highway with guard rails and ramps
crosses it east-west over the streets. Traffic lanes and pedestrian walkways come with it.

Everything is painted into a :class:`~simbridge.world.model.WorldGrid` over north and east
``[-size_m/2, size_m/2]`` (scenario NED metres, heights metres up from ground level). One
``np.random.default_rng(seed)`` is threaded through the whole build, so a seed always gives identical
rasters, lanes and walkways.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Literal

import numpy as np

from simbridge.world.model import ROOF_MATERIALS, Material, SurfaceClass, WorldError, WorldGrid
from simbridge.world.world import Lane, Sun, Walkway, World

Window = tuple[int, int, int, int]
Range = tuple[float, float]

_SIDEWALK_H = 0.15  # kerb height of sidewalks and plazas, metres
_WATER_H = -0.8
_PIER_H = 0.6
_CAR_L, _CAR_W, _CAR_H = 4.5, 1.9, 1.5
_STALL_W, _STALL_D, _AISLE_W = 2.6, 5.0, 6.5
_FRONTAGE_W = 12.0  # ground road beside the elevated deck: 6 m traffic lane + 6 m ramp strip
_RAMP_W = 6.0
_HW_LANE_W = 3.6
_RAIL_W, _RAIL_H = 0.3, 0.9


class CityError(WorldError):
    """City parameters or a city request that cannot be built."""


@dataclass(frozen=True, slots=True)
class CityParams:
    """The city's knobs. Ranges are ``(min, max)``; lengths in metres, speeds in m/s.

    ``height_mix`` is a tuple of ``(min_m, max_m, weight)`` building-height bands; fractions of blocks
    (``park_fraction`` etc.) are probabilities per block, the rest of the blocks hold buildings.
    """

    block_m: Range = (60.0, 110.0)
    street_width_m: Range = (10.0, 16.0)  # carriageway, kerb to kerb
    street_lanes: tuple[int, int] = (2, 4)
    sidewalk_m: Range = (2.0, 4.0)
    lot_m: Range = (14.0, 40.0)  # building footprint lots inside a block
    height_mix: tuple[tuple[float, float, float], ...] = (
        (8.0, 25.0, 0.70),
        (25.0, 60.0, 0.25),
        (60.0, 90.0, 0.05),
    )
    pitched_fraction: float = 0.12  # of low buildings (<= 20 m)
    parapet_fraction: float = 0.8  # of flat roofs
    clear_roof_fraction: float = 0.25  # flat roofs with no clutter at all
    heavy_clutter_fraction: float = 0.25  # flat roofs cluttered all over; the rest partly cluttered
    clutter_per_m2: Range = (0.02, 0.06)  # objects per m2 of cluttered zone: partial, heavy
    helipad_fraction: float = 0.2  # of clear roofs on buildings >= 25 m tall
    park_fraction: float = 0.10
    plaza_fraction: float = 0.04
    parking_lot_fraction: float = 0.08
    parking_structures_per_km2: float = 2.0
    parking_structure_height_m: Range = (10.0, 15.0)
    parked_occupancy: Range = (0.3, 0.85)
    tree_per_m2: float = 1.0 / 160.0  # in parks
    tree_radius_m: Range = (2.0, 5.0)
    tree_height_m: Range = (6.0, 14.0)
    river_width_m: Range = (45.0, 80.0)
    promenade_m: Range = (4.0, 8.0)
    piers_per_km: float = 8.0  # per bank
    highway_width_m: Range = (20.0, 28.0)
    highway_height_m: Range = (8.0, 12.0)
    highway_ramp_grade: Range = (0.05, 0.07)
    arrivals_per_min: Range = (3.0, 12.0)
    street_speed_m_s: Range = (8.0, 14.0)
    highway_speed_m_s: Range = (15.0, 25.0)
    walkway_fraction: float = 0.3  # of sidewalk segments between crossings
    walkway_count: tuple[int, int] = (2, 6)
    roof_walkway_fraction: float = 0.05  # of clear roofs

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name == "height_mix":
                continue
            if isinstance(value, tuple):
                lo, hi = value
                if not (lo > 0 and lo <= hi) and not (f.name == "parked_occupancy" and 0 <= lo <= hi):
                    raise CityError(
                        f"CityParams.{f.name} must be (min, max) with 0 < min <= max, got {value}"
                    )
            elif f.name.endswith("fraction"):
                if not 0.0 <= value <= 1.0:
                    raise CityError(f"CityParams.{f.name} must be in [0, 1], got {value}")
            elif not math.isfinite(value) or value < 0:
                raise CityError(f"CityParams.{f.name} must be a finite number >= 0, got {value}")
        if self.parked_occupancy[1] > 1.0:
            raise CityError(f"CityParams.parked_occupancy must lie in [0, 1], got {self.parked_occupancy}")
        if self.block_m[0] < 30.0:
            raise CityError(f"CityParams.block_m minimum must be >= 30 m, got {self.block_m}")
        if self.lot_m[0] < 6.0 or self.lot_m[0] * 2 > self.lot_m[1]:
            raise CityError(f"CityParams.lot_m must have min >= 6 m and max >= 2 * min, got {self.lot_m}")
        if self.street_width_m[0] / self.street_lanes[1] < 2.5:
            raise CityError(
                f"CityParams.street_width_m {self.street_width_m} is too narrow for {self.street_lanes[1]} "
                "lanes: need at least 2.5 m per lane"
            )
        if self.highway_width_m[0] < 16.0:
            raise CityError(f"CityParams.highway_width_m minimum must be >= 16 m, got {self.highway_width_m}")
        if self.highway_ramp_grade[1] >= 0.2:
            raise CityError(f"CityParams.highway_ramp_grade must be < 0.2, got {self.highway_ramp_grade}")
        if self.walkway_count[0] < 1 or self.walkway_count[1] < self.walkway_count[0]:
            raise CityError(
                f"CityParams.walkway_count must be (min >= 1, max >= min), got {self.walkway_count}"
            )
        if self.park_fraction + self.plaza_fraction + self.parking_lot_fraction > 1.0:
            raise CityError("CityParams park_fraction + plaza_fraction + parking_lot_fraction must be <= 1")
        if self.clear_roof_fraction + self.heavy_clutter_fraction > 1.0:
            raise CityError("CityParams clear_roof_fraction + heavy_clutter_fraction must be <= 1")
        if not self.height_mix:
            raise CityError("CityParams.height_mix must name at least one (min_m, max_m, weight) band")
        for band in self.height_mix:
            if len(band) != 3 or not (3.0 < band[0] <= band[1]) or band[2] < 0:
                raise CityError(
                    "CityParams.height_mix bands must be (min_m > 3, max_m >= min_m, weight >= 0), "
                    f"got {band}"
                )
        if sum(b[2] for b in self.height_mix) <= 0:
            raise CityError("CityParams.height_mix weights must not all be zero")


@dataclass(frozen=True, slots=True)
class _Street:
    """A straight street across the whole city. ``axis`` "ew" runs east (fixed north ``centre``)."""

    axis: Literal["ew", "ns"]
    centre: float
    width: float  # carriageway
    sidewalk: float
    lanes: int
    corridor: bool = False  # the ground road under the elevated highway

    @property
    def half_total(self) -> float:
        return self.width / 2 + self.sidewalk

    @property
    def right_sign(self) -> float:
        """Sign of the across coordinate on the right of forward (east / north) traffic."""
        return -1.0 if self.axis == "ew" else 1.0


@dataclass(frozen=True, slots=True)
class _Roof:
    region: int
    n_lo: float
    n_hi: float
    e_lo: float
    e_hi: float
    height: float
    margin: float  # parapet width + clearance


def _span(lo: float, hi: float, origin: float, res: float, count: int) -> tuple[int, int]:
    """Cells ``[a, b)`` whose centres lie in ``[lo, hi)``, clipped to ``[0, count)``."""
    a = max(math.ceil((lo - origin) / res - 0.5), 0)
    b = min(math.ceil((hi - origin) / res - 0.5), count)
    return a, b


class _CityBuilder:
    def __init__(self, seed: int, size_m: float, res: float, params: CityParams) -> None:
        self.p = params
        self.rng = np.random.default_rng(seed)
        self.half = size_m / 2
        self.size = size_m
        self.grid = WorldGrid.empty((-self.half, self.half), (-self.half, self.half), res)
        self.lanes: list[Lane] = []
        self.walkways: list[Walkway] = []
        self.clear_roofs: list[_Roof] = []
        self.next_region = 1
        self.n_buildings = 0

    # ------------------------------------------------------------------ painting helpers
    def _box(
        self, n_lo: float, n_hi: float, e_lo: float, e_hi: float
    ) -> tuple[Window, np.ndarray, np.ndarray] | None:
        """Window of the cells centred in an axis-aligned box.

        Returns the window with the cells' north centres as a (rows, 1) and east centres as a (1, cols)
        array, so masks built from them broadcast to the window.
        """
        g = self.grid
        rows, cols = g.shape
        i0, i1 = _span(n_lo, n_hi, g.n0, g.res, rows)
        j0, j1 = _span(e_lo, e_hi, g.e0, g.res, cols)
        if i0 >= i1 or j0 >= j1:
            return None
        n = (g.n0 + (np.arange(i0, i1) + 0.5) * g.res)[:, None]
        e = (g.e0 + (np.arange(j0, j1) + 0.5) * g.res)[None, :]
        return (i0, i1, j0, j1), n, e

    def _fill(
        self,
        n_lo: float,
        n_hi: float,
        e_lo: float,
        e_hi: float,
        height: float | np.ndarray | None,
        cls: SurfaceClass | None,
        mat: Material | None,
        region: int | None = None,
    ) -> None:
        got = self._box(n_lo, n_hi, e_lo, e_hi)
        if got is None:
            return
        win, _, _ = got
        mask = np.ones((win[1] - win[0], win[3] - win[2]), bool)
        self.grid.paint(win, mask, height, cls, mat, region, "set")

    def _paint_mask(
        self,
        win: Window,
        mask: np.ndarray,
        height: float | np.ndarray | None,
        cls: SurfaceClass | None,
        mat: Material | None,
        mode: str = "set",
    ) -> None:
        shape = (win[1] - win[0], win[3] - win[2])
        full = np.broadcast_to(mask, shape)
        if isinstance(height, np.ndarray):
            height = np.broadcast_to(height, shape)
        self.grid.paint(win, full, height, cls, mat, None, mode)

    def _line_w(self, w: float) -> float:
        """A painted line at least one cell wide."""
        return max(w, self.grid.res * 1.01)

    def _street_frame(
        self, st: _Street, across_lo: float, across_hi: float
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

    def _street_point(self, st: _Street, along: float, across: float) -> tuple[float, float]:
        if st.axis == "ew":
            return (st.centre + across, along)
        return (along, st.centre + across)

    def _in_grid(self, x: float, margin: float = 1.0) -> bool:
        """Whether a north or east coordinate lies inside the grid, ``margin`` metres from its edges."""
        return -self.half + margin <= x <= self.half - margin

    def _u(self, r: Range) -> float:
        return float(self.rng.uniform(r[0], r[1]))

    def _new_region(self) -> int:
        rid = self.next_region
        self.next_region += 1
        return rid

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
    ) -> tuple[list[_Street], list[Range], Range]:
        """Streets and blocks along one axis, with one special span (river column or highway corridor)."""
        p = self.p
        x = -self.half - float(self.rng.uniform(0.3, 0.9)) * p.block_m[0]
        target = float(self.rng.uniform(-0.2, 0.2)) * self.size
        streets: list[_Street] = []
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
                st = _Street(axis, x + special_w / 2, special_w - 6.0, 3.0, 2, corridor=True)
                special = (x, x + special_w)
            else:
                width, sidewalk, lanes = self._street_size()
                st = _Street(axis, x + width / 2 + sidewalk, width, sidewalk, lanes)
            streets.append(st)
            x += 2 * st.half_total
        if special is None:  # pragma: no cover - the loop always places it for size_m >= 300
            raise CityError("city too small to hold the river and the highway")
        return streets, blocks, special

    # ------------------------------------------------------------------ streets
    def _paint_streets(self, ew: list[_Street], ns: list[_Street]) -> None:
        for st in ew + ns:  # sidewalks first: carriageways then cut through them at crossings
            fr = self._street_frame(st, -st.half_total, st.half_total)
            if fr is not None:
                self._paint_mask(
                    fr[0], np.ones((1, 1), bool), _SIDEWALK_H, SurfaceClass.SIDEWALK, Material.PAVING
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

    def _marking_offsets(self, st: _Street) -> tuple[list[float], list[float]]:
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

    def _paint_markings(self, st: _Street, crossing: list[_Street]) -> None:
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

    def _paint_crosswalks(self, st: _Street, crossing: list[_Street]) -> None:
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

    def _street_lanes(self, st: _Street, cuts: list[Range]) -> None:
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

    def _between(self, crossing: list[_Street]) -> list[Range]:
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

    def _sidewalk_walkways(self, st: _Street, crossing: list[_Street]) -> None:
        for lo, hi in self._between(crossing):
            for side in (-1.0, 1.0):
                off = side * (st.width / 2 + st.sidewalk / 2)
                if self._in_grid(st.centre + off):
                    a, b = self._street_point(st, lo, off), self._street_point(st, hi, off)
                    self._maybe_walkway(a, b, _SIDEWALK_H, st.sidewalk)

    # ------------------------------------------------------------------ river
    def _paint_river(self, col: Range, ew: list[_Street]) -> None:
        p = self.p
        e_lo, e_hi = col
        prom = self._u(p.promenade_m)
        self._fill(-self.half, self.half, e_lo, e_hi, _SIDEWALK_H, SurfaceClass.SIDEWALK, Material.PAVING)
        w_lo, w_hi = e_lo + prom, e_hi - prom
        self._fill(-self.half, self.half, w_lo, w_hi, _WATER_H, SurfaceClass.WATER, Material.WATER)
        for lo, hi in self._between(ew):  # people strolling along the waterfront
            for e in (e_lo + prom / 2, e_hi - prom / 2):
                if self._in_grid(e):
                    self._maybe_walkway((lo, e), (hi, e), _SIDEWALK_H, prom)
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
                self._fill(c - width / 2, c + width / 2, e_a, e_b, _PIER_H, SurfaceClass.PIER, Material.WOOD)
                if tee:
                    t_a, t_b = sorted((bank + side * (length - 4.0), bank + side * length))
                    self._fill(
                        c - head / 2, c + head / 2, t_a, t_b, _PIER_H, SurfaceClass.PIER, Material.WOOD
                    )

    # ------------------------------------------------------------------ highway
    def _paint_highway(self, cor: _Street, river: Range) -> None:
        p = self.p
        deck_w = cor.width - 2 * _FRONTAGE_W
        h = self._u(p.highway_height_m)
        c = cor.centre
        half = deck_w / 2
        self._fill(c - half, c + half, -self.half, self.half, h, SurfaceClass.HIGHWAY, Material.ASPHALT)
        usable = half - _RAIL_W - 0.3
        n_dir = max(2, math.floor((usable - 1.0) / _HW_LANE_W))
        inner = 0.3 + 0.5
        # markings on the deck
        hw = _Street("ew", c, deck_w, 0.0, 2 * n_dir)
        fr = self._street_frame(hw, -half, half)
        if fr is not None:
            win, along, across = fr
            lw = self._line_w(0.15)
            solid = np.zeros(across.shape, bool)
            dashed = np.zeros(across.shape, bool)
            for sgn in (-1.0, 1.0):
                for off in (inner, inner + n_dir * _HW_LANE_W):
                    solid |= np.abs(across - sgn * off) <= lw / 2
                for k in range(1, n_dir):
                    dashed |= np.abs(across - sgn * (inner + k * _HW_LANE_W)) <= lw / 2
            mask = solid | (dashed & (np.mod(along, 12.0) < 3.0))
            self._paint_mask(win, mask, None, SurfaceClass.HIGHWAY, Material.LANE_MARKING)
        # median barrier
        med = self._line_w(0.6) / 2
        self._fill(
            c - med, c + med, -self.half, self.half, h + _RAIL_H, SurfaceClass.GUARD_RAIL, Material.CONCRETE
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
                rc = c + sgn * (half + _RAMP_W / 2)
                self.grid.fill_ramp((rc, high_a), (rc, low_a), _RAMP_W, h, 0.0)
                rail = c + sgn * (half + _RAMP_W - _RAIL_W / 2)
                self.grid.fill_ramp(
                    (rail, high_a), (rail, low_a), self._line_w(_RAIL_W), h + _RAIL_H, _RAIL_H,
                    cls=SurfaceClass.GUARD_RAIL, mat=Material.METAL,
                )  # fmt: skip
                gore = 0.3 * length
                gaps[sgn].append((a0, a0 + gore) if descend_east else (a1 - gore, a1))
        rail_w = self._line_w(_RAIL_W)
        for sgn in (-1.0, 1.0):
            lo_v, hi_v = sorted((sgn * half, sgn * (half - rail_w)))
            fr = self._street_frame(hw, lo_v, hi_v)
            if fr is None:
                continue
            win, along, _ = fr
            keep = np.ones(along.shape, bool)
            for lo, hi in gaps[sgn]:
                keep &= (along < lo) | (along > hi)
            self._paint_mask(win, keep, h + _RAIL_H, SurfaceClass.GUARD_RAIL, Material.METAL)
        # highway traffic: eastbound south of the median
        for sgn, forward in ((-1.0, True), (1.0, False)):
            for k in range(n_dir):
                off = sgn * (inner + (k + 0.5) * _HW_LANE_W)
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

    def _paint_bays(
        self, n_lo: float, n_hi: float, e_lo: float, e_hi: float, surf_h: float, cls: SurfaceClass
    ) -> None:
        """Stall markings and parked cars: double rows of stalls facing aisles along the longer side."""
        got = self._box(n_lo, n_hi, e_lo, e_hi)
        if got is None:
            return
        win, n, e = got
        along_n = (n_hi - n_lo) >= (e_hi - e_lo)
        a, c = (n - n_lo, e - e_lo) if along_n else (e - e_lo, n - n_lo)
        a_len, c_len = (n_hi - n_lo, e_hi - e_lo) if along_n else (e_hi - e_lo, n_hi - n_lo)
        module = 2 * _STALL_D + _AISLE_W
        n_mod = math.floor((c_len - 1.0) / module)
        n_stalls = math.floor((a_len - 12.0) / _STALL_W)
        if n_mod < 1 or n_stalls < 1:
            return
        c = c - 1.0
        m_idx = np.floor(c / module)
        cm = c - m_idx * module
        second = cm >= _STALL_D + _AISLE_W
        in_row = ((cm < _STALL_D) | second) & (m_idx >= 0) & (m_idx < n_mod)
        s = a - 6.0
        in_a = (s >= 0) & (s < n_stalls * _STALL_W)
        rows = in_row & in_a
        sm = np.mod(s, _STALL_W)
        lw = self._line_w(0.12)
        line = np.minimum(sm, _STALL_W - sm) <= lw / 2
        depth = np.where(second, cm - (_STALL_D + _AISLE_W), cm)
        head = np.abs(depth - np.where(second, _STALL_D, 0.0)) <= lw / 2  # back line of each row
        self._paint_mask(win, rows & (line | head), None, cls, Material.LANE_MARKING)
        occ_p = self._u(self.p.parked_occupancy) if self.p.parked_occupancy[1] > 0 else 0.0
        n_rows = 2 * n_mod
        occupied = self.rng.random((n_rows, n_stalls)) < occ_p
        jit_a = self.rng.uniform(-0.2, 0.2, (n_rows, n_stalls))
        jit_c = self.rng.uniform(-0.2, 0.2, (n_rows, n_stalls))
        row_i = np.clip(2 * m_idx + second, 0, n_rows - 1).astype(np.intp)
        st_i = np.clip(np.floor(s / _STALL_W), 0, n_stalls - 1).astype(np.intp)
        row_i, st_i = np.broadcast_arrays(row_i, st_i)
        car = (
            rows
            & occupied[row_i, st_i]
            & (np.abs(sm - _STALL_W / 2 - jit_a[row_i, st_i]) <= _CAR_W / 2)
            & (np.abs(depth - _STALL_D / 2 - jit_c[row_i, st_i]) <= _CAR_L / 2)
        )
        self._paint_mask(win, car, surf_h + _CAR_H, SurfaceClass.VEHICLE, Material.CAR_PAINT)

    def _paint_park(self, n0: float, n1: float, e0: float, e1: float) -> None:
        p = self.p
        self._fill(n0, n1, e0, e1, 0.05, SurfaceClass.GRASS, Material.GRASS)
        cn, ce = (n0 + n1) / 2, (e0 + e1) / 2
        paths: list[tuple[tuple[float, float], tuple[float, float]]] = []
        if self.rng.random() < 0.6:
            paths.append(((n0, e0), (n1, e1)) if self.rng.random() < 0.5 else ((n0, e1), (n1, e0)))
        paths.append(((n0, ce), (n1, ce)))
        if self.rng.random() < 0.6:
            paths.append(((cn, e0), (cn, e1)))
        for a, b in paths:
            w = float(self.rng.uniform(2.5, 4.0))
            self.grid.fill_polyline([a, b], w, height_m=0.05, cls=SurfaceClass.SIDEWALK, mat=Material.PAVING)
            if self.rng.random() < 0.7:
                count = int(self.rng.integers(p.walkway_count[0], p.walkway_count[1] + 1))
                pts = (self._clip_pt(a, 1.0), self._clip_pt(b, 1.0))
                self.walkways.append(Walkway(pts, count, 0.05, w))
        if self.rng.random() < 0.3:  # a pond
            r = float(self.rng.uniform(6.0, min(15.0, 0.25 * min(n1 - n0, e1 - e0))))
            pn = float(self.rng.uniform(n0 + r + 3, n1 - r - 3))
            pe = float(self.rng.uniform(e0 + r + 3, e1 - r - 3))
            self.grid.fill_disc((pn, pe), r, height_m=-0.5, cls=SurfaceClass.WATER, mat=Material.WATER)
        n_trees = round((n1 - n0) * (e1 - e0) * p.tree_per_m2)
        for _ in range(n_trees):
            r = self._u(p.tree_radius_m)
            h = self._u(p.tree_height_m)
            if n1 - n0 < 2 * r + 2 or e1 - e0 < 2 * r + 2:
                continue
            for _try in range(4):
                tn = float(self.rng.uniform(n0 + r + 0.5, n1 - r - 0.5))
                te = float(self.rng.uniform(e0 + r + 0.5, e1 - r - 0.5))
                if self.grid.class_at(tn, te) in (SurfaceClass.GRASS, SurfaceClass.TREE):
                    self.grid.fill_disc(
                        (tn, te),
                        r,
                        height_m=h,
                        dome=True,
                        cls=SurfaceClass.TREE,
                        mat=Material.FOLIAGE,
                        mode="max",
                    )
                    break

    def _clip_pt(self, pt: tuple[float, float], margin: float) -> tuple[float, float]:
        lo, hi = -self.half + margin, self.half - margin
        return (min(max(pt[0], lo), hi), min(max(pt[1], lo), hi))

    def _paint_plaza(self, n0: float, n1: float, e0: float, e1: float) -> None:
        p = self.p
        self._fill(n0, n1, e0, e1, _SIDEWALK_H, SurfaceClass.SIDEWALK, Material.PAVING)
        cn, ce = (n0 + n1) / 2, (e0 + e1) / 2
        r = float(self.rng.uniform(3.0, 6.0))
        self.grid.fill_disc((cn, ce), r + 0.5, height_m=0.5, cls=SurfaceClass.GROUND, mat=Material.CONCRETE)
        self.grid.fill_disc((cn, ce), r, height_m=-0.1, cls=SurfaceClass.WATER, mat=Material.WATER)
        for fn, fe in ((0.2, 0.2), (0.2, 0.8), (0.8, 0.2), (0.8, 0.8), (0.5, 0.15), (0.5, 0.85)):
            if self.rng.random() < 0.8:
                tr = float(self.rng.uniform(2.0, 3.5))
                tn, te = n0 + fn * (n1 - n0), e0 + fe * (e1 - e0)
                h = self._u(p.tree_height_m)
                self.grid.fill_disc(
                    (tn, te),
                    tr,
                    height_m=h,
                    dome=True,
                    cls=SurfaceClass.TREE,
                    mat=Material.FOLIAGE,
                    mode="max",
                )
        for a, b in (((n0 + 3, e0 + 3), (n1 - 3, e1 - 3)), ((n0 + 3, e1 - 3), (n1 - 3, e0 + 3))):
            count = int(self.rng.integers(p.walkway_count[0], p.walkway_count[1] + 1))
            self.walkways.append(
                Walkway((self._clip_pt(a, 1.0), self._clip_pt(b, 1.0)), count, _SIDEWALK_H, 3.0)
            )

    def _paint_garage_block(self, n0: float, n1: float, e0: float, e1: float) -> None:
        """A parking structure at one end of the block, buildings on the rest."""
        p = self.p
        along_n = (n1 - n0) >= (e1 - e0)
        length = float(self.rng.uniform(45.0, 70.0))
        lo, hi = (n0, n1) if along_n else (e0, e1)
        if hi - lo - length < 25.0:
            length = hi - lo
        at_start = bool(self.rng.random() < 0.5)
        g_lo, g_hi = (lo, lo + length) if at_start else (hi - length, hi)
        if along_n:
            gn0, gn1, ge0, ge1 = g_lo + 2.0, g_hi - 2.0, e0 + 2.0, e1 - 2.0
        else:
            gn0, gn1, ge0, ge1 = n0 + 2.0, n1 - 2.0, g_lo + 2.0, g_hi - 2.0
        self._fill(n0, n1, e0, e1, 0.0, SurfaceClass.GROUND, Material.CONCRETE)
        h = self._u(p.parking_structure_height_m)
        rid = self._new_region()
        self.n_buildings += 1
        self._fill(gn0, gn1, ge0, ge1, h + 1.0, SurfaceClass.PARAPET, Material.CONCRETE, rid)
        pw = self._line_w(0.3)
        self._fill(
            gn0 + pw, gn1 - pw, ge0 + pw, ge1 - pw, h, SurfaceClass.PARKING_ROOF, Material.CONCRETE, rid
        )
        self._paint_bays(gn0 + pw, gn1 - pw, ge0 + pw, ge1 - pw, h, SurfaceClass.PARKING_ROOF)
        # stair / lift core in a corner
        cn = gn0 + pw + 3.0 if self.rng.random() < 0.5 else gn1 - pw - 3.0
        ce = ge0 + pw + 2.5 if self.rng.random() < 0.5 else ge1 - pw - 2.5
        self._fill(
            cn - 3.0, cn + 3.0, ce - 2.5, ce + 2.5, h + 3.0, SurfaceClass.ROOF_CLUTTER, Material.CONCRETE
        )
        if length < hi - lo:
            r_lo, r_hi = (g_hi, hi) if at_start else (lo, g_lo)
            if along_n:
                self._paint_building_block(r_lo, r_hi, e0, e1, base=False)
            else:
                self._paint_building_block(n0, n1, r_lo, r_hi, base=False)

    def _paint_building_block(self, n0: float, n1: float, e0: float, e1: float, base: bool = True) -> None:
        p = self.p
        if base:
            self._fill(n0, n1, e0, e1, 0.0, SurfaceClass.GROUND, Material.CONCRETE)
        stack = [(n0 + 1.0, n1 - 1.0, e0 + 1.0, e1 - 1.0)]
        lots: list[tuple[float, float, float, float]] = []
        while stack:
            a0, a1, b0, b1 = stack.pop()
            dn, de = a1 - a0, b1 - b0
            big = max(dn, de)
            if big <= p.lot_m[1] or big < 2 * p.lot_m[0]:
                lots.append((a0, a1, b0, b1))
                continue
            f = float(self.rng.uniform(0.35, 0.65))
            if dn >= de:
                cut = min(max(a0 + f * dn, a0 + p.lot_m[0]), a1 - p.lot_m[0])
                stack += [(a0, cut, b0, b1), (cut, a1, b0, b1)]
            else:
                cut = min(max(b0 + f * de, b0 + p.lot_m[0]), b1 - p.lot_m[0])
                stack += [(a0, a1, b0, cut), (a0, a1, cut, b1)]
        for a0, a1, b0, b1 in lots:
            if self.rng.random() < 0.05:
                continue  # an empty yard
            gap = 0.0 if self.rng.random() < 0.35 else float(self.rng.uniform(1.0, 4.0))
            self._paint_building(a0 + gap / 2, a1 - gap / 2, b0 + gap / 2, b1 - gap / 2)

    def _building_height(self, dn: float, de: float) -> float:
        mix = self.p.height_mix
        w = np.array([b[2] for b in mix], float)
        k = int(self.rng.choice(len(mix), p=w / w.sum()))
        h = float(self.rng.uniform(mix[k][0], mix[k][1]))
        return min(h, max(mix[0][0], 5.0 * min(dn, de)))  # no needles

    def _paint_building(self, n0: float, n1: float, e0: float, e1: float) -> None:
        p = self.p
        dn, de = n1 - n0, e1 - e0
        if dn < 5.0 or de < 5.0:
            return
        rid = self._new_region()
        self.n_buildings += 1
        h = self._building_height(dn, de)
        if h <= 20.0 and min(dn, de) <= 30.0 and self.rng.random() < p.pitched_fraction:
            length, width, yaw = (dn, de, 0.0) if dn >= de else (de, dn, math.pi / 2)
            ridge = h + float(self.rng.uniform(0.25, 0.6)) * width / 2
            mat = Material.TILES if self.rng.random() < 0.75 else Material.METAL
            self._fill(n0, n1, e0, e1, h, SurfaceClass.ROOF_PITCHED, mat, rid)  # covers rect_mask edge cells
            self.grid.fill_pitched(
                ((n0 + n1) / 2, (e0 + e1) / 2), length, width, yaw, h, ridge, region=rid, mat=mat
            )
            if self.rng.random() < 0.4:  # a chimney
                v = float(self.rng.uniform(-0.3, 0.3)) * width
                u = float(self.rng.uniform(-0.35, 0.35)) * length
                local = h + (ridge - h) * (1.0 - abs(v) / (width / 2))
                cn, ce = (
                    ((n0 + n1) / 2 + u, (e0 + e1) / 2 + v)
                    if yaw == 0.0
                    else ((n0 + n1) / 2 + v, (e0 + e1) / 2 + u)
                )
                self._fill(
                    cn - 0.4,
                    cn + 0.4,
                    ce - 0.4,
                    ce + 0.4,
                    local + 1.2,
                    SurfaceClass.ROOF_CLUTTER,
                    Material.BRICK,
                )
            return
        weights = np.array([0.3, 0.25, 0.2, 0.2, 0.05])
        roof_mat = ROOF_MATERIALS[int(self.rng.choice(len(ROOF_MATERIALS), p=weights))]
        margin = 0.5
        if self.rng.random() < p.parapet_fraction:
            pw = self._line_w(float(self.rng.uniform(0.3, 0.5)))
            ph = float(self.rng.uniform(0.8, 1.2))
            pmat = Material.CONCRETE if self.rng.random() < 0.7 else Material.BRICK
            self._fill(n0, n1, e0, e1, h + ph, SurfaceClass.PARAPET, pmat, rid)
            self._fill(n0 + pw, n1 - pw, e0 + pw, e1 - pw, h, SurfaceClass.ROOF_FLAT, roof_mat, rid)
            margin += pw
        else:
            self._fill(n0, n1, e0, e1, h, SurfaceClass.ROOF_FLAT, roof_mat, rid)
        roof = _Roof(rid, n0, n1, e0, e1, h, margin)
        x = self.rng.random()
        if x < p.clear_roof_fraction:
            self.clear_roofs.append(roof)
            if h >= 25.0 and min(dn, de) >= 18.0 and self.rng.random() < p.helipad_fraction:
                self._paint_helipad(roof)
        elif x < p.clear_roof_fraction + p.heavy_clutter_fraction:
            self._paint_clutter(
                roof, (n0 + margin, n1 - margin, e0 + margin, e1 - margin), p.clutter_per_m2[1]
            )
        else:
            zn0, zn1, ze0, ze1 = n0 + margin, n1 - margin, e0 + margin, e1 - margin
            f = float(self.rng.uniform(0.3, 0.55))
            side = int(self.rng.integers(0, 4))
            if side == 0:
                zn1 = zn0 + f * (zn1 - zn0)
            elif side == 1:
                zn0 = zn1 - f * (zn1 - zn0)
            elif side == 2:
                ze1 = ze0 + f * (ze1 - ze0)
            else:
                ze0 = ze1 - f * (ze1 - ze0)
            self._paint_clutter(roof, (zn0, zn1, ze0, ze1), p.clutter_per_m2[0])

    def _paint_helipad(self, roof: _Roof) -> None:
        cn, ce = (roof.n_lo + roof.n_hi) / 2, (roof.e_lo + roof.e_hi) / 2
        r = min(9.0, min(roof.n_hi - roof.n_lo, roof.e_hi - roof.e_lo) / 2 - roof.margin - 1.0)
        got = self._box(cn - r, cn + r, ce - r, ce + r)
        if got is None or r < 4.0:
            return
        win, n, e = got
        dn, de = n - cn, e - ce
        d = np.hypot(dn, de)
        lw = self._line_w(0.4)
        ring = np.abs(d - (r - lw)) <= lw / 2
        hs = 0.55 * r
        bars = (np.abs(np.abs(de) - 0.4 * hs) <= lw) & (np.abs(dn) <= hs)
        cross = (np.abs(dn) <= lw) & (np.abs(de) <= 0.4 * hs)
        self._paint_mask(win, ring | bars | cross, None, None, Material.PAINT_TEXT)

    def _paint_clutter(self, roof: _Roof, zone: tuple[float, float, float, float], density: float) -> None:
        """Rooftop objects inside ``zone``, ``density`` per m2; heights absolute (roof + object)."""
        zn0, zn1, ze0, ze1 = zone
        zdn, zde = zn1 - zn0, ze1 - ze0
        if zdn < 1.0 or zde < 1.0:
            return
        h = roof.height
        rng = self.rng
        count = min(80, max(1, round(zdn * zde * density)))
        kinds = ("hvac", "vent", "pipe", "dome", "antenna", "dish", "solar", "rubble", "penthouse")
        weights = np.array([0.33, 0.17, 0.1, 0.06, 0.07, 0.05, 0.11, 0.04, 0.07])
        thin = self._line_w(0.3)
        have_penthouse = False
        for _ in range(count):
            kind = kinds[int(rng.choice(len(kinds), p=weights))]
            if kind == "penthouse" and (have_penthouse or h < 20.0):
                kind = "hvac"  # one stair / lift housing, on taller buildings only
            have_penthouse |= kind == "penthouse"
            if kind in ("vent", "dish", "dome"):
                r_range = {"vent": (0.2, 0.5), "dish": (0.5, 1.2), "dome": (1.0, 3.0)}[kind]
                r = min(max(self._u(r_range), 0.75 * self.grid.res), zdn / 2, zde / 2)
                cn, ce = self._place(zone, 2 * r, 2 * r)
                if kind == "dome":
                    self._dome(cn, ce, r, h, float(rng.uniform(0.8, 2.5)))
                else:
                    top = h + (float(rng.uniform(0.5, 1.5)) if kind == "vent" else 1.2)
                    self.grid.fill_disc(
                        (cn, ce), r, height_m=top, cls=SurfaceClass.ROOF_CLUTTER, mat=Material.METAL
                    )
                continue
            # box-shaped objects: footprint (north, east) metres, height above the roof, material
            if kind == "hvac":
                sn, se, dh, mat = (
                    self._u((1.5, 4.0)),
                    self._u((1.5, 4.0)),
                    self._u((1.0, 2.5)),
                    Material.METAL,
                )
            elif kind == "penthouse":
                sn, se, dh, mat = (
                    self._u((3.0, 6.0)),
                    self._u((3.0, 6.0)),
                    self._u((2.5, 4.0)),
                    Material.CONCRETE,
                )
            elif kind == "pipe":
                length, dh, mat = self._u((4.0, 15.0)), self._u((0.4, 0.8)), Material.METAL
                sn, se = (length, thin) if rng.random() < 0.5 else (thin, length)
            elif kind == "antenna":
                sn, se, dh, mat = thin, thin, self._u((3.0, 8.0)), Material.METAL
            elif kind == "solar":
                sn, se, dh, mat = self._u((4.0, 14.0)), self._u((3.0, 10.0)), 0.0, Material.SOLAR
            else:  # rubble
                sn, se, dh, mat = self._u((2.0, 6.0)), self._u((2.0, 6.0)), 0.0, Material.RUBBLE
            sn, se = min(sn, zdn), min(se, zde)
            cn, ce = self._place(zone, sn, se)
            box = (cn - sn / 2, cn + sn / 2, ce - se / 2, ce + se / 2)
            if kind == "solar":
                self._solar(*box, h)
            elif kind == "rubble":
                self._rubble(*box, h)
            else:
                self._fill(*box, h + dh, SurfaceClass.ROOF_CLUTTER, mat)

    def _place(self, zone: tuple[float, float, float, float], sn: float, se: float) -> tuple[float, float]:
        """A centre for an ``sn`` x ``se`` object inside the zone."""
        zn0, zn1, ze0, ze1 = zone
        return (
            float(self.rng.uniform(zn0 + sn / 2, max(zn1 - sn / 2, zn0 + sn / 2 + 1e-6))),
            float(self.rng.uniform(ze0 + se / 2, max(ze1 - se / 2, ze0 + se / 2 + 1e-6))),
        )

    def _dome(self, cn: float, ce: float, r: float, base: float, dome_h: float) -> None:
        """A spherical cap of height ``dome_h`` standing on a roof at ``base`` (painted with mode max)."""
        got = self._box(cn - r, cn + r, ce - r, ce + r)
        if got is None:
            return
        win, n, e = got
        d2 = (n - cn) ** 2 + (e - ce) ** 2
        heights = (base + dome_h * np.sqrt(np.clip(1.0 - d2 / r**2, 0.0, 1.0))).astype(np.float32)
        self._paint_mask(win, d2 <= r**2, heights, SurfaceClass.ROOF_CLUTTER, Material.METAL, mode="max")

    def _rubble(self, n0: float, n1: float, e0: float, e1: float, roof_h: float) -> None:
        """A patch of debris, 0.05-0.6 m above the roof, cell by cell."""
        got = self._box(n0, n1, e0, e1)
        if got is None:
            return
        win = got[0]
        shape = (win[1] - win[0], win[3] - win[2])
        heights = (roof_h + self.rng.uniform(0.05, 0.6, shape)).astype(np.float32)
        self._paint_mask(win, np.ones(shape, bool), heights, SurfaceClass.ROOF_CLUTTER, Material.RUBBLE)

    def _solar(self, n0: float, n1: float, e0: float, e1: float, roof_h: float) -> None:
        """Rows of tilted panels (1.2 m deep, 0.8 m apart) rising 0.3 -> 1.0 m above the roof."""
        got = self._box(n0, n1, e0, e1)
        if got is None:
            return
        win, n, _ = got
        phase = np.mod(n - n0, 2.0)
        mask = np.broadcast_to(phase < 1.2, (win[1] - win[0], win[3] - win[2]))
        heights = (roof_h + 0.3 + 0.7 * np.minimum(phase, 1.2) / 1.2).astype(np.float32)
        self._paint_mask(win, mask, heights, SurfaceClass.ROOF_CLUTTER, Material.SOLAR)

    # ------------------------------------------------------------------ the whole city
    def build(self, seed: int) -> World:
        p = self.p
        river_w = self._u(p.river_width_m) + 2 * p.promenade_m[1]
        deck_w = self._u(p.highway_width_m)
        corridor_w = deck_w + 2 * _FRONTAGE_W + 6.0
        ns, e_blocks, river = self._layout_axis("ns", river_w, special_is_street=False)
        ew, n_blocks, _ = self._layout_axis("ew", corridor_w, special_is_street=True)
        cor = next(st for st in ew if st.corridor)
        self._paint_river(river, ew)
        self._paint_streets(ew, ns)
        self._paint_blocks(n_blocks, e_blocks)
        self._paint_highway(cor, river)
        for st in ew:
            self._street_lanes(st, [])
            self._sidewalk_walkways(st, ns)
        cut = (cor.centre - cor.width / 2 - 3.0, cor.centre + cor.width / 2 + 3.0)
        for st in ns:
            self._street_lanes(st, [cut])
            self._sidewalk_walkways(st, ew)
        roofs = [
            r
            for r in self.clear_roofs
            if min(r.n_hi - r.n_lo, r.e_hi - r.e_lo) >= 8.0
            and all(self._in_grid(x, 0.0) for x in (r.n_lo, r.n_hi, r.e_lo, r.e_hi))
        ]
        picked = [r for r in roofs if self.rng.random() < p.roof_walkway_fraction]
        if not picked and roofs:
            picked = [roofs[int(self.rng.integers(0, len(roofs)))]]
        for r in picked:
            m = r.margin + 1.0
            if r.n_hi - r.n_lo >= r.e_hi - r.e_lo:
                ce = (r.e_lo + r.e_hi) / 2
                pts = ((r.n_lo + m, ce), (r.n_hi - m, ce))
            else:
                cn = (r.n_lo + r.n_hi) / 2
                pts = ((cn, r.e_lo + m), (cn, r.e_hi - m))
            pts = (self._clip_pt(pts[0], 1.0), self._clip_pt(pts[1], 1.0))
            self.walkways.append(Walkway(pts, int(self.rng.integers(1, 3)), r.height, 1.5))
        sun = Sun(
            azimuth_deg=float(self.rng.uniform(90.0, 270.0)),
            elevation_deg=float(self.rng.uniform(35.0, 65.0)),
        )
        desc = (
            f"procedural city {self.size:.0f} m square, seed {seed}: {self.n_buildings} buildings, "
            f"{len(ew) + len(ns)} streets, a river and an elevated highway"
        )
        return World(
            name="city", seed=seed, grid=self.grid, launch_ne_m=(0.0, 0.0), launch_height_m=110.0, sun=sun,
            safe_zones=(), lanes=tuple(self.lanes), walkways=tuple(self.walkways), description=desc,
        )  # fmt: skip


def generate_city(
    seed: int, size_m: float = 1200.0, res: float = 0.2, params: CityParams | None = None
) -> World:
    """Build a procedural city, identical for identical arguments.

    Args:
        seed: non-negative integer seeding the one ``np.random.Generator`` used for everything.
        size_m: side of the square city in metres; the grid spans north and east ``[-size_m/2, size_m/2]``.
        res: grid resolution in metres per cell.
        params: the city's knobs; defaults to :class:`CityParams()`.

    Returns:
        A :class:`World` named ``"city"`` with the painted grid, traffic lanes (streets at 0 m, the
        highway at its deck height), pedestrian walkways (sidewalks, parks, plazas, a few roofs) and
        the sun; no safe zones (landings in the city are graded from the grid's classes).

    Raises:
        CityError: a negative seed, a city smaller than 300 m, or bad ``params``.
    """
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise CityError(f"city seed must be a non-negative integer, got {seed!r}")
    if not math.isfinite(size_m) or size_m < 300.0:
        raise CityError(f"city size_m must be at least 300 m (room for the river and highway), got {size_m}")
    builder = _CityBuilder(int(seed), float(size_m), res, params if params is not None else CityParams())
    return builder.build(int(seed))
