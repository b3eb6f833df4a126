"""``simbridge --autopilot ardupilot-sitl``: the same world, sensors, episode log and grading, flown by
real ArduCopter firmware (SITL) instead of the emulation.

The vehicle starts on the ground at the launch point, where SITL's home is (its reply positions are
relative to the resting vehicle there, so the firmware's home and EKF origin are the launch point: a
companion gets its local frame from the autopilot, as on a real vehicle). SITL's SERIAL0 goes to the
``--mavlink udpout:`` endpoint (the companion), SERIAL1 to simbridge's own link
(:mod:`simbridge.sitl_pilot`), which watches modes and arming for the episode log and, with
``--start air``, flies the firmware to the launch pose before the episode's ``ready`` event. SITL paces
itself to ``--speed`` (its ``--speedup``); simbridge's lock step answers every frame in its own thread.
Touchdowns are detected on the world's truth, as the emulation's land detector does, and graded the same.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import signal
import time
from typing import Any, TypeVar

from landfall_link.mavlink import LinkUrl
from simbridge.physics import CONTACT_MARGIN_M, GEAR_HEIGHT_M, VehicleState
from simbridge.sim import SimBridge
from simbridge.sitl import (
    FirmwareProcess,
    LockStep,
    SitlError,
    SitlProcess,
    claim_instance,
    find_arducopter,
    heading_deg,
)
from simbridge.sitl_pilot import READY_POS_M, READY_SPEED_M_S, SitlNotReady, SitlPilot

P = TypeVar("P", bound=SitlPilot)
_LANDED_CONFIRM_S = 0.3
_AIRBORNE_M = 0.25
_EKF_GOOD = 0x33F  # attitude, velocities, positions (rel/abs, vertical), predicted positions
_EKF_CONST_POS = 0x80
GPS_FAULT_STEP_M = 0.25  # a drifting GPS fault reaches the firmware in steps this big


class TouchdownWatch:
    """A touchdown on the world's truth: near the ground (gear contact, or the CG within a margin of
    its resting height), sinking slower than 0.5 m/s for 0.3 s, after having flown."""

    def __init__(self) -> None:
        self.armed_watch = False
        self.flown = False
        self.landed = False
        self._since: float | None = None

    def update(self, s: VehicleState) -> bool:
        """True once, at the touchdown."""
        if not self.armed_watch:
            return False
        agl = s.height_agl_m
        near = s.on_ground or agl < GEAR_HEIGHT_M + CONTACT_MARGIN_M
        if agl > GEAR_HEIGHT_M + _AIRBORNE_M:
            self.flown = True
            self.landed = False
        if self.landed or not self.flown:
            return False
        if near and abs(s.vel_ned_m_s[2]) < 0.5:
            if self._since is None:
                self._since = s.t_s
            elif s.t_s - self._since >= _LANDED_CONFIRM_S:
                self.landed = True
                self._since = None
                return True
        else:
            self._since = None
        return False


class FirmwareBridge(SimBridge):
    """:class:`SimBridge` with real firmware in place of the emulation: what ArduCopter SITL
    (:class:`SitlBridge`) and PX4 SITL (:class:`simbridge.px4_bridge.Px4SitlBridge`) share: the vehicle
    resting at the launch point where the firmware's home is, the episode log fed from the lock step,
    touchdowns on the world's truth, ``ready`` once the firmware holds the launch pose (air start) or
    could arm (ground start), and a clear error when the firmware dies or stops answering.

    Subclasses give ``firmware`` (its name in logs), :meth:`_find_binary`, :meth:`_start_firmware`
    (start it, its lock step and simbridge's pilot link; returns the pilot and the lock step),
    :meth:`_estimator_ready` and :meth:`_stop_fields`."""

    firmware = "firmware"

    def _init_autopilot(self) -> None:
        cfg = self.config
        self._find_binary()
        self.target = LinkUrl.parse(cfg.mavlink)
        sc = self.scenario
        n, e, d = self.home_ned_m
        self.rest_ned_m = (n, e, d - GEAR_HEIGHT_M)
        self.vehicle.reset(self.rest_ned_m, sc.launch_yaw_rad)  # real firmware starts on the ground
        self.launch_ned_m = (n, e, d - sc.launch_height_m)
        self.touchdown = TouchdownWatch()
        self.touchdown.armed_watch = cfg.start == "ground"
        self.boot_offset_ms: float | None = None
        self.pilot: SitlPilot | None = None
        self.lockstep: Any = None
        self.ready = asyncio.Event()
        self.failure: SitlError | None = None
        self.gps_fault = self._gps_fault()
        self._fault_sent: tuple[float, float] = (0.0, 0.0)

    def _find_binary(self) -> None:
        raise NotImplementedError

    async def _start_firmware(self, stack: contextlib.AsyncExitStack) -> tuple[SitlPilot, Any]:
        raise NotImplementedError

    def _estimator_ready(self, pilot: SitlPilot) -> bool:
        raise NotImplementedError

    async def _open_pilot(self, stack: contextlib.AsyncExitStack, kind: type[P]) -> P:
        """simbridge's own link to the firmware (``kind``: its pilot class), closed with ``stack``."""
        pilot = kind(self.config.system_id, self._on_event, self.sim_time_s, logger=self.log)
        await stack.enter_async_context(pilot)
        self.pilot = pilot
        pilot.on_boot_time = self._on_boot_time
        return pilot

    def _launch(
        self, stack: contextlib.AsyncExitStack, proc: FirmwareProcess, lock: Any, instance: int
    ) -> None:
        """Start the firmware and its lock step, each ended when ``stack`` closes, and say so."""
        cfg = self.config
        self.process, self.lockstep = proc, lock
        proc.start()
        stack.callback(proc.close)
        lock.start()
        stack.callback(lock.stop)
        self.log.info(
            "simbridge %s (instance %d, pid %s) to %s: scenario %s, seed %d, speed %.1fx, start %s",
            cfg.autopilot, instance, proc.pid, cfg.mavlink, cfg.scenario, cfg.seed, cfg.speed, cfg.start,
        )  # fmt: skip

    def _stop_fields(self) -> dict[str, Any]:
        raise NotImplementedError

    def _gps_offset(self, offset_ne_m: tuple[float, float]) -> None:
        """The firmware's GPS reports positions ``offset_ne_m`` away from now on (the lock step's
        thread: keep it cheap)."""
        raise NotImplementedError

    # ------------------------------------------------------------------ clocks
    def sim_time_s(self) -> float:
        return self.lockstep.sim_time_s() if self.lockstep is not None else 0.0

    def time_boot_ms(self, t_s: float) -> int:
        """The firmware's boot clock: the lock step's clock plus the offset seen in its messages."""
        offset = self.boot_offset_ms if self.boot_offset_ms is not None else 0.0
        return round((t_s - self.vehicle_t0_s) * 1000 + offset)

    async def _capture(self, want: set[str]) -> Any:
        """A sensor frame rendered with the world standing still: the lock step's physics waits
        (``LockStepThread.gate``) from the pose taken to the frame done, as a lock-step simulator
        renders within its step. Otherwise the firmware's clock runs on while the renderer shares
        the processor with the lock step, and at --speed 4 a frame 50 ms in the making arrived up to
        4.5 simulated seconds old, older than the companion accepts (sensors.max_frame_age_s)."""
        lock = self.lockstep
        if lock is None:
            return await super()._capture(want)
        # the lock step holds the gate for one physics step at a time (about 0.1 ms): poll it, never a
        # blocking acquire in a worker thread, which a cancelled capture would leave holding the gate
        while not lock.gate.acquire(blocking=False):  # noqa: ASYNC110 - a threading lock has no event
            await asyncio.sleep(0.0005)
        try:
            return await super()._capture(want)
        finally:
            lock.gate.release()

    # ------------------------------------------------------------------ lock-step hook (its thread)
    def _on_state(self, s: VehicleState) -> None:
        pilot = self.pilot
        if pilot is not None:
            v = pilot.view
            self.episode.state(
                s, v.mode, v.armed, v.landed_state, 100 * self.vehicle.battery.remaining_fraction
            )
        if self.vehicle.physics.collision is not None and not self._crash_seen:
            self._crash_seen = True  # the firmware's own crash check decides about its motors
            self._call(self._crashed, s)
        elif self.touchdown.update(s):
            self._call(self._on_event, "touchdown", {"pos_ned_m": [round(c, 3) for c in s.pos_ned_m]})
        fault = self.gps_fault
        if fault is not None and self.ready.is_set():
            offset = fault.update(s)
            if math.dist(offset, self._fault_sent) >= GPS_FAULT_STEP_M or (
                offset == fault.config.offset_ne_m and offset != self._fault_sent
            ):
                self._fault_sent = offset
                self._gps_offset(offset)
        if self.config.duration_s is not None and s.t_s >= self.config.duration_s:
            self._call(self._stop.set)

    def _call(self, fn: Any, *args: Any) -> None:
        with contextlib.suppress(RuntimeError):  # the loop is closing
            self._loop_ref.call_soon_threadsafe(fn, *args)

    def _launch_pose_ned(self) -> tuple[float, float, float]:
        """Above home (moved onto land when the launch point is not), where the firmware climbs to."""
        return self.launch_ned_m

    def _at_launch(self) -> bool:
        s = self.vehicle.state
        ln, le, ld = self.launch_ned_m
        n, e, d = s.pos_ned_m
        near = math.dist((n, e, d), (ln, le, ld)) < READY_POS_M
        return near and math.sqrt(sum(c * c for c in s.vel_ned_m_s)) < READY_SPEED_M_S

    # ------------------------------------------------------------------ running
    async def run(self) -> None:
        loop = asyncio.get_running_loop()
        self._loop_ref = loop
        for sig in (signal.SIGINT, signal.SIGTERM):
            with contextlib.suppress(NotImplementedError, RuntimeError):
                loop.add_signal_handler(sig, self._stop.set)
        cfg = self.config
        if cfg.camera_info_out is not None:
            self.write_camera_info(cfg.camera_info_out)
        if cfg.sensors is not None:
            self._warm_up_sensors()
        if not await self._go():
            return
        self.vehicle_t0_s = self.vehicle.state.t_s
        wall0 = time.monotonic()
        try:
            async with contextlib.AsyncExitStack() as stack:
                pilot, lock = await self._start_firmware(stack)
                if cfg.sensors is not None:
                    await stack.enter_async_context(self._sensor_server(*cfg.sensors))
                await self._supervise(pilot, lock)
        finally:
            self.wall_elapsed_s = time.monotonic() - wall0
            self._write_stop()

    async def _supervise(self, pilot: SitlPilot, lock: Any) -> None:
        """Bring the firmware to ``ready``, then run until stopped, the duration, or a firmware failure."""
        start = asyncio.ensure_future(self._get_ready(pilot))
        stop = asyncio.ensure_future(self._stop.wait())
        try:
            while not self._stop.is_set():
                if lock.done.is_set():
                    raise lock.error or SitlError("lock step ended")
                if start.done() and start.exception() is not None:
                    raise start.exception()  # type: ignore[misc]
                await asyncio.wait([stop], timeout=0.2)
        finally:
            for task in (start, stop):
                task.cancel()
                with contextlib.suppress(asyncio.CancelledError, SitlError):
                    await task

    async def _get_ready(self, pilot: SitlPilot) -> None:
        if self.config.start == "air":
            await pilot.fly_to_launch(self.scenario.launch_height_m, self._at_launch)
            self.touchdown.armed_watch = True
        else:
            await pilot.wait_estimator(lambda: self._estimator_ready(pilot))
        fields = self.ready_fields()
        fields["sim_s_to_ready"] = round(self.sim_time_s(), 2)
        self.log.info("%s boot clock = lock-step clock + %.1f ms", self.firmware, self.boot_offset_ms or 0.0)
        self._on_event("ready", fields)
        self.ready.set()

    def _on_boot_time(self, time_boot_ms: int) -> None:
        """The firmware's clock is the lock step's plus a constant: a message stamped ``time_boot_ms``
        was sent at or before the lock step's present, so the largest difference seen is the offset."""
        sample = time_boot_ms - 1000.0 * self.sim_time_s()
        if self.boot_offset_ms is None or sample > self.boot_offset_ms:
            self.boot_offset_ms = sample

    def _write_stop(self) -> None:
        s = self.vehicle.state
        lock = self.lockstep
        st = self.pilot.link.stats if self.pilot is not None else None
        fields: dict[str, Any] = {"wall_s": round(self.wall_elapsed_s, 3)}
        fields.update(self._stop_fields())
        fields["pilot_received"] = st.received if st else 0
        fields["error"] = str(lock.error).splitlines()[0] if lock and lock.error else None
        self.episode.event(s.t_s, "stop", fields)
        self.episode.close()
        rtf = s.t_s / max(self.wall_elapsed_s, 1e-9)
        self.log.info("simbridge (%s) stopped at t=%.1f s after %.1f s wall (%.1fx)", self.config.autopilot,
                      s.t_s, self.wall_elapsed_s, rtf)  # fmt: skip


class SitlBridge(FirmwareBridge):
    """Real ArduCopter SITL in place of the emulation (module docstring)."""

    firmware = "ArduCopter SITL"

    def _find_binary(self) -> None:
        self.binary = find_arducopter(self.config.sitl)

    async def _start_firmware(self, stack: contextlib.AsyncExitStack) -> tuple[SitlPilot, LockStep]:
        cfg = self.config
        instance, sock = claim_instance()
        stack.callback(sock.close)
        lat, lon, alt = cfg.origin.to_geodetic(*self.rest_ned_m)
        home = (lat, lon, alt, heading_deg(self.scenario.launch_yaw_rad))
        pilot = await self._open_pilot(stack, SitlPilot)
        proc = SitlProcess(
            self.binary, instance, home, speedup=cfg.speed,
            serial0=(self.target.host, self.target.port), serial1=("127.0.0.1", pilot.port),
            sysid=cfg.system_id, logger=self.log,
        )  # fmt: skip
        lock = LockStep(sock, self.vehicle, self.rest_ned_m, proc, on_state=self._on_state)
        self._launch(stack, proc, lock, instance)
        return pilot, lock

    def _estimator_ready(self, pilot: SitlPilot) -> bool:
        return _ekf_ready(pilot.view.ekf_flags, pilot.view.gps_fix)

    def _gps_offset(self, offset_ne_m: tuple[float, float]) -> None:
        """SITL's own GPS glitch: ``SIM_GPS1_GLTCH_X/Y`` are added to the fix's latitude and
        longitude, in degrees."""
        origin = self.config.origin
        lat, lon, _alt = origin.to_geodetic(offset_ne_m[0], offset_ne_m[1], 0.0)
        glitch = {"SIM_GPS1_GLTCH_X": lat - origin.lat_deg, "SIM_GPS1_GLTCH_Y": lon - origin.lon_deg}
        if self.pilot is not None:
            self._call(self.pilot.set_params, glitch)

    def _stop_fields(self) -> dict[str, Any]:
        lock = self.lockstep
        return {
            "frames": lock.frames if lock else 0,
            "resent": lock.resent if lock else 0,
            "skipped": lock.skipped if lock else 0,
        }


def _ekf_ready(flags: int, gps_fix: int) -> bool:
    return gps_fix >= 3 and flags & _EKF_GOOD == _EKF_GOOD and not flags & _EKF_CONST_POS


__all__ = ["FirmwareBridge", "SitlBridge", "SitlNotReady", "TouchdownWatch"]
