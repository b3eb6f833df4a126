"""Real ArduCopter firmware (SITL) as simbridge's autopilot, with simbridge as its physics.

ArduPilot's software-in-the-loop build (``arducopter``) started with ``--model JSON:127.0.0.1`` takes its
physics from outside: at every step it sends its servo outputs as one binary UDP datagram to port
``9002 + 10 x instance`` and waits for the vehicle's state as one line of JSON in reply (ArduPilot's
JSON-interface.md; the binary and a copy of that page are in ``../shared/sitl/ardupilot``). This module
is that outside simulator:

- :func:`find_arducopter` finds the binary: ``--sitl PATH``, else ``$LANDFALL_ARDUCOPTER``, else
  ``../shared/sitl/ardupilot/arducopter`` beside the repository.
- :class:`SitlProcess` runs it as a child in its own temporary directory (parameters, EEPROM), with its
  own instance number (so several run at once), MAVLink on ``udpclient`` serial ports only (nothing
  listening beyond what SITL always opens), and ends it with SIGINT then SIGKILL (SITL ignores SIGTERM
  while it waits for physics). Its last output lines go into every error.
- :class:`LockStep` answers the servo frames in a thread of its own: quad-X servos 1-4 are JSBSim's F450
  engines 0-3 (front right, back left, front left, back right: the same order and spin directions), PWM
  1000..2000 us is ESC 0..1; one JSBSim step of ``1 / frame_rate`` per new frame; the reply carries time,
  gyro and specific force in body axes, NED position and velocity from home, the attitude quaternion and
  the downward rangefinder. A frame sent again (SITL re-sends after about a second without a reply) is
  answered again without stepping. Ground contact stays the world's: JSBSim's gear on the world's height.

Wire format facts (checked against this build): the servo datagram is ``<HHI16H`` (magic 18458,
frame rate, frame count, 16 PWM values); SITL parses the last complete ``\\n``-framed line of a reply and
fails on spaces inside vectors, so replies are compact JSON; its clock advances by exactly the change in
``timestamp`` between replies.
"""

from __future__ import annotations

import collections
import contextlib
import ctypes
import logging
import math
import os
import shutil
import signal
import socket
import struct
import subprocess
import tempfile
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from simbridge.autopilot.flavours import ArduPilotFlavour
from simbridge.geo import Quat, Vec3
from simbridge.physics import VehicleState
from simbridge.telemetry import RANGEFINDER_MAX_CM, RANGEFINDER_MIN_CM
from simbridge.vehicle import Vehicle

__all__ = [
    "ENV_BINARY",
    "LockStep",
    "ServoFrame",
    "SitlDied",
    "SitlError",
    "SitlNotAnswering",
    "SitlNotFound",
    "SitlProcess",
    "SitlProtocolError",
    "decode_servo",
    "encode_state",
    "esc_from_pwm",
    "find_arducopter",
]

ENV_BINARY = "LANDFALL_ARDUCOPTER"
SHARED_BINARY = Path(__file__).resolve().parent.parent.parent / "shared" / "sitl" / "ardupilot" / "arducopter"
SERVO_MAGIC = 18458  # 16 channels (29569 would be 32: SERVO_32_ENABLE, not used)
_SERVO = struct.Struct("<HHI16H")
JSON_BASE_PORT = 9002
PORT_STRIDE = 10  # every SITL port moves by 10 per instance
MAX_INSTANCES = 32
PWM_MIN_US, PWM_MAX_US = 1000.0, 2000.0
MOTORS = 4
RATE_HZ = 600  # SIM_RATE_HZ: physics frames per simulated second (>= 1.8 x the 300 Hz loop)
RANGE_EVERY = 12  # frames between two rangefinder casts (50 Hz at 600 Hz)
RANGE_MAX_M = RANGEFINDER_MAX_CM / 100  # the emulation's rangefinder: the same F450's sensor
FIRST_FRAME_S = 20.0  # wall seconds SITL may take to send its first servo frame
STALL_S = 10.0  # wall seconds without a frame after the first: SITL is not answering
_TAIL_LINES = 60

