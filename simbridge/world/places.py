"""Kinds of procedural place: what ``--place`` builds for the scenario ``city`` (simbridge and
companion-bench).

Each kind has its own plan, drawn from the city seed alone (``--city-seed``): one seed, one place,
whatever the episode's seed. ``downtown`` (the street grid of flat-roofed blocks with its river and
elevated highway, :mod:`simbridge.world.city`) is the default; ``suburb`` is curving streets and
cul-de-sacs of detached houses under pitched roofs, with lawns, pools, driveways, a school's sports
field and a park (:mod:`simbridge.world.suburb`); ``industrial`` is an estate of big flat-roofed sheds,
yards with lorries and container stacks, car parks and a railway (:mod:`simbridge.world.industrial`);
``farmland`` is fields of crops, pasture and ploughed soil between hedgerows, country roads, farmyards
with barns and machinery, a village, and power lines whose conductors the sensors see
(:mod:`simbridge.world.farmland`); ``waterfront`` is a curving shore with a crowded sand beach, a
promenade, a marina of pontoons and moored boats, and a seaside town behind them
(:mod:`simbridge.world.waterfront`); ``hillside`` is a village on the sides of a valley, its ground not
level: switchback roads, houses on levelled platforms, terraced fields and woods
(:mod:`simbridge.world.hillside`); ``town`` is a downtown core, suburbs and an industrial edge joined by
arterial roads (:mod:`simbridge.world.town`).
The builders are imported when a place is built, so that naming the kinds (command-line choices)
costs nothing.
"""

from __future__ import annotations

import importlib

from simbridge.world.world import World

__all__ = ["DEFAULT_PLACE", "PLACES", "generate_place"]

# kind -> (module, builder): builder(seed) -> World
_BUILDERS: dict[str, tuple[str, str]] = {
    "downtown": ("simbridge.world.city", "generate_city"),
    "suburb": ("simbridge.world.suburb", "generate_suburb"),
    "industrial": ("simbridge.world.industrial", "generate_industrial"),
    "farmland": ("simbridge.world.farmland", "generate_farmland"),
    "waterfront": ("simbridge.world.waterfront", "generate_waterfront"),
    "hillside": ("simbridge.world.hillside", "generate_hillside"),
    "town": ("simbridge.world.town", "generate_town"),
}
PLACES: tuple[str, ...] = tuple(_BUILDERS)
DEFAULT_PLACE = "downtown"


def generate_place(place: str, seed: int) -> World:
    """The procedural place of kind ``place`` drawn from ``seed``.

    Raises:
        ValueError: an unknown kind (the message lists the known ones), or the builder's own error for
            a bad seed (``CityError``, a ValueError).
    """
    if place not in _BUILDERS:
        raise ValueError(f"unknown place {place!r}; known places: {', '.join(PLACES)}")
    module, name = _BUILDERS[place]
    builder = getattr(importlib.import_module(module), name)
    world: World = builder(seed)
    return world
