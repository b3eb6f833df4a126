"""The emulated ArduPilot flavour against real ArduCopter: the same checks, flown
against both, must pass on both. What a companion meets: what arrives unasked, stream requests and
their ACKs, the local frame's origin (the EKF origin at the launch point, not the scenario's origin),
HOME_POSITION and GPS_GLOBAL_ORIGIN, GUIDED / arm / takeoff ACKs, the landed states through a takeoff
and a LAND, position targets in the local frame, the land detector's delay and the disarm after LAND.

The real-firmware runs need ArduPilot's SITL (``../shared/sitl/ardupilot/arducopter``); they skip
elsewhere, saying how to get it, and fail in CI (``LANDFALL_REQUIRE_SITL=1``).
"""

from __future__ import annotations

import math
import time
from collections import Counter
from collections.abc import Callable
from typing import Any

import pytest
from pymavlink import mavutil

from companion.daemon import STREAMS_HZ
from simbridge.geo import GeoOrigin
from tests.conftest import SimProcess
from tests.mavclient import AP_MODES, MavClient

pytestmark = pytest.mark.slow
M = mavutil.mavlink
LAUNCH = (12.0, 8.0)
ON_GROUND, IN_AIR, TAKEOFF, LANDING = 1, 2, 3, 4


@pytest.fixture(params=["ardupilot", pytest.param("ardupilot-sitl", marks=pytest.mark.sitl)])
def vehicle(request: pytest.FixtureRequest, start_sim: Callable[..., SimProcess]) -> tuple[str, SimProcess]:
    autopilot = str(request.param)
    extra: list[str] = []
    if autopilot == "ardupilot-sitl":
        extra = ["--sitl", str(request.getfixturevalue("arducopter"))]
    sim = start_sim("--autopilot", autopilot, *extra, "--scenario", "flat", "--start", "ground",
                    "--launch", f"{LAUNCH[0]},{LAUNCH[1]}", "--speed", "10")  # fmt: skip
    return autopilot, sim


