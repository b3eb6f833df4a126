"""Named scenarios: the world, where the vehicle starts, and where home is.

``flat`` is open ground; ``scenario1`` and ``scenario2`` are the curated city blocks (TOML files in
simbridge/world/scenarios/); ``city`` is the procedural place of ``city_seed``, of the kind
``place`` names (:mod:`simbridge.world.places`: ``downtown``, the default, ``suburb``,
``industrial``); any path ending in ``.toml`` is loaded as a scenario file. Scenario coordinates are
NED metres from the scenario origin; the launch point is above the origin unless the scenario (or
``launch``) says otherwise.

Two seeds (DESIGN.md section 7): the episode's ``seed`` drives the traffic and pedestrians (and, in
simbridge, the sensor noise and the wind); the city's own ``city_seed`` draws the city, so one campaign
flies one city. A scenario file's random furniture (rubble, park trees, parked cars) comes from ``seed``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

from simbridge.terrain import FlatTerrain, Terrain


@dataclass(frozen=True, slots=True)
class Scenario:
    name: str
    terrain: Terrain
    launch_ne_m: tuple[float, float] = (0.0, 0.0)
    launch_height_m: float = 100.0  # above the ground under the launch point
    launch_yaw_rad: float = 0.0
    world_digest: str | None = None  # the static world's fingerprint (WorldGrid.digest); None when flat


def scenario_names() -> list[str]:
    from simbridge.world.scenario_file import builtin_scenario_names

    return ["flat", *builtin_scenario_names(), "city"]


def load_scenario(
    name: str,
    seed: int,
    launch: tuple[float, ...] | None = None,
    world_kwargs: dict[str, object] | None = None,
    *,
    city_seed: int = 0,
    place: str = "downtown",
    world_cache: Path | None = None,
) -> Scenario:
    """Build a scenario; ``launch`` = (north, east[, height above ground]) overrides its launch point.

    Args:
        name: ``flat``, a built-in scenario, ``city`` or a ``.toml`` path.
        seed: the episode's seed: the actors everywhere, a scenario file's furniture too.
        launch: (north, east[, height above ground]) metres, overriding the launch point.
        world_kwargs: keyword arguments for :class:`~simbridge.world.live.LiveWorld` (sensor models).
        city_seed: the procedural city's seed (``city`` only; ignored otherwise).
        place: the kind of place ``city`` builds (:data:`simbridge.world.places.PLACES`; ignored
            otherwise).
        world_cache: a folder where ``city`` keeps the places it builds and finds those built before
            (:mod:`simbridge.world.cache`); None: built here.

    Raises:
        ValueError: an unknown name or place (the message lists the known ones), a bad scenario file
            or a negative ``city_seed``.
    """
    if name == "flat":
        sc = Scenario(name="flat", terrain=FlatTerrain())
    else:
        from simbridge.world.live import LiveWorld

        if name == "city":
            from simbridge.world.cache import cached_place

            world = cached_place(place, city_seed, world_cache)  # CityError (a ValueError): seed < 0
        else:
            from simbridge.world.scenario_file import BUILTIN_SCENARIO_DIR, load_scenario_file

            path = Path(name) if name.endswith(".toml") else BUILTIN_SCENARIO_DIR / f"{name}.toml"
            if not path.exists():
                known = ", ".join(scenario_names())
                raise ValueError(
                    f"unknown scenario {name!r}; known scenarios: {known}, or a path to a .toml file"
                )
            world = load_scenario_file(path, seed)
        live = LiveWorld(world, actor_seed=seed, **(world_kwargs or {}))  # type: ignore[arg-type]
        sc = Scenario(
            world.name,
            live,
            world.launch_ne_m,
            world.launch_height_m,
            world.launch_yaw_rad,
            world_digest=live.world_digest,
        )
    if launch is not None:
        if len(launch) not in (2, 3):
            raise ValueError(f"launch must be N,E or N,E,HEIGHT, got {launch}")
        height = launch[2] if len(launch) == 3 else sc.launch_height_m
        sc = replace(sc, launch_ne_m=(launch[0], launch[1]), launch_height_m=height)
    return sc
