"""simbridge as ArduCopter SITL's physics: the wire format, the lock step against a stand-in
SITL on a real UDP socket, and real ArduCopter firmware flying simbridge's JSBSim F450.

The tests marked ``sitl`` need ArduPilot's SITL build (``../shared/sitl/ardupilot/arducopter`` beside the
repository, or ``$LANDFALL_ARDUCOPTER``); they skip elsewhere, saying how to get it, and fail in CI
(``LANDFALL_REQUIRE_SITL=1``) rather than skip.
"""

from __future__ import annotations

import json
import math
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from simbridge.geo import GeoOrigin
from simbridge.physics import GEAR_HEIGHT_M
from simbridge.sim import SimConfig
from simbridge.sitl import (
    ENV_BINARY,
    SERVO_MAGIC,
    LockStep,
    SitlDied,
    SitlNotFound,
    SitlProtocolError,
    decode_servo,
    encode_state,
    esc_from_pwm,
    find_arducopter,
)
from simbridge.terrain import FlatTerrain
from simbridge.vehicle import Vehicle
from tests.conftest import Rig, SimProcess
from tests.mavclient import MavClient

_SERVO = "<HHI16H"


def servo_bytes(count: int, pwm: tuple[int, ...] = (1000,) * 16, rate: int = 600) -> bytes:
    import struct

    return struct.pack(_SERVO, SERVO_MAGIC, rate, count, *pwm)


# ---------------------------------------------------------------------------------------------- wire format
def test_servo_frames_decode_and_anything_else_is_refused() -> None:
    f = decode_servo(servo_bytes(7, (1100, 1200, 1300, 1400, *([1000] * 12))))
    assert (f.frame_rate_hz, f.frame_count, f.pwm_us[:4]) == (600, 7, (1100, 1200, 1300, 1400))
    with pytest.raises(SitlProtocolError, match="bytes"):
        decode_servo(servo_bytes(1)[:-2])
    with pytest.raises(SitlProtocolError, match="magic"):
        decode_servo(b"\x00\x00" + servo_bytes(1)[2:])


def test_pwm_maps_to_the_f450_engines_in_order_and_clips() -> None:
    # ArduPilot quad X servos 1-4: front right, back left, front left, back right = JSBSim engines 0-3
    assert esc_from_pwm((1000, 1500, 2000, 1250, 1900)) == (0.0, 0.5, 1.0, 0.25)
    assert esc_from_pwm((900, 2100, 1000, 1000)) == (0.0, 1.0, 0.0, 0.0)


def test_the_reply_is_compact_newline_framed_json_sitl_parses() -> None:
    raw = encode_state(
        12.5,
        (0.1, -0.2, 0.3),
        (0.0, 0.0, -9.81),
        (1.0, 2.0, -3.0),
        (0.5, 0.0, -0.1),
        (1.0, 0.0, 0.0, 0.0),
        3.25,
    )
    text = raw.decode()
    assert text.startswith("\n")
    assert text.endswith("\n")
    assert " " not in text  # SITL fails on spaces inside vectors
    body = json.loads(text.strip())
    assert body["timestamp"] == 12.5
    assert body["imu"] == {"gyro": [0.1, -0.2, 0.3], "accel_body": [0.0, 0.0, -9.81]}
    assert body["position"] == [1.0, 2.0, -3.0]
    assert body["velocity"] == [0.5, 0.0, -0.1]
    assert body["quaternion"] == [1.0, 0.0, 0.0, 0.0]
    assert body["rng_1"] == 3.25


def test_the_accelerometer_reads_specific_force() -> None:
    """At rest on the gear an accelerometer reads -g on body z; in free fall it reads nothing."""
    v = Vehicle(GeoOrigin(), FlatTerrain())
    v.physics.set_dt(1 / 600)
    for _ in range(600):
        v.step_esc((0.0, 0.0, 0.0, 0.0))
    fx, fy, fz = v.physics.specific_force_frd()
    assert abs(fx) < 0.2
    assert abs(fy) < 0.2
    assert fz == pytest.approx(-9.81, abs=0.05)
    v.reset((0.0, 0.0, -50.0), 0.0)
    v.step_esc((0.0, 0.0, 0.0, 0.0))
    assert math.hypot(*v.physics.specific_force_frd()) < 0.2
    for _ in range(300):  # full throttle: climbing, reads more than g
        v.step_esc((0.6, 0.6, 0.6, 0.6))
    assert v.physics.specific_force_frd()[2] < -11.0
    assert v.state.vel_ned_m_s[2] < -0.5


