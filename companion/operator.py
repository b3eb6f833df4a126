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

import asyncio
import contextlib
import logging
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from companion.control import VehicleController
from companion.flavour import Mode
from companion.params import CANCEL_MODE_NAMES, Binding, ParamError
from companion.telemetry import TelemetryCache

__all__ = ["CANCEL_MODES", "MAV_CMD_USER_2", "RC_STALE_S", "InhibitSwitch", "OperatorControls", "cancel_mode"]

RESULT_ACCEPTED, RESULT_DENIED = 0, 2  # MAV_RESULT

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


class OperatorControls:
    """The cancel and the inhibit switch of the module docstring, with their settings (which the
    parameter protocol reads and changes: :meth:`bindings`).

    Args:
        tm: the autopilot's telemetry (RC_CHANNELS).
        ctl: what releases the vehicle and sets its mode.
        announce: STATUSTEXT to every peer (severity, text).
        record_event: a flight-record event (kind, data).
        log: the daemon's logger.
        cancel_to: ``hold``, ``land`` or ``rtl``.
        inhibit: the switch, or None.

    Raises:
        ValueError: ``cancel_to`` none of ``CANCEL_MODES``.
    """

    def __init__(
        self,
        tm: TelemetryCache,
        ctl: VehicleController,
        announce: Callable[[int, str], None],
        record_event: Callable[[str, dict[str, Any]], None],
        log: logging.Logger,
        *,
        cancel_to: str = "hold",
        inhibit: InhibitSwitch | None = None,
    ) -> None:
        self._tm, self._ctl, self._announce, self._record, self._log = tm, ctl, announce, record_event, log
        self.cancel_mode = cancel_mode(cancel_to)
        self.inhibit = inhibit
        self._band = inhibit.pwm_us if inhibit is not None else (1800, 2200)
        self._said_inhibited = False  # what the switch said at the last look (announced on each change)
        self.cancelling: asyncio.Task[None] | None = None

    def inhibited(self) -> bool:
        """Whether the switch says no to alarms now."""
        if self.inhibit is None:
            return False
        return self.inhibit.inhibits(self._tm.state.rc_pwm_us, self._tm.age_s("rc"))

    def watch(self) -> None:
        """Say each change of the switch (STATUSTEXT and log); called every second."""
        now = self.inhibited()
        if now != self._said_inhibited:
            self._said_inhibited = now
            ch = self.inhibit.channel if self.inhibit is not None else 0
            text = f"Landfall inhibited (RC channel {ch})" if now else f"Landfall enabled (RC channel {ch})"
            self._log.warning(text)
            self._announce(5, text)

    def cancel(self, recovery: asyncio.Task[Any] | None, source: tuple[int, int]) -> int:
        """ACCEPTED and ``recovery`` stopped in the background (:meth:`_cancel`), or DENIED when no
        recovery runs (or one is being cancelled already)."""
        busy = self.cancelling is not None and not self.cancelling.done()
        if recovery is None or recovery.done() or busy:
            self._log.info("cancel from system %d: no recovery to cancel", source[0])
            return RESULT_DENIED
        loop = asyncio.get_running_loop()
        self.cancelling = loop.create_task(self._cancel(recovery, source), name="cancel")
        return RESULT_ACCEPTED

    async def _cancel(self, recovery: asyncio.Task[Any], source: tuple[int, int]) -> None:
        """Stop the recovery, release the vehicle and put it in the cancel mode; say so."""
        recovery.cancel()
        with contextlib.suppress(asyncio.CancelledError, Exception):  # its own failure is logged already
            await recovery
        await self._ctl.release()
        mode = self.cancel_mode
        try:
            await self._ctl.set_mode(mode)
            done, said = f"vehicle in {mode.value.upper()}", f"Landfall cancelled: {mode.value.upper()}"
        except Exception as exc:  # the autopilot refused or did not answer: the pilot must act
            self._log.error("after the cancel the autopilot did not take %s: %s", mode.value, exc)
            done = f"{mode.value.upper()} not taken ({exc}): fly it"
            said = f"Landfall cancelled: {mode.value.upper()} refused, fly it"
        self._log.warning("recovery cancelled by system %d: %s", source[0], done)
        self._announce(4, said)  # one STATUSTEXT (50 characters)
        self._record("cancelled", {"by": list(source), "mode": mode.value, "result": done})

    def bindings(self) -> dict[str, Binding]:
        """LF_CANCEL_MODE and the switch's LF_INH_* (companion/params.py), read and applied live."""

        def set_mode(v: float) -> None:
            self.cancel_mode = cancel_mode(CANCEL_MODE_NAMES[int(v)])

        def set_channel(v: float) -> None:
            self.inhibit = InhibitSwitch(int(v), self._band) if v else None

        def set_band(lo: float, hi: float) -> None:
            if lo > hi:
                raise ParamError(f"LF_INH_PWM: band {lo:g}..{hi:g}, low above high")
            self._band = (int(lo), int(hi))
            set_channel(self.inhibit.channel if self.inhibit is not None else 0)

        return {
            "LF_CANCEL_MODE": Binding(lambda: CANCEL_MODE_NAMES.index(self.cancel_mode.value), set_mode),
            "LF_INH_RC_CH": Binding(lambda: self.inhibit.channel if self.inhibit else 0, set_channel),
            "LF_INH_PWM_LO": Binding(lambda: self._band[0], lambda v: set_band(v, self._band[1])),
            "LF_INH_PWM_HI": Binding(lambda: self._band[1], lambda v: set_band(self._band[0], v)),
        }
