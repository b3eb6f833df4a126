"""What every part of the procedural city's builder shares: the city's grid and generator, the
streets' and roofs' records, and the painting helpers (:mod:`simbridge.world.city` builds with them)."""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Literal

import numpy as np

from simbridge.world.model import Material, SurfaceClass, WorldError, WorldGrid
from simbridge.world.world import Lane, Sun, Walkway, Wire, World

Window = tuple[int, int, int, int]
Range = tuple[float, float]

SIDEWALK_H = 0.15  # kerb height of sidewalks and plazas, metres
WATER_H = -0.8
PIER_H = 0.6
CAR_L, CAR_W, CAR_H = 4.5, 1.9, 1.5
STALL_W, STALL_D, AISLE_W = 2.6, 5.0, 6.5
FRONTAGE_W = 12.0  # ground road beside the elevated deck: 6 m traffic lane + 6 m ramp strip
RAMP_W = 6.0
HW_LANE_W = 3.6
RAIL_W, RAIL_H = 0.3, 0.9


class CityError(WorldError):
    """City parameters or a city request that cannot be built."""


def check_place_request(what: str, seed: object, size_m: float, why: str = "") -> None:
    """A procedural place's seed (a non-negative integer) and size (at least 300 m), or ``CityError``
    naming the place ``what`` (and ``why`` the size matters, when given)."""
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise CityError(f"{what} seed must be a non-negative integer, got {seed!r}")
    if not math.isfinite(size_m) or size_m < 300.0:
        raise CityError(f"{what} size_m must be at least 300 m{why}, got {size_m}")


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
class Street:
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
class Roof:
    region: int
    n_lo: float
    n_hi: float
    e_lo: float
    e_hi: float
    height: float
    margin: float  # parapet width + clearance


def span(lo: float, hi: float, origin: float, res: float, count: int) -> tuple[int, int]:
    """Cells ``[a, b)`` whose centres lie in ``[lo, hi)``, clipped to ``[0, count)``."""
    a = max(math.ceil((lo - origin) / res - 0.5), 0)
    b = min(math.ceil((hi - origin) / res - 0.5), count)
    return a, b


class CityParts:
    """The builder's state and painting helpers; the parts (:class:`~simbridge.world.city_plan.CityPlan`,
    :class:`~simbridge.world.city_props.Props`, :class:`~simbridge.world.city_buildings.Buildings`)
    each paint one kind of thing with them."""

    def __init__(self, seed: int, size_m: float, res: float, params: CityParams) -> None:
        self.p = params
        self.rng = np.random.default_rng(seed)
        self.half = size_m / 2
        self.size = size_m
        self.grid = WorldGrid.empty((-self.half, self.half), (-self.half, self.half), res)
        self.lanes: list[Lane] = []
        self.walkways: list[Walkway] = []
        self.clear_roofs: list[Roof] = []
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
        i0, i1 = span(n_lo, n_hi, g.n0, g.res, rows)
        j0, j1 = span(e_lo, e_hi, g.e0, g.res, cols)
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

    def _in_grid(self, x: float, margin: float = 1.0) -> bool:
        """Whether a north or east coordinate lies inside the grid, ``margin`` metres from its edges."""
        return -self.half + margin <= x <= self.half - margin

    def _u(self, r: Range) -> float:
        return float(self.rng.uniform(r[0], r[1]))

    def _new_region(self) -> int:
        rid = self.next_region
        self.next_region += 1
        return rid

    def _sun(self, elevation_deg: Range) -> Sun:
        """The sun from this place's generator: azimuth 90-270 deg (the south half), ``elevation_deg``."""
        return Sun(
            azimuth_deg=float(self.rng.uniform(90.0, 270.0)),
            elevation_deg=float(self.rng.uniform(*elevation_deg)),
        )

    def _world(
        self, name: str, seed: int, sun: Sun, description: str, *, launch_height_m: float = 100.0,
        wires: tuple[Wire, ...] = (),
    ) -> World:  # fmt: skip
        """The place built: its grid, lanes and walkways, launching ``launch_height_m`` above (0, 0); no
        safe zones (landings are graded from the grid's classes)."""
        return World(
            name=name, seed=seed, grid=self.grid, launch_ne_m=(0.0, 0.0), launch_height_m=launch_height_m,
            sun=sun, safe_zones=(), lanes=tuple(self.lanes), walkways=tuple(self.walkways),
            description=description, wires=wires,
        )  # fmt: skip

    def _clip_pt(self, pt: tuple[float, float], margin: float) -> tuple[float, float]:
        lo, hi = -self.half + margin, self.half - margin
        return (min(max(pt[0], lo), hi), min(max(pt[1], lo), hi))

    # ------------------------------------------------------------------ what the parts provide
    # declared here so that each part can call the others; theirs come first in the builder's MRO
    def _paint_bays(
        self, n_lo: float, n_hi: float, e_lo: float, e_hi: float, surf_h: float, cls: SurfaceClass
    ) -> None:
        raise NotImplementedError

    def _paint_park(self, n0: float, n1: float, e0: float, e1: float) -> None:
        raise NotImplementedError

    def _paint_plaza(self, n0: float, n1: float, e0: float, e1: float) -> None:
        raise NotImplementedError

    def _paint_garage_block(self, n0: float, n1: float, e0: float, e1: float) -> None:
        raise NotImplementedError

    def _paint_building_block(self, n0: float, n1: float, e0: float, e1: float, base: bool = True) -> None:
        raise NotImplementedError

    def _street_frame(
        self, st: Street, across_lo: float, across_hi: float
    ) -> tuple[Window, np.ndarray, np.ndarray] | None:
        raise NotImplementedError

    def _layout_axis(
        self, axis: Literal["ew", "ns"], special_w: float, special_is_street: bool
    ) -> tuple[list[Street], list[Range], Range]:
        raise NotImplementedError

    def _paint_streets(self, ew: list[Street], ns: list[Street]) -> None:
        raise NotImplementedError

    def _paint_river(self, col: Range, ew: list[Street]) -> None:
        raise NotImplementedError

    def _paint_highway(self, cor: Street, river: Range) -> None:
        raise NotImplementedError

    def _paint_blocks(self, n_blocks: list[Range], e_blocks: list[Range]) -> None:
        raise NotImplementedError

    def _street_lanes(self, st: Street, cuts: list[Range]) -> None:
        raise NotImplementedError

    def _sidewalk_walkways(self, st: Street, crossing: list[Street]) -> None:
        raise NotImplementedError

    def _street_point(self, st: Street, along: float, across: float) -> tuple[float, float]:
        raise NotImplementedError

    def _paint_building(self, n0: float, n1: float, e0: float, e1: float) -> None:
        raise NotImplementedError
