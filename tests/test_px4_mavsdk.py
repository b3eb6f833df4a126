"""The real MAVSDK (PyPI mavsdk 4.x, asyncio API) flies simbridge's PX4 flavour end to end."""

from __future__ import annotations

import asyncio
import math
from collections.abc import Callable

import pytest
from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
from mavsdk.asyncio.plugins.action import ActionAsync
from mavsdk.asyncio.plugins.offboard import OffboardAsync, PositionNedYaw
from mavsdk.asyncio.plugins.telemetry import FlightMode, TelemetryAsync

from tests.conftest import SimProcess

pytestmark = pytest.mark.slow


async def _wait_for(
    gen_factory: Callable[[], object], cond: Callable[[object], bool], timeout_s: float
) -> object:
    async def scan() -> object:
        async for value in gen_factory():  # type: ignore[attr-defined]
            if cond(value):
                return value
        raise AssertionError("telemetry stream ended")

    return await asyncio.wait_for(scan(), timeout_s)


async def test_mavsdk_px4_takeoff_offboard_hold_land(start_sim: Callable[..., SimProcess]) -> None:
    sim = start_sim("--autopilot", "px4", "--start", "ground", "--speed", "2")
    config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    async with Mavsdk(config) as mavsdk:
        await mavsdk.add_any_connection(f"udpin://127.0.0.1:{sim.port}")
        system = await mavsdk.first_autopilot(timeout_s=30.0)
        assert system is not None, "MAVSDK did not discover the simbridge autopilot"
        action, offboard, telemetry = ActionAsync(system), OffboardAsync(system), TelemetryAsync(system)

        await action.set_takeoff_altitude(8.0)
        assert await action.get_takeoff_altitude() == pytest.approx(8.0)
        await action.arm()
        await action.takeoff()
        await _wait_for(telemetry.subscribe_position_velocity_ned, lambda pv: pv.position.down_m < -7.7, 30)  # type: ignore[attr-defined]
        await _wait_for(telemetry.subscribe_flight_mode, lambda m: m == FlightMode.HOLD, 10)

        target = PositionNedYaw(30.0, 0.0, -8.0, 0.0)
        await offboard.set_position_ned(target)  # MAVSDK's documented flow: one setpoint, then start
        await offboard.start()
        await _wait_for(telemetry.subscribe_flight_mode, lambda m: m == FlightMode.OFFBOARD, 5)

        def near(pv: object) -> bool:
            p = pv.position  # type: ignore[attr-defined]
            return math.dist((p.north_m, p.east_m, p.down_m), (30.0, 0.0, -8.0)) < 0.3

        await _wait_for(telemetry.subscribe_position_velocity_ned, near, 40)
        # hold: every sample over the next 3 s (simulated 6 s) stays within 0.5 m
        worst = 0.0
        loop = asyncio.get_running_loop()
        end = loop.time() + 3.0
        async for pv in telemetry.subscribe_position_velocity_ned():
            p = pv.position
            worst = max(worst, math.dist((p.north_m, p.east_m, p.down_m), (30.0, 0.0, -8.0)))
            if loop.time() > end:
                break
        assert worst < 0.5

        await offboard.stop()
        await action.land()
        await _wait_for(telemetry.subscribe_armed, lambda armed: not armed, 40)

    touchdown = sim.events("touchdown")
    assert len(touchdown) == 1
    n, e, _ = touchdown[0]["pos_ned_m"]  # type: ignore[misc]
    assert math.hypot(n - 30.0, e) < 0.5
    modes = [ev["mode"] for ev in sim.events("mode")]
    assert modes[:4] == ["AUTO.TAKEOFF", "AUTO.LOITER", "OFFBOARD", "AUTO.LOITER"]
    assert "AUTO.LAND" in modes
