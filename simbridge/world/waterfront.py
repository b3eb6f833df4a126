"""A procedural waterfront, generated from a seed: a lake or sea shore with a beach, a promenade, a
marina and a seaside town behind them.

The plan follows the shore, not a grid. The shoreline crosses the whole square as a smooth curve (two
long waves and a wide bay off the launch point, which lies 20-40 m inland of the water), the water on
one side covering 33-42 % of the square. Inland of the shoreline, bands parallel to it:

- a sand beach along 300-650 m of the shore (``GROUND``, ``Material.SAND``) crowded with people lying or
  standing still, walking along the waterline, paddling and crossing the sand, with umbrellas (``CLOTH``
  discs 2-2.4 m up) and kiosks; elsewhere a rock revetment with lawns and trees behind it, people
  crossing them;
- a marina on one side of the beach: pontoons with finger berths out into the water, boats moored in
  them (``VEHICLE``: :mod:`~simbridge.world.waterfront_marina`), and behind the quay a boat yard with
  boats on trailers and a car park;
- a promenade (``SIDEWALK``, paving) with benches, lamp posts and strollers; the shore road (a lane each
  way) and its sidewalk;
- the town: terrace streets following the shore, cross streets square to it, blocks of mixed
  buildings (flat roofs clear or cluttered, pitched roofs), hotels with flat roofs and garden pools on
  the first row, a park and a car park (:mod:`~simbridge.world.waterfront_town`).

Everything comes from one ``np.random.default_rng(seed)`` threaded through the build, so a seed always
gives identical rasters, lanes and walkways. The parts: :mod:`~simbridge.world.waterfront_shore` (the
frame, the water and the bands), :mod:`~simbridge.world.waterfront_marina`,
:mod:`~simbridge.world.waterfront_town`, over the downtown city's painting helpers.
"""

from __future__ import annotations

from simbridge.world.city_parts import CityError, CityParams, check_place_request
from simbridge.world.waterfront_town import TownParts
from simbridge.world.world import World

__all__ = ["CityError", "generate_waterfront"]

TOWN_PARAMS = CityParams(
    height_mix=((6.0, 14.0, 0.6), (14.0, 24.0, 0.32), (24.0, 36.0, 0.08)),
    pitched_fraction=0.35,
    parapet_fraction=0.6,
    clear_roof_fraction=0.3,
    parked_occupancy=(0.4, 0.9),
)


class _WaterfrontBuilder(TownParts):
    """Builds one waterfront from its seed: the shore's bands, the beach, the marina, the town."""

    def build(self, seed: int) -> World:
        self._paint_shore()
        self._paint_beach()
        self._paint_lawns()
        n_piers = self._paint_marina()
        terraces, cross = self._paint_town()
        sun = self._sun((35.0, 65.0))
        desc = (
            f"procedural waterfront {self.size:.0f} m square, seed {seed}: a beach of "
            f"{self.beach[1] - self.beach[0]:.0f} m, a marina with {n_piers} piers, {self.n_buildings} "
            f"buildings on {terraces} terrace and {cross} cross streets, {len(self.clear_roofs)} clear roofs"
        )
        return self._world("waterfront", seed, sun, desc)


def generate_waterfront(seed: int, size_m: float = 1200.0, res: float = 0.2) -> World:
    """Build a procedural waterfront, identical for identical arguments.

    Args:
        seed: non-negative integer seeding the one ``np.random.Generator`` used for everything.
        size_m: side of the square in metres; the grid spans north and east ``[-size_m/2, size_m/2]``.
        res: grid resolution in metres per cell.

    Returns:
        A :class:`World` named ``"waterfront"`` launching 100 m above (0, 0), near the shore: the painted
        grid, traffic lanes on the shore road and the town's terrace streets, walkways (people still or
        walking on the beach, the promenade, the lawns, the piers, the park and the sidewalks) and the sun.

    Raises:
        CityError: a negative or non-integer seed, or a square smaller than 300 m.
    """
    check_place_request("waterfront", seed, size_m)
    return _WaterfrontBuilder(int(seed), float(size_m), res, TOWN_PARAMS).build(int(seed))