def _ready(sim: SimProcess, timeout_s: float = 120.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not sim.events("ready"):
        assert sim.proc.poll() is None, sim.stderr_path.read_text()[-3000:]
        assert time.monotonic() < deadline, "no ready event"
        time.sleep(0.2)


def _seen(c: MavClient, wall_s: float) -> set[str]:
    kinds: set[str] = set()
    end = time.monotonic() + wall_s
    while time.monotonic() < end:
        m = c.conn.recv_match(blocking=True, timeout=0.1)
        if m is not None:
            kinds.add(m.get_type())
    return kinds


def _landed(c: MavClient, want: int, timeout_s: float) -> float:
    """Wall time at which EXTENDED_SYS_STATE first says ``want``."""
    c.recv("EXTENDED_SYS_STATE", timeout_s, cond=lambda m: m.landed_state == want)
    return time.monotonic()


def test_the_emulation_and_the_firmware_meet_a_companion_alike(
    vehicle: tuple[str, SimProcess], client_for: Callable[..., MavClient]
) -> None:
    autopilot, sim = vehicle
    c = client_for(sim.port)
    hb = c.wait_heartbeat(60, ask=False)
    assert hb.autopilot == M.MAV_AUTOPILOT_ARDUPILOTMEGA
    assert hb.type == M.MAV_TYPE_QUADROTOR
    unasked = _seen(c, 2.0)
    assert not unasked & {"LOCAL_POSITION_NED", "ATTITUDE", "ATTITUDE_QUATERNION", "GLOBAL_POSITION_INT"}
    _ready(sim)
    for msg_id, hz in STREAMS_HZ.items():  # what the companion asks for, at its rates
        assert c.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, msg_id, 1e6 / hz) == 0
    # the local frame starts at the EKF origin: the launch point, 14 m from the scenario's origin
    p = c.position(10)
    assert math.hypot(p.x, p.y) < 0.5
    assert abs(p.z) < 0.5
    # each stream at the rate asked, counted over 4 s of the autopilot's clock
    first = c.position()
    counts: Counter[int] = Counter()
    while True:
        m = c.recv(["LOCAL_POSITION_NED", *(M.mavlink_map[i].msgname for i in STREAMS_HZ)], 5)
        if m.get_type() == "LOCAL_POSITION_NED" and m.time_boot_ms >= first.time_boot_ms + 4000:
            break
        counts[m.get_msgId()] += 1
    for msg_id, hz in STREAMS_HZ.items():
        name = M.mavlink_map[msg_id].msgname
        assert counts[msg_id] == pytest.approx(4 * hz, rel=0.2), (
            f"{autopilot}: {counts[msg_id]} {name} in 4 s at {hz} Hz"
        )
    assert c.command(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN) == 0
    origin = c.recv("GPS_GLOBAL_ORIGIN", 10)
    launch = GeoOrigin().to_geodetic(LAUNCH[0], LAUNCH[1], 0.0)
    n, e, _ = GeoOrigin().to_ned(origin.latitude / 1e7, origin.longitude / 1e7, launch[2])
    assert math.hypot(n - LAUNCH[0], e - LAUNCH[1]) < 1.0
    # GUIDED, arm, take off: accepted by both; the landed state goes through TAKEOFF or straight to IN_AIR
    assert c.set_mode_ap("GUIDED") == 0
    assert c.arm() == 0
    assert c.command(M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, 0, 0, 10) == 0
    c.recv("EXTENDED_SYS_STATE", 30, cond=lambda m: m.landed_state in (TAKEOFF, IN_AIR))
    c.wait_position(0.0, 0.0, -10.0, 1.0, 60)
    # a position target in the local frame lands in the world at the launch point plus it
    c.wait_position(5.0, 0.0, -10.0, 0.3, 60, stream=True)
    c.stream_position(5.0, 0.0, -10.0, wall_s=1.0)  # settle (10 s simulated)
    told = c.position()
    state = sim.events("state")[-1]
    wn, we, _ = state["pos_ned_m"]  # type: ignore[misc]
    assert math.hypot(wn - (LAUNCH[0] + 5.0), we - LAUNCH[1]) < 1.0
    assert math.hypot(wn - (LAUNCH[0] + told.x), we - (LAUNCH[1] + told.y)) < 1.0
    # LAND: LANDING, then ON_GROUND a land detector's delay after the gear touches, then disarmed
    assert c.set_mode_ap("LAND") == 0
    c.recv("EXTENDED_SYS_STATE", 10, cond=lambda m: m.landed_state == LANDING)
    t_boot = contact = on_ground = None
    deadline = time.monotonic() + 120
    while on_ground is None:
        assert time.monotonic() < deadline, f"{autopilot}: no ON_GROUND after LAND"
        m = c.recv(["LOCAL_POSITION_NED", "EXTENDED_SYS_STATE"], 10)
        if m.get_type() == "LOCAL_POSITION_NED":
            t_boot = m.time_boot_ms / 1000.0
            if contact is None and m.z > -0.05:  # the CG within 5 cm of its resting height
                contact = t_boot
        elif m.landed_state == ON_GROUND and t_boot is not None:
            on_ground = t_boot
    assert contact is not None
    delay = on_ground - contact
    print(f"{autopilot}: ON_GROUND {delay:.2f} s after contact")
    assert 0.5 <= delay <= 3.0, f"{autopilot}: ON_GROUND {delay:.2f} s after contact"
    c.wait_disarmed(30)
    c.statustext("Disarming motors")
    c.drain(1.0)  # 10 s simulated
    assert c.heartbeat().custom_mode == AP_MODES["LAND"], f"{autopilot}: left LAND after the disarm"


def test_mode_changes_and_arming_refusals_on_the_ground_alike(
    vehicle: tuple[str, SimProcess], client_for: Callable[..., MavClient]
) -> None:
    """Disarmed on the ground with a position: every mode a companion uses is accepted, and arming is
    refused (FAILED, with the firmware's words) in the modes that cannot take off, accepted in GUIDED
    and LOITER; no STATUSTEXT answers a mode change."""
    autopilot, sim = vehicle
    c = _few_streams(client_for(sim.port), sim)
    for name in ("LAND", "RTL", "BRAKE"):
        assert c.set_mode_ap(name) == M.MAV_RESULT_ACCEPTED, f"{autopilot}: {name}"
        c.drain(0.3)
        assert c.heartbeat().custom_mode == AP_MODES[name]
        assert c.arm() == M.MAV_RESULT_FAILED, f"{autopilot}: armed in {name}"
        c.statustext(f"Arm: {name} mode not armable")
    for name in ("LOITER", "GUIDED"):
        assert c.set_mode_ap(name) == M.MAV_RESULT_ACCEPTED, f"{autopilot}: {name}"
        c.drain(0.3)
        assert c.arm() == M.MAV_RESULT_ACCEPTED, f"{autopilot}: not armed in {name}"
        c.statustext("Arming motors")
        assert c.arm(False) == M.MAV_RESULT_ACCEPTED
        c.drain(0.3)
    said = [m.text for m in c.texts]
    assert not [t for t in said if t.startswith("Mode ")], f"{autopilot}: {said}"