# Parameters on top of ArduPilot's copter.parm + airsim-quadX.parm (its own set for an external quad X).
PARAMS: dict[str, float] = {
    "SIM_RATE_HZ": RATE_HZ,
    "LOG_BACKEND_TYPE": 0,  # no dataflash logs (65535-bit logging writes ~1 MB/s of simulated flight)
    "TERRAIN_ENABLE": 0,  # no terrain database requests over MAVLink
    # the F450's rotors: thrust ~ ESC^2 over ESC 0.15..0.95 (MOT_SPIN_MIN..MAX) fits expo 0.65;
    # hovering takes about 0.19 of full thrust (hover learning refines it in flight)
    "MOT_THST_EXPO": 0.65,
    "MOT_THST_HOVER": 0.2,
    "RNGFND1_TYPE": 100,  # SITL's rangefinder, fed by the reply's rng_1
    "RNGFND1_MIN": RANGEFINDER_MIN_CM / 100,
    "RNGFND1_MAX": RANGE_MAX_M,
    "RNGFND1_ORIENT": 25,  # pointing down
    # precision landing on the companion's LANDING_TARGET (docs/companion.md, "Precision landing")
    "PLND_ENABLED": 1,
    "PLND_TYPE": 1,
}
# The flight envelope the emulated ArduPilot flies (and companion-bench's kinematic bound assumes) in
# place of airsim-quadX.parm's (20 m/s across, 3 m/s down, 4 m/s2): the same F450 whoever flies it.
_ENVELOPE = ("WPNAV_SPEED", "WPNAV_SPEED_UP", "WPNAV_SPEED_DN", "WPNAV_ACCEL", "ANGLE_MAX")
PARAMS.update({p.name: p.default for p in ArduPilotFlavour.params if p.name in _ENVELOPE})


class SitlError(RuntimeError):
    """ArduCopter SITL cannot be run or stopped answering; ``tail`` holds its last output lines."""

    def __init__(self, message: str, tail: str = "") -> None:
        super().__init__(message + (f"\n--- last SITL output ---\n{tail}" if tail else ""))
        self.tail = tail


class SitlNotFound(SitlError):
    """No usable ``arducopter`` binary."""


class SitlDied(SitlError):
    """The SITL process exited."""


class SitlNotAnswering(SitlError):
    """SITL sent no servo frame for too long (a wrong binary, a blocked port, a hung process)."""


class SitlProtocolError(SitlError):
    """A datagram that is not a servo frame, or a frame count that went backwards (SITL restarted)."""


def find_binary(
    explicit: str | os.PathLike[str] | None, flag: str, env: str, shared: Path, what: str, how: str
) -> Path:
    """A firmware binary: ``explicit`` (given as ``flag``), else ``$env``, else ``shared`` (the rig
    beside the repository).

    Raises:
        SitlNotFound: saying where it looked and ``how`` to get one.
    """
    for source, value in ((flag, explicit), (env, os.environ.get(env))):
        if value:
            path = Path(value).expanduser()
            if not path.is_file():
                raise SitlNotFound(f"{source}: {path} is not a file; {how}")
            if not os.access(path, os.X_OK):
                raise SitlNotFound(f"{source}: {path} is not executable")
            return path
    if shared.is_file() and os.access(shared, os.X_OK):
        return shared
    raise SitlNotFound(f"no {what} binary found: {how}")


def find_arducopter(explicit: str | os.PathLike[str] | None = None) -> Path:
    """The ArduCopter SITL binary: ``explicit``, else ``$LANDFALL_ARDUCOPTER``, else the shared rig.

    Raises:
        SitlNotFound: saying where it looked and how to get one.
    """
    how = (
        f"pass --sitl PATH, set {ENV_BINARY}, or put ArduPilot's SITL build at {SHARED_BINARY} "
        "(how to build it: that folder's README.md)"
    )
    return find_binary(explicit, "--sitl", ENV_BINARY, SHARED_BINARY, "ArduCopter SITL", how)


# ---------------------------------------------------------------------------------------------- wire format
@dataclass(frozen=True, slots=True)
class ServoFrame:
    frame_rate_hz: int
    frame_count: int
    pwm_us: tuple[int, ...]  # 16 channels


def decode_servo(data: bytes) -> ServoFrame:
    """One servo datagram; raises SitlProtocolError for anything else."""
    if len(data) != _SERVO.size:
        raise SitlProtocolError(f"servo frame of {len(data)} bytes, expected {_SERVO.size}")
    magic, rate, count, *pwm = _SERVO.unpack(data)
    if magic != SERVO_MAGIC:
        raise SitlProtocolError(f"servo frame magic {magic}, expected {SERVO_MAGIC}")
    if rate <= 0:
        raise SitlProtocolError(f"servo frame rate {rate} Hz")
    return ServoFrame(rate, count, tuple(pwm))


