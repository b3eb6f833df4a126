"""What the companion knows about the vehicle, from its MAVLink stream, with the age of each part.

Updated by :meth:`TelemetryCache.on_message` for every message from the vehicle's autopilot;
``await wait_update()`` wakes on each new position so control waits on telemetry, not on sleeps.

The autopilot's estimate of where the vehicle was is kept for ``PoseHistory.HISTORY_S`` seconds of its
boot clock (LOCAL_POSITION_NED and ATTITUDE_QUATERNION, both stamped ``time_boot_ms``), so a sensor
frame is placed in the world with the pose the autopilot estimated at the frame's capture time
(:meth:`PoseHistory.at`), never with a pose the sensor side claims: on a vehicle, the autopilot's EKF is
all the companion has, in the autopilot's local frame (relative to its EKF origin).

That frame can jump: an estimator that rejected a lying GPS for a while and then resets onto it (a
glitch, a spoofer) moves its position by metres in one step, while its velocity stays smooth.
:class:`ResetWatch` notices such a step (a position further from the last one than the velocities
between carried it) and keeps it, so that what the companion placed in the old frame (its target, the
site it follows) can be moved into the new one.
"""

from __future__ import annotations

import asyncio
import bisect
import collections
import math
import time
from dataclasses import dataclass, field
from typing import Any, Generic, TypeVar

from landfall_link.boot_clock import BootClock

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
    rc_pwm_us: tuple[int, ...] = ()  # RC_CHANNELS' chan1_raw ... chan18_raw (0 or 65535: unused)
    home_ned_m: tuple[float, float, float] | None = None  # HOME_POSITION's local x, y, z (None: not heard)
    t_boot_s: float = 0.0
    stamps: dict[str, float] = field(default_factory=dict)  # part -> monotonic time of last update

    @property
    def on_ground(self) -> bool:
        """Disarmed, or the autopilot's land detector says ON_GROUND."""
        return not self.armed or self.landed_state == LANDED_ON_GROUND


@dataclass(frozen=True, slots=True)
class Pose:
    """The autopilot's estimate at one instant of its boot clock."""

    t_boot_s: float
    pos_ned_m: tuple[float, float, float]
    quat_wxyz: tuple[float, float, float, float]


T = TypeVar("T")


class _Samples(Generic[T]):
    """Values by boot-clock time, newest last, the last ``history_s`` seconds kept."""

    def __init__(self, history_s: float, reboot_back_s: float) -> None:
        self.history_s, self.reboot_back_s = history_s, reboot_back_s
        self.t: collections.deque[float] = collections.deque()
        self.v: collections.deque[T] = collections.deque()

    def add(self, t_s: float, value: T) -> None:
        if self.t and t_s <= self.t[-1]:
            if t_s >= self.t[-1] - self.reboot_back_s:
                return  # a duplicate or a late packet
            self.t.clear()  # the autopilot rebooted: its clock started again
            self.v.clear()
        self.t.append(t_s)
        self.v.append(value)
        while self.t[0] < t_s - self.history_s:
            self.t.popleft()
            self.v.popleft()

    def around(self, t: float, extrapolate_s: float, max_gap_s: float) -> tuple[int, float] | None:
        """``(k, w)``: ``t`` lies at weight ``w`` between samples ``k - 1`` and ``k``; ``(len, dt)``
        when it is ``dt`` past the newest (at most ``extrapolate_s``); None otherwise."""
        ts = self.t
        if not ts or t < ts[0]:
            return None
        k = bisect.bisect_right(ts, t)
        if k == len(ts):
            dt = t - ts[-1]
            return (k, dt) if dt <= extrapolate_s else None
        t0, t1 = ts[k - 1], ts[k]
        return (k, (t - t0) / (t1 - t0)) if t1 - t0 <= max_gap_s else None


Vec3 = tuple[float, float, float]


