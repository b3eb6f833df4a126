"""A built world: the static grid, where the vehicle launches, the sun, the ground-truth safe
landing zones and the actors' routes. Scenario files and the procedural city both produce one."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from simbridge.world.model import WorldGrid


@dataclass(frozen=True, slots=True)
class SafeZone:
    """A ground-truth landing zone (rotated rectangle) for the Surface ID Jaccard index."""

    centre_ne: tuple[float, float]
    length_m: float
    width_m: float
    yaw_rad: float = 0.0
    label: str = ""

    def corners_ne(self) -> np.ndarray:
        """(4, 2) corners in scenario (north, east) metres."""
        c, s = math.cos(self.yaw_rad), math.sin(self.yaw_rad)
        hl, hw = self.length_m / 2, self.width_m / 2
        local = np.array([[hl, hw], [hl, -hw], [-hl, -hw], [-hl, hw]])
        n = self.centre_ne[0] + local[:, 0] * c - local[:, 1] * s
        e = self.centre_ne[1] + local[:, 0] * s + local[:, 1] * c
        return np.stack([n, e], axis=1)


@dataclass(frozen=True, slots=True)
class Lane:
    """A traffic lane: cars enter at the first point and leave at the last.

    ``deck_height_m`` is the road surface height (elevated highways); ``arrivals_per_min`` the mean
    rate of a Poisson arrival process; speeds are drawn uniformly from ``speed_m_s``.
    """

    points_ne: tuple[tuple[float, float], ...]
    speed_m_s: tuple[float, float] = (8.0, 14.0)
    arrivals_per_min: float = 6.0
    deck_height_m: float = 0.0


@dataclass(frozen=True, slots=True)
class Walkway:
    """Pedestrians walking back and forth along a path (sidewalk, plaza, now and then a roof)."""

    points_ne: tuple[tuple[float, float], ...]
    count: int = 4
    surface_height_m: float = 0.0
    width_m: float = 2.0


@dataclass(frozen=True, slots=True)
class Sun:
    """Where the sun is: azimuth from north toward east, elevation above the horizon."""

    azimuth_deg: float = 135.0
    elevation_deg: float = 50.0

    def direction_neu(self) -> tuple[float, float, float]:
        """Unit vector pointing *toward* the sun in (north, east, up)."""
        az, el = math.radians(self.azimuth_deg), math.radians(self.elevation_deg)
        return (math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el))


@dataclass
class World:
    name: str
    seed: int
    grid: WorldGrid
    launch_ne_m: tuple[float, float] = (0.0, 0.0)
    launch_height_m: float = 110.0  # above the ground under the launch point
    launch_yaw_rad: float = 0.0
    sun: Sun = field(default_factory=Sun)
    safe_zones: tuple[SafeZone, ...] = ()
    lanes: tuple[Lane, ...] = ()
    walkways: tuple[Walkway, ...] = ()
    description: str = ""

    def digest(self) -> str:
        """The static world's fingerprint (:meth:`WorldGrid.digest`): call it before actors are stamped."""
        return self.grid.digest()