def esc_from_pwm(pwm_us: Sequence[int]) -> tuple[float, float, float, float]:
    """Servos 1-4 (ArduPilot quad X) as ESC commands 0..1 for JSBSim's F450 engines 0-3 (same order)."""
    span = PWM_MAX_US - PWM_MIN_US
    a, b, c, d = (min(1.0, max(0.0, (p - PWM_MIN_US) / span)) for p in pwm_us[:MOTORS])
    return (a, b, c, d)


_REPLY = (
    '\n{"timestamp":%.6f,"imu":{"gyro":[%.6f,%.6f,%.6f],"accel_body":[%.5f,%.5f,%.5f]},'
    '"position":[%.4f,%.4f,%.4f],"velocity":[%.4f,%.4f,%.4f],"quaternion":[%.7f,%.7f,%.7f,%.7f],'
    '"rng_1":%.3f}\n'
)


def encode_state(
    t_s: float,
    gyro_frd: Vec3,
    accel_frd: Vec3,
    pos_ned_m: Vec3,
    vel_ned_m_s: Vec3,
    quat: Quat,
    range_m: float,
) -> bytes:
    """The reply SITL parses: compact JSON between newlines (a %-template: json.dumps per frame at
    600 Hz is a sizeable share of the lock step's budget)."""
    return (_REPLY % (t_s, *gyro_frd, *accel_frd, *pos_ned_m, *vel_ned_m_s, *quat, range_m)).encode()


# ---------------------------------------------------------------------------------------------- the process
def _die_with_parent() -> None:  # pragma: no cover - runs in the child between fork and exec
    """Linux: SIGKILL the child when simbridge dies, even by SIGKILL (prctl PR_SET_PDEATHSIG)."""
    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL)


def claim_instance(host: str = "127.0.0.1") -> tuple[int, socket.socket]:
    """The first instance number whose JSON port is free, and that port bound (simbridge keeps it:
    no other simbridge can take the instance meanwhile)."""
    for n in range(MAX_INSTANCES):
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            sock.bind((host, JSON_BASE_PORT + PORT_STRIDE * n))
        except OSError:
            sock.close()
            continue
        return n, sock
    raise SitlError(
        f"no free SITL instance: UDP ports {JSON_BASE_PORT}..+{PORT_STRIDE * MAX_INSTANCES} in use"
    )


class FirmwareProcess:
    """A firmware build run as simbridge's child: its output kept (the last lines go into every error),
    killed with simbridge (PR_SET_PDEATHSIG), stopped with ``stop_signal`` then SIGKILL, its temporary
    working directory removed. Subclasses build the command in ``start()`` and call :meth:`_spawn`."""

    name = "firmware"
    stop_signal = signal.SIGINT
    stop_wait_s = 2.0

    def __init__(self, binary: Path, instance: int, logger: logging.Logger | None) -> None:
        self.binary = binary
        self.instance = instance
        self.log = logger or logging.getLogger("simbridge.sitl")
        self.workdir: Path | None = None
        self._proc: subprocess.Popen[bytes] | None = None
        self._tail: collections.deque[str] = collections.deque(maxlen=_TAIL_LINES)
        self._reader: threading.Thread | None = None

    def _spawn(self, cmd: list[str], cwd: Path, env: dict[str, str] | None = None) -> None:
        self.log.info("starting %s instance %d: %s", self.name, self.instance, " ".join(cmd))
        try:
            self._proc = subprocess.Popen(
                cmd, cwd=cwd, env=env, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                stderr=subprocess.STDOUT, start_new_session=True, preexec_fn=_die_with_parent,
            )  # fmt: skip
        except OSError as exc:
            self._cleanup()
            raise SitlNotFound(f"cannot run {self.binary}: {exc}") from exc
        self._reader = threading.Thread(target=self._read, name=f"{self.name}-output", daemon=True)
        self._reader.start()

    def _read(self) -> None:
        proc = self._proc
        assert proc is not None
        assert proc.stdout is not None
        for raw in proc.stdout:
            line = raw.decode("utf-8", "replace").rstrip()
            self._tail.append(line)
            self.log.debug("%s: %s", self.name, line)
            self._on_line(line)

    def _on_line(self, line: str) -> None:
        """Each line the firmware prints (its output thread)."""

    def tail(self) -> str:
        return "\n".join(self._tail)

    def returncode(self) -> int | None:
        return None if self._proc is None else self._proc.poll()

    @property
    def pid(self) -> int | None:
        return None if self._proc is None else self._proc.pid

    def close(self) -> None:
        """``stop_signal``, ``stop_wait_s``, then SIGKILL to its process group; the directory goes."""
        proc = self._proc
        if proc is not None and proc.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                proc.send_signal(self.stop_signal)
            try:
                proc.wait(timeout=self.stop_wait_s)
            except subprocess.TimeoutExpired:
                with contextlib.suppress(ProcessLookupError, PermissionError):
                    os.killpg(proc.pid, signal.SIGKILL)
                proc.wait(timeout=5.0)
        if self._reader is not None:
            self._reader.join(timeout=2.0)
        self._cleanup()

    def _cleanup(self) -> None:
        if self.workdir is not None:
            shutil.rmtree(self.workdir, ignore_errors=True)
            self.workdir = None

    def __enter__(self) -> FirmwareProcess:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def start(self) -> None:
        raise NotImplementedError


