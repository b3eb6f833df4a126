"""Alarms: what makes the companion land the vehicle.

Over MAVLink an alarm is a COMMAND_LONG ``MAV_CMD_USER_1`` (31010) addressed to the companion
(the vehicle's system id, component 191): param1 the reason code, param2 the criticality
(0 low, 1 high, 2 critical). The free-text reason travels just before it as a STATUSTEXT from the
same sender, starting "ALARM: ". The companion also raises alarms itself from autopilot signals it
watches (battery critical, failsafe STATUSTEXT, GPS fix lost).
"""

from __future__ import annotations

import enum
import math
import time
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

MAV_CMD_USER_1 = 31010
ALARM_TEXT_PREFIX = "ALARM: "


class Criticality(enum.IntEnum):
    LOW = 0
    HIGH = 1
    CRITICAL = 2

    @staticmethod
    def parse(text: str) -> Criticality:
        try:
            return Criticality[text.upper()]
        except KeyError:
            raise ValueError(f"criticality must be low, high or critical, got {text!r}") from None


class ReasonCode(enum.IntEnum):
    OTHER = 0
    GPS_SPOOFING = 1
    SENSOR_FAILURE = 2
    LOW_BATTERY = 3
    WEATHER = 4
    FAILSAFE = 5
    GPS_LOST = 6


@dataclass(frozen=True, slots=True)
class Alarm:
    code: ReasonCode
    criticality: Criticality
    reason: str
    source: tuple[int, int]  # (system, component) of whoever raised it; (0, 0) for our own watchers
    received_monotonic: float

    def to_json(self) -> dict[str, Any]:
        """What the flight record and the ground feed say of an alarm (``from_json`` reads it back)."""
        return {
            "reason": self.reason,
            "code": self.code.name.lower(),
            "criticality": self.criticality.name.lower(),
            "source": list(self.source),
        }

    @staticmethod
    def from_json(row: Mapping[str, Any]) -> Alarm:
        """An alarm from ``to_json``'s fields, as received now; names it does not know give OTHER and
        HIGH, a missing reason the code's name. The source is (0, 0): the daemon raises it itself."""
        try:
            code = ReasonCode[str(row.get("code", "other")).upper()]
            criticality = Criticality[str(row.get("criticality", "high")).upper()]
        except KeyError:
            code, criticality = ReasonCode.OTHER, Criticality.HIGH
        reason = str(row.get("reason") or code.name.lower())[:50]
        return Alarm(code, criticality, reason, (0, 0), time.monotonic())

    @staticmethod
    def from_command(param1: float, param2: float, text: str, source: tuple[int, int]) -> Alarm:
        """Decode a USER_1 command; ValueError with the problem if the params are not an alarm."""
        if not (math.isfinite(param1) and math.isfinite(param2)):  # NaN or infinity (found by fuzzing)
            raise ValueError(f"alarm params must be finite numbers, got {param1}, {param2}")
        try:
            code = ReasonCode(int(param1))
        except ValueError:
            code = ReasonCode.OTHER
        if int(param2) != param2 or int(param2) not in (0, 1, 2):
            raise ValueError(f"criticality must be 0, 1 or 2, got {param2}")
        return Alarm(code, Criticality(int(param2)), text or code.name.lower(), source, time.monotonic())
