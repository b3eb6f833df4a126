"""The ground under the vehicle: the seam where the world model plugs into the physics.

The vehicle needs only two things from the world: the ground height under a point (for contact
and the rangefinder) and, at touchdown, what the vehicle landed on. ``FlatTerrain`` is the empty
world; the city model implements the same protocol.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Protocol

from simbridge.geo import Quat, rotate_body_to_ned


@dataclass(frozen=True, slots=True)
class TouchdownGrade:
    """Ground-truth verdict on a touchdown point."""

    surface: str
    safe: bool
    reasons: tuple[str, ...] = field(default_factory=tuple)


class Terrain(Protocol):
    """What the vehicle needs to know about the world."""

    def height_m(self, north_m: float, east_m: float) -> float:
        """Ground (or roof) height above the scenario origin at a NED point, metres, up positive."""
        ...

    def grade_touchdown(self, north_m: float, east_m: float, t_s: float) -> TouchdownGrade:
        """Ground-truth surface class and safety verdict for a touchdown at (north, east)."""
        ...

    def rangefinder_m(self, pos_ned_m: tuple[float, float, float], quat: Quat, max_m: float = 200.0) -> float:
        """Distance along the body +z axis (downward rangefinder) to the first surface."""
        ...


@dataclass(frozen=True, slots=True)
class FlatTerrain:
    """Open, flat, empty ground at a fixed height: the world before the city exists."""

    ground_height_m: float = 0.0

    def height_m(self, north_m: float, east_m: float) -> float:
        return self.ground_height_m

    def grade_touchdown(self, north_m: float, east_m: float, t_s: float) -> TouchdownGrade:
        return TouchdownGrade(surface="open_ground", safe=True, reasons=())

    def rangefinder_m(self, pos_ned_m: tuple[float, float, float], quat: Quat, max_m: float = 200.0) -> float:
        down = rotate_body_to_ned(quat, (0.0, 0.0, 1.0))[2]
        height = -pos_ned_m[2] - self.ground_height_m
        if down <= 1e-6 or height <= 0:
            return max_m if height > 0 else 0.0
        return min(height / down, max_m) if not math.isnan(height) else max_m
