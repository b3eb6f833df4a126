"""A MAVLink link that comes back after a silence (``VehicleController.await_link``), on a link without a
socket: back with the autopilot in its own offboard-loss failsafe, the heartbeat a moment before the
first position, is the link back (the recovery then takes the failsafe with the link up); heartbeats in
the failsafe with no position after them are the estimator without a position."""

from __future__ import annotations

import asyncio
import time
from typing import Any

import pytest
from pymavlink.dialects.v20 import common as mavlink2

from companion.control import HEARD_WITHOUT_POSITION_S, AutopilotFailsafe, VehicleController
from companion.telemetry import TelemetryCache
from tests.autopilot_frames import AUTOPILOT, accept_commands, frames
from tests.fake_link import FakeLink

OFFBOARD, POSCTL = 6 << 16, 3 << 16
MAV_STATE_ACTIVE, MAV_STATE_CRITICAL = 4, 5


def _heartbeat(custom_mode: int, status: int) -> Any:
    return AUTOPILOT.heartbeat_encode(
        mavlink2.MAV_TYPE_QUADROTOR,
        mavlink2.MAV_AUTOPILOT_PX4,
        mavlink2.MAV_MODE_FLAG_SAFETY_ARMED | mavlink2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
        custom_mode,
        status,
    )


def _position(t_ms: int) -> Any:
    return AUTOPILOT.local_position_ned_encode(t_ms, 0.0, 0.0, -40.0, 0.0, 0.0, 0.0)


def _engaged_px4() -> tuple[VehicleController, FakeLink]:
    """A controller that holds OFFBOARD on a PX4 40 m up, its own mode heard once."""
    tm = TelemetryCache(1)
    link = FakeLink(answer=accept_commands)
    ctl = VehicleController(tm, link)

    def received(msg: Any, _addr: Any) -> None:
        tm.on_message(msg)
        if msg.get_type() == "COMMAND_ACK":
            ctl.on_command_ack(msg)

    link.attach(received)
    link.receive(frames(_heartbeat(OFFBOARD, MAV_STATE_ACTIVE), _position(1000)))
    return ctl, link


async def _engaged_then_silent(ctl: VehicleController, link: FakeLink) -> None:
    await ctl.engage()
    await asyncio.sleep(0.1)
    link.receive(frames(_heartbeat(OFFBOARD, MAV_STATE_ACTIVE), _position(1100)))
    await asyncio.sleep(0.2)  # the stream has heard its own mode


def test_a_link_back_with_px4_in_its_offboard_loss_failsafe_is_the_link_back() -> None:
    """PX4's offboard-loss failsafe took the vehicle into POSCTL while the link was dead. The link comes
    back with its heartbeat first and positions 0.3 s later: that is the link back, and the failsafe is
    then seen with the link up."""
    ctl, link = _engaged_px4()

    async def scenario() -> tuple[float, BaseException | None]:
        await _engaged_then_silent(ctl, link)

        async def link_back() -> None:
            await asyncio.sleep(0.3)
            link.receive(frames(_heartbeat(POSCTL, MAV_STATE_CRITICAL)))
            await asyncio.sleep(0.3)  # the stream's takeover check hears it meanwhile
            for k in range(10):
                link.receive(frames(_position(9000 + 50 * k)))
                await asyncio.sleep(0.05)

        feeder = asyncio.create_task(link_back())
        silent_s = await ctl.await_link(10.0)
        await feeder
        try:
            ctl.check_interruption()
        except AutopilotFailsafe as exc:
            caught: BaseException | None = exc
        else:
            caught = None
        await ctl.release()
        return silent_s, caught

    silent_s, caught = asyncio.run(scenario())
    assert silent_s >= 0.6
    assert isinstance(caught, AutopilotFailsafe)
    assert caught.custom_mode == POSCTL


def test_heartbeats_in_a_failsafe_without_positions_raise_the_failsafe() -> None:
    """The link is up (heartbeats) but no position follows: the estimator has none, and the failsafe
    is raised once it has been heard without a position for ``HEARD_WITHOUT_POSITION_S``."""
    ctl, link = _engaged_px4()

    async def scenario() -> float:
        await _engaged_then_silent(ctl, link)

        async def heartbeats_only() -> None:
            for _ in range(30):
                await asyncio.sleep(0.1)
                link.receive(frames(_heartbeat(POSCTL, MAV_STATE_CRITICAL)))

        feeder = asyncio.create_task(heartbeats_only())
        start = time.monotonic()
        try:
            with pytest.raises(AutopilotFailsafe):
                await ctl.await_link(10.0)
            return time.monotonic() - start
        finally:
            feeder.cancel()
            await ctl.release()

    waited_s = asyncio.run(scenario())
    assert waited_s >= HEARD_WITHOUT_POSITION_S
