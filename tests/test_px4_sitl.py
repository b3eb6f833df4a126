"""simbridge as real PX4's simulator: the HIL lock step, and real PX4 v1.15 firmware flying
simbridge's JSBSim F450 with the companion unchanged.

The tests marked ``sitl`` need PX4's SITL build (``../shared/sitl/px4/bin/px4`` beside the repository, its
ROMFS in the ``etc/`` beside ``bin/``, or ``$LANDFALL_PX4``); they skip elsewhere, saying how to get it,
and fail in CI (``LANDFALL_REQUIRE_SITL=1``) rather than skip.
"""

from __future__ import annotations

import itertools
import math
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink2

import simbridge.px4_sitl as px4_sitl
from simbridge.geo import GeoOrigin
from simbridge.physics import GEAR_HEIGHT_M
from simbridge.px4_pilot import px4_mode_name
from simbridge.px4_sitl import (
    ENV_BINARY,
    GPS_EVERY,
    SENSOR_HZ,
    TRUTH_EVERY,
    HilLockStep,
    Px4Process,
    find_px4,
)
from simbridge.sim import SimConfig
from simbridge.sitl import SitlDied, SitlNotAnswering, SitlNotFound, SitlProtocolError
from simbridge.terrain import FlatTerrain
from simbridge.vehicle import Vehicle
from tests.conftest import Rig, SimProcess
from tests.mavclient import MavClient
from tests.test_sitl import _alarm_when_ready, _wait_event

M = mavlink2


# ---------------------------------------------------------------------------------------------- set-up
def _fake_px4(root: Path, script: str = "#!/bin/sh\nexit 0\n") -> Path:
    """A px4_sitl_default layout: bin/px4 (``script``), a module link written as a file naming its
    target (as copies of the build leave them), and the ROMFS's start-up files."""
    (root / "bin").mkdir(parents=True)
    px4 = root / "bin" / "px4"
    px4.write_text(script)
    px4.chmod(0o755)
    (root / "bin" / "px4-param").write_text("px4")
    (root / "bin" / "px4-alias.sh").write_text("#!/bin/sh\n")
    posix = root / "etc" / "init.d-posix"
    posix.mkdir(parents=True)
    (posix / "rcS").write_text("#!/bin/sh\n")
    (posix / "px4-rc.params").write_text("#!/bin/sh\n")
    (posix / "px4-rc.mavlink").write_text("mavlink start -u 18570 -o 14550\n")
    return px4


