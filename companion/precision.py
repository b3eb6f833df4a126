"""Whether the autopilot will fly a precision landing on the LANDING_TARGET messages the companion
sends, read from its parameters once it is heard (docs/companion.md, "Precision landing").

- **ArduPilot** lands on a companion's target in LAND mode when ``PLND_ENABLED`` is 1 and ``PLND_TYPE``
  is 1 (the MAVLink / companion-computer backend). The target goes in body FRD (x, y, z and the angles).
- **PX4** (1.15) lands on one in AUTO.PRECLAND (navigator's precision land, built in when its ``PLD_*``
  parameters exist): LANDING_TARGET in ``MAV_FRAME_LOCAL_NED`` with ``position_valid`` 1 becomes its
  landing target pose (where the site is in its local frame; PX4 stamps it on arrival while no TIMESYNC
  runs). It flies over the target at its height, waits there within ``PLD_HACC_RAD``, then descends onto
  it; when it loses the target it starts over, climbing to ``PLD_SRCH_ALT`` above its origin to search,
  up to ``PLD_MAX_SRCH`` times. A descent onto a roof must not climb to a height set above the launch
  point, so the companion needs ``PLD_MAX_SRCH`` 0: a lost target then lands where it is, as ArduPilot
  does. AUTO.PRECLAND searches a second after it starts without a target, so the companion switches to
  it only right after a target went out.

Either way, where the autopilot is not set up the companion says what to set and lands on its absolute
target.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

from companion.telemetry import MAV_AUTOPILOT_ARDUPILOTMEGA, MAV_AUTOPILOT_PX4

__all__ = ["PLND_TYPE_COMPANION", "PrecisionLanding", "check_precision_landing"]

PLND_TYPE_COMPANION = 1  # ArduPilot's PLND_TYPE for targets from a companion computer over MAVLink
PX4_PARAMS = ("PLD_BTOUT", "PLD_HACC_RAD", "PLD_MAX_SRCH")  # PX4's precision land, read at start


class ParamReader(Protocol):
    async def read_param(self, name: str, *, timeout_s: float = ..., tries: int = ...) -> float | None: ...


@dataclass(frozen=True, slots=True)
class PrecisionLanding:
    """Whether the autopilot lands on the companion's target, and why (said and recorded).

    ``local_ned``: the target goes in the autopilot's local frame (PX4) rather than body FRD
    (ArduPilot); ``own_mode``: the autopilot lands on it in a mode of its own (PX4's AUTO.PRECLAND)
    rather than in its land mode."""

    ready: bool
    why: str
    local_ned: bool = False
    own_mode: bool = False


async def check_precision_landing(ctl: ParamReader, autopilot: int) -> PrecisionLanding:
    """Read what the autopilot needs for a precision landing on the companion's target.

    Args:
        ctl: reads a parameter (:meth:`companion.control.VehicleController.read_param`).
        autopilot: the heartbeat's MAV_AUTOPILOT.
    """
    if autopilot == MAV_AUTOPILOT_PX4:
        return await _check_px4(ctl)
    if autopilot != MAV_AUTOPILOT_ARDUPILOTMEGA:
        return PrecisionLanding(False, "this autopilot's precision landing is unknown: the absolute target")
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


async def _check_px4(ctl: ParamReader) -> PrecisionLanding:
    values = {name: await ctl.read_param(name) for name in PX4_PARAMS}
    if values["PLD_BTOUT"] is None:
        return PrecisionLanding(
            False, "the autopilot has no PLD_BTOUT (built without precision land): the absolute target"
        )
    searches = values["PLD_MAX_SRCH"]
    if searches is None or round(searches) != 0:
        have = "unknown" if searches is None else f"{searches:g}"
        return PrecisionLanding(
            False,
            f"precision land not used: PLD_MAX_SRCH is {have} (set 0: a lost target would make AUTO.PRECLAND "
            "climb to PLD_SRCH_ALT above its origin to search): the absolute target",
        )
    radius = values["PLD_HACC_RAD"]
    return PrecisionLanding(
        True,
        f"AUTO.PRECLAND, PLD_MAX_SRCH 0, PLD_BTOUT {values['PLD_BTOUT']:g} s"
        + ("" if radius is None else f", PLD_HACC_RAD {radius:g} m"),
        local_ned=True,
        own_mode=True,
    )
