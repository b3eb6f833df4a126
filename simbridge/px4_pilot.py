"""simbridge's own MAVLink link to real PX4 (its ground-station link): watching, and the air start.

PX4's ground-station MAVLink instance (UDP 18570 + N) sends to this link (``udpin`` on loopback, any free
port: the ROMFS copy points it here instead of 14550, :class:`simbridge.px4_sitl.Px4Process`). PX4 streams
its telemetry on that link unasked (HEARTBEAT, EXTENDED_SYS_STATE, LOCAL_POSITION_NED, GPS_RAW_INT,
SYS_STATUS, STATUSTEXT); changes of mode and arming go to the episode log as the emulation's
``mode``/``armed``/``disarmed`` events, with the emulation's mode names (``AUTO.LOITER``, ``OFFBOARD``, ...).

``--start air`` cannot spawn real firmware in the air: PX4's estimator initialises on the ground (GPS
checks, a few simulated seconds until "Ready for takeoff!") and it refuses to arm in flight.
:meth:`Px4Pilot.fly_to_launch` flies it there as a pilot with a ground station would: arm (retried once a
simulated second until accepted), MAV_CMD_NAV_TAKEOFF (AUTO.TAKEOFF to ``MIS_TAKEOFF_ALT``, the launch
height, set at boot), then waits until PX4 holds in AUTO.LOITER within ``READY_POS_M`` and
``READY_SPEED_M_S`` of the launch pose for ``READY_HOLD_S``. Then it stops commanding: the companion takes
over a vehicle holding in AUTO.LOITER, as over the emulation's.
"""

from __future__ import annotations

import math
from collections.abc import Callable

from pymavlink.dialects.v20 import ardupilotmega as M

from simbridge.autopilot.flavours import Px4Flavour
from simbridge.sitl_pilot import SitlPilot

_MAIN = {1: "MANUAL", 2: "ALTCTL", 3: "POSCTL", 5: "ACRO", 6: "OFFBOARD", 7: "STABILIZED", 8: "RATTITUDE"}
_AUTO = {
    1: "AUTO.READY", 2: "AUTO.TAKEOFF", 3: "AUTO.LOITER", 4: "AUTO.MISSION", 5: "AUTO.RTL", 6: "AUTO.LAND",
    8: "AUTO.FOLLOW_TARGET", 9: "AUTO.PRECLAND",
}  # fmt: skip
_ON_GROUND = (M.MAV_LANDED_STATE_UNDEFINED, M.MAV_LANDED_STATE_ON_GROUND)
_KNOWN = {m.custom_mode: m.name for m in Px4Flavour.modes}


def px4_mode_name(custom_mode: int) -> str:
    """PX4's mode from HEARTBEAT.custom_mode (main mode in bits 16-23, AUTO's sub mode in 24-31)."""
    if custom_mode in _KNOWN:
        return _KNOWN[custom_mode]
    main, sub = (custom_mode >> 16) & 0xFF, (custom_mode >> 24) & 0xFF
    if main == 4:
        return _AUTO.get(sub, f"AUTO.{sub}")
    return _MAIN.get(main, f"MODE{main}")


class Px4Pilot(SitlPilot):
    """:class:`SitlPilot` for PX4 (module docstring)."""

    firmware = "PX4 SITL"
    hold_mode = "AUTO.LOITER"
    ready: Callable[[], bool] | None = None  # set by the bridge: PX4 said "Ready for takeoff!"

    def mode_name(self, custom_mode: int) -> str:
        return px4_mode_name(custom_mode)

    def _ask_streams(self) -> None:
        self._streams_asked = True  # PX4 streams on its ground-station link unasked

    def can_start(self) -> bool:
        return self.ready() if self.ready is not None else True

    def _ask_next(self, height_m: float) -> None:
        """Arm, then NAV_TAKEOFF (to ``MIS_TAKEOFF_ALT``, the launch height, set at boot), then hold."""
        v = self.view
        if not v.armed:
            self.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1)
        elif v.landed_state in _ON_GROUND and v.mode != "AUTO.TAKEOFF":
            self.command(M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, math.nan, math.nan, math.nan)
        elif v.mode not in ("AUTO.TAKEOFF", "AUTO.LOITER"):
            self.command(M.MAV_CMD_DO_SET_MODE, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 4, 3)  # AUTO.LOITER