def test_finding_the_binary_says_where_and_how(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    with pytest.raises(SitlNotFound, match="is not a file") as exc:
        find_px4(tmp_path / "none")
    assert "README" in str(exc.value)
    lone = tmp_path / "lone" / "px4"
    lone.parent.mkdir()
    lone.write_text("#!/bin/sh\n")
    lone.chmod(0o755)
    with pytest.raises(SitlNotFound, match="no PX4 ROMFS"):
        find_px4(lone)
    px4 = _fake_px4(tmp_path / "build")
    monkeypatch.setenv(ENV_BINARY, str(px4))
    assert find_px4() == px4


def test_config_refuses_what_real_px4_cannot_do_here() -> None:
    with pytest.raises(ValueError, match="signing"):
        SimConfig(autopilot="px4-sitl", signing_key=bytes(32))
    with pytest.raises(ValueError, match="cannot listen"):
        SimConfig(autopilot="px4-sitl", mavlink="udpin:0.0.0.0:14550")
    with pytest.raises(ValueError, match="--battery"):
        SimConfig(autopilot="px4-sitl", battery_pct=50.0)
    with pytest.raises(ValueError, match="--ekf-error"):
        SimConfig(autopilot="px4-sitl", ekf_error="nominal")
    with pytest.raises(ValueError, match="--camera-stream: with the emulated autopilots"):
        SimConfig(autopilot="px4-sitl", camera_stream=("127.0.0.1", 5600))


def test_px4_boots_with_simbridge_parameters_and_the_companion_link(tmp_path: Path) -> None:
    """The ROMFS copy: simbridge's parameters at boot, PX4's ground-station link to simbridge's
    watcher (not 14550, where a companion listens), the offboard link, PX4's own link to the companion;
    the module commands become links to px4; the shared build is not touched."""
    px4 = _fake_px4(tmp_path / "build")
    proc = Px4Process(px4, 3, companion=("127.0.0.1", 14555), pilot_port=40001)
    proc.params["MAV_SYS_ID"] = 7
    romfs = proc._romfs(tmp_path)
    params = (romfs / "init.d-posix" / "px4-rc.params").read_text()
    assert "param set MAV_SYS_ID 7" in params
    assert "param set EKF2_DECL_TYPE 0" in params
    assert "param set MPC_XY_VEL_MAX 5" in params  # the emulation's envelope
    links = (romfs / "init.d-posix" / "px4-rc.mavlink").read_text()
    assert "-o 40001" in links
    assert "-o 14550" not in links
    (api,) = [line for line in links.splitlines() if "-o $((14540+px4_instance))" in line]
    assert "-m onboard" not in api  # PX4's normal mode: MAVSDK asks for what it needs
    assert f"-u {proc.companion_local_port} -r 4000000 -f -m onboard -o 14555 -t 127.0.0.1" in links
    assert (tmp_path / "build" / "etc" / "init.d-posix" / "px4-rc.mavlink").read_text().count("\n") == 1
    binary = proc._bin(tmp_path)
    assert binary.resolve() == px4.resolve()
    assert (tmp_path / "bin" / "px4-param").resolve() == px4.resolve()


def test_px4_modes_read_as_the_emulation_names_them() -> None:
    assert px4_mode_name(4 << 16 | 3 << 24) == "AUTO.LOITER"
    assert px4_mode_name(4 << 16 | 6 << 24) == "AUTO.LAND"
    assert px4_mode_name(6 << 16) == "OFFBOARD"
    assert px4_mode_name(4 << 16 | 9 << 24) == "AUTO.PRECLAND"
    assert px4_mode_name(2 << 16) == "ALTCTL"
    assert px4_mode_name(99 << 16) == "MODE99"


def test_simbridge_exits_with_px4_output_when_the_firmware_dies(tmp_path: Path) -> None:
    px4 = _fake_px4(tmp_path / "build", "#!/bin/sh\necho 'px4 could not start here'\nexit 3\n")
    out = subprocess.run(
        [sys.executable, "-m", "simbridge", "--autopilot", "px4-sitl", "--px4", str(px4),
         "--mavlink", "udpout:127.0.0.1:9", "--scenario", "flat"],
        capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert out.returncode == 2, out.stderr[-2000:]
    assert "exited with status 3" in out.stderr
    assert "px4 could not start here" in out.stderr


# ---------------------------------------------------------------------------------------------- lock step
class _FakeProcess:
    """The PX4 child as the lock step sees it (exit status, output)."""

    name = "PX4 SITL"

    def __init__(self) -> None:
        self.rc: int | None = None

    def returncode(self) -> int | None:
        return self.rc

    def tail(self) -> str:
        return "stand-in PX4 output"


class _StandInPx4:
    """PX4's simulator_mavlink at the TCP boundary: connects, reads what simbridge sends, answers."""

    def __init__(self, port: int) -> None:
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=5.0)
        self.mav = M.MAVLink(None, srcSystem=1, srcComponent=1)
        self.mav.robust_parsing = True
        self.pending: list[Any] = []

    def until(self, kind: str) -> list[Any]:
        """Messages up to and including the next ``kind``."""
        got: list[Any] = []
        while True:
            while self.pending:
                msg = self.pending.pop(0)
                got.append(msg)
                if msg.get_type() == kind:
                    return got
            self.pending.extend(self.mav.parse_buffer(self.sock.recv(65536)) or [])

    def drain(self, quiet_s: float) -> None:
        """Read everything sent until nothing comes for ``quiet_s``."""
        self.sock.settimeout(quiet_s)
        try:
            while True:
                self.pending.extend(self.mav.parse_buffer(self.sock.recv(65536)) or [])
        except TimeoutError:
            pass
        finally:
            self.sock.settimeout(5.0)
        self.pending.clear()

    def answer(self, motors: tuple[float, ...], armed: bool = True) -> None:
        mode = M.MAV_MODE_FLAG_SAFETY_ARMED if armed else 0
        controls = [*motors, *[0.0] * (16 - len(motors))]
        self.sock.sendall(self.mav.hil_actuator_controls_encode(0, controls, mode, 0).pack(self.mav))


@pytest.fixture
def hil() -> Iterator[tuple[HilLockStep, _StandInPx4, _FakeProcess]]:
    server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    server.bind(("127.0.0.1", 0))
    server.listen(1)
    v = Vehicle(GeoOrigin(), FlatTerrain())
    v.reset((0.0, 0.0, -GEAR_HEIGHT_M), 0.0)
    proc = _FakeProcess()
    lock = HilLockStep(server, v, GeoOrigin(), proc, np.random.default_rng(0), speed=1000.0)  # type: ignore[arg-type]
    lock.start()
    px4 = _StandInPx4(server.getsockname()[1])
    yield lock, px4, proc
    lock.stop()
    px4.sock.close()
    server.close()


def test_the_lock_step_sends_each_sensor_at_its_rate_and_steps_once_per_answer(
    hil: tuple[HilLockStep, _StandInPx4, _FakeProcess],
) -> None:
    lock, px4, _ = hil
    sensors: list[Any] = []
    gps: list[Any] = []
    for _ in range(2 * GPS_EVERY):
        got = px4.until("HIL_SENSOR")
        sensors.append(got[-1])
        gps += [m for m in got if m.get_type() == "HIL_GPS"]
        px4.answer((0.0, 0.0, 0.0, 0.0))
    # before PX4's first answer sensors go out paced in wall time (answered above too); once answers
    # come, one step per answer: with none coming the lock step waits, and each answer moves it one step
    px4.drain(0.3)
    steps = lock.steps
    px4.drain(0.3)
    assert lock.steps == steps
    for _ in range(SENSOR_HZ):
        px4.answer((0.0, 0.0, 0.0, 0.0))
        px4.until("HIL_SENSOR")
    assert lock.steps == steps + SENSOR_HZ
    times = [m.time_usec for m in sensors]
    assert all(b - a == 1_000_000 // SENSOR_HZ for a, b in itertools.pairwise(times))
    at_rest = sensors[-1]
    assert at_rest.zacc == pytest.approx(-9.81, abs=0.2)  # specific force, FRD: the gear holds it up
    assert abs(at_rest.xgyro) < 0.02
    full = [m for m in sensors if m.fields_updated & (0b111 << 6)]
    assert len(full) in (2 * GPS_EVERY // TRUTH_EVERY, 2 * GPS_EVERY // TRUTH_EVERY + 1)
    mag = full[-1]
    assert mag.xmag > 0.1  # north and down: no declination, inclined 63 deg
    assert mag.zmag > 0.3
    assert mag.abs_pressure == pytest.approx(1013.25 * (1 - 2.25577e-5 * 488.15) ** 5.25588, abs=0.05)
    assert len({m.abs_pressure for m in full}) > 1  # noisy: PX4 calls a constant sensor stale
    assert len(gps) == 2
    assert gps[-1].fix_type == 3
    assert gps[-1].lat == pytest.approx(GeoOrigin().lat_deg * 1e7, abs=20)


def test_motor_commands_fly_the_f450_only_while_px4_says_armed(
    hil: tuple[HilLockStep, _StandInPx4, _FakeProcess],
) -> None:
    lock, px4, _ = hil
    for _ in range(SENSOR_HZ):
        px4.until("HIL_SENSOR")
        px4.answer((0.8, 0.8, 0.8, 0.8), armed=False)
    assert lock.vehicle.state.height_agl_m < GEAR_HEIGHT_M + 0.02
    for _ in range(SENSOR_HZ):
        px4.until("HIL_SENSOR")
        px4.answer((0.8, 0.8, 0.8, 0.8))
    px4.until("HIL_SENSOR")
    s = lock.vehicle.state
    assert s.height_agl_m > 1.0
    assert abs(s.euler_rad[0]) < 0.15  # equal thrust, open loop: near level, no spin-up
    assert abs(s.euler_rad[1]) < 0.15
    assert abs(s.rates_frd_rad_s[2]) < 0.5


def test_a_closed_connection_or_nan_motors_end_the_lock_step_with_a_clear_error(
    hil: tuple[HilLockStep, _StandInPx4, _FakeProcess],
) -> None:
    lock, px4, _ = hil
    px4.until("HIL_SENSOR")
    px4.answer((math.nan, 0.0, 0.0, 0.0))
    assert lock.done.wait(5.0)
    assert isinstance(lock.error, SitlProtocolError)
    assert "NaN" in str(lock.error)
    assert "stand-in PX4 output" in str(lock.error)


def test_px4_closing_the_simulator_connection_is_reported(
    hil: tuple[HilLockStep, _StandInPx4, _FakeProcess],
) -> None:
    lock, px4, _ = hil
    px4.until("HIL_SENSOR")
    px4.sock.close()
    assert lock.done.wait(5.0)
    assert isinstance(lock.error, SitlDied)
    assert "closed the simulator connection" in str(lock.error)


def test_a_px4_that_exits_is_reported(hil: tuple[HilLockStep, _StandInPx4, _FakeProcess]) -> None:
    lock, px4, proc = hil
    px4.until("HIL_SENSOR")
    px4.answer((0.0, 0.0, 0.0, 0.0))
    proc.rc = -11
    deadline = time.monotonic() + 5
    while not lock.done.is_set() and time.monotonic() < deadline:
        time.sleep(0.05)  # no more answers: the lock step waits for one, and checks on PX4 meanwhile
    assert isinstance(lock.error, SitlDied)
    assert "status -11" in str(lock.error)


# ---------------------------------------------------------------------------------------------- real firmware
def _px4_children(pid: int) -> list[int]:
    out = subprocess.run(["ps", "-eo", "pid,ppid,comm"], capture_output=True, text=True).stdout
    rows = [line.split() for line in out.splitlines()[1:]]
    return [int(r[0]) for r in rows if len(r) >= 3 and r[2] == "px4" and int(r[1]) == pid]


@pytest.mark.slow
@pytest.mark.sitl
def test_real_px4_takes_off_holds_and_lands_on_the_world(
    px4: Path, start_sim: Callable[..., SimProcess]
) -> None:
    """``--start air``: real PX4 initialises on the ground, arms, climbs to the launch pose and holds in
    AUTO.LOITER (``ready``); a ground station on the companion's port (PX4's own MAVLink instance)
    switches it to AUTO.LAND: it lands on the world's ground, the touchdown is graded, PX4's land
    detector disarms it; SIGTERM ends simbridge and PX4 with it."""
    sim = start_sim("--autopilot", "px4-sitl", "--px4", str(px4), "--scenario", "flat", "--start", "air",
                    "--speed", "8")  # fmt: skip
    client = MavClient(sim.port)
    try:
        hb = client.wait_heartbeat(60, ask=False)
        assert hb.autopilot == 12  # MAV_AUTOPILOT_PX4: the real firmware on the companion's port
        ready = _wait_event(sim, "ready", 240)
        pos = ready["pos_ned_m"]
        assert isinstance(pos, list)
        assert math.hypot(pos[0], pos[1]) < 0.5
        children = _px4_children(sim.proc.pid)
        assert len(children) == 1
        client.drop_backlog()  # a full buffer (~245 datagrams) of telemetry unread: the answer must not queue
        assert client.set_mode_px4("AUTO.LAND") == 0
        touchdown = _wait_event(sim, "touchdown", 120)
        assert touchdown["safe"] is True
        assert touchdown["surface"]
        _wait_event(sim, "disarmed", 60)
        modes = [e["mode"] for e in sim.events("mode")]
        assert modes[modes.index("AUTO.TAKEOFF") :][:3] == ["AUTO.TAKEOFF", "AUTO.LOITER", "AUTO.LAND"]
    finally:
        client.close()
    sim.proc.send_signal(signal.SIGTERM)
    assert sim.proc.wait(timeout=30) == 0
    stop = sim.events("stop")[0]
    assert stop["error"] is None
    assert isinstance(stop["frames"], int)
    assert stop["frames"] > 5_000  # 250 Hz lock step: over 20 s simulated
    deadline = time.monotonic() + 10
    while any(Path(f"/proc/{c}").exists() for c in children) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert not [c for c in children if Path(f"/proc/{c}").exists()], "PX4 outlived simbridge"


@pytest.mark.slow
@pytest.mark.sitl
def test_a_lost_companion_link_hands_real_px4_to_its_own_failsafe_then_the_companion_lands(
    px4: Path, start_rig: Callable[..., Rig], tmp_path: Path
) -> None:
    """The product unchanged on real PX4, and the firmware's own failsafe in the middle of it (one flight
    for both: the suite flies each behaviour once). An alarm: OFFBOARD position setpoints through the
    firmware's own entry rules, the descent. Then the MAVLink link between real PX4 and the companion
    goes dead for 5 s during the first descent step. PX4's own offboard-loss failsafe (COM_OF_LOSS_T 1
    s, COM_OBL_RC_ACT 0: position, which with no RC holds) takes the vehicle out of OFFBOARD into
    POSCTL; the companion sees the silence and keeps its target; once the link is back PX4 takes
    OFFBOARD again as the setpoints arrive, and the companion confirms the same site again and lands on
    it through PX4's precision land (AUTO.PRECLAND on its LANDING_TARGET; AUTO.LAND if none went out in
    time), PX4's land detector and disarm; the world grades the touchdown: the checks the emulation's
    PX4 passes in tests/test_companion_e2e.py."""
    from tests.test_companion_e2e import _clean_relay, _events, _land_through_a_link_blackout, _via

    relays: list[Any] = []
    record = tmp_path / "record"

    def alarmed() -> Rig:
        rig = start_rig(
            ["--autopilot", "px4-sitl", "--px4", str(px4), "--scenario", "scenario1", "--speed", "4"],
            ["--record", str(record)],
            mavlink_via=_via(relays, _clean_relay),
        )
        return _alarm_when_ready(rig, "px4-sitl")

    # "descending 70 m, site clear: ...": the first step
    rig, td, log = _land_through_a_link_blackout(
        relays, alarmed, first_step="descending ", step_timeout_s=300, touchdown_timeout_s=400
    )
    _wait_event(rig.sim, "disarmed", 60)
    timed = [(e["t_s"], e["mode"]) for e in rig.sim.events("mode")]
    modes = [m for _, m in timed]
    taken = modes.index("OFFBOARD")
    assert modes[taken : taken + 3] == ["OFFBOARD", "POSCTL", "OFFBOARD"], modes  # PX4's own hold
    # the touchdown is the firmware's: its precision land on the companion's LANDING_TARGET, where one
    # went out in time, else AUTO.LAND (PX4 changes mode again as it disarms)
    events = _events(record)
    (landing,) = [e for e in events if e["kind"] == "precision_landing"]
    assert landing["why"].startswith("AUTO.PRECLAND, PLD_MAX_SRCH 0") or not landing["used"], landing
    assert landing["mode"] == ("AUTO.PRECLAND" if landing["used"] else "AUTO.LAND"), landing
    assert landing["mode"] in modes[taken + 3 :], modes
    assert [m for t, m in timed if t <= td["t_s"]][-1] == landing["mode"], timed
    assert "PLD_MAX_SRCH 0, PLD_BTOUT 5 s" in log  # read from the firmware when it was first heard
    kinds = [e["kind"] for e in events]
    restored = kinds.index("link_restored")
    assert "confirm" in kinds[restored:]


def test_a_px4_that_never_connects_is_an_error_not_a_hang(monkeypatch: pytest.MonkeyPatch) -> None:
    import simbridge.px4_sitl as px4_sitl

    monkeypatch.setattr(px4_sitl, "CONNECT_S", 0.5)
    server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    server.bind(("127.0.0.1", 0))
    server.listen(1)
    v = Vehicle(GeoOrigin(), FlatTerrain())
    lock = HilLockStep(server, v, GeoOrigin(), _FakeProcess(), np.random.default_rng(0))  # type: ignore[arg-type]
    lock.start()
    try:
        assert lock.done.wait(5.0)
        assert isinstance(lock.error, SitlNotAnswering)
        assert "did not connect" in str(lock.error)
        assert "stand-in PX4 output" in str(lock.error)
    finally:
        lock.stop()
        server.close()


def test_the_lock_step_keeps_to_its_speed_and_does_not_race_after_a_stall() -> None:
    """``--speed`` caps simulated seconds per wall second; after PX4 stalls (no answer for a while)
    the lock step carries on at that pace rather than racing to make up the lost time. An upper bound
    only: a slower machine can only make it slower."""
    server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    server.bind(("127.0.0.1", 0))
    server.listen(1)
    v = Vehicle(GeoOrigin(), FlatTerrain())
    v.reset((0.0, 0.0, -GEAR_HEIGHT_M), 0.0)
    lock = HilLockStep(server, v, GeoOrigin(), _FakeProcess(), np.random.default_rng(0), speed=2.0)  # type: ignore[arg-type]
    lock.start()
    px4 = _StandInPx4(server.getsockname()[1])
    try:

        def answer_for(wall_s: float) -> float:
            """Answer every sensor message for ``wall_s``; the simulated seconds that passed."""
            t0, sim0 = time.monotonic(), lock.sim_time_s()
            while time.monotonic() - t0 < wall_s:
                px4.until("HIL_SENSOR")
                px4.answer((0.0, 0.0, 0.0, 0.0))
            return lock.sim_time_s() - sim0

        assert answer_for(1.0) <= 2.0 * (1.0 + px4_sitl.MAX_LAG_S) + 0.1
        time.sleep(0.5)  # PX4 stalls: no answers
        assert (
            answer_for(1.0) <= 2.0 * (1.0 + px4_sitl.MAX_LAG_S) + 0.1
        )  # not 2 x 1.5 s: the stall is not made up
    finally:
        lock.stop()
        px4.sock.close()
        server.close()
