"""Real PX4 firmware (SITL) as simbridge's autopilot, with simbridge as its simulator.

PX4's ``px4_sitl_default`` build with airframe 10016 (``none_iris``) starts ``simulator_mavlink``, which
connects as a TCP client to port ``4560 + instance`` and takes its whole world from there: the way Gazebo
Classic, jMAVSim, AirSim and PX4's own JSBSim bridge drive it (the binary and its notes are in
``../shared/sitl/px4``). This module is that simulator:

- :func:`find_px4` finds the binary: ``--px4 PATH``, else ``$LANDFALL_PX4``, else
  ``../shared/sitl/px4/bin/px4`` beside the repository; its ROMFS is the ``etc/`` beside ``bin/``.
- :class:`Px4Process` runs it as a child in a temporary directory of its own (parameters, logs,
  dataman) with instance ``-i N`` (every PX4 port shifts by N, so several run at once). It runs a copy of
  the ROMFS with two additions, so they apply at boot, before the estimator starts: simbridge's
  parameters (:data:`PARAMS`) appended to ``px4-rc.params``, and ``px4-rc.mavlink`` with three MAVLink
  instances: the ground-station link (UDP 18570 + N) sending to simbridge's watcher
  (:mod:`simbridge.px4_pilot`) instead of 14550, where a companion listening on its default port would
  take it for a second vehicle; the standard API/offboard link (14580 + N, sending to MAVSDK's 14540 +
  N); and ``mavlink start -u LOCAL -o PORT -t HOST -m onboard``, PX4's own link to the companion
  (``--mavlink udpout:HOST:PORT``), not a relay in simbridge. It ends with SIGTERM, then SIGKILL.
- :class:`HilLockStep` is the TCP server PX4 connects to, in a thread of its own. Every step of
  ``1 / SENSOR_HZ`` simulated seconds it sends HIL_SENSOR (accelerometer and gyro with white noise and a
  constant bias drawn per run, magnetometer, barometer, temperature: PX4 reports a sensor whose values
  never change as stale), HIL_GPS every ``GPS_EVERY`` steps, HIL_STATE_QUATERNION (ground truth) and the
  downward DISTANCE_SENSOR every ``TRUTH_EVERY``; then it waits for PX4's HIL_ACTUATOR_CONTROLS and flies
  one JSBSim step with them. Lock step: PX4's clock is the ``time_usec`` of the HIL_SENSOR messages, so
  PX4 runs exactly as fast as simbridge can answer (paced to ``--speed`` when that is slower). Until
  PX4's first actuator message (its controllers start a few seconds after boot) sensors go out paced in
  wall time. Motors: ``controls[0..3]`` in [0, 1] are rotors 0-3 of the airframe (front right, back
  left, front left, back right: JSBSim's F450 engines 0-3, the same order and spin directions).

The world's magnetic field is a dipole-like field of ``MAG_FIELD_GAUSS`` at ``MAG_INCLINATION_DEG`` with
no declination, and PX4 is told so (``EKF2_DECL_TYPE`` 0, ``EKF2_MAG_DECL`` 0, no comparison with its
world magnetic model): the scenario's origin may be anywhere, and a field that disagrees with the model
PX4 carries would turn its heading.
"""

from __future__ import annotations

import logging
import math
import os
import shutil
import signal
import socket
import struct
import tempfile
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from pymavlink.dialects.v20 import common as mavlink2

from simbridge.autopilot.flavours import Px4Flavour
from simbridge.geo import GeoOrigin, Quat, Vec3, rotate_body_to_ned
from simbridge.hil_wire import ActuatorControls, HilWire
from simbridge.physics import VehicleState
from simbridge.sitl import (
    FirmwareProcess,
    LockStepThread,
    SitlDied,
    SitlError,
    SitlNotAnswering,
    SitlNotFound,
    SitlProtocolError,
    find_binary,
)
from simbridge.telemetry import RANGEFINDER_MAX_CM, RANGEFINDER_MIN_CM
from simbridge.vehicle import Vehicle

__all__ = [
    "ENV_BINARY",
    "PARAMS",
    "HilLockStep",
    "Px4Process",
    "claim_px4_instance",
    "find_px4",
]

