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

The builder is in parts, one idea each: :mod:`~simbridge.world.city_plan` (streets, river, highway,
blocks), :mod:`~simbridge.world.city_props` (parks, plazas, parking), :mod:`~simbridge.world.city_buildings`
(buildings, roofs, clutter), over :mod:`~simbridge.world.city_parts` (the parameters, the grid and the
painting helpers they share).
"""

from __future__ import annotations

from simbridge.world.city_buildings import Buildings
from simbridge.world.city_parts import FRONTAGE_W, CityError, CityParams, check_place_request
from simbridge.world.city_plan import CityPlan
from simbridge.world.city_props import Props
from simbridge.world.world import Walkway, World

__all__ = ["CityError", "CityParams", "generate_city"]


class _CityBuilder(CityPlan, Props, Buildings):
    """Builds one city from its seed: the plan, then the props and the buildings in its blocks."""

    # ------------------------------------------------------------------ the whole city
    def build(self, seed: int) -> World:
        p = self.p
        river_w = self._u(p.river_width_m) + 2 * p.promenade_m[1]
        deck_w = self._u(p.highway_width_m)
        corridor_w = deck_w + 2 * FRONTAGE_W + 6.0
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
        sun = self._sun((35.0, 65.0))
        desc = (
            f"procedural city {self.size:.0f} m square, seed {seed}: {self.n_buildings} buildings, "
            f"{len(ew) + len(ns)} streets, a river and an elevated highway"
        )
        return self._world("city", seed, sun, desc, launch_height_m=110.0)


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
    check_place_request("city", seed, size_m, " (room for the river and highway)")
    builder = _CityBuilder(int(seed), float(size_m), res, params if params is not None else CityParams())
    return builder.build(int(seed))