class SitlProcess(FirmwareProcess):
    """``arducopter --model JSON`` as a child process (module docstring). ``start()``, then ``close()``.

    Args:
        binary: the SITL executable.
        instance: ``-I``: shifts every SITL port by 10 per instance.
        home: (lat deg, lon deg, alt m AMSL, heading deg): SITL's home and the origin of the reply's
            position.
        speedup: simulated seconds per wall second SITL paces itself to.
        serial0: where SERIAL0 (the companion's MAVLink) goes, ``(host, port)``, as a UDP client.
        serial1: the same for SERIAL1 (simbridge's own link), or None.
        sysid: MAV_SYSID.
    """

    name = "ArduCopter SITL"  # SIGINT: SITL ignores SIGTERM while it waits for physics

    def __init__(
        self,
        binary: Path,
        instance: int,
        home: tuple[float, float, float, float],
        *,
        speedup: float,
        serial0: tuple[str, int],
        serial1: tuple[str, int] | None,
        sysid: int = 1,
        params: dict[str, float] | None = None,
        logger: logging.Logger | None = None,
    ) -> None:
        super().__init__(binary, instance, logger)
        self.home = home
        self.speedup = speedup
        self.serial0 = serial0
        self.serial1 = serial1
        self.sysid = sysid
        self.params = dict(PARAMS if params is None else params)

    def command(self, workdir: Path) -> list[str]:
        ap = self.binary.parent
        defaults = [p for p in (ap / "copter.parm", ap / "airsim-quadX.parm") if p.is_file()]
        lat, lon, alt, hdg = self.home
        cmd = [
            str(self.binary), "--model", "JSON:127.0.0.1", "--speedup", f"{self.speedup:g}",
            "-I", str(self.instance), "--sysid", str(self.sysid),
            "--defaults", ",".join(str(p) for p in [*defaults, workdir / "landfall-sitl.parm"]),
            "--home", f"{lat:.8f},{lon:.8f},{alt:.3f},{hdg:.1f}",
            "--serial0", "udpclient:{}:{}".format(*self.serial0),
            "--serial1", "udpclient:{}:{}".format(*self.serial1) if self.serial1 else "none",
            "--serial2", "none",
        ]  # fmt: skip
        return cmd

    def start(self) -> None:
        self.workdir = Path(tempfile.mkdtemp(prefix=f"landfall-sitl-{self.instance}-"))
        lines = [f"{k} {v:g}" for k, v in self.params.items()]
        (self.workdir / "landfall-sitl.parm").write_text("\n".join(lines) + "\n")
        self._spawn(self.command(self.workdir), self.workdir)


# ---------------------------------------------------------------------------------------------- lock step
StateHook = Callable[[VehicleState], None]


class LockStepThread:
    """Serves the firmware's physics exchange from a thread of its own: ``start()``, ``stop()``; ``done``
    is set when it ends, stopped or failed, and ``error`` then says why. Subclasses give ``_serve``."""

    thread_name = "lockstep"

    def __init__(self, vehicle: Vehicle, process: FirmwareProcess) -> None:
        self.vehicle = vehicle
        self.process = process
        self.error: SitlError | None = None
        self.done = threading.Event()
        # held by whoever must see the world stand still (a sensor frame being rendered): the lock
        # step takes it for every physics step, so simulated time does not pass meanwhile
        self.gate = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._t0_s = vehicle.state.t_s

    def start(self) -> None:
        self._thread = threading.Thread(target=self._run, name=self.thread_name, daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)

    def sim_time_s(self) -> float:
        """Simulated seconds since the lock step began (the firmware's clock, up to a constant)."""
        return self.vehicle.state.t_s - self._t0_s

    def _run(self) -> None:
        try:
            self._serve()
        except SitlError as exc:
            self.error = exc
        except Exception as exc:  # a bug here must still end the run with a clear error
            self.error = SitlError(f"{self.process.name} lock step failed: {exc!r}", self.process.tail())
        finally:
            self.done.set()

    def _serve(self) -> None:
        raise NotImplementedError


