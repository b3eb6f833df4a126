"""Whether the autopilot will fly a precision landing on the LANDING_TARGET messages the companion
sends, read from its parameters once it is heard (docs/companion.md, "Precision landing").

ArduPilot lands on a companion's target in LAND mode when ``PLND_ENABLED`` is 1 and ``PLND_TYPE`` is 1
(the MAVLink / companion-computer backend). PX4 1.15 is not used this way yet: its precision landing
(AUTO.PRECLAND) takes a target in its local frame and searches upward when it loses it, and the
companion has not been flown against it; with PX4 the companion lands on its absolute target, as with
an ArduPilot whose parameters say no.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

from companion.telemetry import MAV_AUTOPILOT_ARDUPILOTMEGA

__all__ = ["PLND_TYPE_COMPANION", "PrecisionLanding", "check_precision_landing"]

PLND_TYPE_COMPANION = 1  # ArduPilot's PLND_TYPE for targets from a companion computer over MAVLink


class ParamReader(Protocol):
    async def read_param(self, name: str, *, timeout_s: float = ..., tries: int = ...) -> float | None: ...


@dataclass(frozen=True, slots=True)
class PrecisionLanding:
    """Whether the autopilot lands on the companion's target, and why (said and recorded)."""

    ready: bool
    why: str


async def check_precision_landing(ctl: ParamReader, autopilot: int) -> PrecisionLanding:
    """Read what the autopilot needs for a precision landing on the companion's target.

    Args:
        ctl: reads a parameter (:meth:`companion.control.VehicleController.read_param`).
        autopilot: the heartbeat's MAV_AUTOPILOT.
    """
    if autopilot != MAV_AUTOPILOT_ARDUPILOTMEGA:
        return PrecisionLanding(
            False, "this autopilot's precision landing is not used yet (ArduPilot's is): the absolute target"
        )
    enabled = await ctl.read_param("PLND_ENABLED")
    kind = await ctl.read_param("PLND_TYPE")
    if enabled is None:
        return PrecisionLanding(
            False, "the autopilot has no PLND_ENABLED (built without precision landing): the absolute target"
        )
    missing = []
    if round(enabled) != 1:
        missing.append(f"PLND_ENABLED is {enabled:g} (set 1)")
    if kind is None or round(kind) != PLND_TYPE_COMPANION:
        missing.append(
            f"PLND_TYPE is {'unknown' if kind is None else f'{kind:g}'} (set {PLND_TYPE_COMPANION})"
        )
    if missing:
        return PrecisionLanding(
            False, "precision landing off: " + ", ".join(missing) + ": the absolute target"
        )
    return PrecisionLanding(True, f"PLND_ENABLED 1, PLND_TYPE {PLND_TYPE_COMPANION}")