class PoseHistory:
    """Position and attitude samples of the last ``HISTORY_S`` seconds, by ``time_boot_ms``."""

    HISTORY_S = 10.0
    EXTRAPOLATE_S = 0.15  # past the newest sample: dead reckoning on its velocity (attitude held)
    MAX_GAP_S = 1.0  # two samples further apart than this are not interpolated between
    REBOOT_BACK_S = 2.0  # a sample this much older than the newest: the autopilot's clock restarted

    def __init__(self) -> None:
        self._pos: _Samples[tuple[Vec3, Vec3]] = _Samples(self.HISTORY_S, self.REBOOT_BACK_S)
        self._att: _Samples[tuple[float, float, float, float]] = _Samples(self.HISTORY_S, self.REBOOT_BACK_S)

    def add_position(self, t_s: float, pos: Vec3, vel: Vec3) -> None:
        self._pos.add(t_s, (pos, vel))

    def add_attitude(self, t_s: float, quat: tuple[float, float, float, float]) -> None:
        self._att.add(t_s, quat)

    def span(self) -> tuple[float, float] | None:
        """(oldest, newest) boot-clock seconds with a position, or None."""
        ts = self._pos.t
        return (ts[0], ts[-1]) if ts else None

    def at(self, t_s: float) -> Pose | None:
        """The estimate at ``t_s``: positions interpolated linearly, attitudes normalised-linearly;
        up to ``EXTRAPOLATE_S`` past the newest sample by its velocity; None before the oldest sample,
        further past the newest, across a gap, or with no attitude at all."""
        pos = self._position_at(t_s)
        quat = self._attitude_at(t_s)
        if pos is None or quat is None:
            return None
        return Pose(t_s, pos, quat)

    def turn_rate_at(self, t_s: float, half_s: float = 0.1) -> float:
        """How fast the attitude turned about ``t_s`` (rad/s): the angle between the attitudes
        ``half_s`` either side of it (the newest sample at most), over the time between them; NaN
        where they are not known or less than ``half_s`` apart."""
        ts = self._att.t
        if not ts:
            return math.nan
        t0, t1 = t_s - half_s, min(t_s + half_s, ts[-1])
        before, after = self._attitude_at(t0), self._attitude_at(t1)
        if before is None or after is None or t1 - t0 < half_s:
            return math.nan
        dot = abs(sum(a * b for a, b in zip(before, after, strict=True)))
        return 2.0 * math.acos(min(1.0, dot)) / (t1 - t0)

    def _position_at(self, t: float) -> Vec3 | None:
        found = self._pos.around(t, self.EXTRAPOLATE_S, self.MAX_GAP_S)
        if found is None:
            return None
        k, w = found
        values = self._pos.v
        if k == len(values):  # w is the time past the newest sample
            (n, e, d), (vn, ve, vd) = values[-1]
            return (n + vn * w, e + ve * w, d + vd * w)
        (p0, v0), (p1, v1) = values[k - 1], values[k]
        t0, t1 = self._pos.t[k - 1], self._pos.t[k]
        dt = t1 - t0
        jump_n = p1[0] - (p0[0] + 0.5 * (v0[0] + v1[0]) * dt)
        jump_e = p1[1] - (p0[1] + 0.5 * (v0[1] + v1[1]) * dt)
        if math.hypot(jump_n, jump_e) >= ResetWatch.MIN_M:
            # the estimate reset between the two: a time before the later sample is in the frame of
            # reference before the reset (ResetWatch dates it at the later sample), carried on from the
            # earlier one; a blend would put it part of the way, in neither (a site found 12 m off)
            a = t - t0
            return (p0[0] + v0[0] * a, p0[1] + v0[1] * a, p0[2] + v0[2] * a)
        return (p0[0] + w * (p1[0] - p0[0]), p0[1] + w * (p1[1] - p0[1]), p0[2] + w * (p1[2] - p0[2]))

    def _attitude_at(self, t: float) -> tuple[float, float, float, float] | None:
        found = self._att.around(t, self.EXTRAPOLATE_S, self.MAX_GAP_S)
        if found is None:
            return None
        k, w = found
        values = self._att.v
        if k == len(values):
            return values[-1]
        q0, q1 = values[k - 1], values[k]
        sign = 1.0 if sum(a * b for a, b in zip(q0, q1, strict=True)) >= 0.0 else -1.0  # the shorter way
        q = [a + w * (sign * b - a) for a, b in zip(q0, q1, strict=True)]
        norm = math.sqrt(sum(c * c for c in q)) or 1.0
        return (q[0] / norm, q[1] / norm, q[2] / norm, q[3] / norm)


