"""The autopilot's circular fence, read from its parameters: how far from home a recovery may go.

An operator sets a fence around the area a flight is allowed in; crossing it hands the vehicle to the
autopilot's fence action (return, land or hold), which ends the companion's recovery wherever that
happens. A recovery that keeps inside it never meets that action: its search legs end, and the sites
it flies to lie, ``KEEP_IN_M`` inside the circle (or the autopilot's own ``FENCE_MARGIN`` when that is
more). What is read, once the autopilot is heard:

- **ArduPilot**: ``FENCE_ENABLE`` 1 and ``FENCE_TYPE`` with its circle bit (2; the firmware's default
  7 has it, and an autopilot that has no ``FENCE_TYPE`` counts as that default): ``FENCE_RADIUS``
  metres around home; ``FENCE_MARGIN``.
- **PX4**: ``GF_MAX_HOR_DIST`` above 0: metres from home (whatever ``GF_ACTION`` does on a breach, it
  is a limit the operator set).

Polygon fences (ArduPilot's ``FENCE_TYPE`` bit 4, PX4's geofence file) are uploaded as mission items
and are not read: a recovery does not keep to them. Home is where the autopilot's ``HOME_POSITION``
puts it in the local frame, else the local frame's origin (where both autopilots put it for a flight
that took off from home).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from companion.precision import ParamReader
from companion.telemetry import MAV_AUTOPILOT_ARDUPILOTMEGA, MAV_AUTOPILOT_PX4

__all__ = ["KEEP_IN_M", "Fence", "read_fence"]

KEEP_IN_M = 15.0  # legs and sites this far inside the circle: room to brake and to look about
FENCE_TYPE_CIRCLE = 2  # ArduPilot's FENCE_TYPE bit for the circle around home
FENCE_TYPE_DEFAULT = 7  # ArduCopter's default: altitude, circle and polygon


@dataclass(frozen=True, slots=True)
class Fence:
    """A circle around home the recovery keeps inside (``radius_m`` None: none known), and what the
    autopilot said of it (logged when it is read)."""

    radius_m: float | None
    why: str
    margin_m: float = KEEP_IN_M

    def keep_in_m(self) -> float | None:
        """The radius legs and sites keep within (metres from home), or None."""
        if self.radius_m is None:
            return None
        return max(0.0, self.radius_m - self.margin_m)

    def inside(self, ne_m: tuple[float, float], home_ne_m: tuple[float, float]) -> bool:
        """Whether ``ne_m`` (local north, east) lies within :meth:`keep_in_m` of home."""
        keep = self.keep_in_m()
        return keep is None or math.dist(ne_m, home_ne_m) <= keep


NO_FENCE = Fence(None, "no circular fence: the search is not bounded")


async def read_fence(ctl: ParamReader, autopilot: int) -> Fence:
    """Read the autopilot's circular fence (module docstring).

    Args:
        ctl: reads a parameter (:meth:`companion.control.VehicleController.read_param`).
        autopilot: the heartbeat's MAV_AUTOPILOT.
    """
    if autopilot == MAV_AUTOPILOT_PX4:
        radius = await ctl.read_param("GF_MAX_HOR_DIST")
        if radius is None or not radius > 0:
            return NO_FENCE
        return _circle("GF_MAX_HOR_DIST", radius, KEEP_IN_M)
    if autopilot != MAV_AUTOPILOT_ARDUPILOTMEGA:
        return NO_FENCE
    enabled = await ctl.read_param("FENCE_ENABLE")
    if enabled is None or round(enabled) != 1:
        return NO_FENCE
    kind = await ctl.read_param("FENCE_TYPE")
    if not int(FENCE_TYPE_DEFAULT if kind is None else kind) & FENCE_TYPE_CIRCLE:
        return Fence(None, f"FENCE_TYPE {kind:g} has no circle: the search is not bounded")
    radius = await ctl.read_param("FENCE_RADIUS")
    if radius is None or not radius > 0:
        return NO_FENCE
    margin = await ctl.read_param("FENCE_MARGIN")
    own = margin if margin is not None and margin > 0 else 0.0
    return _circle("FENCE_RADIUS", radius, max(KEEP_IN_M, own))


def _circle(name: str, radius_m: float, margin_m: float) -> Fence:
    keep = max(0.0, radius_m - margin_m)
    why = f"{name} {radius_m:g} m: searches and sites keep within {keep:g} m of home"
    return Fence(radius_m, why, margin_m)
