"""simbridge: a JSBSim multirotor behind a PX4/ArduPilot MAVLink autopilot emulation.

Frames and units used throughout (stated once here):

* World frame: local NED in metres, origin at the scenario origin on the ground (``pos_ned_m``).
* Body frame: FRD (x forward, y right, z down).
* Attitude: unit quaternion ``(w, x, y, z)`` rotating body FRD vectors into NED.
* Time: simulated seconds since boot (``t_s``); MAVLink ``time_boot_ms`` is simulated time too.
"""

from simbridge.geo import GeoOrigin
from simbridge.physics import F450Physics, VehicleState
from simbridge.terrain import FlatTerrain, Terrain

__all__ = ["F450Physics", "FlatTerrain", "GeoOrigin", "Terrain", "VehicleState"]
