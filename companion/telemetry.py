"""What the companion knows about the vehicle, from its MAVLink stream, with the age of each part.

Updated by :meth:`TelemetryCache.on_message` for every message from the vehicle's autopilot;
``await wait_update()`` wakes on each new position so control waits on telemetry, not on sleeps.
"""

from __future__ import annotations

import asyncio
import math
import time
from dataclasses import dataclass, field
from typing import Any

MAV_COMP_ID_AUTOPILOT1 = 1
MAV_TYPE_GCS = 6
MAV_AUTOPILOT_INVALID = 8
MAV_AUTOPILOT_ARDUPILOTMEGA = 3
MAV_AUTOPILOT_PX4 = 12
LANDED_ON_GROUND = 1


@dataclass
class VehicleState:
    system_id: int = 0  # 0 until the first autopilot heartbeat
    autopilot: int = 0
    custom_mode: int = 0
    base_mode: int = 0
    system_status: int = 0
    armed: bool = False
    pos_ned_m: tuple[float, float, float] = (math.nan, math.nan, math.nan)
    vel_ned_m_s: tuple[float, float, float] = (math.nan, math.nan, math.nan)
    quat_wxyz: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)
    rangefinder_m: float = math.nan
    landed_state: int = 0
    battery_pct: float = math.nan
    gps_fix: int = -1
    t_boot_s: float = 0.0
    stamps: dict[str, float] = field(default_factory=dict)  # part -> monotonic time of last update

    @property
    def on_ground(self) -> bool:
        """Disarmed, or the autopilot's land detector says ON_GROUND."""
        return not self.armed or self.landed_state == LANDED_ON_GROUND


class TelemetryCache:
    """Latest vehicle state; parts older than their use allows are reported by :meth:`age_s`."""

    def __init__(self, vehicle_system_id: int = 0) -> None:
        self.state = VehicleState(system_id=vehicle_system_id)
        self._update = asyncio.Event()
        self.texts: list[tuple[float, int, str]] = []  # (monotonic, severity, text): the last 50
        self.texts_received = 0  # every STATUSTEXT from the autopilot so far (``texts`` keeps the last 50)

    def _stamp(self, part: str) -> None:
        self.state.stamps[part] = time.monotonic()

    def age_s(self, part: str) -> float:
        t = self.state.stamps.get(part)
        return math.inf if t is None else time.monotonic() - t

    def is_autopilot(self, msg: Any) -> bool:
        sysid, compid = msg.get_srcSystem(), msg.get_srcComponent()
        if compid != MAV_COMP_ID_AUTOPILOT1:
            return False
        if self.state.system_id == 0:
            return bool(
                msg.get_type() == "HEARTBEAT"
                and msg.type != MAV_TYPE_GCS
                and msg.autopilot != MAV_AUTOPILOT_INVALID
            )
        return bool(sysid == self.state.system_id)

    def on_message(self, msg: Any) -> None:
        if not self.is_autopilot(msg):
            return
        s = self.state
        kind = msg.get_type()
        if kind == "HEARTBEAT":
            if s.system_id == 0:
                s.system_id = msg.get_srcSystem()
            s.autopilot, s.custom_mode, s.base_mode = (
                int(msg.autopilot),
                int(msg.custom_mode),
                int(msg.base_mode),
            )
            s.system_status = int(msg.system_status)
            s.armed = bool(msg.base_mode & 128)
            self._stamp("heartbeat")
        elif kind == "LOCAL_POSITION_NED":
            s.pos_ned_m = (float(msg.x), float(msg.y), float(msg.z))
            s.vel_ned_m_s = (float(msg.vx), float(msg.vy), float(msg.vz))
            s.t_boot_s = msg.time_boot_ms / 1000.0
            self._stamp("position")
            self._update.set()
            self._update = asyncio.Event()
        elif kind == "ATTITUDE_QUATERNION":
            s.quat_wxyz = (float(msg.q1), float(msg.q2), float(msg.q3), float(msg.q4))
            self._stamp("attitude")
        elif kind == "DISTANCE_SENSOR" and msg.orientation == 25:
            s.rangefinder_m = msg.current_distance / 100.0
            self._stamp("rangefinder")
        elif kind == "EXTENDED_SYS_STATE":
            s.landed_state = int(msg.landed_state)
            self._stamp("landed")
        elif kind == "SYS_STATUS":
            if msg.battery_remaining >= 0:
                s.battery_pct = float(msg.battery_remaining)
            self._stamp("battery")
        elif kind == "GPS_RAW_INT":
            s.gps_fix = int(msg.fix_type)
            self._stamp("gps")
        elif kind == "STATUSTEXT":
            self.texts.append((time.monotonic(), int(msg.severity), str(msg.text)))
            del self.texts[:-50]
            self.texts_received += 1

    async def wait_update(self, timeout_s: float) -> None:
        """Wait for the next position update; TimeoutError if none comes in ``timeout_s``."""
        async with asyncio.timeout(timeout_s):
            await self._update.wait()

    @property
    def speed_m_s(self) -> float:
        return math.hypot(*self.state.vel_ned_m_s)
