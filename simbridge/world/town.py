"""A procedural town, generated from a seed: a downtown core, suburb neighbourhoods and an industrial
edge, each the place of its own kind, joined by arterial roads along the seams between them.

Two arterials cross the square, one north-south and one east-west, and split it into four districts.
The crossroads lies 5-12.5 % of the town's side from the launch point (60-150 m on a 1.2 km town),
diagonally away from the downtown quadrant, so the launch point (0, 0) is always inside the downtown
core, that far from either arterial. Of the other three quadrants one is the industrial edge and two are
suburbs; which is which, where the crossroads lies and the arterials' width (a 24-30 m band) come from
the town's seed.

Each district is built by its own kind's builder (:func:`~simbridge.world.city.generate_city`,
:func:`~simbridge.world.suburb.generate_suburb`, :func:`~simbridge.world.industrial.generate_industrial`)
as a square as large as the district's longer side, from a seed drawn from the town's, and pasted in
(:func:`~simbridge.world.paste.paste_world`); its lanes and walkways are cut where the arterials' band
begins. Buildings the band cuts through are cleared to grass, whole, and trees along its edge with them;
then the arterials are painted (:mod:`simbridge.world.town_roads`): grass verges, sidewalks, a four-lane
carriageway with markings, zebra crossings at the crossroads, and a mouth through the verge and a zebra
across the sidewalk wherever a district's street reaches the band, so every street meets the arterial.

Ground is flat (heights are metres up from the flat ground, as in every district). Relief, when a place
gets it, goes in one step of :meth:`_TownBuilder.build`, after the seams are painted: see the comment
there.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import numpy as np

from simbridge.world.city import generate_city
from simbridge.world.city_parts import CityError, check_place_request
from simbridge.world.industrial import generate_industrial
from simbridge.world.model import Material, SurfaceClass, WorldGrid
from simbridge.world.paste import Box, paste_world
from simbridge.world.suburb import generate_suburb
from simbridge.world.town_roads import Seam, paint_seams, seam_band_mask
from simbridge.world.world import Lane, Sun, Walkway, World

__all__ = ["District", "TownPlan", "generate_town", "plan_town"]

DistrictKind = Literal["downtown", "suburb", "industrial"]
BUILDERS: dict[DistrictKind, Callable[[int, float, float], World]] = {
    "downtown": generate_city,
    "suburb": generate_suburb,
    "industrial": generate_industrial,
}
MIN_TOWN_M = 600.0
MIN_DISTRICT_M = 300.0  # the smallest square a district's builder makes (a smaller district is cut from it)
CROSSROADS_FRACTION = (0.05, 0.125)  # of the side: how far the crossroads lies from the launch point
BAND_HALF_M = (12, 15)  # whole metres: the arterial's band is 24-30 m wide
TREE_CLEAR_M = 6.0  # trees within this of the band's edge are cleared (no half-cut crowns)


@dataclass(frozen=True, slots=True)
class District:
    """One district: its kind, its part of the town (up to the seams' centre lines) and its seed."""

    kind: DistrictKind
    area: Box
    seed: int


@dataclass(frozen=True, slots=True)
class TownPlan:
    """Where the districts and arterials lie (town NE metres), drawn from the town's seed alone."""

    size_m: float
    districts: tuple[District, ...]
    seams: tuple[Seam, ...]
    crossroads_ne: tuple[float, float]

    def district_at(self, north_m: float, east_m: float) -> District | None:
        """The district whose area holds the point (on a seam line: the first listed)."""
        return next((d for d in self.districts if d.area.contains(north_m, east_m)), None)


def _compass(centre: tuple[float, float]) -> str:
    return ("N" if centre[0] > 0 else "S") + ("E" if centre[1] > 0 else "W")


def plan_town(seed: int, size_m: float = 1200.0) -> TownPlan:
    """The town's layout from its seed: four quadrant districts round a crossroads of two arterials.

    The downtown quadrant holds the launch point (0, 0); the crossroads lies diagonally away from it by
    ``CROSSROADS_FRACTION`` of ``size_m`` along each axis (whole metres).
    """
    rng = np.random.default_rng(seed)
    half = size_m / 2
    s_n, s_e = (1.0 if rng.random() < 0.5 else -1.0 for _ in range(2))
    c_n = -s_n * round(float(rng.uniform(*CROSSROADS_FRACTION)) * size_m)
    c_e = -s_e * round(float(rng.uniform(*CROSSROADS_FRACTION)) * size_m)
    band_half = float(rng.integers(BAND_HALF_M[0], BAND_HALF_M[1] + 1))
    others: list[DistrictKind] = ["industrial", "suburb", "suburb"]
    order = rng.permutation(3)
    quadrants = [(q_n, q_e) for q_n in (1.0, -1.0) for q_e in (1.0, -1.0) if (q_n, q_e) != (s_n, s_e)]
    kinds: dict[tuple[float, float], DistrictKind] = {(s_n, s_e): "downtown"}
    for quadrant, k in zip(quadrants, order, strict=True):
        kinds[quadrant] = others[int(k)]
    districts = []
    for (q_n, q_e), kind in sorted(kinds.items(), key=lambda kv: kv[1] != "downtown"):
        n_lo, n_hi = (c_n, half) if q_n > 0 else (-half, c_n)
        e_lo, e_hi = (c_e, half) if q_e > 0 else (-half, c_e)
        districts.append(District(kind, Box(n_lo, n_hi, e_lo, e_hi), int(rng.integers(0, 2**31 - 1))))
    seams = (
        Seam("ns", c_e, -half, half, band_half),
        Seam("ew", c_n, -half, half, band_half),
    )
    return TownPlan(size_m, tuple(districts), seams, (c_n, c_e))


class _TownBuilder:
    """Builds one town from its plan: the districts pasted in, the seams cleared and the arterials painted."""

    def __init__(self, seed: int, size_m: float, res: float) -> None:
        self.seed = seed
        self.size = size_m
        self.half = size_m / 2
        self.res = res
        self.plan = plan_town(seed, size_m)
        self.grid = WorldGrid.empty((-self.half, self.half), (-self.half, self.half), res)
        self.lanes: list[Lane] = []
        self.walkways: list[Walkway] = []

    def build(self) -> World:
        region = 1
        for d in self.plan.districts:
            region = self._paste(d, region)
        band = seam_band_mask(self.grid, self.plan.seams)
        self._clear_cut_objects(band)
        rng = np.random.default_rng([self.seed, 1])  # the arterials' own stream: districts stay as drawn
        lanes, walkways = paint_seams(self.grid, self.plan.seams, rng)
        self.lanes += lanes
        self.walkways += walkways
        # Relief goes here: once a relief module gives a height field for the town's seed, add it to
        # self.grid.height (every district, the arterials and the cleared ground are painted on flat
        # ground at 0 m) and lift each lane's deck and walkway's surface by the ground under it.
        sun = Sun(float(rng.uniform(90.0, 270.0)), float(rng.uniform(35.0, 65.0)))
        parts = ", ".join(
            f"{d.kind} {_compass(d.area.centre_ne)} ({d.area.size_ne[0]:.0f} x {d.area.size_ne[1]:.0f} m)"
            for d in self.plan.districts
        )
        c_n, c_e = self.plan.crossroads_ne
        desc = (
            f"procedural town {self.size:.0f} m square, seed {self.seed}: {parts}, joined by arterial roads "
            f"crossing at {c_n:.0f} N {c_e:.0f} E; the launch point is in the downtown core"
        )
        return World(
            name="town", seed=self.seed, grid=self.grid, launch_ne_m=(0.0, 0.0), launch_height_m=100.0,
            sun=sun, safe_zones=(), lanes=tuple(self.lanes), walkways=tuple(self.walkways), description=desc,
        )  # fmt: skip

    def _paste(self, d: District, region_base: int) -> int:
        """Build district ``d`` as a square over its longer side and paste it into its area; returns the
        next free region id."""
        side = 2.0 * math.ceil(max(*d.area.size_ne, MIN_DISTRICT_M) / 2.0) + 2.0  # even metres: cells align
        world = BUILDERS[d.kind](d.seed, side, self.res)
        c_n, c_e = d.area.centre_ne
        offset = (round(c_n / self.res) * self.res, round(c_e / self.res) * self.res)
        pasted = paste_world(
            self.grid, world, offset, d.area, keep_routes=self._route_box(d.area), region_base=region_base
        )
        self.lanes += pasted.lanes
        self.walkways += pasted.walkways
        return pasted.next_region

    def _route_box(self, area: Box) -> Box:
        """A district's area less the seams' bands (and 1 m along the town's edge)."""

        def inset(x: float, towards: float) -> float:
            if abs(abs(x) - self.half) < 1e-9:
                return x + math.copysign(1.0, towards - x)
            pad = next(s.band_half_m for s in self.plan.seams) + 0.5
            return x + math.copysign(pad, towards - x)

        c_n, c_e = area.centre_ne
        return Box(inset(area.n_lo, c_n), inset(area.n_hi, c_n), inset(area.e_lo, c_e), inset(area.e_hi, c_e))

    def _clear_cut_objects(self, band: np.ndarray) -> None:
        """Clear to grass every building the band cuts through or touches (all of its cells), and
        the trees along the band's edge, so no half-cut object is left beside an arterial."""
        g = self.grid
        cut = np.unique(g.region[seam_band_mask(g, self.plan.seams, g.res)])  # flush against it: cut too
        cut = cut[cut > 0]
        gone = np.isin(g.region, cut) & ~band if cut.size else np.zeros_like(band)
        near = seam_band_mask(g, self.plan.seams, TREE_CLEAR_M) & ~band
        gone |= near & (g.cls == SurfaceClass.TREE)
        g.height[gone] = 0.05
        g.cls[gone] = SurfaceClass.GRASS
        g.mat[gone] = Material.GRASS
        g.region[gone] = 0


def generate_town(seed: int, size_m: float = 1200.0, res: float = 0.2) -> World:
    """Build a procedural town, identical for identical arguments.

    Args:
        seed: non-negative integer; the plan (:func:`plan_town`), the districts' seeds, the arterials'
            traffic and the sun are drawn from it.
        size_m: side of the square town in metres (at least 600 m); the grid spans north and east
            ``[-size_m/2, size_m/2]``.
        res: grid resolution in metres per cell (a whole number of cells per metre).

    Returns:
        A :class:`World` named ``"town"`` launching 100 m above (0, 0) in the downtown core: the painted
        grid, the districts' lanes and walkways and the arterials' own, and the sun; no safe zones
        (landings are graded from the grid's classes).

    Raises:
        CityError: a negative or non-integer seed, or a town smaller than 600 m.
    """
    check_place_request("town", seed, size_m)
    if size_m < MIN_TOWN_M:
        raise CityError(
            f"town size_m must be at least {MIN_TOWN_M:.0f} m (four districts of 300 m), got {size_m}"
        )
    return _TownBuilder(int(seed), float(size_m), res).build()
