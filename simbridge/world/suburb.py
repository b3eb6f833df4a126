"""A procedural suburb, generated from a seed: the low, green, mostly residential place a drone meets
outside a city, where open ground to land on lies between pitched roofs, gardens, pools and cars.

The plan is organic, not a grid. A few gently curving collector roads (7-8 m of asphalt with a dashed
centre line, sidewalks both sides, slow traffic each way) cross the whole place, one of them past the
launch point. Open ground is claimed next: a school with its sports field (a marked pitch, a running
track round it on a large place, the building and its car park), a park with trees, paths and maybe a
pond, and a few open lawns and small playing fields, one near the launch point. Residential streets
(6-7 m, no markings) then branch off the collectors and off each other wherever the land is free:
crescents that loop back to the road they leave and cul-de-sacs ending in a turning circle. Lots line
both sides of every street: a lawn with a detached house under a pitched roof (25-45 degrees; tiles,
shingle, slate, standing seam or corrugated sheet; a third of the wide ones L-shaped), a driveway with
cars, and now and then a pool, a shed, hedges and fences on the boundaries and garden trees. What is
left is grass with clumps of trees. People walk on the collectors' sidewalks and across the open
ground (the park, the sports field and its track, the lawns).

Everything is painted into a :class:`~simbridge.world.model.WorldGrid` over north and east
``[-size_m/2, size_m/2]`` (scenario NED metres, heights metres up from the flat ground). One
``np.random.default_rng(seed)`` is threaded through the whole build, so a seed always gives identical
rasters, lanes and walkways. Each street, site and lot claims its land on a coarse claim raster before
it is painted, so later pieces never overlap earlier ones.

The builder is in parts: :mod:`~simbridge.world.suburb_plan` (the streets, the claims, traffic),
:mod:`~simbridge.world.suburb_sites` (school, park, lawns), :mod:`~simbridge.world.suburb_lots` (lots
and houses), over the city's painting helpers (:class:`~simbridge.world.city_parts.CityParts`) and park
painter (:class:`~simbridge.world.city_props.Props`).
"""

from __future__ import annotations

from simbridge.world.city_parts import CityError, check_place_request
from simbridge.world.model import Material, SurfaceClass
from simbridge.world.suburb_lots import SuburbLots
from simbridge.world.suburb_sites import SuburbSites
from simbridge.world.world import World

__all__ = ["CityError", "generate_suburb"]

CLUMPS_PER_M2 = 1.0 / 2500.0  # tree clumps tried on the land left over


class _SuburbBuilder(SuburbSites, SuburbLots):
    """Builds one suburb from its seed: collectors, open ground, residential streets, lots, leftovers."""

    def build(self, seed: int) -> World:
        collectors = self._collectors()
        pitch = self._open_ground()
        local = self._local_streets(collectors)
        self._paint_roads(collectors, local)
        self._paint_lots(collectors + local)
        self._tree_clumps()
        for road in collectors:
            self._collector_traffic(road)
        sun = self._sun((35.0, 65.0))
        school = (
            "no school"
            if pitch is None
            else f"a school with its sports field at {pitch[0]:.0f} N {pitch[1]:.0f} E"
        )
        desc = (
            f"procedural suburb {self.size:.0f} m square, seed {seed}: {self.n_buildings} buildings on "
            f"{len(collectors)} collector roads and {len(local)} residential streets, {school}, "
            "a park and open lawns"
        )
        return self._world("suburb", seed, sun, desc)

    def _tree_clumps(self) -> None:
        """Clumps of one to five trees on grass nothing has claimed (the land between the lots)."""
        n = round(self.size**2 * CLUMPS_PER_M2)
        for _ in range(n):
            cn, ce = self._u((-self.half, self.half)), self._u((-self.half, self.half))
            if self.claim.class_at(cn, ce) != SurfaceClass.UNKNOWN:
                continue
            for _k in range(int(self.rng.integers(1, 6))):
                tn, te = cn + self._u((-8.0, 8.0)), ce + self._u((-8.0, 8.0))
                r = self._u((2.0, 4.5))
                if self._rect_free((tn, te), 2 * r, 2 * r, 0.0):
                    self.grid.fill_disc((tn, te), r, height_m=self._u((5.0, 13.0)), dome=True,
                                        cls=SurfaceClass.TREE, mat=Material.FOLIAGE, mode="max")  # fmt: skip


def generate_suburb(seed: int, size_m: float = 1200.0, res: float = 0.2) -> World:
    """Build a procedural suburb, identical for identical arguments.

    Args:
        seed: non-negative integer seeding the one ``np.random.Generator`` used for everything.
        size_m: side of the square suburb in metres; the grid spans north and east ``[-size_m/2, size_m/2]``.
        res: grid resolution in metres per cell.

    Returns:
        A :class:`World` named ``"suburb"`` launching 100 m above (0, 0), with the painted grid, traffic
        lanes on the collector roads, pedestrian walkways (sidewalks and open ground) and the sun; no safe
        zones (landings are graded from the grid's classes).

    Raises:
        CityError: a negative or non-integer seed, or a suburb smaller than 300 m.
    """
    check_place_request("suburb", seed, size_m)
    return _SuburbBuilder(int(seed), float(size_m), res).build(int(seed))
