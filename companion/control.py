"""Flying the vehicle from the companion: mode changes with acknowledgements, a position setpoint
streamed at 10 Hz (PX4 needs it before and during OFFBOARD), arrival judged from telemetry, and an
operator takeover detected the moment someone else changes the mode.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import time
from collections.abc import Callable
from typing import Any

from pymavlink.dialects.v20 import common as mavlink2

from companion.fence import Fence
from companion.flavour import Flavour, Mode, flavour_for
from companion.precision import PrecisionLanding
from companion.telemetry import TelemetryCache
from landfall_link.mavlink import MavlinkSender

POSITION_YAW_MASK = 2552  # use x, y, z and yaw
STREAM_HZ = 20.0  # >= 10 Hz on a real vehicle; 20 keeps PX4's 2 Hz rule at 4x simulation speed
MAV_STATE_CRITICAL = 5
MAV_RESULT_ACCEPTED, MAV_RESULT_TEMPORARILY_REJECTED = 0, 1
LINK_SILENCE_S = 3.0  # wall seconds without LOCAL_POSITION_NED before the link counts as lost
# a link coming back: heartbeats in another mode with no position this long after them mean the
# estimator lost the position (not a position still on its way)
HEARD_WITHOUT_POSITION_S = 1.0


class ControlError(RuntimeError):
    """Base of the companion's flight-control errors."""


class CommandRefused(ControlError):
    def __init__(self, command: int, result: int) -> None:
        super().__init__(f"command {command} refused by the autopilot (MAV_RESULT {result})")
        self.command = command
        self.result = result


class OperatorTakeover(ControlError):
    """Someone else changed the mode: the companion stops commanding at once."""

    def __init__(self, mode: int, name: str | None = None) -> None:
        super().__init__(
            f"mode changed to {name or f'custom_mode {mode}'} by someone else: operator takeover"
        )
        self.custom_mode = mode


class AutopilotFailsafe(ControlError):
    """The autopilot left our mode by itself (system status critical): a failsafe, not an operator."""

    def __init__(self, mode: int) -> None:
        super().__init__(f"autopilot failsafe switched to custom_mode {mode}")
        self.custom_mode = mode


class TargetTimeout(ControlError):
    def __init__(self, target: tuple[float, float, float], error_m: float, timeout_s: float) -> None:
        super().__init__(f"target {target} not reached within {timeout_s:.0f} s ({error_m:.1f} m away)")
        self.target = target
        self.error_m = error_m


class TouchedDown(ControlError):
    """The vehicle is on the ground (landed or disarmed) while the companion still flew it: a descent
    step met the surface before the final approach. A mode change that comes with the disarm (PX4
    leaves OFFBOARD when it auto-disarms) is the landing, not a takeover."""


class TelemetryLost(ControlError):
    """No LOCAL_POSITION_NED for ``LINK_SILENCE_S``: the MAVLink link to the autopilot is down."""


