"""The companion daemon: one MAVLink endpoint shared with the autopilot, the ground station and the
alarm tool (replies routed by system/component id), its own HEARTBEAT, alarm intake and watchers,
and at most one recovery at a time."""

from __future__ import annotations

import asyncio
import collections
import contextlib
import dataclasses
import logging
import time
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Any

from companion.alarms import ALARM_TEXT_PREFIX, MAV_CMD_USER_1, Alarm, Criticality, ReasonCode
from companion.control import VehicleController
from companion.fence import read_fence
from companion.frame_source import FrameSource
from companion.ground import GroundFeed, TeeRecord, telemetry_snapshot
from companion.memory import trim_malloc
from companion.operator import MAV_CMD_USER_2, InhibitSwitch, OperatorControls
from companion.params import Binding, ParamServer
from companion.precision import check_precision_landing
from companion.reasoning.base import Reasoner
from companion.reasoning.cascade import Cascade
from companion.reasoning.onboard import OnboardReasoner
from companion.recovery import Outcome, Record, Recovery, RecoveryParams
from companion.recovery.looking import warm_up
from companion.supervise import supervised
from companion.telemetry import TelemetryCache
from landfall_link.mavlink import MavlinkLink, open_link

MAV_TYPE_ONBOARD_CONTROLLER = 18
MAV_AUTOPILOT_INVALID = 8
MAV_STATE_STANDBY, MAV_STATE_ACTIVE = 3, 4
SEVERITY_WARNING = 4  # MAV_SEVERITY_WARNING: autopilot texts this grave or graver go into a recovery's record
RESULT_ACCEPTED, RESULT_TEMP_REJECTED, RESULT_DENIED, RESULT_UNSUPPORTED, RESULT_IN_PROGRESS = 0, 1, 2, 3, 5
# the sensor stream not up yet: tried again after this, then twice as long each time up to the maximum
SENSOR_RETRY_FIRST_S, SENSOR_RETRY_MAX_S = 0.2, 1.0
RESUME_WAIT_S = 60.0  # after a restart mid-recovery: how long to wait for telemetry and sensors
# What the companion needs from the autopilot, Hz: real ArduPilot sends none of it unasked (PX4 and the
# emulation stream it anyway; asking is harmless there). Asked on the first heartbeat and again while
# any of it stays missing.
STREAMS_HZ: dict[int, float] = {
    31: 20.0,  # ATTITUDE_QUATERNION
    32: 20.0,  # LOCAL_POSITION_NED
    245: 5.0,  # EXTENDED_SYS_STATE
    132: 10.0,  # DISTANCE_SENSOR
    1: 2.0,  # SYS_STATUS
    24: 5.0,  # GPS_RAW_INT
}
STREAM_PARTS = ("attitude", "position", "landed", "battery", "gps")  # TelemetryCache parts they feed
STREAM_CHECK_S = 2.0
# texts that say "failsafe" of something other than the vehicle: ArduCopter's precision landing says
# "PrecLand: Failsafe Measures" when land mode has no target (it lands without one); an alarm from it
# took a fence failsafe's landing back (found by tests/test_autopilot_failsafes.py's fence flight)
NOT_A_VEHICLE_FAILSAFE = ("PrecLand:",)
OWN_ALARM_RETRY_S = 30.0  # how long a watcher alarm refused for now is asked again
MAV_CMD_SET_MESSAGE_INTERVAL = 511


