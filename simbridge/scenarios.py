"""Named scenarios: the world, where the vehicle starts, and where home is.

Scenario coordinates are NED metres from the scenario origin; the launch point is above the
origin unless a scenario says otherwise.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from simbridge.terrain import FlatTerrain, Terrain


@dataclass(frozen=True, slots=True)
class Scenario:
    name: str
    terrain: Terrain
    launch_ne_m: tuple[float, float] = (0.0, 0.0)
    launch_height_m: float = 100.0  # above the ground under the launch point
    launch_yaw_rad: float = 0.0


def _flat(seed: int) -> Scenario:
    return Scenario(name="flat", terrain=FlatTerrain())


SCENARIOS: dict[str, Callable[[int], Scenario]] = {"flat": _flat}


def load_scenario(name: str, seed: int) -> Scenario:
    try:
        factory = SCENARIOS[name]
    except KeyError:
        known = ", ".join(sorted(SCENARIOS))
        raise ValueError(f"unknown scenario {name!r}; known scenarios: {known}") from None
    return factory(seed)