def test_the_legacy_stream_request_starts_and_stops_a_group_alike(
    vehicle: tuple[str, SimProcess], client_for: Callable[..., MavClient]
) -> None:
    """REQUEST_DATA_STREAM (MAVProxy's way): MAV_DATA_STREAM_POSITION at 5 Hz brings LOCAL_POSITION_NED
    at 5 Hz of the autopilot's clock; start_stop 0 stops it."""
    autopilot, sim = vehicle
    c = client_for(sim.port)
    c.wait_heartbeat(60, ask=False)
    _ready(sim)
    c.mav.request_data_stream_send(1, 1, M.MAV_DATA_STREAM_POSITION, 5, 1)
    first = c.recv("LOCAL_POSITION_NED", 10)
    count = 0
    while c.position().time_boot_ms < first.time_boot_ms + 4000:
        count += 1
    assert count == pytest.approx(20, abs=4), f"{autopilot}: {count} in 4 s at 5 Hz"
    c.mav.request_data_stream_send(1, 1, M.MAV_DATA_STREAM_POSITION, 5, 0)
    c.drain(0.5)
    assert "LOCAL_POSITION_NED" not in _seen(c, 1.5), f"{autopilot}: still streaming after the stop"


def _few_streams(c: MavClient, sim: SimProcess) -> MavClient:
    """Only what the checks read (every stream at 20 Hz of a 10x clock drowned COMMAND_ACKs)."""
    c.wait_heartbeat(60, ask=False)
    _ready(sim)
    for msg_id, hz in ((M.MAVLINK_MSG_ID_LOCAL_POSITION_NED, 10), (M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE, 5)):
        assert c.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, msg_id, 1e6 / hz) == 0
    return c


def _take_off_then(c: MavClient, autopilot: str, alt_m: float, mode: str) -> Any:
    """GUIDED, arm, take off to ``alt_m``, settle, switch to ``mode``: the position at the switch."""
    assert c.set_mode_ap("GUIDED") == M.MAV_RESULT_ACCEPTED
    assert c.arm() == M.MAV_RESULT_ACCEPTED
    assert c.command(M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, 0, 0, alt_m) == M.MAV_RESULT_ACCEPTED
    c.wait_position(0.0, 0.0, -alt_m, 1.0, 90)
    c.stream_position(0.0, 0.0, -alt_m, wall_s=0.3)
    c.drop_backlog()  # the position at the switch, not one still queued from before (a loaded machine)
    start = c.position()
    assert c.set_mode_ap(mode) == M.MAV_RESULT_ACCEPTED, f"{autopilot}: {mode} in the air"
    return start


def _at(c: MavClient, boot_ms: float) -> Any:
    """The first LOCAL_POSITION_NED at or after ``boot_ms`` of the autopilot's clock."""
    m = c.position()
    while m.time_boot_ms < boot_ms:
        m = c.position()
    return m