class ResetWatch:
    """Horizontal resets of the estimate: ``resets`` holds ``(t_boot_s, (north, east))`` for each,
    the step the position took beyond what the velocity carried it (module docstring)."""

    MIN_M = 2.0  # a step this much beyond the velocity's carry is a reset (5 m/s^2 over 0.5 s: 0.6 m)
    MAX_DT_S = 0.5  # two samples further apart than this are not compared (a gap, a lossy link)

    def __init__(self) -> None:
        self.resets: list[tuple[float, tuple[float, float]]] = []
        self._last: tuple[float, Vec3, Vec3] | None = None

    def add(self, t_s: float, pos: Vec3, vel: Vec3) -> None:
        last = self._last
        if last is not None and last[0] - PoseHistory.REBOOT_BACK_S < t_s <= last[0]:
            return  # a repeated or reordered sample: the newest stays the reference
        self._last = (t_s, pos, vel)
        if last is None or not 0.0 < t_s - last[0] <= self.MAX_DT_S:
            return  # the first sample, after a gap, or the autopilot's clock restarted
        t0, p0, v0 = last
        dt = t_s - t0
        dn = pos[0] - (p0[0] + 0.5 * (v0[0] + vel[0]) * dt)
        de = pos[1] - (p0[1] + 0.5 * (v0[1] + vel[1]) * dt)
        if all(math.isfinite(v) for v in (dn, de)) and math.hypot(dn, de) >= self.MIN_M:
            self.resets.append((t_s, (dn, de)))

    def since(self, t_s: float) -> tuple[float, float]:
        """The resets after ``t_s`` added up: what moves a position placed then into the frame now."""
        dn = sum(r[1][0] for r in self.resets if r[0] > t_s)
        de = sum(r[1][1] for r in self.resets if r[0] > t_s)
        return (dn, de)


class TelemetryCache:
    """Latest vehicle state; parts older than their use allows are reported by :meth:`age_s`."""

    def __init__(self, vehicle_system_id: int = 0) -> None:
        self.state = VehicleState(system_id=vehicle_system_id)
        self.poses = PoseHistory()
        self.position_resets = ResetWatch()
        self.clock = BootClock()
        self._update = asyncio.Event()
        self.texts: list[tuple[float, int, str]] = []  # (monotonic, severity, text): the last 50
        self.texts_received = 0  # every STATUSTEXT from the autopilot so far (``texts`` keeps the last 50)
        self.heartbeats = 0  # distinct autopilot heartbeats so far (a duplicated datagram counts once)
        self._heartbeat_seq = -1

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
            if msg.get_seq() == self._heartbeat_seq:
                return  # the same heartbeat twice: a link that duplicates datagrams
            self._heartbeat_seq = msg.get_seq()
            self.heartbeats += 1
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
            self.poses.add_position(s.t_boot_s, s.pos_ned_m, s.vel_ned_m_s)
            self.position_resets.add(s.t_boot_s, s.pos_ned_m, s.vel_ned_m_s)
            self._stamp("position")
            self.clock.add(s.stamps["position"], s.t_boot_s)
            self._update.set()
            self._update = asyncio.Event()
        elif kind == "ATTITUDE_QUATERNION":
            s.quat_wxyz = (float(msg.q1), float(msg.q2), float(msg.q3), float(msg.q4))
            self.poses.add_attitude(msg.time_boot_ms / 1000.0, s.quat_wxyz)
            self._stamp("attitude")
        elif kind == "DISTANCE_SENSOR" and msg.orientation == 25:
            # a rangefinder that sees nothing reports its maximum (ArduCopter: 40 m on a 40 m sensor
            # 100 m up): the ground is farther, not there, so no reading (NaN)
            beyond = 0 < msg.max_distance <= msg.current_distance
            s.rangefinder_m = math.nan if beyond else msg.current_distance / 100.0
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
        elif kind == "RC_CHANNELS":
            s.rc_pwm_us = tuple(int(getattr(msg, f"chan{k}_raw")) for k in range(1, 19))
            self._stamp("rc")
        elif kind == "HOME_POSITION":
            home = (float(msg.x), float(msg.y), float(msg.z))
            if all(math.isfinite(v) for v in home):
                s.home_ned_m = home
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