def test_finding_the_binary_says_where_and_how(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    with pytest.raises(SitlNotFound, match=r"nope.*README"):
        find_arducopter(tmp_path / "nope")
    plain = tmp_path / "arducopter"
    plain.write_text("")
    plain.chmod(0o644)
    with pytest.raises(SitlNotFound, match="not executable"):
        find_arducopter(plain)
    plain.chmod(0o755)
    monkeypatch.setenv(ENV_BINARY, str(plain))
    assert find_arducopter() == plain
    monkeypatch.setenv(ENV_BINARY, str(tmp_path / "gone"))
    with pytest.raises(SitlNotFound, match=ENV_BINARY):
        find_arducopter()


def test_config_refuses_what_real_firmware_cannot_do_here() -> None:
    with pytest.raises(ValueError, match="signing"):
        SimConfig(autopilot="ardupilot-sitl", signing_key=bytes(32))
    with pytest.raises(ValueError, match="cannot listen"):
        SimConfig(autopilot="ardupilot-sitl", mavlink="udpin:0.0.0.0:14550")
    with pytest.raises(ValueError, match="--autopilot"):
        SimConfig(autopilot="betaflight")


# ---------------------------------------------------------------------------------------------- lock step
class _FakeProcess:
    """The SITL child as the lock step sees it (exit status, output)."""

    def __init__(self) -> None:
        self.rc: int | None = None

    def returncode(self) -> int | None:
        return self.rc

    def tail(self) -> str:
        return "stand-in SITL output"


@pytest.fixture
def lockstep() -> Iterator[tuple[LockStep, socket.socket, _FakeProcess]]:
    server = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    server.bind(("127.0.0.1", 0))
    v = Vehicle(GeoOrigin(), FlatTerrain())
    proc = _FakeProcess()
    lock = LockStep(server, v, (0.0, 0.0, -GEAR_HEIGHT_M), proc)  # type: ignore[arg-type]
    sitl = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sitl.settimeout(5.0)
    sitl.connect(server.getsockname())
    lock.start()
    yield lock, sitl, proc
    lock.stop()
    sitl.close()
    server.close()


def _exchange(sitl: socket.socket, count: int, pwm: tuple[int, ...] = (1000,) * 16) -> dict[str, object]:
    sitl.send(servo_bytes(count, pwm))
    return dict(json.loads(sitl.recv(4096).decode().strip()))


def test_lock_step_steps_once_per_new_frame_and_answers_a_repeat_without_stepping(
    lockstep: tuple[LockStep, socket.socket, _FakeProcess],
) -> None:
    lock, sitl, _ = lockstep
    replies = [_exchange(sitl, k) for k in range(1, 601)]
    assert lock.frames == 600
    assert replies[-1]["timestamp"] == pytest.approx(1.0, abs=1e-6)  # 600 frames at 600 Hz
    again = _exchange(sitl, 600)
    assert again == replies[-1]
    assert lock.frames == 600
    assert lock.resent == 1
    position = replies[-1]["position"]
    assert isinstance(position, list)
    assert abs(position[2]) < 0.01
    accel = replies[-1]["imu"]
    assert isinstance(accel, dict)
    assert accel["accel_body"][2] == pytest.approx(-9.81, abs=0.05)
    lifted = [_exchange(sitl, k, (1700,) * 4 + (1000,) * 12) for k in range(601, 1201)]
    pos = lifted[-1]["position"]
    assert isinstance(pos, list)
    assert pos[2] < -0.5


def test_a_frame_count_going_back_is_a_restart_error(
    lockstep: tuple[LockStep, socket.socket, _FakeProcess],
) -> None:
    lock, sitl, _ = lockstep
    _exchange(sitl, 10)
    sitl.send(servo_bytes(3))
    assert lock.done.wait(5.0)
    assert isinstance(lock.error, SitlProtocolError)
    assert "restarted" in str(lock.error)
    assert "stand-in SITL output" in str(lock.error)


def test_a_garbled_datagram_ends_the_lock_step_with_a_clear_error(
    lockstep: tuple[LockStep, socket.socket, _FakeProcess],
) -> None:
    lock, sitl, _ = lockstep
    sitl.send(b"hello")
    assert lock.done.wait(5.0)
    assert isinstance(lock.error, SitlProtocolError)
    assert "5 bytes" in str(lock.error)


def test_a_sitl_that_exits_is_reported(lockstep: tuple[LockStep, socket.socket, _FakeProcess]) -> None:
    lock, sitl, proc = lockstep
    _exchange(sitl, 1)
    proc.rc = -11
    assert lock.done.wait(5.0)
    assert isinstance(lock.error, SitlDied)
    assert "status -11" in str(lock.error)


def test_simbridge_exits_with_sitl_output_when_the_firmware_dies(tmp_path: Path) -> None:
    fake = tmp_path / "arducopter"
    fake.write_text("#!/bin/sh\necho 'bad things happened here'\nexit 3\n")
    fake.chmod(0o755)
    out = subprocess.run(
        [sys.executable, "-m", "simbridge", "--autopilot", "ardupilot-sitl", "--sitl", str(fake),
         "--mavlink", "udpout:127.0.0.1:9", "--scenario", "flat"],
        capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert out.returncode == 2, out.stderr[-2000:]
    assert "exited with status 3" in out.stderr
    assert "bad things happened here" in out.stderr


def test_simbridge_names_a_missing_binary(tmp_path: Path) -> None:
    out = subprocess.run(
        [sys.executable, "-m", "simbridge", "--autopilot", "ardupilot-sitl", "--sitl", str(tmp_path / "none"),
         "--mavlink", "udpout:127.0.0.1:9"],
        capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert out.returncode == 2
    assert "none is not a file" in out.stderr
    assert "README" in out.stderr


# ---------------------------------------------------------------------------------------------- real firmware
def _wait_event(sim: SimProcess, name: str, timeout_s: float) -> dict[str, object]:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        found = sim.events(name)
        if found:
            return found[0]
        assert sim.proc.poll() is None, f"simbridge exited: {sim.stderr_path.read_text()[-3000:]}"
        time.sleep(0.2)
    raise AssertionError(f"no {name!r} event in {timeout_s} s: {sim.stderr_path.read_text()[-3000:]}")


def _alarm_when_ready(rig: Rig, autopilot: str) -> Rig:
    """Once real firmware holds at the launch pose (simbridge's ``ready``, naming ``autopilot``) and the
    companion's sensor stream is up, a high GPS-spoofing alarm, accepted."""
    ready = _wait_event(rig.sim, "ready", 240)
    assert ready["autopilot"] == autopilot
    rig.wait_log("sensor stream connected", timeout_s=60)
    out = rig.alarm_accepted("--reason", "GPS spoofing detected", "--criticality", "high")
    assert out.returncode == 0, out.stdout + out.stderr
    return rig


def _sitl_children(pid: int) -> list[int]:
    out = subprocess.run(["ps", "-eo", "pid,ppid,comm"], capture_output=True, text=True).stdout
    return [int(line.split()[0]) for line in out.splitlines()[1:] if line.split()[2:3] == ["arducopter"]
            and int(line.split()[1]) == pid]  # fmt: skip


@pytest.mark.slow
@pytest.mark.sitl
def test_real_arducopter_takes_off_holds_and_lands_on_the_world(
    arducopter: Path, start_sim: Callable[..., SimProcess]
) -> None:
    """``--start air``: the real firmware initialises on the ground, arms, climbs to the launch pose
    (``ready``); then a ground station on the companion's port switches it to LAND: it lands on the
    world's ground, the touchdown is graded, the firmware disarms; SIGTERM ends SITL too."""
    sim = start_sim("--autopilot", "ardupilot-sitl", "--sitl", str(arducopter), "--scenario", "flat",
                    "--start", "air", "--speed", "20")  # fmt: skip
    client = MavClient(sim.port)
    try:
        hb = client.wait_heartbeat(60, ask=False)  # a LAND command needs no telemetry streams
        assert hb.autopilot == 3  # ArduPilotMega: the real firmware speaks on the companion's port
        ready = _wait_event(sim, "ready", 240)
        pos = ready["pos_ned_m"]
        assert isinstance(pos, list)
        assert math.hypot(pos[0], pos[1]) < 0.5
        start = sim.events("start")[0]
        assert isinstance(start["home_ned_m"], list)
        children = _sitl_children(sim.proc.pid)
        assert len(children) == 1
        client.drop_backlog()  # telemetry left unread while it climbed: the answer must not queue behind it
        assert client.set_mode_ap("LAND") == 0
        touchdown = _wait_event(sim, "touchdown", 120)
        assert touchdown["safe"] is True
        assert touchdown["surface"]
        _wait_event(sim, "disarmed", 60)
        modes = [e["mode"] for e in sim.events("mode")]
        assert modes[-1] == "LAND"
        assert "GUIDED" in modes
    finally:
        client.close()
    sim.proc.send_signal(signal.SIGTERM)
    assert sim.proc.wait(timeout=30) == 0
    stop = sim.events("stop")[0]
    assert stop["error"] is None
    assert isinstance(stop["frames"], int)
    assert stop["frames"] > 10_000
    deadline = time.monotonic() + 10
    while any(os.path.exists(f"/proc/{c}") for c in children) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert not [c for c in children if os.path.exists(f"/proc/{c}")], "SITL outlived simbridge"


@pytest.mark.slow
@pytest.mark.sitl
def test_a_five_second_link_loss_on_real_arducopter_holds_then_lands_on_the_same_roof(
    arducopter: Path, start_rig: Callable[..., Rig]
) -> None:
    """The product unchanged on real firmware, and a link loss in the middle of it (one flight for both:
    the suite flies each behaviour once). The companion asks ArduCopter for its telemetry, places every
    frame with the autopilot's estimate in the autopilot's own frame (EKF origin at the launch point,
    not the scenario's origin), flies GUIDED targets and descends. The MAVLink link between real
    ArduCopter and the companion goes dead for 5 s during the first descent step: the firmware's
    GUIDED holds the last target (no failsafe of its own: the companion is no ground station); the
    companion notices the silence, keeps its target, and once the link is back confirms the same site
    again and lands on it through LAND; the firmware disarms; the world grades the touchdown."""
    from tests.test_companion_e2e import _clean_relay, _land_through_a_link_blackout, _via

    relays: list[Any] = []

    def alarmed() -> Rig:
        rig = start_rig(
            ["--autopilot", "ardupilot-sitl", "--sitl", str(arducopter), "--scenario", "scenario2",
             "--launch", "12,8", "--speed", "8"],
            mavlink_via=_via(relays, _clean_relay),
        )  # fmt: skip
        _alarm_when_ready(rig, "ardupilot-sitl")
        home = rig.sim.events("start")[0]["home_ned_m"]
        assert isinstance(home, list)
        assert math.hypot(home[0], home[1]) > 5  # the EKF origin is the launch point, not the scenario's
        return rig

    # "descending 62 m, site clear: ...": the first step
    rig, _td, _log = _land_through_a_link_blackout(
        relays, alarmed, first_step="descending ", step_timeout_s=300, touchdown_timeout_s=400
    )
    _wait_event(rig.sim, "disarmed", 60)
    modes = [e.get("mode") for e in rig.sim.events("mode")]
    assert "LAND" in modes, modes  # the end of the descent is the firmware's LAND
    assert not {"RTL", "SMART_RTL", "BRAKE"} & set(modes), modes  # no failsafe of the firmware's own
