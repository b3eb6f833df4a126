"""pymavlink flies the ArduPilot flavour: GUIDED, arm, takeoff, position target, LAND."""

from __future__ import annotations

from collections.abc import Callable

import pytest
from pymavlink import mavutil

from tests.conftest import SimProcess
from tests.mavclient import MAV_RESULT_ACCEPTED, MavClient

pytestmark = pytest.mark.slow
CMD = mavutil.mavlink


def test_ardupilot_guided_takeoff_target_land(
    start_sim: Callable[..., SimProcess], client_for: Callable[..., MavClient]
) -> None:
    sim = start_sim("--autopilot", "ardupilot", "--start", "ground", "--speed", "4")
    c = client_for(sim.port)
    hb = c.wait_heartbeat()
    assert hb.autopilot == mavutil.mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA
    assert hb.type == mavutil.mavlink.MAV_TYPE_QUADROTOR

    assert c.set_mode_ap("GUIDED") == MAV_RESULT_ACCEPTED
    assert c.heartbeat().custom_mode == 4
    assert c.arm() == MAV_RESULT_ACCEPTED
    assert c.command(CMD.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 10.0) == MAV_RESULT_ACCEPTED
    c.wait_position(0.0, 0.0, -10.0, tol_m=0.5, timeout_s=30)

    c.send_position(15.0, -10.0, -12.0)  # held indefinitely: sent once
    held = c.wait_position(15.0, -10.0, -12.0, tol_m=0.3, timeout_s=40)
    assert abs(held.vx) < 0.5

    assert c.set_mode_ap("LAND") == MAV_RESULT_ACCEPTED
    c.wait_disarmed(timeout_s=60)
    touchdowns = sim.events("touchdown")
    assert len(touchdowns) == 1
    n, e, _ = touchdowns[0]["pos_ned_m"]  # type: ignore[misc]
    assert abs(n - 15.0) < 0.5
    assert abs(e + 10.0) < 0.5
    modes = [ev["mode"] for ev in sim.events("mode")]
    assert modes == ["GUIDED", "LAND"]  # ArduCopter stays in LAND once disarmed
    assert [ev["event"] for ev in sim.events() if ev["event"] in ("armed", "disarmed")] == [
        "armed",
        "disarmed",
    ]