def test_the_pilots_modes_with_the_sticks_at_rest_alike(
    vehicle: tuple[str, SimProcess], client_for: Callable[..., MavClient]
) -> None:
    """STABILIZE, ACRO, ALT_HOLD and POSHOLD are accepted and armable on the ground (and never
    auto-disarm there), accepted in the air; with no transmitter the sticks rest centred, the throttle
    at its minimum (SITL's RC3 = 1000): ALT_HOLD and POSHOLD descend at PILOT_SPEED_UP (2.5 m/s; 0 in
    PILOT_SPEED_DN means that) and do not drift; touching down, ALT_HOLD says ON_GROUND a land
    detector's delay later and stays armed. SPORT is not built: FAILED."""
    autopilot, sim = vehicle
    c = _few_streams(client_for(sim.port), sim)
    for name in ("STABILIZE", "ACRO", "ALT_HOLD", "POSHOLD"):
        assert c.set_mode_ap(name) == M.MAV_RESULT_ACCEPTED, f"{autopilot}: {name}"
        c.drain(0.3)
        assert c.heartbeat().custom_mode == AP_MODES[name]
        assert c.arm() == M.MAV_RESULT_ACCEPTED, f"{autopilot}: not armed in {name}"
        assert c.arm(False) == M.MAV_RESULT_ACCEPTED
    assert c.command(M.MAV_CMD_DO_SET_MODE, 1, 13) == M.MAV_RESULT_FAILED, f"{autopilot}: SPORT"
    assert c.set_mode_ap("ALT_HOLD") == M.MAV_RESULT_ACCEPTED
    assert c.arm() == M.MAV_RESULT_ACCEPTED
    t0 = c.position().time_boot_ms
    _at(c, t0 + 15_000)  # past DISARM_DELAY
    assert c.heartbeat().base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED, f"{autopilot}: auto-disarmed in ALT_HOLD"
    assert c.arm(False) == M.MAV_RESULT_ACCEPTED
    start = _take_off_then(c, autopilot, 40.0, "POSHOLD")
    _check_descent(autopilot, "POSHOLD", c, start, settle_ms=1500)
    assert c.set_mode_ap("GUIDED") == M.MAV_RESULT_ACCEPTED
    c.wait_position(0.0, 0.0, -40.0, 1.0, 90, stream=True)
    c.stream_position(0.0, 0.0, -40.0, wall_s=0.3)
    start = c.position()
    assert c.set_mode_ap("ALT_HOLD") == M.MAV_RESULT_ACCEPTED, f"{autopilot}: ALT_HOLD in the air"
    _check_descent(autopilot, "ALT_HOLD", c, start, settle_ms=1500)
    # touching the ground in ALT_HOLD: ON_GROUND a land detector's delay later, and still armed 20 s on
    contact = on_ground = None
    t_boot = 0
    deadline = time.monotonic() + 60
    while on_ground is None or t_boot < contact + 20_000:
        assert time.monotonic() < deadline, f"{autopilot}: contact {contact}, ON_GROUND {on_ground}"
        m = c.recv(["LOCAL_POSITION_NED", "EXTENDED_SYS_STATE", "HEARTBEAT"], 10)
        if m.get_type() == "LOCAL_POSITION_NED":
            t_boot = m.time_boot_ms
            if contact is None and m.z > -0.05:
                contact = t_boot
        elif m.get_type() == "EXTENDED_SYS_STATE":
            if on_ground is None and m.landed_state == ON_GROUND and contact is not None:
                on_ground = t_boot
        elif m.get_srcComponent() == 1:
            assert m.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED, f"{autopilot}: disarmed in ALT_HOLD"
    delay = (on_ground - contact) / 1000
    print(f"{autopilot}: ALT_HOLD ON_GROUND {delay:.2f} s after contact, armed 20 s on")
    assert 0.5 <= delay <= 3.0, f"{autopilot}: ON_GROUND {delay:.2f} s after contact"


def _check_descent(autopilot: str, name: str, c: MavClient, start: Any, settle_ms: float) -> None:
    """Over 3 s from ``settle_ms`` after ``start``: down at 2.5 m/s, within 1 m of where it started."""
    first = _at(c, start.time_boot_ms + settle_ms)
    last = _at(c, first.time_boot_ms + 3000)
    climb = (first.z - last.z) / ((last.time_boot_ms - first.time_boot_ms) / 1000)
    drift = math.hypot(last.x - start.x, last.y - start.y)
    print(f"{autopilot}: {name} climbs {climb:.2f} m/s, drifts {drift:.2f} m")
    assert climb == pytest.approx(-2.5, abs=0.3), f"{autopilot}: {name} climbs {climb:.2f} m/s"
    assert drift < 1.0, f"{autopilot}: {name} drifts {drift:.2f} m"


def test_stabilize_with_the_throttle_at_its_minimum_falls_alike(
    vehicle: tuple[str, SimProcess], client_for: Callable[..., MavClient]
) -> None:
    """STABILIZE in the air, the throttle at its minimum: the motors at their minimum, it falls (the
    firmware: 3.8 to 4.4 m in the first second). A vehicle of its own: real ArduCopter SITL caught
    out of that fall (GUIDED, ALT_HOLD) went astray or stopped (a floating point exception)."""
    autopilot, sim = vehicle
    c = _few_streams(client_for(sim.port), sim)
    start = _take_off_then(c, autopilot, 30.0, "STABILIZE")
    end = _at(c, start.time_boot_ms + 1000)
    drop = end.z - start.z
    print(f"{autopilot}: STABILIZE drops {drop:.2f} m in 1 s, {end.vz:.2f} m/s down")
    assert 3.0 < drop < 6.0, f"{autopilot}: STABILIZE dropped {drop:.2f} m in 1 s"
    assert end.vz > 6.0
    assert math.hypot(end.x - start.x, end.y - start.y) < 1.0
