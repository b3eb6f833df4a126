"""The operator's controls over MAVLink: cancel a recovery, and an RC switch that inhibits Landfall.

**Cancel.** A COMMAND_LONG ``MAV_CMD_USER_2`` (31011) addressed to the companion (the vehicle's system
id, component 191; no parameters) from a system allowed to raise alarms
(``alarms.accept_from_system_ids``; with a signing key, only signed frames reach the daemon at all)
stops the running recovery: the setpoint stream is released and the vehicle put in
``alarms.cancel_mode`` (``hold``: PX4 AUTO.LOITER, ArduPilot LOITER; ``land``; ``rtl``: PX4 AUTO.RTL,
ArduPilot RTL), said in a STATUSTEXT and the flight record (``cancelled``). The command is acknowledged
ACCEPTED when a recovery was running, DENIED when none was (nothing to cancel) or the sender may not.
``trigger_alarm.py --cancel`` sends it. The pilot's own mode change also ends a recovery (a takeover:
docs/companion.md); cancel is for a ground station or a script.

**Inhibit.** With ``alarms.inhibit_rc_channel`` N (1-18), the autopilot's RC_CHANNELS ``chanN_raw``
within ``alarms.inhibit_pwm_us`` (inclusive, microseconds) inhibits Landfall: every alarm, the
operator's and the companion's own, is refused DENIED and counted, and each change of the switch is
said in a STATUSTEXT. A switch moved to inhibit during a recovery does not stop it (cancel does). A
channel the receiver does not fill (0 or 65535) or RC_CHANNELS older than ``RC_STALE_S`` (RC lost)
inhibits nothing: the companion stays able to land the vehicle when the pilot cannot.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from companion.flavour import Mode

__all__ = ["CANCEL_MODES", "MAV_CMD_USER_2", "RC_STALE_S", "InhibitSwitch", "cancel_mode"]

MAV_CMD_USER_2 = 31011  # cancel the running recovery
RC_STALE_S = 2.0  # RC_CHANNELS older than this: the RC link is lost and inhibits nothing
CANCEL_MODES = {"hold": Mode.HOLD, "land": Mode.LAND, "rtl": Mode.RTL}
_UNUSED_PWM = (0, 65535)  # RC_CHANNELS' values for a channel the receiver does not fill


def cancel_mode(name: str) -> Mode:
    """The mode ``alarms.cancel_mode`` names.

    Raises:
        ValueError: a name that is not one of ``CANCEL_MODES``.
    """
    try:
        return CANCEL_MODES[name]
    except KeyError:
        raise ValueError(f"cancel mode must be one of {', '.join(CANCEL_MODES)}, got {name!r}") from None


@dataclass(frozen=True, slots=True)
class InhibitSwitch:
    """An RC channel (1-18) and the PWM band (microseconds, inclusive) in which it inhibits Landfall."""

    channel: int
    pwm_us: tuple[int, int] = (1800, 2200)

    def __post_init__(self) -> None:
        if not 1 <= self.channel <= 18:
            raise ValueError(f"inhibit RC channel must be 1..18, got {self.channel}")
        lo, hi = self.pwm_us
        if not 800 <= lo <= hi <= 2200:
            raise ValueError(f"inhibit PWM band must be 800 <= low <= high <= 2200 us, got {self.pwm_us}")

    def inhibits(self, rc_pwm_us: tuple[int, ...], rc_age_s: float) -> bool:
        """Whether channels ``rc_pwm_us`` (RC_CHANNELS' chan1_raw ...), ``rc_age_s`` old, inhibit."""
        if not math.isfinite(rc_age_s) or rc_age_s > RC_STALE_S or len(rc_pwm_us) < self.channel:
            return False
        pwm = rc_pwm_us[self.channel - 1]
        return pwm not in _UNUSED_PWM and self.pwm_us[0] <= pwm <= self.pwm_us[1]
