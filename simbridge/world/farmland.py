"""Procedural farmland with a village, generated from a seed: open country where a drone meets fields
of standing crops it must not land in, pasture it may land on, hedgerows, farmyards and power lines.

The plan is neither a grid nor a street network. The land is cut into fields: a Voronoi partition of seed
points kept apart (convex polygons, mostly 2-15 ha), some of them ploughed into two to four parallel
strips. Each field (or strip) is standing crops (``CROP``, 0.3-1.6 m tall in rows 0.75 m apart with the
soil seen between them, so rough to a LiDAR; never a landing site), pasture (``GRASS``) or ploughed soil
(``GROUND`` over ``SOIL``, shallow furrows). Along the field edges run hedgerows (1.5-3 m), hedgerows with
trees, lines of trees, open margins, and now and then a farm track (gravel, ``GROUND``) with a tractor or
two on it. Two or three country roads (5-6.5 m of asphalt, no markings, no sidewalks, grass verges) wind
across the whole place; where the first two cross lies a village of detached houses under pitched roofs
with their gardens (:mod:`simbridge.world.farmland_sites`). Farmsteads stand beside the roads: a gravel or
concrete yard with barns and sheds (pitched or flat roofs), a farmhouse and its garden, machinery parked
in the yard (``MACHINERY``: tractors, trailers, a combine, stacks of bales). Power lines on wooden poles
cross the land (:mod:`simbridge.world.farmland_power`): the poles stand in the grid, the conductors are
:class:`~simbridge.world.world.Wire`\\ s sagging between them.

Cars and the odd slow tractor use the country roads and tracks (``Lane``\\ s); people walk a footpath
across the fields from the village, across pastures and across the farmyards (``Walkway``\\ s on open
ground). Everything comes from one ``np.random.default_rng(seed)`` threaded through the build, so a seed
always gives identical rasters, wires, lanes and walkways.
"""

from __future__ import annotations

from simbridge.world.city_parts import CityError, CityParams, check_place_request
from simbridge.world.farmland_power import FarmPower
from simbridge.world.farmland_sites import FarmSites
from simbridge.world.world import World

__all__ = ["CityError", "generate_farmland"]


class _FarmlandBuilder(FarmSites, FarmPower):
    """Builds one stretch of farmland from its seed: fields, edges, roads, village, farmsteads, lines."""

    def build(self, seed: int) -> World:
        self._fields()
        self._field_edges()
        roads = self._roads()
        for road in roads:
            self._paint_road(road)
        centre = self._village(roads)
        self._footpath(centre if centre is not None else (0.0, 0.0))
        n_farms = self._farmsteads(roads, centre)
        self._pasture_walks()
        n_lines = self._power_lines(centre)
        sun = self._sun((30.0, 65.0))
        desc = (
            f"procedural farmland {self.size:.0f} m square, seed {seed}: {len(self.fields)} fields, "
            f"{len(roads)} country roads, a village of {self.n_houses} houses, {n_farms} farmsteads, "
            f"{n_lines} power lines on {self.n_poles} poles"
        )
        return self._world("farmland", seed, sun, desc, wires=tuple(self.wires))


def generate_farmland(seed: int, size_m: float = 1200.0, res: float = 0.2) -> World:
    """Build procedural farmland with a village, identical for identical arguments.

    Args:
        seed: non-negative integer seeding the one ``np.random.Generator`` used for everything.
        size_m: side of the square in metres; the grid spans north and east ``[-size_m/2, size_m/2]``.
        res: grid resolution in metres per cell.

    Returns:
        A :class:`World` named ``"farmland"`` launching 100 m above (0, 0): the painted grid, the power
        lines' conductors (``World.wires``), traffic lanes on the roads and tracks, walkways on open
        ground, and the sun; no safe zones (landings are graded from the grid's classes and the wires).

    Raises:
        CityError: a negative or non-integer seed, or a place smaller than 300 m.
    """
    check_place_request("farmland", seed, size_m)
    return _FarmlandBuilder(int(seed), float(size_m), res, CityParams()).build(int(seed))