M = mavlink2
ENV_BINARY = "LANDFALL_PX4"
SHARED_BINARY = Path(__file__).resolve().parent.parent.parent / "shared" / "sitl" / "px4" / "bin" / "px4"
AIRFRAME = 10016  # none_iris: generic quad X, simulator_mavlink
MODEL = "none_iris"
HIL_BASE_PORT = 4560
MAX_INSTANCES = 10  # PX4's offboard port 14540 + N is shared beyond 10 instances
SENSOR_HZ = 250  # HIL_SENSOR rate = PX4's IMU_INTEG_RATE; one JSBSim step each
GPS_EVERY = SENSOR_HZ // 10  # 10 Hz
TRUTH_EVERY = SENSOR_HZ // 50  # ground truth, barometer, magnetometer and rangefinder at 50 Hz
CONNECT_S = 60.0  # wall seconds from start to PX4's TCP connection
STALL_S = 15.0  # wall seconds without an actuator message once they have started
MAX_LAG_S = 0.05  # wall seconds the lock step may fall behind --speed before it drops the lag
BOOT_PACE_S = 1.0 / SENSOR_HZ  # wall pacing of sensor steps before PX4's controllers answer
_TAIL_LINES = 60
_NOISE_BLOCK = SENSOR_HZ  # sensor noise drawn for this many steps at once

# sensor model (white noise per sample; biases drawn once per run)
ACCEL_NOISE = 0.03  # m/s^2
ACCEL_BIAS = 0.02
GYRO_NOISE = 0.003  # rad/s
GYRO_BIAS = 0.001
ACCEL_RANGE = 16 * 9.80665  # m/s^2: the IMU's range, +-16 g (and +-2000 deg/s), as common MEMS IMUs
GYRO_RANGE = math.radians(2000.0)
MAG_NOISE = 0.002  # gauss
MAG_FIELD_GAUSS = 0.48
MAG_INCLINATION_DEG = 63.0
BARO_NOISE_M = 0.05
GPS_NOISE_M = 0.02
GPS_VEL_NOISE = 0.02

# Parameters applied at boot (px4-rc.params of the ROMFS copy).
PARAMS: dict[str, float] = {
    "EKF2_DECL_TYPE": 0,  # the world's field has no declination (module docstring) ...
    "EKF2_MAG_DECL": 0.0,
    "EKF2_MAG_CHECK": 0,  # ... and need not match PX4's world magnetic model
    "COM_ARM_MAG_STR": 0,
    "COM_RC_IN_MODE": 4,  # no RC transmitter, and none expected (the ground link is MAVLink only)
    "NAV_RCL_ACT": 0,
    "COM_RCL_EXCEPT": 4,  # no RC-loss reaction in OFFBOARD
    "NAV_DLL_ACT": 0,  # a lost ground station link is no reason to land: the companion decides
    "COM_DISARM_PRFLT": 60.0,  # the air start arms, then asks for the takeoff a moment later
    "MPC_TKO_SPEED": 3.0,  # and climbs at the envelope's climb rate (MPC_Z_VEL_MAX_UP)
    "SDLOG_MODE": -1,  # no flight logs in the temporary directory
    # precision land on the companion's LANDING_TARGET (companion/precision.py): a lost target lands
    # where it is rather than climbing to PLD_SRCH_ALT above the origin to search for it
    "PLD_MAX_SRCH": 0,
}
# The flight envelope the emulated PX4 flies (and companion-bench's kinematic bound assumes), in place of
# PX4's defaults (12 m/s across): the same F450 whoever flies it.
_ENVELOPE = (
    "MPC_XY_VEL_MAX", "MPC_Z_VEL_MAX_UP", "MPC_Z_VEL_MAX_DN", "MPC_TILTMAX_AIR", "MPC_ACC_HOR",
    "MPC_LAND_SPEED", "MPC_LAND_ALT2", "COM_OF_LOSS_T", "COM_OBL_RC_ACT", "COM_DISARM_LAND",
)  # fmt: skip
PARAMS.update({p.name: p.default for p in Px4Flavour.params if p.name in _ENVELOPE})


