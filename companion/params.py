"""The companion's operator settings as MAVLink parameters, for QGroundControl's and MAVProxy's editors.

The companion's component (191) answers the parameter protocol: PARAM_REQUEST_LIST (every parameter,
each in a PARAM_VALUE with its index and the count), PARAM_REQUEST_READ (by name, or by index) and
PARAM_SET (checked against the parameter's range; applied at once; answered with a PARAM_VALUE
holding the value now in force, the new one or, when refused, the old one with a STATUSTEXT saying
why). Requests addressed to component 0 (every component) or 191 of the vehicle's system are answered.
Values travel as MAV_PARAM_TYPE_REAL32 (ArduPilot's convention, exact for these small integers), so
no editor has to know a byte-wise integer encoding.

Who may raise an alarm may change a setting: with ``alarms.accept_from_system_ids`` set, a PARAM_SET
from another system is refused and counted; with a signing key only signed frames reach the daemon.

Values set over MAVLink are kept in ``mavlink.params_file`` (JSON, written whole and renamed into
place) and applied over the configuration at the next start; without it they last until the daemon
stops. The parameters (``PARAMS``):

==============  =======  ===========================================================================
name            range    what (the configuration key it overrides)
==============  =======  ===========================================================================
LF_CANCEL_MODE  0-2      the mode a cancelled recovery leaves the vehicle in: 0 hold, 1 land, 2 rtl
                         (``alarms.cancel_mode``)
LF_INH_RC_CH    0-18     the RC channel of the inhibit switch, 0 none (``alarms.inhibit_rc_channel``)
LF_INH_PWM_LO   800-2200 the inhibit band's low end, us (``alarms.inhibit_pwm_us[0]``)
LF_INH_PWM_HI   800-2200 the inhibit band's high end, us (``alarms.inhibit_pwm_us[1]``)
LF_BATT_CRIT    0-100    battery % below which the companion raises its own alarm, 0 off
                         (``alarms.battery_critical_pct``, ``alarms.watch_battery``)
LF_WATCH_FS     0-1      an alarm on the autopilot's failsafe texts (``alarms.watch_failsafe_text``)
LF_WATCH_GPS    0-1      an alarm when the GPS fix is lost (``alarms.watch_gps``)
==============  =======  ===========================================================================
"""

from __future__ import annotations

import json
import logging
import math
import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from landfall_link.mavlink import MavlinkLink

__all__ = ["MAV_PARAM_TYPE_REAL32", "PARAMS", "Param", "ParamError", "ParamServer"]

MAV_PARAM_TYPE_REAL32 = 9
CANCEL_MODE_NAMES = ("hold", "land", "rtl")  # LF_CANCEL_MODE's values, in order


class ParamError(ValueError):
    """A value a parameter cannot take; the message says why."""


@dataclass(frozen=True, slots=True)
class Param:
    """One parameter: its MAVLink name (at most 16 characters), range and whether it is whole."""

    name: str
    lo: float
    hi: float
    integer: bool
    doc: str

    def check(self, value: float) -> float:
        """``value`` as this parameter holds it.

        Raises:
            ParamError: not finite, outside the range, or not whole for an integer parameter.
        """
        if not math.isfinite(value):
            raise ParamError(f"{self.name}: {value} is not a number")
        if self.integer and value != round(value):
            raise ParamError(f"{self.name}: {value:g} is not a whole number")
        if not self.lo <= value <= self.hi:
            raise ParamError(f"{self.name}: {value:g} outside {self.lo:g}..{self.hi:g}")
        return float(round(value)) if self.integer else float(value)


PARAMS = (
    Param("LF_CANCEL_MODE", 0, 2, True, "mode after a cancel: 0 hold, 1 land, 2 rtl"),
    Param("LF_INH_RC_CH", 0, 18, True, "RC channel of the inhibit switch, 0 none"),
    Param("LF_INH_PWM_LO", 800, 2200, True, "inhibit band, low end (us)"),
    Param("LF_INH_PWM_HI", 800, 2200, True, "inhibit band, high end (us)"),
    Param("LF_BATT_CRIT", 0, 100, False, "own alarm below this battery %, 0 off"),
    Param("LF_WATCH_FS", 0, 1, True, "own alarm on the autopilot's failsafe texts"),
    Param("LF_WATCH_GPS", 0, 1, True, "own alarm when the GPS fix is lost"),
)
_BY_NAME = {p.name: p for p in PARAMS}


@dataclass(slots=True)
class Binding:
    """How the daemon reads and applies one parameter (``set`` raises ParamError to refuse)."""

    get: Callable[[], float]
    set: Callable[[float], None]