class LockStep(LockStepThread):
    """Answers SITL's servo frames from a thread of its own (module docstring).

    Args:
        sock: the bound JSON port (:func:`claim_instance`).
        vehicle: the airframe; stepped with :meth:`Vehicle.step_esc`.
        home_ned_m: the world point SITL's home is; reply positions are relative to it.
        process: the SITL child, watched for exits.
        on_state: called in the lock-step thread after every physics step (keep it cheap).
    """

    thread_name = "sitl-lockstep"

    def __init__(
        self,
        sock: socket.socket,
        vehicle: Vehicle,
        home_ned_m: Vec3,
        process: SitlProcess,
        on_state: StateHook | None = None,
    ) -> None:
        super().__init__(vehicle, process)
        self.sock = sock
        self.home_ned_m = home_ned_m
        self.on_state = on_state
        self.frames = 0
        self.resent = 0
        self.skipped = 0
        self.first_frame_wall_s: float | None = None
        self._range_m = RANGE_MAX_M

    def _serve(self) -> None:
        sock = self.sock
        sock.settimeout(0.25)
        vehicle = self.vehicle
        physics = vehicle.physics
        last_count = -1
        last_reply = b""
        last_frame_wall = time.monotonic()
        started = last_frame_wall
        while not self._stop.is_set():
            try:
                data, addr = sock.recvfrom(256)
            except TimeoutError:
                rc = self.process.returncode()
                if rc is not None:
                    raise SitlDied(f"ArduCopter SITL exited with status {rc}", self.process.tail()) from None
                idle = time.monotonic() - last_frame_wall
                if self.first_frame_wall_s is None and idle > FIRST_FRAME_S:
                    raise SitlNotAnswering(
                        f"no servo frame from SITL within {FIRST_FRAME_S:.0f} s of its start",
                        self.process.tail(),
                    ) from None
                if self.first_frame_wall_s is not None and idle > STALL_S:
                    raise SitlNotAnswering(
                        f"SITL sent no servo frame for {idle:.0f} s", self.process.tail()
                    ) from None
                continue
            frame = decode_servo(data)
            now = time.monotonic()
            last_frame_wall = now
            if self.first_frame_wall_s is None:
                self.first_frame_wall_s = now - started
            if frame.frame_count == last_count:
                self.resent += 1  # counted before the reply goes: whoever reads it after the reply sees it
                sock.sendto(last_reply, addr)  # our reply was lost or late: answer again, no step
                continue
            if frame.frame_count < last_count:
                raise SitlProtocolError(
                    f"frame count went back from {last_count} to {frame.frame_count}: SITL restarted",
                    self.process.tail(),
                )
            if last_count >= 0 and frame.frame_count > last_count + 1:
                self.skipped += frame.frame_count - last_count - 1
            last_count = frame.frame_count
            dt = 1.0 / frame.frame_rate_hz
            if abs(dt - physics.dt_s) > 1e-12:
                physics.set_dt(dt)
            with self.gate:
                s = vehicle.step_esc(esc_from_pwm(frame.pwm_us))
            self.frames += 1
            if self.frames % RANGE_EVERY == 1:
                self._range_m = physics.terrain.rangefinder_m(s.pos_ned_m, s.quat, RANGE_MAX_M)
            hn, he, hd = self.home_ned_m
            n, e, d = s.pos_ned_m
            last_reply = encode_state(
                s.t_s - self._t0_s, s.rates_frd_rad_s, physics.specific_force_frd(), (n - hn, e - he, d - hd),
                s.vel_ned_m_s, s.quat, self._range_m,
            )  # fmt: skip
            sock.sendto(last_reply, addr)
            if self.on_state is not None:
                self.on_state(s)


def heading_deg(yaw_rad: float) -> float:
    return math.degrees(yaw_rad) % 360.0