def find_px4(explicit: str | os.PathLike[str] | None = None) -> Path:
    """The PX4 SITL binary: ``explicit``, else ``$LANDFALL_PX4``, else the shared rig; with its ROMFS.

    Raises:
        SitlNotFound: saying where it looked and how to get one.
    """
    how = (
        f"pass --px4 PATH, set {ENV_BINARY}, or put PX4's px4_sitl_default build at {SHARED_BINARY} "
        "(its ROMFS in the etc/ beside bin/; how to build it: that folder's README.md)"
    )
    binary = find_binary(explicit, "--px4", ENV_BINARY, SHARED_BINARY, "PX4 SITL", how)
    rc = romfs_of(binary) / "init.d-posix" / "rcS"
    if not rc.is_file():
        raise SitlNotFound(f"{binary}: no PX4 ROMFS beside it ({rc} missing); {how}")
    return binary


def romfs_of(binary: Path) -> Path:
    return binary.resolve().parent.parent / "etc"


def claim_px4_instance(host: str = "127.0.0.1") -> tuple[int, socket.socket]:
    """The first instance whose simulator port (4560 + N) is free and whose PX4 lock is not held, with
    that port bound and listening (simbridge keeps it: no other simbridge takes the instance)."""
    for n in range(MAX_INSTANCES):
        if _px4_running(n):
            continue
        sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # a finished run's TIME_WAIT is no owner
        try:
            sock.bind((host, HIL_BASE_PORT + n))
        except OSError:
            sock.close()
            continue
        sock.listen(1)
        return n, sock
    last = HIL_BASE_PORT + MAX_INSTANCES - 1
    raise SitlError(f"no free PX4 instance: TCP ports {HIL_BASE_PORT}..{last} in use")


def _px4_running(instance: int) -> bool:
    """Whether a live PX4 holds instance ``instance`` (its server lock file, flock'ed while it runs)."""
    lock = Path(f"/tmp/px4_lock-{instance}")
    if not lock.exists():
        return False
    import fcntl

    try:
        with lock.open("rb") as fh:
            fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
            fcntl.flock(fh, fcntl.LOCK_UN)
    except OSError:
        return True
    return False


def free_udp_port(host: str = "127.0.0.1") -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind((host, 0))
        return int(s.getsockname()[1])


