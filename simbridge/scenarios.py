"""Named scenarios: the world, where the vehicle starts, and where home is.

``flat`` is open ground; ``scenario1`` and ``scenario2`` are the curated city blocks (TOML files in
simbridge/world/scenarios/); ``city`` is the procedural city for a seed; any path ending in ``.toml``
is loaded as a scenario file. Scenario coordinates are NED metres from the scenario origin; the
launch point is above the origin unless the scenario (or ``launch``) says otherwise.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from simbridge.terrain import FlatTerrain, Terrain


@dataclass(frozen=True, slots=True)
class Scenario:
    name: str
    terrain: Terrain
    launch_ne_m: tuple[float, float] = (0.0, 0.0)
    launch_height_m: float = 100.0  # above the ground under the launch point
    launch_yaw_rad: float = 0.0


def scenario_names() -> list[str]:
    from simbridge.world.scenario_file import builtin_scenario_names

    return ["flat", *builtin_scenario_names(), "city"]


def load_scenario(
    name: str,
    seed: int,
    launch: tuple[float, ...] | None = None,
    world_kwargs: dict[str, object] | None = None,
) -> Scenario:
    """Build a scenario; ``launch`` = (north, east[, height above ground]) overrides its launch point.

    Raises:
        ValueError: an unknown name (the message lists the known ones) or a bad scenario file.
    """
    if name == "flat":
        sc = Scenario(name="flat", terrain=FlatTerrain())
    else:
        from simbridge.world.live import LiveWorld

        if name == "city":
            from simbridge.world.city import generate_city

            world = generate_city(seed)
        else:
            from simbridge.world.scenario_file import BUILTIN_SCENARIO_DIR, load_scenario_file

            path = Path(name) if name.endswith(".toml") else BUILTIN_SCENARIO_DIR / f"{name}.toml"
            if not path.exists():
                known = ", ".join(scenario_names())
                raise ValueError(
                    f"unknown scenario {name!r}; known scenarios: {known}, or a path to a .toml file"
                )
            world = load_scenario_file(path, seed)
        live = LiveWorld(world, **(world_kwargs or {}))  # type: ignore[arg-type]
        sc = Scenario(world.name, live, world.launch_ne_m, world.launch_height_m, world.launch_yaw_rad)
    if launch is not None:
        if len(launch) not in (2, 3):
            raise ValueError(f"launch must be N,E or N,E,HEIGHT, got {launch}")
        height = launch[2] if len(launch) == 3 else sc.launch_height_m
        sc = Scenario(sc.name, sc.terrain, (launch[0], launch[1]), height, sc.launch_yaw_rad)
    return sc
