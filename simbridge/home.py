"""Where the vehicle took off (home), which the autopilot's local frame, its return and its fence are
around."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

HOME_STEP_M = 5.0  # home's search from a launch over water: rings this far apart, points this far apart
HOME_SEARCH_M = 600.0  # and out to this far
HOME_ROOM_M = 20.0  # the launch point at least this far inside the map's circle around a home on the shore


def home_on_land(terrain: Any, north_m: float, east_m: float) -> tuple[float, float]:
    """Where the vehicle took off (home): the ground under the launch point, unless that is water. A
    multirotor takes off from land: one launched over a lake or the sea flew out from the shore, so its
    home is the nearest point, in rings ``HOME_STEP_M`` apart out to ``HOME_SEARCH_M``, on open ground, a
    lawn, a car park or a pier where a touchdown would grade safe (the operator's take-off spot, clear of
    people then), and around which the circle out to the map's nearest edge holds the launch point with
    ``HOME_ROOM_M`` to spare (the flight so far inside the area an operator's fence around home would
    draw: ``--fence map``). A world without a grid, or no such point, keeps the launch point."""
    from simbridge.world.model import SurfaceClass

    grid = getattr(terrain, "grid", None)
    if grid is None or grid.class_at(north_m, east_m) != SurfaceClass.WATER:
        return north_m, east_m
    land = (SurfaceClass.GROUND, SurfaceClass.GRASS, SurfaceClass.PARKING_LOT, SurfaceClass.PIER)
    n0, n1, e0, e1 = grid.extent_m
    for r in np.arange(HOME_STEP_M, HOME_SEARCH_M, HOME_STEP_M):
        k = max(8, math.ceil(2.0 * math.pi * r / HOME_STEP_M))
        for a in np.linspace(0.0, 2.0 * math.pi, k, endpoint=False):
            n, e = north_m + r * math.cos(a), east_m + r * math.sin(a)
            room = min(n - n0, n1 - n, e - e0, e1 - e) - r  # the circle to the map's edge, past the launch
            on_land = room >= HOME_ROOM_M and grid.class_at(n, e) in land
            if on_land and terrain.grade_touchdown(n, e, 0.0).safe:
                return float(n), float(e)
    return north_m, east_m