class Px4Process(FirmwareProcess):
    """``px4 -d ROMFS -s etc/init.d-posix/rcS -i N`` as a child (module docstring): ``start()``, ``close()``.

    Args:
        binary: the px4 executable (:func:`find_px4`).
        instance: ``-i``: shifts every PX4 port by N.
        companion: where PX4's companion MAVLink instance sends, ``(host, port)``, or None for none.
        pilot_port: the loopback UDP port PX4's ground-station link sends to (simbridge's watcher).
        params: boot parameters (default :data:`PARAMS`).
    """

    name = "PX4 SITL"
    stop_signal = signal.SIGTERM  # PX4 shuts its modules down
    stop_wait_s = 3.0

    def __init__(
        self,
        binary: Path,
        instance: int,
        *,
        companion: tuple[str, int] | None,
        pilot_port: int,
        params: dict[str, float] | None = None,
        logger: logging.Logger | None = None,
    ) -> None:
        super().__init__(binary, instance, logger or logging.getLogger("simbridge.px4"))
        self.companion = companion
        self.pilot_port = pilot_port
        self.companion_local_port: int | None = None
        self.params = dict(PARAMS if params is None else params)
        self.ready_for_takeoff = threading.Event()

    def _romfs(self, workdir: Path) -> Path:
        romfs = workdir / "romfs"
        shutil.copytree(romfs_of(self.binary), romfs, symlinks=True)
        posix = romfs / "init.d-posix"
        with (posix / "px4-rc.params").open("a") as fh:
            fh.write("\n# simbridge (landfall)\n")
            for name, value in self.params.items():
                fh.write(f"param set {name} {value:g}\n")
        lines = [
            "#!/bin/sh",
            "# simbridge (landfall): PX4's MAVLink links",
            "# the ground-station link, to simbridge's own watcher (in place of QGroundControl's 14550)",
            f"mavlink start -x -u $((18570+px4_instance)) -r 4000000 -f -o {self.pilot_port}",
            "# the API/offboard link (MAVSDK's default: PX4 sends to 14540 + N), in PX4's normal mode:",
            "# MAVSDK asks for the rates it needs; onboard mode's streams to a port nobody may listen on",
            "# cost PX4 a fifth of its CPU in lock step (docs/px4-sitl.md)",
            "mavlink start -x -u $((14580+px4_instance)) -r 4000000 -f -o $((14540+px4_instance))",
        ]
        if self.companion is not None:
            host, port = self.companion
            self.companion_local_port = free_udp_port()
            local = self.companion_local_port
            lines += [
                "# the companion computer's link (simbridge --mavlink udpout:HOST:PORT)",
                f"mavlink start -x -u {local} -r 4000000 -f -m onboard -o {port} -t {host}",
            ]
        (posix / "px4-rc.mavlink").write_text("\n".join(lines) + "\n")
        return romfs

    def _bin(self, workdir: Path) -> Path:
        """A folder of links: ``px4`` to the binary, and every ``px4-MODULE`` command the start-up scripts
        call to ``px4`` (the build makes them links; copied folders often turn them into small files
        naming the target, which the shell cannot run), with ``px4-alias.sh``. px4 puts its own folder
        on PATH."""
        here = workdir / "bin"
        here.mkdir()
        (here / "px4").symlink_to(self.binary.resolve())
        for f in self.binary.resolve().parent.iterdir():
            if f.name.startswith("px4-") and f.name != "px4-alias.sh":
                (here / f.name).symlink_to("px4")
        alias = self.binary.resolve().parent / "px4-alias.sh"
        if alias.is_file():
            shutil.copy(alias, here / "px4-alias.sh")
        return here / "px4"

    def command(self, px4: Path, romfs: Path) -> list[str]:
        return [str(px4), "-d", str(romfs), "-s", "etc/init.d-posix/rcS", "-i", str(self.instance)]

    def start(self) -> None:
        self.workdir = Path(tempfile.mkdtemp(prefix=f"landfall-px4-{self.instance}-"))
        romfs = self._romfs(self.workdir)
        px4 = self._bin(self.workdir)
        run = self.workdir / "run"
        run.mkdir()
        env = dict(os.environ, PX4_SYS_AUTOSTART=str(AIRFRAME), PX4_SIM_MODEL=MODEL)
        env.pop("PX4_SIM_SPEED_FACTOR", None)
        self._spawn(self.command(px4, romfs), run, env)

    def _on_line(self, line: str) -> None:
        if "Ready for takeoff" in line:
            self.ready_for_takeoff.set()


# ---------------------------------------------------------------------------------------------- sensors
@dataclass(frozen=True, slots=True)
class Isa:
    """International Standard Atmosphere below 11 km."""

    @staticmethod
    def pressure_hpa(alt_m: float) -> float:
        return float(1013.25 * (1.0 - 2.25577e-5 * alt_m) ** 5.25588)

    @staticmethod
    def temperature_c(alt_m: float) -> float:
        return 15.0 - 0.0065 * alt_m


def _i16(v: float) -> int:
    """An int16 field (cm/s, mG): a crash's spike of acceleration saturates rather than breaking the
    frame (a touchdown at speed read 33 g for one step, more than int16 milli-g holds)."""
    return max(-32767, min(32767, round(v)))


def _unit(v: float) -> float:
    return 1.0 if v > 1.0 else (v if v > 0.0 else 0.0)


def mag_field_ned() -> Vec3:
    inc = math.radians(MAG_INCLINATION_DEG)
    return (MAG_FIELD_GAUSS * math.cos(inc), 0.0, MAG_FIELD_GAUSS * math.sin(inc))


def ned_to_body(q: Quat, v: Vec3) -> Vec3:
    w, x, y, z = q
    return rotate_body_to_ned((w, -x, -y, -z), v)


# ---------------------------------------------------------------------------------------------- lock step
IO_TIMEOUT_S = 0.25  # the simulator socket's send and receive timeouts