class VehicleController:
    """Commands one vehicle through ``link`` (its codec builds the messages, its ``send_to`` sends
    them: the daemon's MAVLink endpoint, or a test's link without a socket).

    :meth:`on_command_ack` and :meth:`on_param_value` must be fed every COMMAND_ACK and PARAM_VALUE
    the link receives.
    """

    def __init__(
        self,
        telemetry: TelemetryCache,
        link: MavlinkSender,
        *,
        logger: logging.Logger | None = None,
    ) -> None:
        self.tm = telemetry
        self._link = link
        self._log = logger or logging.getLogger("companion.control")
        self._acks: dict[int, asyncio.Future[int]] = {}
        self._params: dict[str, asyncio.Future[float]] = {}
        self._target: tuple[float, float, float, float] | None = None  # n, e, d, yaw
        self._asked_mode: int | None = None  # a mode change in flight (its custom_mode)
        self._streamer: asyncio.Task[None] | None = None
        self._engaged_mode: int | None = None
        self._mode_set_at = 0.0
        self._own_mode_heard = False  # a heartbeat in our mode since we set it
        self._foreign_heartbeat: int | None = None  # ``tm.heartbeats`` at the first in another mode
        self.takeover: OperatorTakeover | None = None
        self.failsafe: AutopilotFailsafe | None = None
        self.failsafe_modes: list[int] = []  # the modes the last failsafe went through (its grace period)
        # the autopilot's precision landing, read from its parameters once it is heard (the daemon)
        self.precision: PrecisionLanding | None = None
        # the autopilot's circular fence, read likewise: legs and sites keep inside it
        self.fence: Fence | None = None
        self.longest_stream_gap_s = 0.0  # wall seconds between two setpoints: the event loop's health
        self._failing: str | None = None  # the stream's failure last logged, until a send succeeds

    # ------------------------------------------------------------------ basics
    @property
    def flavour(self) -> Flavour:
        return flavour_for(self.tm.state.autopilot)

    @property
    def vehicle(self) -> tuple[int, int]:
        return (self.tm.state.system_id, 1)

    @property
    def target(self) -> tuple[float, float, float, float] | None:
        """The position setpoint streamed now (north, east, down in metres NED, yaw in radians); None
        while the companion commands no position."""
        return self._target

    @property
    def engaged_mode(self) -> int | None:
        """The autopilot's ``custom_mode`` the companion holds (acknowledged, or its land mode); None
        when it holds none."""
        return self._engaged_mode

    def on_command_ack(self, msg: Any) -> None:
        if (msg.get_srcSystem(), msg.get_srcComponent()) != self.vehicle:
            return
        fut = self._acks.get(int(msg.command))
        if fut is not None and not fut.done():
            fut.set_result(int(msg.result))

    def on_param_value(self, msg: Any) -> None:
        """Feed every PARAM_VALUE the link receives (answers to :meth:`read_param`)."""
        if (msg.get_srcSystem(), msg.get_srcComponent()) != self.vehicle:
            return
        name = msg.param_id if isinstance(msg.param_id, str) else bytes(msg.param_id).decode(errors="replace")
        fut = self._params.get(name.rstrip("\x00"))
        if fut is not None and not fut.done():
            fut.set_result(float(msg.param_value))

    async def read_param(self, name: str, *, timeout_s: float = 1.5, tries: int = 3) -> float | None:
        """One parameter's value as its PARAM_VALUE carries it (ArduPilot sends integers as floats,
        PX4 bytewise); None when the autopilot does not answer (no such parameter: both stay silent
        then)."""
        sys_id, comp_id = self.vehicle
        request = self._link.mav.param_request_read_encode(sys_id, comp_id, name.encode(), -1)
        value: float | None = await self._ask(self._params, name, lambda _attempt: request, timeout_s, tries)
        return value

    def send_landing_target(self, target_frd_m: tuple[float, float, float], time_usec: int) -> None:
        """LANDING_TARGET: where the landing site is from the vehicle now, body FRD metres (the
        frame ArduPilot's precision landing reads; the angles say the same for older firmware)."""
        x, y, z = target_frd_m
        distance = math.sqrt(x * x + y * y + z * z)
        if not (math.isfinite(distance) and distance > 0 and z > 0):
            raise ControlError(f"refusing a landing target not below the vehicle ({x}, {y}, {z})")
        # angle_x: image right (body right); angle_y: image down (body aft), as ArduPilot reads them
        angles = (math.atan2(y, z), math.atan2(-x, z), distance)
        self._send_landing_target(mavlink2.MAV_FRAME_BODY_FRD, angles, target_frd_m, time_usec)

    def send_landing_target_local(self, site_ned_m: tuple[float, float, float], time_usec: int) -> None:
        """LANDING_TARGET in ``MAV_FRAME_LOCAL_NED``: where the landing site is in the autopilot's local
        frame (what PX4's precision land reads; it stamps the target on arrival unless TIMESYNC runs)."""
        if not all(math.isfinite(v) for v in site_ned_m):
            raise ControlError(f"refusing a landing target that is not a place {site_ned_m}")
        # the angles and the distance are not read in this frame
        self._send_landing_target(mavlink2.MAV_FRAME_LOCAL_NED, (0.0, 0.0, 0.0), site_ned_m, time_usec)

    def _send_landing_target(
        self,
        frame: int,
        angles: tuple[float, float, float],
        xyz: tuple[float, float, float],
        time_usec: int,
    ) -> None:
        """LANDING_TARGET with ``position_valid`` 1: ``xyz`` in ``frame``, ``angles`` (angle_x, angle_y,
        distance) beside them."""
        sys_id, comp_id = self.vehicle
        msg = self._link.mav.landing_target_encode(
            time_usec, 0, frame, *angles, 0.0, 0.0, *xyz, [1.0, 0.0, 0.0, 0.0],
            mavlink2.LANDING_TARGET_TYPE_VISION_OTHER, 1,
        )  # fmt: skip
        self._link.send_to(msg, sys_id, comp_id)

    async def command(self, command: int, *params: float, timeout_s: float = 1.5, tries: int = 3) -> int:
        """COMMAND_LONG to the autopilot; returns its MAV_RESULT (retried on silence)."""
        p = [*params, *([0.0] * (7 - len(params)))]
        sys_id, comp_id = self.vehicle
        result: int | None = await self._ask(
            self._acks,
            command,
            lambda attempt: self._link.mav.command_long_encode(sys_id, comp_id, command, attempt, *p),
            timeout_s,
            tries,
        )
        if result is None:
            raise ControlError(f"no COMMAND_ACK for command {command} after {tries} tries")
        return result

    async def _ask(
        self,
        pending: dict[Any, asyncio.Future[Any]],
        key: Any,
        encode: Callable[[int], Any],
        timeout_s: float,
        tries: int,
    ) -> Any:
        """Send ``encode(attempt)`` until the answer filed under ``key`` in ``pending`` comes (its
        value), at most ``tries`` times ``timeout_s``; None when none came."""
        loop = asyncio.get_running_loop()
        for attempt in range(tries):
            fut: asyncio.Future[Any] = loop.create_future()
            pending[key] = fut
            sys_id, comp_id = self.vehicle
            self._link.send_to(encode(attempt), sys_id, comp_id)
            try:
                async with asyncio.timeout(timeout_s):
                    return await fut
            except TimeoutError:
                continue
            finally:
                pending.pop(key, None)
        return None

    async def _heard_in_mode(self, custom_mode: int, heartbeats: int = 2) -> int:
        """Return MAV_RESULT_ACCEPTED once ``heartbeats`` heartbeats in a row, all received from now
        on, show ``custom_mode``: the autopilot took the mode even if every COMMAND_ACK was lost."""
        seen = self.tm.heartbeats
        in_mode = 0
        while in_mode < heartbeats:
            with contextlib.suppress(TimeoutError):
                await self.tm.wait_update(0.5)
            if self.tm.heartbeats == seen:
                continue
            seen = self.tm.heartbeats
            in_mode = in_mode + 1 if self.tm.state.custom_mode == custom_mode else 0
        return MAV_RESULT_ACCEPTED

    async def _mode_command(self, params: tuple[float, ...], custom_mode: int) -> int:
        """DO_SET_MODE, answered by its COMMAND_ACK or, when a lossy link ate the ACKs, by the
        heartbeats that show the mode taken; whichever comes first."""
        ack = asyncio.ensure_future(self.command(mavlink2.MAV_CMD_DO_SET_MODE, *params, tries=5))
        heard = asyncio.ensure_future(self._heard_in_mode(custom_mode))
        try:
            done, _ = await asyncio.wait({ack, heard}, return_when=asyncio.FIRST_COMPLETED)
        finally:
            for task in (ack, heard):
                task.cancel()
        if heard in done:
            self._log.info("mode change seen in the heartbeats (its COMMAND_ACK was lost)")
        return done.pop().result()

    async def set_mode(self, mode: Mode) -> None:
        params = self.flavour.set_mode[mode]
        # while the command is out, a heartbeat already in the asked mode (it can come before the
        # acknowledgement) is the autopilot obeying, not someone else taking over
        self._asked_mode = self.flavour.modes[mode]
        try:
            await self._set_mode(params, mode)
        finally:
            self._asked_mode = None

    async def _set_mode(self, params: tuple[float, float, float], mode: Mode) -> None:
        for _ in range(5):
            result = await self._mode_command(params, self.flavour.modes[mode])
            if result == MAV_RESULT_ACCEPTED:
                self._engaged_mode = self.flavour.modes[mode]
                self._mode_set_at = time.monotonic()
                self._own_mode_heard = False
                self._foreign_heartbeat = None
                return
            if result != MAV_RESULT_TEMPORARILY_REJECTED:
                break
            await self.tm.wait_update(2.0)  # give the setpoint stream another telemetry period
        raise CommandRefused(mavlink2.MAV_CMD_DO_SET_MODE, result)

    # ------------------------------------------------------------------ setpoints
    def _send_target(self) -> None:
        if self._target is None:
            return
        n, e, d, yaw = self._target
        sys_id, comp_id = self.vehicle
        msg = self._link.mav.set_position_target_local_ned_encode(
            int(self.tm.state.t_boot_s * 1000) & 0xFFFFFFFF,
            sys_id,
            comp_id,
            1,
            POSITION_YAW_MASK,
            n,
            e,
            d,
            0,
            0,
            0,
            0,
            0,
            0,
            yaw,
            0,
        )
        try:
            self._link.send_to(msg, sys_id, comp_id)
        except OSError as exc:  # the link gone for a moment: the stream sends it again next tick
            self._fault("setpoint not sent", exc)
            return
        self._failing = None

    def _fault(self, what: str, exc: BaseException) -> None:
        """Log a failure once until the next success (``_failing``): 20 a second would drown the log."""
        if self._failing != repr(exc):
            self._log.error("%s (%r): the setpoint stream goes on", what, exc)
        self._failing = repr(exc)

    async def _stream(self) -> None:
        """The setpoint stream: the target (and the takeover check) ``STREAM_HZ`` times a second until
        cancelled. A send that fails (a link gone for a moment: ``OSError``) or any other error in one
        tick is logged, once until a tick succeeds again, and the stream goes on: an autopilot without
        fresh setpoints leaves OFFBOARD or GUIDED by its own failsafe."""
        period = 1.0 / STREAM_HZ
        last = time.monotonic()
        while True:
            try:
                self._check_takeover()
                self._send_target()
            except Exception as exc:
                self._fault("setpoint tick failed", exc)
            await asyncio.sleep(period)
            now = time.monotonic()
            self.longest_stream_gap_s = max(self.longest_stream_gap_s, now - last)
            last = now

    def _check_takeover(self) -> None:
        if self._engaged_mode is None or self.takeover is not None or self.failsafe is not None:
            return
        heard = self.tm.state.stamps.get("heartbeat", 0.0)
        if heard <= self._mode_set_at:
            return  # the heartbeat predates our own mode change
        if self.tm.state.custom_mode == self._engaged_mode:
            self._own_mode_heard = True
            self._foreign_heartbeat = None
            return
        if self.tm.state.custom_mode == self._asked_mode:
            return  # the mode being asked for, heard before its acknowledgement
        # Until a heartbeat has shown our mode, one in someone else's may be an old one the link
        # delivered late (a reordered datagram overtaken by our mode change's COMMAND_ACK): then a
        # takeover is two heartbeats in a row. Once ours has been heard, one is enough.
        if not self._own_mode_heard:
            if self._foreign_heartbeat is None:
                self._foreign_heartbeat = self.tm.heartbeats
            if self.tm.heartbeats == self._foreign_heartbeat:
                return
        if self.tm.state.system_status == MAV_STATE_CRITICAL:
            self.failsafe = AutopilotFailsafe(self.tm.state.custom_mode)
            self._log.warning("%s", self.failsafe)
        else:
            mode = self.tm.state.custom_mode
            self.takeover = OperatorTakeover(mode, self.flavour.mode_name(mode))
            self._log.warning("%s", self.takeover)
        self._target = None  # stop commanding at once

    def check_interruption(self) -> None:
        """Raise ``TouchedDown``, ``OperatorTakeover`` or ``AutopilotFailsafe`` if the latest
        telemetry says so. Being on the ground is checked first: an autopilot that auto-disarms after
        a touchdown changes its mode in the same heartbeat."""
        s = self.tm.state
        if self._engaged_mode is not None and s.on_ground:
            self._target = None
            raise TouchedDown(
                f"on the ground ({'disarmed' if not s.armed else 'landed'}) while the companion flew it"
            )
        if self._streamer is not None and self._streamer.done():
            self._streaming()  # a stream that ended while engaged starts again
        self._check_takeover()
        if self.takeover is not None:
            raise self.takeover
        if self.failsafe is not None:
            raise self.failsafe

    async def await_link(self, timeout_s: float) -> float:
        """After ``TelemetryLost``: wait until LOCAL_POSITION_NED flows again and a heartbeat sent
        after the wait began has come (the mode the autopilot is in *now*). The setpoint stream keeps
        running meanwhile. Returns the seconds since the last position before the silence; raises
        ``TelemetryLost`` when nothing came within ``timeout_s``, and ``AutopilotFailsafe`` or
        ``OperatorTakeover`` when heartbeats say the autopilot left the companion's mode and no
        position follows them within ``HEARD_WITHOUT_POSITION_S`` (the link is up, its estimator lost
        the position). A link that comes back with the autopilot in its own failsafe (PX4's offboard
        loss) returns as any other: the heartbeat often comes a moment before the first position,
        and the caller then sees the failsafe with the link up."""
        start = time.monotonic()
        last_heard = self.tm.state.stamps.get("position", start - LINK_SILENCE_S)
        deadline = start + timeout_s
        interrupted_at: float | None = None
        while True:
            now = time.monotonic()
            fresh = self.tm.age_s("position") < LINK_SILENCE_S / 3
            if fresh and self.tm.state.stamps.get("heartbeat", 0.0) > start:
                return now - last_heard
            # heartbeats without a position: the link is up but the estimator has none (a GPS loss);
            # the autopilot's own failsafe taking the vehicle then is seen as at any time
            interruption = self.failsafe if self.failsafe is not None else self.takeover
            if interruption is not None:
                interrupted_at = now if interrupted_at is None else interrupted_at
                if now - interrupted_at >= HEARD_WITHOUT_POSITION_S:
                    raise interruption
            remaining = deadline - now
            if remaining <= 0:
                raise TelemetryLost(f"no telemetry for {timeout_s + LINK_SILENCE_S:.0f} s")
            with contextlib.suppress(TimeoutError):
                await self.tm.wait_update(min(remaining, 0.1 if interruption is not None else 1.0))

    def set_target(self, n: float, e: float, d: float, yaw: float | None = None) -> None:
        if not all(math.isfinite(v) for v in (n, e, d)):
            raise ControlError(f"refusing a non-finite target ({n}, {e}, {d})")
        if yaw is None:
            w, x, y, z = self.tm.state.quat_wxyz
            yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
        self._target = (n, e, d, yaw)
        self._send_target()

    def retarget(self, n: float, e: float) -> None:
        """Move the current position target horizontally (its height and heading kept): the site
        followed in the camera during a descent step. Nothing when there is no target."""
        if self._target is None:
            return
        _n, _e, d, yaw = self._target
        self.set_target(n, e, d, yaw)

    async def engage(self) -> None:
        """Hold where the vehicle is and take control: one hold setpoint, then OFFBOARD or GUIDED.

        PX4 takes OFFBOARD while its last setpoint is younger than COM_OF_LOSS_T, so the setpoint
        sent here (and the stream that keeps it fresh) is enough; a TEMPORARILY_REJECTED answer is
        retried by :meth:`set_mode` after another telemetry period."""
        n, e, d = self.tm.state.pos_ned_m
        self.takeover = None
        self.failsafe = None
        self._engaged_mode = None  # not ours yet: no takeover checks until our mode is acknowledged
        self.set_target(n, e, d)
        self._streaming()
        await self.set_mode(Mode.GUIDED)
        self.set_target(n, e, d)

    def _streaming(self) -> None:
        """The setpoint stream running: started when there is none, or started again when it ended
        (its failure logged): :meth:`engage` and every :meth:`check_interruption` while engaged."""
        task = self._streamer
        if task is not None and not task.done():
            return
        if task is not None and not task.cancelled() and task.exception() is not None:
            self._log.error("the setpoint stream had stopped (%r): started again", task.exception())
        self._streamer = asyncio.create_task(self._stream(), name="setpoint-stream")

    async def release(self) -> None:
        """Stop the setpoint stream and command nothing more. A stream that had failed is logged,
        never raised: releasing the vehicle always succeeds."""
        task, self._streamer = self._streamer, None
        if task is not None:
            task.cancel()
            try:
                await task
            except asyncio.CancelledError:
                pass
            except Exception as exc:
                self._log.error("the setpoint stream had failed: %r", exc)
        self._engaged_mode = None

    async def ride_out_failsafe(self, grace_s: float) -> bool:
        """After an ``AutopilotFailsafe``: for up to ``grace_s`` stream a hold where the vehicle is,
        commanding no mode, and watch the heartbeat. True when the autopilot went back to the
        companion's mode by itself (its failsafe cleared: PX4's offboard-loss fallback does once
        setpoints flow again), and the companion commands again; False when it did not (or the vehicle
        is down): then the setpoints stop, and the caller decides from the mode the autopilot is in.
        The hold is ignored by an autopilot in any other mode."""
        if self.failsafe is None or self._engaged_mode is None:
            return False
        n, e, d = self.tm.state.pos_ned_m
        self.set_target(n, e, d)
        start = time.monotonic()
        self.failsafe_modes = [self.failsafe.custom_mode]
        while (remaining := start + grace_s - time.monotonic()) > 0:
            with contextlib.suppress(TimeoutError):
                await self.tm.wait_update(min(remaining, 0.5))
            s = self.tm.state
            if s.custom_mode != self.failsafe_modes[-1]:
                self.failsafe_modes.append(s.custom_mode)
            if s.on_ground:
                break
            if s.stamps.get("heartbeat", 0.0) > start and s.custom_mode == self._engaged_mode:
                self.failsafe = None
                return True
        self._target = None
        return False

    async def wait_on_ground(self, timeout_s: float) -> bool:
        """Without commanding anything: wait until the vehicle is on the ground (landed or
        disarmed). False when ``timeout_s`` passed first."""
        deadline = time.monotonic() + timeout_s
        while not self.tm.state.on_ground:
            if time.monotonic() > deadline:
                return False
            with contextlib.suppress(TimeoutError):
                await self.tm.wait_update(1.0)
        return True

    async def goto(
        self, n: float, e: float, d: float, *, tolerance_m: float, speed_m_s: float, timeout_s: float
    ) -> None:
        """Fly to a point; return when within ``tolerance_m`` and slower than ``speed_m_s``. A target
        moved meanwhile by :meth:`retarget` is the one flown to and waited for."""
        self.set_target(n, e, d)
        deadline = time.monotonic() + timeout_s
        err = math.inf
        while True:
            if self._target is not None:
                n, e, d = self._target[:3]
            self.check_interruption()
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise TargetTimeout((n, e, d), err, timeout_s)
            try:
                await self.tm.wait_update(min(remaining, 3.0))
            except TimeoutError:
                if self.tm.age_s("position") > LINK_SILENCE_S:
                    raise TelemetryLost(f"no LOCAL_POSITION_NED for {LINK_SILENCE_S:g} s") from None
                continue
            err = math.dist(self.tm.state.pos_ned_m, (n, e, d))
            if err < tolerance_m and self.tm.speed_m_s < speed_m_s:
                return

    async def land(self, timeout_s: float, mode: Mode = Mode.LAND) -> None:
        """Hand over to the autopilot's land mode (or ``mode``: PX4's AUTO.PRECLAND) and wait for the
        touchdown (landed or disarmed)."""
        await self.set_mode(mode)
        self._target = None
        await self.release()
        self._engaged_mode = self.flavour.modes[mode]
        deadline = time.monotonic() + timeout_s
        while not self.tm.state.on_ground:
            self.check_interruption()
            if time.monotonic() > deadline:
                raise ControlError(f"no touchdown within {timeout_s:.0f} s of switching to land")
            with contextlib.suppress(TimeoutError):
                await self.tm.wait_update(3.0)