class ParamServer:
    """The parameter protocol for one component (module docstring).

    Args:
        link: where PARAM_VALUE and STATUSTEXT go.
        bindings: the daemon's getter and setter of every parameter of ``PARAMS``.
        allowed: may this system id change settings (the alarms' rule).
        path: the params file (None: values are not kept across restarts).
    """

    def __init__(
        self,
        link: MavlinkLink,
        bindings: dict[str, Binding],
        allowed: Callable[[int], bool],
        path: Path | None = None,
        logger: logging.Logger | None = None,
    ) -> None:
        missing = set(_BY_NAME) - set(bindings)
        if missing:
            raise ValueError(f"no binding for {', '.join(sorted(missing))}")
        self._link = link
        self._bind = bindings
        self._allowed = allowed
        self._path = path
        self._log = logger or logging.getLogger("companion.params")
        self.refused = 0  # PARAM_SETs refused (a value out of range, a sender not allowed)

    def load(self) -> None:
        """Apply the values kept in the params file; a file that cannot be read, or an entry that is
        unknown or out of range, is logged and left out (the configuration's value stays)."""
        if self._path is None or not self._path.exists():
            return
        try:
            kept = json.loads(self._path.read_text())
            if not isinstance(kept, dict):
                raise ValueError("not a JSON object")
        except (OSError, ValueError) as exc:
            self._log.error("params file %s not used: %s", self._path, exc)
            return
        for name, value in kept.items():
            try:
                if name not in _BY_NAME or not isinstance(value, int | float):
                    raise ParamError(f"{name}: not a parameter of this companion, or not a number")
                self._bind[name].set(_BY_NAME[name].check(float(value)))
            except ParamError as exc:
                self._log.error("params file %s: %s: left out", self._path, exc)

    def on_message(self, msg: Any, ours: Callable[[Any], bool]) -> bool:
        """Handle ``msg`` if it is a parameter request addressed to us (``ours(msg)``); True if it was."""
        kind = msg.get_type()
        if kind not in ("PARAM_REQUEST_LIST", "PARAM_REQUEST_READ", "PARAM_SET") or not ours(msg):
            return False
        src = (msg.get_srcSystem(), msg.get_srcComponent())
        if kind == "PARAM_REQUEST_LIST":
            for index, param in enumerate(PARAMS):
                self._value(param, index, src)
        elif kind == "PARAM_REQUEST_READ":
            found = self._find(_name(msg.param_id), int(msg.param_index))
            if found is not None:
                self._value(found[1], found[0], src)
        else:
            self._set(_name(msg.param_id), float(msg.param_value), src)
        return True

    def _find(self, name: str, index: int) -> tuple[int, Param] | None:
        if 0 <= index < len(PARAMS):
            return index, PARAMS[index]
        for k, param in enumerate(PARAMS):
            if param.name == name:
                return k, param
        return None

    def _set(self, name: str, value: float, src: tuple[int, int]) -> None:
        found = self._find(name, -1)
        if found is None:
            self._refuse(f"{name}: no such parameter", src)
            return
        index, param = found
        if not self._allowed(src[0]):
            self._refuse(f"{name}: system {src[0]} may not change settings", src)
        else:
            try:
                self._bind[name].set(param.check(value))
            except ParamError as exc:
                self._refuse(str(exc), src)
            else:
                self._log.warning("parameter %s set to %g by system %d", name, self._bind[name].get(), src[0])
                self._keep()
        self._value(param, index, None)  # the value in force, to every peer (editors show it)

    def _refuse(self, why: str, src: tuple[int, int]) -> None:
        self.refused += 1
        self._log.warning("PARAM_SET from system %d refused: %s", src[0], why)
        self._link.send_to(self._link.mav.statustext_encode(4, why[:50].encode(), 0, 0), *src)

    def _value(self, param: Param, index: int, to: tuple[int, int] | None) -> None:
        value = float(self._bind[param.name].get())
        msg = self._link.mav.param_value_encode(
            param.name.encode(), value, MAV_PARAM_TYPE_REAL32, len(PARAMS), index
        )
        if to is None:
            self._link.send(msg)
        else:
            self._link.send_to(msg, *to)

    def _keep(self) -> None:
        """Write every parameter's value to the params file (whole, then renamed into place)."""
        if self._path is None:
            return
        values = {p.name: self._bind[p.name].get() for p in PARAMS}
        tmp = self._path.with_name(self._path.name + ".tmp")
        try:
            self._path.parent.mkdir(parents=True, exist_ok=True)
            tmp.write_text(json.dumps(values, indent=1) + "\n")
            os.replace(tmp, self._path)
        except OSError as exc:
            self._log.error("params file %s not written: %s (the values hold until the daemon stops)",
                            self._path, exc)  # fmt: skip


def _name(raw: Any) -> str:
    text = raw if isinstance(raw, str) else bytes(raw).decode(errors="replace")
    return text.rstrip("\x00")
