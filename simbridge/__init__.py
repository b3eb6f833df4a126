"""simbridge: a JSBSim multirotor behind a PX4/ArduPilot MAVLink autopilot emulation.

Frames and units used throughout (stated once here):

* World frame: local NED in metres, origin at the scenario origin on the ground (``pos_ned_m``).
* Body frame: FRD (x forward, y right, z down).
* Attitude: unit quaternion ``(w, x, y, z)`` rotating body FRD vectors into NED.
* Time: simulated seconds since boot (``t_s``); MAVLink ``time_boot_ms`` is simulated time too.

JSBSim and numba come with the ``sim`` extra (``pip install 'landfall[sim]'``): the names below are
imported when first used, so that ``simbridge.extra`` can say so when they are missing.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from simbridge.geo import GeoOrigin
    from simbridge.physics import F450Physics, VehicleState
    from simbridge.terrain import FlatTerrain, Terrain

__all__ = ["F450Physics", "FlatTerrain", "GeoOrigin", "Terrain", "VehicleState"]

_HOME = {
    "GeoOrigin": "simbridge.geo",
    "F450Physics": "simbridge.physics",
    "VehicleState": "simbridge.physics",
    "FlatTerrain": "simbridge.terrain",
    "Terrain": "simbridge.terrain",
}


def __getattr__(name: str) -> Any:
    if name in _HOME:
        return getattr(importlib.import_module(_HOME[name]), name)
    raise AttributeError(f"module 'simbridge' has no attribute {name!r}")
