"""simbridge's own MAVLink link to ArduCopter SITL (its SERIAL1): watching, and the air start.

With real firmware there is no emulation to ask what the vehicle is doing, so simbridge listens like a
ground station on a second serial port of SITL's: heartbeats (mode, armed), EXTENDED_SYS_STATE (landed
state), EKF_STATUS_REPORT, GPS_RAW_INT, LOCAL_POSITION_NED and STATUSTEXT, requested on that port with
SET_MESSAGE_INTERVAL (ArduPilot sends nothing but heartbeats unasked). Changes of mode and arming go to
the episode log as the emulation's ``mode``/``armed``/``disarmed`` events.

``--start air`` cannot spawn real firmware in the air: its estimator must initialise on the ground
(about 45 simulated seconds until it has a position: GPS lock, EKF origin, EKF using GPS) and it
refuses to arm in flight. :meth:`SitlPilot.fly_to_launch` flies it there as a pilot would: GUIDED, arm
(retried once a simulated second until accepted), NAV_TAKEOFF to the launch height, then waits until it
holds within ``READY_POS_M`` and ``READY_SPEED_M_S`` of the launch pose for ``READY_HOLD_S``. Then it
stops commanding: the companion takes over a vehicle holding in GUIDED.
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import logging
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from landfall_link.mavlink import MavlinkUdpLink
from simbridge.autopilot.flavours import ArduPilotFlavour
from simbridge.sitl import SitlError

M = mavlink2
COPTER_GUIDED = 4
PILOT_SYSID, PILOT_COMPID = 255, 190  # a ground station's ids (SYSID_MYGCS default 255)
READY_POS_M = 0.5
READY_SPEED_M_S = 0.3
READY_HOLD_S = 2.0
READY_TIMEOUT_S = 240.0  # simulated seconds from SITL's start to holding at the launch pose
RETRY_S = 1.0  # simulated seconds between two tries of a refused command
STREAMS_HZ = {  # on simbridge's port only; the companion asks for its own on SERIAL0
    M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: 4.0,
    M.MAVLINK_MSG_ID_LOCAL_POSITION_NED: 10.0,
    M.MAVLINK_MSG_ID_EKF_STATUS_REPORT: 2.0,
    M.MAVLINK_MSG_ID_GPS_RAW_INT: 2.0,
    M.MAVLINK_MSG_ID_SYS_STATUS: 1.0,
    M.MAVLINK_MSG_ID_SYSTEM_TIME: 2.0,
}
_MODES = {m.custom_mode: m.name for m in ArduPilotFlavour.modes} | {
    0: "STABILIZE", 1: "ACRO", 2: "ALT_HOLD", 3: "AUTO", 7: "CIRCLE", 13: "SPORT", 16: "POSHOLD",
    21: "SMART_RTL",
}  # fmt: skip


def mode_name(custom_mode: int) -> str:
    return _MODES.get(custom_mode, f"MODE{custom_mode}")


class SitlNotReady(SitlError):
    """The firmware did not reach the launch pose in time (its refusals are in the message)."""


@dataclass
class VehicleView:
    """What SITL last said about itself on simbridge's link."""

    heartbeat: bool = False
    mode: str = "?"
    armed: bool = False
    landed_state: int = 0  # MAV_LANDED_STATE
    ekf_flags: int = 0
    gps_fix: int = 0
    local_ned: tuple[float, float, float] | None = None
    local_vel: tuple[float, float, float] | None = None
    battery_pct: float = 100.0
    time_boot_ms: int = 0


Events = Callable[[str, dict[str, Any]], None]
Clock = Callable[[], float]