def _kernel_timeouts(conn: socket.socket) -> None:
    """A blocking socket whose timeouts the kernel keeps (SO_RCVTIMEO, SO_SNDTIMEO): a receive is one
    system call, where Python's own timeout adds a poll before each (two calls a step, 500 a simulated
    second); a timeout raises BlockingIOError."""
    conn.settimeout(None)
    tv = struct.pack("ll", 0, round(IO_TIMEOUT_S * 1e6))
    conn.setsockopt(socket.SOL_SOCKET, socket.SO_RCVTIMEO, tv)
    conn.setsockopt(socket.SOL_SOCKET, socket.SO_SNDTIMEO, tv)


StateHook = Callable[[VehicleState], None]


class HilLockStep(LockStepThread):
    """Serves PX4's simulator_mavlink from a thread of its own (module docstring).

    Args:
        server: the bound, listening simulator port (:func:`claim_px4_instance`).
        vehicle: the airframe, stepped with :meth:`Vehicle.step_esc`.
        origin: the world's geodetic origin (HIL_GPS positions).
        process: the PX4 child, watched for exits.
        rng: noise source.
        speed: simulated seconds per wall second at most.
        on_state: called in this thread after every physics step (keep it cheap).
    """

    thread_name = "px4-lockstep"

    def __init__(
        self,
        server: socket.socket,
        vehicle: Vehicle,
        origin: GeoOrigin,
        process: Px4Process,
        rng: np.random.Generator,
        *,
        speed: float = 1.0,
        on_state: StateHook | None = None,
    ) -> None:
        super().__init__(vehicle, process)
        self.server = server
        self.origin = origin
        self.rng = rng
        self.speed = speed
        self.on_state = on_state
        self.steps = 0
        self.actuator_msgs = 0
        self.connected_wall_s: float | None = None
        self.first_answer: tuple[float, int] | None = None  # (monotonic, steps) at PX4's first answer
        self.gps_offset_ne_m = (0.0, 0.0)  # a GPS fault: HIL_GPS positions this far off (north, east)
        self._mav = M.MAVLink(None, srcSystem=1, srcComponent=51)
        self._mav.robust_parsing = True
        self._wire = HilWire(self._mav)
        self._noise = np.empty((0, 12))  # standard normals, drawn a block at a time (one row a step)
        self._accel_bias = tuple(rng.normal(0.0, ACCEL_BIAS, 3))
        self._gyro_bias = tuple(rng.normal(0.0, GYRO_BIAS, 3))
        self._controls: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)

    def _accept(self) -> socket.socket:
        self.server.settimeout(0.25)
        started = time.monotonic()
        while not self._stop.is_set():
            try:
                conn, _ = self.server.accept()
            except TimeoutError:
                rc = self.process.returncode()
                if rc is not None:
                    raise SitlDied(f"PX4 SITL exited with status {rc}", self.process.tail()) from None
                if time.monotonic() - started > CONNECT_S:
                    raise SitlNotAnswering(
                        f"PX4 did not connect to the simulator port within {CONNECT_S:.0f} s",
                        self.process.tail(),
                    ) from None
                continue
            self.connected_wall_s = time.monotonic() - started
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            return conn
        raise SitlError("stopped before PX4 connected")

    def _serve(self) -> None:
        conn = self._accept()
        try:
            self._loop(conn)
        finally:
            conn.close()

    def _loop(self, conn: socket.socket) -> None:
        vehicle = self.vehicle
        physics = vehicle.physics
        physics.set_dt(1.0 / SENSOR_HZ)
        _kernel_timeouts(conn)
        wall0 = time.monotonic()
        last_actuator_wall = wall0
        s = vehicle.state
        while not self._stop.is_set():
            t_s = s.t_s - self._t0_s
            data = self._sensors(s, t_s)
            self.steps += 1  # before it goes: whoever reads it after the answer comes sees it
            conn.sendall(data)
            if self.actuator_msgs == 0:
                # PX4's controllers are not up yet: no answer to wait for, keep time moving
                self._drain(conn, block=False)
                time.sleep(BOOT_PACE_S)
                self._check_alive(wall0, last_actuator_wall)
            else:
                got = self.actuator_msgs
                while self.actuator_msgs == got and not self._stop.is_set():
                    if not self._drain(conn, block=True):
                        self._check_alive(wall0, last_actuator_wall)
                last_actuator_wall = time.monotonic()
            ahead = (t_s / self.speed) - (time.monotonic() - wall0)
            if ahead > 0.002:
                time.sleep(ahead)
            elif ahead < -MAX_LAG_S:
                # behind the pace (a busy machine): carry on from here, never race to catch up, which
                # would squeeze simulated seconds into a blink of wall time for the companion
                wall0 += -ahead - MAX_LAG_S
            with self.gate:
                s = vehicle.step_esc(self._controls)
            if self.on_state is not None:
                self.on_state(s)

    def _check_alive(self, wall0: float, last_actuator_wall: float) -> None:
        rc = self.process.returncode()
        if rc is not None:
            raise SitlDied(f"PX4 SITL exited with status {rc}", self.process.tail())
        if self.actuator_msgs and time.monotonic() - last_actuator_wall > STALL_S:
            raise SitlNotAnswering(
                f"PX4 sent no HIL_ACTUATOR_CONTROLS for {STALL_S:.0f} s", self.process.tail()
            )

    def _drain(self, conn: socket.socket, *, block: bool) -> bool:
        """Read what PX4 sent; True if anything came."""
        try:
            data = conn.recv(65536, 0 if block else socket.MSG_DONTWAIT)
        except (BlockingIOError, TimeoutError):  # nothing yet, or the kernel's receive timeout
            return False
        if not data:
            raise SitlDied("PX4 closed the simulator connection", self.process.tail())
        for msg in self._wire.feed(data):
            self._on_message(msg)
        return True

    def _on_message(self, msg: ActuatorControls | Any) -> None:
        if not isinstance(msg, ActuatorControls):
            if msg.get_type() != "HIL_ACTUATOR_CONTROLS":
                return
            msg = ActuatorControls(msg.time_usec, msg.flags, tuple(msg.controls), msg.mode)  # a signed one
        c0, c1, c2, c3 = msg.controls[:4]
        if math.isnan(c0) or math.isnan(c1) or math.isnan(c2) or math.isnan(c3):
            raise SitlProtocolError("HIL_ACTUATOR_CONTROLS with NaN motor commands", self.process.tail())
        if msg.mode & M.MAV_MODE_FLAG_SAFETY_ARMED:
            self._controls = (_unit(c0), _unit(c1), _unit(c2), _unit(c3))
        else:
            self._controls = (0.0, 0.0, 0.0, 0.0)
        if not self.actuator_msgs:
            self.first_answer = (time.monotonic(), self.steps)
        self.actuator_msgs += 1

    def lockstep_rate(self) -> tuple[float, float] | None:
        """(wall seconds, simulated seconds) since PX4 first answered: the lock step's own pace,
        without the process start before it; None before that."""
        if self.first_answer is None:
            return None
        wall0, steps0 = self.first_answer
        return time.monotonic() - wall0, (self.steps - steps0) / SENSOR_HZ

    def _sensors(self, s: VehicleState, t_s: float) -> bytes:
        mav = self._mav
        rng = self.rng
        usec = round(t_s * 1e6)
        k = self.steps % _NOISE_BLOCK
        if k == 0 or len(self._noise) != _NOISE_BLOCK:
            self._noise = rng.normal(0.0, 1.0, (_NOISE_BLOCK, 12))
        n = self._noise[k].tolist()
        ax, ay, az = self.vehicle.physics.specific_force_frd()
        p, q, r = s.rates_frd_rad_s
        if max(abs(ax), abs(ay), abs(az)) > ACCEL_RANGE or max(abs(p), abs(q), abs(r)) > GYRO_RANGE:
            # an IMU saturates at its range (a crash's spike would not fit the frame's fields otherwise)
            ax, ay, az = (max(-ACCEL_RANGE, min(ACCEL_RANGE, v)) for v in (ax, ay, az))
            p, q, r = (max(-GYRO_RANGE, min(GYRO_RANGE, v)) for v in (p, q, r))
        ba, bg = self._accel_bias, self._gyro_bias
        fields = 0b111111  # accel, gyro
        step = self.steps
        mx = my = mz = 0.0
        abs_p = alt = temp = 0.0
        if step % TRUTH_EVERY == 0:
            mx, my, mz = ned_to_body(s.quat, mag_field_ned())
            mx, my, mz = mx + MAG_NOISE * n[6], my + MAG_NOISE * n[7], mz + MAG_NOISE * n[8]
            alt = self.origin.alt_m - s.pos_ned_m[2] + BARO_NOISE_M * n[9]
            abs_p = Isa.pressure_hpa(alt)
            temp = Isa.temperature_c(alt) + 0.01 * n[10]
            fields |= 0b111 << 6 | 0b1101 << 9  # mag; abs pressure, pressure altitude, temperature
        out = [
            self._wire.hil_sensor(
                usec, ax + ba[0] + ACCEL_NOISE * n[0], ay + ba[1] + ACCEL_NOISE * n[1],
                az + ba[2] + ACCEL_NOISE * n[2], p + bg[0] + GYRO_NOISE * n[3], q + bg[1] + GYRO_NOISE * n[4],
                r + bg[2] + GYRO_NOISE * n[5], mx, my, mz, abs_p, 0.0, alt, temp, fields, 0,
            )
        ]  # fmt: skip
        vn, ve, vd = s.vel_ned_m_s
        if step % GPS_EVERY == 0:
            g = rng.normal(0.0, 1.0, 6)
            fn, fe = self.gps_offset_ne_m
            glat, glon, galt = self.origin.to_geodetic(
                s.pos_ned_m[0] + fn + GPS_NOISE_M * g[0], s.pos_ned_m[1] + fe + GPS_NOISE_M * g[1],
                s.pos_ned_m[2] + 2 * GPS_NOISE_M * g[2],
            )  # fmt: skip
            gvn, gve, gvd = vn + GPS_VEL_NOISE * g[3], ve + GPS_VEL_NOISE * g[4], vd + GPS_VEL_NOISE * g[5]
            cog = math.degrees(math.atan2(gve, gvn)) % 360.0
            out.append(
                mav.hil_gps_encode(
                    usec, 3, round(glat * 1e7), round(glon * 1e7), round(galt * 1000), 60, 90,
                    min(65534, round(math.hypot(gvn, gve) * 100)), _i16(gvn * 100), _i16(gve * 100),
                    _i16(gvd * 100), round(cog * 100), 16,
                ).pack(mav)
            )  # fmt: skip
        if step % TRUTH_EVERY == 1:  # ground truth at 50 Hz: the geodetic conversion only then
            lat, lon, alt_true = self.origin.to_geodetic(*s.pos_ned_m)
            ax_n = rotate_body_to_ned(s.quat, (ax, ay, az))
            out.append(
                mav.hil_state_quaternion_encode(
                    usec, list(s.quat), p, q, r, round(lat * 1e7), round(lon * 1e7), round(alt_true * 1000),
                    _i16(vn * 100), _i16(ve * 100), _i16(vd * 100), 0, 0,
                    _i16(ax_n[0] / 9.80665 * 1000), _i16(ax_n[1] / 9.80665 * 1000),
                    _i16(ax_n[2] / 9.80665 * 1000),
                ).pack(mav)
            )  # fmt: skip
            rng_m = self.vehicle.physics.terrain.rangefinder_m(s.pos_ned_m, s.quat, RANGEFINDER_MAX_CM / 100)
            out.append(
                mav.distance_sensor_encode(
                    usec // 1000, RANGEFINDER_MIN_CM, RANGEFINDER_MAX_CM,
                    max(RANGEFINDER_MIN_CM, min(RANGEFINDER_MAX_CM, round(rng_m * 100))),
                    M.MAV_DISTANCE_SENSOR_LASER, 0, M.MAV_SENSOR_ROTATION_PITCH_270, 0,
                ).pack(mav)
            )  # fmt: skip
        return b"".join(out)
