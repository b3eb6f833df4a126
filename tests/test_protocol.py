"""What clients see on the wire: heartbeats, mode-change results, parameters, requested
messages, the rangefinder and RTL, for both autopilot flavours."""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable

import pytest
from pymavlink import mavutil

from tests.conftest import SimProcess
from tests.mavclient import MAV_RESULT_ACCEPTED, MavClient

pytestmark = pytest.mark.slow
MAV = mavutil.mavlink
TEMPORARILY_REJECTED, DENIED, UNSUPPORTED = 1, 2, 3


@pytest.mark.parametrize(
    ("flavour", "autopilot_id", "custom_mode"),
    [
        ("px4", MAV.MAV_AUTOPILOT_PX4, (4 << 16) | (3 << 24)),
        ("ardupilot", MAV.MAV_AUTOPILOT_ARDUPILOTMEGA, 5),
    ],
)
def test_heartbeat_air_start_is_armed_and_holding(
    start_sim: Callable[..., SimProcess],
    client_for: Callable[..., MavClient],
    flavour: str,
    autopilot_id: int,
    custom_mode: int,
) -> None:
    sim = start_sim("--autopilot", flavour, "--speed", "2")
    c = client_for(sim.port)
    hb = c.wait_heartbeat()
    assert (hb.get_srcSystem(), hb.get_srcComponent()) == (1, 1)
    assert hb.type == MAV.MAV_TYPE_QUADROTOR
    assert hb.autopilot == autopilot_id
    assert hb.base_mode & MAV.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    assert hb.base_mode & MAV.MAV_MODE_FLAG_SAFETY_ARMED
    assert hb.custom_mode == custom_mode
    assert hb.system_status == MAV.MAV_STATE_ACTIVE
    state = c.recv("EXTENDED_SYS_STATE")
    assert state.landed_state == MAV.MAV_LANDED_STATE_IN_AIR


def test_px4_mode_change_results(
    start_sim: Callable[..., SimProcess], client_for: Callable[..., MavClient]
) -> None:
    sim = start_sim("--autopilot", "px4", "--speed", "2")
    c = client_for(sim.port)
    c.wait_heartbeat()
    do_set_mode = MAV.MAV_CMD_DO_SET_MODE
    assert c.command(do_set_mode, 1, 1, 0) == DENIED  # MANUAL: no RC in simulation
    assert c.command(do_set_mode, 1, 9, 0) == UNSUPPORTED  # no such main mode
    assert c.command(do_set_mode, 1, 4, 4) == UNSUPPORTED  # AUTO.MISSION: not emulated
    assert c.set_mode_px4("OFFBOARD") == TEMPORARILY_REJECTED
    assert c.set_mode_px4("POSCTL") == MAV_RESULT_ACCEPTED
    assert c.heartbeat().custom_mode == 3 << 16
    assert [e["mode"] for e in sim.events("mode")] == ["POSCTL"]


def test_ardupilot_mode_change_results(
    start_sim: Callable[..., SimProcess], client_for: Callable[..., MavClient]
) -> None:
    sim = start_sim("--autopilot", "ardupilot", "--speed", "2")
    c = client_for(sim.port)
    c.wait_heartbeat()
    assert c.command(MAV.MAV_CMD_DO_SET_MODE, 1, 3) == DENIED  # AUTO: no mission
    assert c.command(MAV.MAV_CMD_DO_SET_MODE, 1, 13) == MAV.MAV_RESULT_FAILED  # SPORT: not in 4.7
    assert c.command(MAV.MAV_CMD_DO_SET_MODE, 1, 99) == UNSUPPORTED
    assert c.set_mode_ap("BRAKE") == MAV_RESULT_ACCEPTED
    assert c.heartbeat().custom_mode == 17
    # SET_MODE (message 11), as MAVProxy sends it, is acknowledged too
    c.mav.set_mode_send(1, MAV.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 4)
    ack = c.recv("COMMAND_ACK", cond=lambda m: m.command == MAV.MAVLINK_MSG_ID_SET_MODE)
    assert ack.result == MAV_RESULT_ACCEPTED
    assert c.heartbeat().custom_mode == 4


def test_parameters_list_read_set(
    start_sim: Callable[..., SimProcess], client_for: Callable[..., MavClient]
) -> None:
    sim = start_sim("--autopilot", "px4", "--speed", "2")
    c = client_for(sim.port)
    c.wait_heartbeat()
    value = c.param_read("MIS_TAKEOFF_ALT")
    assert value.param_value == pytest.approx(2.5)
    assert value.param_type == MAV.MAV_PARAM_TYPE_REAL32
    c.mav.param_request_list_send(1, 1)
    first = c.recv("PARAM_VALUE")
    seen = {first.param_id}
    for _ in range(first.param_count - 1):
        seen.add(c.recv("PARAM_VALUE").param_id)
    assert {"MIS_TAKEOFF_ALT", "COM_OF_LOSS_T", "COM_OBL_RC_ACT"} <= seen
    assert len(seen) == first.param_count
    echo = c.param_set("MPC_XY_VEL_MAX", 3.0, MAV.MAV_PARAM_TYPE_REAL32)
    assert echo.param_value == pytest.approx(3.0)
    bad = c.param_set("MPC_XY_VEL_MAX", -1.0, MAV.MAV_PARAM_TYPE_REAL32)  # refused: value in force echoed
    assert bad.param_value == pytest.approx(3.0)
    c.statustext("MPC_XY_VEL_MAX rejected")