class SitlPilot:
    """Owns the link to SITL's SERIAL1 (``udpin`` on loopback, any free port: ``port`` after open).
    Subclassed for PX4 (:class:`simbridge.px4_pilot.Px4Pilot`): ``firmware``, :meth:`mode_name`,
    :meth:`_ask_streams` and :meth:`fly_to_launch` are what differ.

    Args:
        sysid: the vehicle's MAV_SYSID.
        on_event: (name, fields) for the episode log.
        sim_time: simulated seconds now (the lock step's clock).
    """

    firmware = "ArduCopter SITL"

    def __init__(
        self, sysid: int, on_event: Events, sim_time: Clock, logger: logging.Logger | None = None
    ) -> None:
        self.sysid = sysid
        self.on_event = on_event
        self.sim_time = sim_time
        self.log = logger or logging.getLogger("simbridge.sitl")
        self.view = VehicleView()
        self.texts: collections.deque[str] = collections.deque(maxlen=12)
        self.link = MavlinkUdpLink(
            "udpin:127.0.0.1:0",
            PILOT_SYSID,
            PILOT_COMPID,
            self._on_message,
            logger=self.log,
            dialect=mavlink2,
        )
        self._acks: dict[int, int] = {}
        self._streams_asked = False
        self._changed = asyncio.Event()
        self.on_boot_time: Callable[[int], None] | None = None  # each time_boot_ms seen

    @property
    def port(self) -> int:
        return self.link.local_port

    async def __aenter__(self) -> SitlPilot:
        await self.link.__aenter__()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.link.__aexit__(*exc)

    # ------------------------------------------------------------------ listening
    def _on_message(self, msg: Any, _addr: tuple[str, int]) -> None:
        if msg.get_srcSystem() != self.sysid:
            return
        v = self.view
        kind = msg.get_type()
        if hasattr(msg, "time_boot_ms"):
            v.time_boot_ms = int(msg.time_boot_ms)
            if self.on_boot_time is not None:
                self.on_boot_time(v.time_boot_ms)
        if kind == "HEARTBEAT" and msg.get_srcComponent() == 1:
            armed = bool(msg.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED)
            mode = self.mode_name(int(msg.custom_mode))
            if mode != v.mode:
                self.on_event("mode", {"mode": mode})
            if armed != v.armed:
                self.on_event("armed" if armed else "disarmed", {} if armed else {"reason": "firmware"})
            v.heartbeat, v.mode, v.armed = True, mode, armed
            if not self._streams_asked:
                self._ask_streams()
        elif kind == "EXTENDED_SYS_STATE":
            v.landed_state = int(msg.landed_state)
        elif kind == "EKF_STATUS_REPORT":
            v.ekf_flags = int(msg.flags)
        elif kind == "GPS_RAW_INT":
            v.gps_fix = int(msg.fix_type)
        elif kind == "LOCAL_POSITION_NED":
            v.local_ned = (msg.x, msg.y, msg.z)
            v.local_vel = (msg.vx, msg.vy, msg.vz)
        elif kind == "SYS_STATUS" and msg.battery_remaining >= 0:
            v.battery_pct = float(msg.battery_remaining)
        elif kind == "STATUSTEXT":
            text = msg.text.rstrip("\x00") if isinstance(msg.text, str) else msg.text.decode(errors="replace")
            self.texts.append(text)
            self.log.info("%s says: %s", self.firmware, text)
        elif kind == "COMMAND_ACK":
            self._acks[int(msg.command)] = int(msg.result)
        self._changed.set()

    def mode_name(self, custom_mode: int) -> str:
        return mode_name(custom_mode)

    def _ask_streams(self) -> None:
        self._streams_asked = True
        for msg_id, hz in STREAMS_HZ.items():
            self.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, msg_id, 1e6 / hz)

    def command(self, command: int, *params: float) -> None:
        p = [*params, *[0.0] * (7 - len(params))]
        self._acks.pop(command, None)
        self.link.send(self.link.mav.command_long_encode(self.sysid, 1, command, 0, *p))

    def set_params(self, params: dict[str, float]) -> None:
        """PARAM_SET each (REAL32), unconfirmed: simulation knobs (``SIM_*``) set while it flies."""
        for name, value in params.items():
            self.link.send(
                self.link.mav.param_set_encode(self.sysid, 1, name.encode(), value, M.MAV_PARAM_TYPE_REAL32)
            )

    async def _wait(self, until: Callable[[], bool], deadline_s: float, what: str) -> None:
        while not until():
            if self.sim_time() > deadline_s:
                said = "; ".join(self.texts) or "nothing"
                raise SitlNotReady(
                    f"{self.firmware} did not {what} by {deadline_s:.0f} s simulated (it said: {said})"
                )
            self._changed.clear()
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self._changed.wait(), 0.5)

    async def wait_estimator(self, ready: Callable[[], bool]) -> None:
        """Until ``ready()`` (the estimator has a position: the vehicle could arm)."""
        await self._wait(ready, self.sim_time() + READY_TIMEOUT_S, "get a position estimate")

    # ------------------------------------------------------------------ the air start
    hold_mode = "GUIDED"  # the mode the firmware holds the launch pose in, the companion takes over from

    async def fly_to_launch(self, height_m: float, at_launch: Callable[[], bool]) -> None:
        """Arm, take off to ``height_m`` over home and hold (module docstring) until ``at_launch()``
        (the simulator's truth: within ``READY_POS_M`` and ``READY_SPEED_M_S`` of the launch pose)
        has held for ``READY_HOLD_S`` in ``hold_mode``.

        One loop, not a sequence of steps: the firmware may undo a step (ArduCopter's RC flight-mode
        channel sets the mode once RC input appears, about 2 s after boot), so each pass asks for
        whatever is missing first (:meth:`_ask_next`), once a simulated second at most."""
        deadline = self.sim_time() + READY_TIMEOUT_S
        v = self.view
        next_try = -math.inf
        held_since: float | None = None

        def step() -> bool:
            nonlocal next_try, held_since
            now = self.sim_time()
            if not v.heartbeat or not self.can_start():
                return False
            if v.armed and v.mode == self.hold_mode and at_launch():
                held_since = now if held_since is None else held_since
                return now - held_since >= READY_HOLD_S
            held_since = None
            if now < next_try:
                return False
            next_try = now + RETRY_S
            self._ask_next(height_m)
            return False

        await self._wait(step, deadline, f"take off and hold at {height_m:.0f} m over the launch point")
        self.log.info("%s holds at the launch pose at %.1f s simulated", self.firmware, self.sim_time())

    def can_start(self) -> bool:
        """Whether the firmware could arm now (ArduCopter: its refusals are retried instead)."""
        return True

    def _ask_next(self, height_m: float) -> None:
        """ArduCopter: GUIDED, then arm, then NAV_TAKEOFF to ``height_m``."""
        v = self.view
        if v.mode != "GUIDED":
            self.command(M.MAV_CMD_DO_SET_MODE, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, COPTER_GUIDED)
        elif not v.armed:
            self.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1)
        elif v.landed_state in (M.MAV_LANDED_STATE_ON_GROUND, M.MAV_LANDED_STATE_UNDEFINED):
            self.command(M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, 0, 0, height_m)