class Companion:
    """Build, then ``await run()``; ``stop()`` ends it.

    The MAVLink endpoint is ``link`` when given (``signing_key`` is then the link's business), else the
    UDP, TCP or serial link ``mavlink_url`` names (:func:`landfall_link.mavlink.open_link`)."""

    def __init__(
        self,
        *,
        mavlink_url: str | None = None,
        link: MavlinkLink | None = None,
        component_id: int = 191,
        vehicle_system_id: int = 0,
        signing_key: bytes | None = None,
        sensors: tuple[str, int] | None = None,
        frame_timeout_s: float = 10.0,
        max_frame_age_s: float = 2.0,
        camera: Any = None,
        camera_latency_s: float = 0.0,
        camera_offset_frd_m: tuple[float, float, float] = (0.0, 0.0, 0.0),
        reasoner: Reasoner | None = None,
        params: RecoveryParams | None = None,
        record: Record | None = None,
        ground: GroundFeed | None = None,
        resume: Alarm | None = None,
        watch_battery_pct: float | None = 15.0,
        watch_failsafe_text: bool = True,
        watch_gps: bool = True,
        accept_from: tuple[int, ...] = (),
        cancel_to: str = "hold",
        inhibit: InhibitSwitch | None = None,
        params_file: Path | None = None,
        heartbeat_hz: float = 1.0,
        logger: logging.Logger | None = None,
    ) -> None:
        self.log = logger or logging.getLogger("companion")
        self.component_id = component_id
        self.tm = TelemetryCache(vehicle_system_id)
        if link is None:
            if mavlink_url is None:
                raise ValueError("a Companion needs a mavlink_url or a link, got neither")
            link = open_link(
                mavlink_url,
                vehicle_system_id or 1,
                component_id,
                signing_key=signing_key,
                logger=logging.getLogger("companion.link"),
            )
            self._link_name: object = link.url
        else:
            self._link_name = link
        self.link: MavlinkLink = link
        self.link.attach(self._on_message)
        self.ctl = VehicleController(self.tm, self.link, logger=self.log)
        self.reasoner: Reasoner = reasoner or Cascade([], [], OnboardReasoner())
        self.params = params or RecoveryParams()
        self.ground = ground
        self._resume_alarm = resume
        # the recovery's events go to the flight record and to the ground feed alike
        self.record: Record | None = (
            TeeRecord(record, ground) if record is not None and ground is not None else record or ground
        )
        self._sensors = sensors
        self._frame_timeout_s = frame_timeout_s
        # a video camera (companion.camera.CameraStream): the image comes from it, the LiDAR (if any)
        # from the sensor stream, each placed with the autopilot's pose at its own capture time
        self._camera = camera
        self.view = FrameSource(
            self.tm,
            max_frame_age_s=max_frame_age_s,
            camera=camera,
            camera_latency_s=camera_latency_s,
            camera_offset_frd_m=camera_offset_frd_m,
            record=self.record,
            logger=self.log,
        )
        self._watch_battery_pct = watch_battery_pct
        self._watch_failsafe = watch_failsafe_text
        self._watch_gps = watch_gps
        self._accept_from = accept_from
        self.operator = OperatorControls(  # ValueError for a cancel mode that is none
            self.tm,
            self.ctl,
            self.announce,
            self._record_event,
            self.log,
            cancel_to=cancel_to,
            inhibit=inhibit,
        )
        self.alarms_inhibited = 0
        bindings, log = self._param_bindings(), logging.getLogger("companion.params")
        self.param_server = ParamServer(self.link, bindings, self._may_command, params_file, log)
        self.param_server.load()  # values set over MAVLink before a restart, over the configuration's
        self._heartbeat_period = 1.0 / heartbeat_hz
        self._alarm_texts: dict[tuple[int, int], str] = {}
        self.recovery: Recovery | None = None
        self._recovery_task: asyncio.Task[Outcome] | None = None
        self.outcomes: list[Outcome] = []
        self.alarms_refused = 0
        self.restarts: collections.Counter[str] = collections.Counter()  # supervised tasks started again
        self._stop = asyncio.Event()
        self._gps_was_ok = False
        # a watcher alarm refused for now (no fresh telemetry or frame yet): asked again each second
        # until this monotonic time, since its cause (a failsafe's one STATUSTEXT) may not come again
        self._own_pending: tuple[Alarm, float] | None = None
        self._texts_seen = 0

    # ------------------------------------------------------------------ MAVLink in
    def _on_message(self, msg: Any, addr: tuple[str, int]) -> None:
        self.tm.on_message(msg)
        if self.tm.state.system_id and self.link.mav.srcSystem != self.tm.state.system_id:
            self.link.mav.srcSystem = self.tm.state.system_id  # our heartbeat carries the vehicle's id
        kind = msg.get_type()
        if kind == "COMMAND_ACK":
            self.ctl.on_command_ack(msg)
        elif kind == "PARAM_VALUE":
            self.ctl.on_param_value(msg)
        elif kind == "COMMAND_LONG":
            self._on_command(msg)
        elif kind in ("PARAM_REQUEST_LIST", "PARAM_REQUEST_READ", "PARAM_SET"):
            self.param_server.on_message(msg, self._addressed)
        elif kind == "STATUSTEXT" and str(msg.text).startswith(ALARM_TEXT_PREFIX):
            self._alarm_texts[(msg.get_srcSystem(), msg.get_srcComponent())] = str(msg.text)[
                len(ALARM_TEXT_PREFIX) :
            ]

    def _ack(self, msg: Any, result: int) -> None:
        src = (msg.get_srcSystem(), msg.get_srcComponent())
        ack = self.link.mav.command_ack_encode(int(msg.command), result, 0, 0, src[0], src[1])
        self.link.send_to(ack, *src)

    def _addressed(self, msg: Any) -> bool:
        """A request to this component: ours or every component (0), of this system or every one (0)."""
        component_ok = msg.target_component in (0, self.component_id)
        return bool(component_ok and msg.target_system in (0, self.link.mav.srcSystem))

    def _may_command(self, system_id: int) -> bool:
        """Whether ``system_id`` may raise an alarm, cancel or change a setting."""
        return not self._accept_from or system_id in self._accept_from

    def _on_command(self, msg: Any) -> None:
        ours = msg.target_component == self.component_id and msg.target_system in (0, self.link.mav.srcSystem)
        if not ours:
            return
        src = (msg.get_srcSystem(), msg.get_srcComponent())
        if int(msg.command) == MAV_CMD_USER_2:
            self._ack(msg, self.cancel(src))
            return
        if int(msg.command) != MAV_CMD_USER_1:
            self._ack(msg, RESULT_UNSUPPORTED)
            return
        try:
            alarm = Alarm.from_command(msg.param1, msg.param2, self._alarm_texts.pop(src, ""), src)
        except ValueError as exc:
            self.log.warning("malformed alarm from %s: %s", src, exc)
            self.alarms_refused += 1
            self._ack(msg, RESULT_DENIED)
            return
        self._ack(msg, self.raise_alarm(alarm))

    def raise_alarm(self, alarm: Alarm) -> int:
        """Start a recovery (ACCEPTED), merge into the running one (IN_PROGRESS), or refuse; the
        ground feed hears of each alarm and of what became of it."""
        result = self._take_alarm(alarm)
        if self.ground is not None:
            self.ground.alarm(alarm, result)
        if result == RESULT_ACCEPTED and self.record is not None:
            # what a restarted daemon resumes when this recovery never records its outcome; the
            # autopilot's clock places the alarm on the autopilot's (and a simulator's) time line
            seen = self.tm.state.t_boot_s > 0
            boot_ms = round(1000 * self.tm.state.t_boot_s) if seen else None
            self.record.record_event("alarm", {**alarm.to_json(), "vehicle_time_boot_ms": boot_ms})
        return result

    async def _resume(self, alarm: Alarm) -> None:
        """Policy after a restart mid-recovery (the previous session recorded an alarm but no outcome):
        once telemetry and the sensor stream are up, a vehicle still flying gets the recovery again
        from where it is (the autopilot held it meanwhile: PX4's offboard-loss failsafe, ArduPilot's
        GUIDED hold); a vehicle on the ground is left alone. Gives up after ``RESUME_WAIT_S``."""
        self.log.warning("the previous session ended mid-recovery (alarm %r): resuming it", alarm.reason)
        deadline = time.monotonic() + RESUME_WAIT_S
        while time.monotonic() < deadline:
            await asyncio.sleep(0.5)
            s = self.tm.state
            if s.system_id == 0 or self.tm.age_s("position") > 3.0 or not self.view.sees():
                continue
            if s.on_ground:
                self.log.info("the vehicle is on the ground: nothing to resume")
                return
            result = self.raise_alarm(dataclasses.replace(alarm, received_monotonic=time.monotonic()))
            if result in (RESULT_ACCEPTED, RESULT_IN_PROGRESS):
                self.log.info("recovery resumed after a restart")
                return
        self.log.warning("could not resume the interrupted recovery within %.0f s", RESUME_WAIT_S)

    def _take_alarm(self, alarm: Alarm) -> int:
        if self._accept_from and alarm.source[0] not in self._accept_from and alarm.source != (0, 0):
            self.alarms_refused += 1
            self.log.warning("alarm from system %d refused: not in accept_from_system_ids", alarm.source[0])
            return RESULT_DENIED
        if self.inhibited():
            self.alarms_refused += 1
            self.alarms_inhibited += 1
            self.log.warning("alarm %r refused: Landfall is inhibited by the RC switch", alarm.reason)
            return RESULT_DENIED
        if self.recovery is not None and self._recovery_task is not None and not self._recovery_task.done():
            self.recovery.raise_criticality(alarm.criticality)
            self.log.info("alarm %r merged into the running recovery", alarm.reason)
            return RESULT_IN_PROGRESS
        s = self.tm.state
        if s.system_id == 0 or self.tm.age_s("position") > 3.0:
            self.log.warning("alarm %r refused: no fresh vehicle telemetry", alarm.reason)
            return RESULT_TEMP_REJECTED
        if s.on_ground:
            self.log.warning("alarm %r refused: the vehicle is not flying", alarm.reason)
            return RESULT_DENIED
        if not self.view.sees():
            missing = "no sensor stream" if self._camera is None else "no camera frame yet"
            self.log.warning("alarm %r refused: %s", alarm.reason, missing)
            return RESULT_TEMP_REJECTED
        self.recovery = Recovery(
            alarm,
            control=self.ctl,
            telemetry=self.tm,
            frames=self.view.frame,
            reasoner=self.reasoner,
            announce=self.announce,
            params=self.params,
            record=self.record,
            logger=self.log,
        )
        self._recovery_task = asyncio.get_running_loop().create_task(self.recovery.run(), name="recovery")
        self._recovery_task.add_done_callback(self._recovery_done)
        return RESULT_ACCEPTED

    def _recovery_done(self, task: asyncio.Task[Outcome]) -> None:
        if task.cancelled():
            return
        exc = task.exception()
        if exc is not None:
            self.log.error("recovery failed: %r", exc)
            self.announce(2, f"Landfall: recovery failed: {exc}"[:150])
            if self.record is not None:
                self.record.record_event("recovery_failed", {"error": repr(exc)[:300]})
            return
        outcome = task.result()
        self.outcomes.append(outcome)
        if self.record is not None:
            self.record.record_event(
                "outcome",
                {
                    "state": outcome.state.value,
                    "rounds": outcome.rounds,
                    "reason": outcome.reason,
                    "longest_setpoint_gap_s": round(self.ctl.longest_stream_gap_s, 3),
                },
            )
        self.log.info(
            "recovery ended: %s after %d rounds (%s); longest setpoint gap %.0f ms",
            outcome.state.value,
            outcome.rounds,
            outcome.reason,
            1000 * self.ctl.longest_stream_gap_s,
        )

    # ------------------------------------------------------------------ the operator's controls
    def inhibited(self) -> bool:
        """Whether the RC inhibit switch (companion/operator.py) says no to alarms now."""
        return self.operator.inhibited()

    def cancel(self, source: tuple[int, int]) -> int:
        """The operator's cancel (companion/operator.py): ACCEPTED and the running recovery stopped,
        or DENIED (a sender that may not raise alarms, or no recovery to cancel)."""
        if not self._may_command(source[0]):
            self.alarms_refused += 1
            self.log.warning("cancel from system %d refused: not in accept_from_system_ids", source[0])
            return RESULT_DENIED
        return self.operator.cancel(self._recovery_task, source)

    def _param_bindings(self) -> dict[str, Binding]:
        """The daemon's side of every MAVLink parameter (companion/params.py): the operator's controls'
        own, and the alarm watchers'."""

        def set_battery(v: float) -> None:
            self._watch_battery_pct = v or None

        def flag(name: str) -> Binding:
            return Binding(lambda: float(getattr(self, name)), lambda v: setattr(self, name, bool(v)))

        return {
            **self.operator.bindings(),
            "LF_BATT_CRIT": Binding(lambda: float(self._watch_battery_pct or 0.0), set_battery),
            "LF_WATCH_FS": flag("_watch_failsafe"),
            "LF_WATCH_GPS": flag("_watch_gps"),
        }

    # ------------------------------------------------------------------ MAVLink out
    def announce(self, severity: int, text: str) -> None:
        """STATUSTEXT to every peer (ground stations show severity <= notice)."""
        self.link.send_statustext(severity, text)

    def _record_event(self, kind: str, data: dict[str, Any]) -> None:
        if self.record is not None:
            self.record.record_event(kind, data)

    async def _heartbeats(self) -> None:
        while True:
            busy = self._recovery_task is not None and not self._recovery_task.done()
            state = MAV_STATE_ACTIVE if busy else MAV_STATE_STANDBY
            self.link.send(
                self.link.mav.heartbeat_encode(
                    MAV_TYPE_ONBOARD_CONTROLLER, MAV_AUTOPILOT_INVALID, 0, 0, state
                )
            )
            await asyncio.sleep(self._heartbeat_period)

    async def _streams(self) -> None:
        """SET_MESSAGE_INTERVAL for ``STREAMS_HZ`` whenever the autopilot is heard but a part it feeds
        is older than ``STREAM_CHECK_S`` (the first heartbeat, an autopilot that rebooted)."""
        asked = False
        while True:
            heard = self.tm.age_s("heartbeat") < 3.0
            if heard and any(self.tm.age_s(p) > STREAM_CHECK_S for p in STREAM_PARTS):
                sysid = self.tm.state.system_id
                for msg_id, hz in STREAMS_HZ.items():
                    cmd = self.link.mav.command_long_encode(
                        sysid, 1, MAV_CMD_SET_MESSAGE_INTERVAL, 0, msg_id, 1e6 / hz, 0, 0, 0, 0, 0
                    )
                    self.link.send_to(cmd, sysid, 1)
                missing = [p for p in STREAM_PARTS if self.tm.age_s(p) > STREAM_CHECK_S]
                level = logging.INFO if not asked else logging.DEBUG
                self.log.log(
                    level, "asked the autopilot for its telemetry streams (missing: %s)", ", ".join(missing)
                )
                asked = True
            await asyncio.sleep(STREAM_CHECK_S)

    async def _precision_check(self) -> None:
        """Once the autopilot is heard: read whether it will land on the companion's LANDING_TARGET
        (:mod:`companion.precision`) and its circular fence (:mod:`companion.fence`), and say so; a
        recovery reads ``ctl.precision`` and ``ctl.fence``. Read again
        should the autopilot change (a reboot into another firmware)."""
        checked_for: int | None = None
        while True:
            if self.tm.age_s("heartbeat") < 3.0 and self.tm.state.autopilot != checked_for:
                autopilot = self.tm.state.autopilot
                setup = await check_precision_landing(self.ctl, autopilot)
                self.ctl.precision = setup
                checked_for = autopilot
                level = logging.INFO if setup.ready else logging.WARNING
                self.log.log(
                    level, "precision landing %s: %s", "ready" if setup.ready else "not used", setup.why
                )
                self.ctl.fence = await read_fence(self.ctl, autopilot)
                self.log.info("fence: %s", self.ctl.fence.why)
            await asyncio.sleep(STREAM_CHECK_S)

    async def _watchers(self) -> None:
        """Raise alarms from autopilot signals: battery critical, failsafe text, GPS fix lost."""
        while True:
            await asyncio.sleep(1.0)
            self.watch_once()

    def watch_once(self) -> None:
        """One look at the autopilot's signals (every second in flight)."""
        self.operator.watch()
        s = self.tm.state
        # texts counted by a running total: ``tm.texts`` keeps only the last 50 (an index into it
        # would stop seeing new ones after the 50th); what came while on the ground is passed over
        fresh = self.tm.texts_received - self._texts_seen
        self._texts_seen = self.tm.texts_received
        new_texts = self.tm.texts[-fresh:] if fresh > 0 else []
        running = self._recovery_task is not None and not self._recovery_task.done()
        if running and self.record is not None:
            # what the autopilot warned of during the recovery (its failsafes, a low battery) goes
            # into the record and the ground feed beside the companion's own decisions
            for _, severity, text in new_texts:
                if severity <= SEVERITY_WARNING:
                    self.record.record_event("autopilot_text", {"severity": severity, "text": text})
        if s.on_ground:
            self._own_pending = None
            return
        pending, self._own_pending = self._own_pending, None
        if pending is not None and time.monotonic() < pending[1]:
            self._own_alarm(pending[0].code, pending[0].criticality, pending[0].reason, until=pending[1])
        if self._watch_battery_pct is not None and s.battery_pct < self._watch_battery_pct:
            self._own_alarm(ReasonCode.LOW_BATTERY, Criticality.HIGH, f"battery {s.battery_pct:.0f} %")
        if self._watch_failsafe:
            for _, _, text in new_texts:
                if "failsafe" in text.lower() and not text.startswith(NOT_A_VEHICLE_FAILSAFE):
                    self._own_alarm(ReasonCode.FAILSAFE, Criticality.HIGH, text)
        if self._watch_gps and s.gps_fix >= 0:
            if s.gps_fix >= 3:
                self._gps_was_ok = True
            elif self._gps_was_ok:
                self._own_alarm(ReasonCode.GPS_LOST, Criticality.CRITICAL, "GPS fix lost")
                self._gps_was_ok = False

    def _own_alarm(
        self, code: ReasonCode, criticality: Criticality, text: str, until: float | None = None
    ) -> None:
        alarm = Alarm(code, criticality, text, (0, 0), time.monotonic())
        result = self.raise_alarm(alarm)
        self.log.info("watcher alarm %r -> MAV_RESULT %d", text, result)
        if result == RESULT_TEMP_REJECTED:
            self._own_pending = (alarm, until if until is not None else time.monotonic() + OWN_ALARM_RETRY_S)

    async def _connect_sensors(self, stack: contextlib.AsyncExitStack, client_cls: Any) -> None:
        """Connect to the sensor stream, retrying after ``SENSOR_RETRY_FIRST_S``, then twice as long
        each time up to a second: it may come up after us, usually within moments (both started at
        boot). Alarms are answered TEMPORARILY_REJECTED until it is there."""
        from landfall_link.sensorstream import SensorStreamError

        assert self._sensors is not None
        warned = False
        wait_s = SENSOR_RETRY_FIRST_S
        while True:
            try:
                client = client_cls(self._sensors[0], self._sensors[1], timeout_s=self._frame_timeout_s)
                self.view.client = await stack.enter_async_context(client)
                self.log.info("sensor stream connected: %s:%d", *self._sensors)
                if self.record is not None:  # what a harness waits for before its alarm
                    self.record.record_event("sensors", {"host": self._sensors[0], "port": self._sensors[1]})
                return
            except SensorStreamError as exc:
                if not warned:
                    self.log.warning(
                        "sensor stream not available yet (%s); retrying, every second at most", exc
                    )
                    warned = True
                await asyncio.sleep(wait_s)
                wait_s = min(2 * wait_s, SENSOR_RETRY_MAX_S)

    async def _warm_up(self) -> None:
        """Surface ID and the onboard tier once, in a worker thread, so that the first alarm does not
        pay the libraries' first-call costs (:func:`companion.recovery.looking.warm_up`). A failure
        here costs only that time: it is logged and the daemon goes on."""
        t0 = time.monotonic()
        try:
            await asyncio.to_thread(warm_up, self.reasoner)
        except Exception as exc:  # the first alarm's round meets the same error and handles it
            self.log.warning("warm-up failed (%s: %s): the first alarm pays the first-call costs",
                             type(exc).__name__, exc)  # fmt: skip
            return
        trim_malloc()  # what the first reads freed goes back to the system: the flight builds on less
        self.log.info("warmed up in %.0f ms: Surface ID and the onboard tier", (time.monotonic() - t0) * 1e3)

    # ------------------------------------------------------------------ lifetime
    def stop(self) -> None:
        self._stop.set()

    async def run(self) -> None:
        from landfall_link.sensorstream import SensorClient

        async with contextlib.AsyncExitStack() as stack:
            await stack.enter_async_context(self.link)
            tasks: list[asyncio.Task[None]] = []

            def start(name: str, factory: Callable[[], Awaitable[object]], forever: bool = True) -> None:
                run = supervised(name, factory, self.log, forever=forever, restarts=self.restarts)
                tasks.append(asyncio.create_task(run, name=name))

            start("heartbeat", self._heartbeats)
            start("streams", self._streams)
            start("watchers", self._watchers)
            start("precision-check", self._precision_check)
            start("warm-up", self._warm_up, forever=False)
            if self._sensors is not None:
                start("sensors", lambda: self._connect_sensors(stack, SensorClient), forever=False)
            if self._camera is not None:
                self._camera.start()
                stack.callback(self._camera.close)
            if self._resume_alarm is not None:
                alarm = self._resume_alarm
                start("resume", lambda: self._resume(alarm), forever=False)
            if self.ground is not None:
                ground = self.ground
                start(
                    "ground-feed",
                    lambda: ground.run(lambda: telemetry_snapshot(self.tm.state), self.raise_alarm),
                )
            self.log.info("companion up on %s (component %d)", self._link_name, self.component_id)
            try:
                await self._stop.wait()
            finally:
                for t in tasks:
                    t.cancel()
                if self._recovery_task is not None and not self._recovery_task.done():
                    self._recovery_task.cancel()
                    with contextlib.suppress(asyncio.CancelledError):
                        await self._recovery_task
                await self.ctl.release()
                for t in tasks:
                    with contextlib.suppress(asyncio.CancelledError):
                        await t
                if self.restarts:
                    self.log.warning("tasks started again after a failure: %s", dict(self.restarts))
                st = self.link.stats
                self.log.info(
                    "companion stopped: %d frames in, %d bad, %d unsigned and %d badly signed refused, "
                    "%d alarms refused; link: %d reconnects, %d errors, %d frames dropped while down",
                    st.received,
                    st.bad_frames,
                    st.rejected_unsigned,
                    st.rejected_bad_signature,
                    self.alarms_refused,
                    st.reconnects,
                    st.link_errors,
                    st.dropped,
                )
                if self.ground is not None:
                    g = self.ground
                    self.log.info(
                        "MQTT: %d messages published, %d dropped (queue full), %d unbuildable",
                        g.published,
                        g.dropped,
                        g.failed,
                    )