def test_request_message_and_set_interval(
    start_sim: Callable[..., SimProcess], client_for: Callable[..., MavClient]
) -> None:
    sim = start_sim("--autopilot", "px4", "--speed", "2")
    c = client_for(sim.port)
    c.wait_heartbeat()
    assert c.command(MAV.MAV_CMD_REQUEST_MESSAGE, MAV.MAVLINK_MSG_ID_AUTOPILOT_VERSION) == MAV_RESULT_ACCEPTED
    version = c.recv("AUTOPILOT_VERSION")
    assert version.capabilities & MAV.MAV_PROTOCOL_CAPABILITY_MAVLINK2
    assert version.capabilities & MAV.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE
    assert c.command(MAV.MAV_CMD_REQUEST_MESSAGE, 9999) == UNSUPPORTED
    # stop the ATTITUDE stream, then bring it back at 1 Hz of simulated time
    assert c.command(MAV.MAV_CMD_SET_MESSAGE_INTERVAL, MAV.MAVLINK_MSG_ID_ATTITUDE, -1) == MAV_RESULT_ACCEPTED
    c.drain(0.2)  # frames already on the wire
    with pytest.raises(TimeoutError):
        c.recv("ATTITUDE", timeout_s=1.5)
    assert (
        c.command(MAV.MAV_CMD_SET_MESSAGE_INTERVAL, MAV.MAVLINK_MSG_ID_ATTITUDE, 1e6) == MAV_RESULT_ACCEPTED
    )
    stamps = [c.recv("ATTITUDE", timeout_s=3.0).time_boot_ms for _ in range(4)]
    gaps = [b - a for a, b in itertools.pairwise(stamps)]
    assert all(990 <= g <= 1010 for g in gaps), gaps
    ping_time = 123456
    c.mav.ping_send(ping_time, 7, 0, 0)
    pong = c.recv("PING", cond=lambda m: m.seq == 7)
    assert (pong.time_usec, pong.target_system) == (ping_time, 255)


def test_distance_sensor_reads_known_height(
    start_sim: Callable[..., SimProcess], client_for: Callable[..., MavClient]
) -> None:
    sim = start_sim("--autopilot", "px4", "--start", "ground", "--speed", "4")
    c = client_for(sim.port)
    c.wait_heartbeat()
    on_ground = c.recv("DISTANCE_SENSOR")
    assert on_ground.orientation == MAV.MAV_SENSOR_ROTATION_PITCH_270
    assert on_ground.current_distance == pytest.approx(15, abs=2)  # the CG rests 15 cm up
    c.takeoff_px4(20.0)
    for _ in range(20):
        c.recv("DISTANCE_SENSOR")  # let the climb settle
    ds = c.recv("DISTANCE_SENSOR")
    pos = c.position()
    # the local frame's origin is the EKF origin: the CG resting on the ground, 15 cm up
    assert ds.current_distance == pytest.approx((-pos.z + 0.15) * 100, abs=15)
    assert ds.current_distance == pytest.approx(2000, abs=35)
    assert ds.min_distance <= ds.current_distance <= ds.max_distance


def test_rtl_returns_home_and_lands(
    start_sim: Callable[..., SimProcess], client_for: Callable[..., MavClient]
) -> None:
    sim = start_sim("--autopilot", "ardupilot", "--start", "air", "--speed", "12")
    c = client_for(sim.port)
    c.wait_heartbeat()
    assert c.set_mode_ap("GUIDED") == MAV_RESULT_ACCEPTED
    c.send_position(40.0, 30.0, -30.0)
    c.wait_position(40.0, 30.0, -30.0, tol_m=0.5, timeout_s=30)
    assert c.command(MAV.MAV_CMD_NAV_RETURN_TO_LAUNCH) == MAV_RESULT_ACCEPTED
    c.wait_disarmed(timeout_s=40)
    touchdown = sim.events("touchdown")[0]
    n, e, _ = touchdown["pos_ned_m"]  # type: ignore[misc]
    assert math.hypot(n, e) < 1.0
    # ArduPilot RTL climbs to RTL_ALT (15 m) only when lower: from 30 m it returns at 30 m
    states = [s for s in sim.events("state") if s["mode"] == "RTL"]
    assert min(-s["pos_ned_m"][2] for s in states if math.hypot(*s["pos_ned_m"][:2]) > 5) > 29.0  # type: ignore[index]
