"""The descent step's height above the site, and a touchdown before the final approach."""

from __future__ import annotations

import asyncio
import math

import pytest

from companion.control import OperatorTakeover, TouchedDown
from companion.daemon import Companion
from companion.flavour import Mode
from companion.guidance.descent import height_above_site
from tests.autopilot_frames import AUTOPILOT, accept_commands, feed, frames, link_of, on_fake_link

LEVEL = (1.0, 0.0, 0.0, 0.0)


def _rolled(deg: float) -> tuple[float, float, float, float]:
    h = math.radians(deg) / 2
    return (math.cos(h), math.sin(h), 0.0, 0.0)


def test_the_lidar_surface_sets_the_height_wherever_the_vehicle_is() -> None:
    # the roof 22 m up, the vehicle 110 m up: 88 m, whatever the sweep's pose was
    h = height_above_site(-110.0, surface_up_m=22.0, site_d_m=-21.5, rangefinder_m=88.2, quat_wxyz=LEVEL)
    assert h == pytest.approx(88.0)


def test_a_tilted_rangefinder_reading_the_street_past_the_roof_edge_is_not_believed() -> None:
    """What a CI run caught: 18 degrees of tilt put the beam off the roof onto the street 116 m away;
    0.8 x 116 m as the step would have flown into the roof."""
    h = height_above_site(
        -110.0, surface_up_m=22.0, site_d_m=-22.0, rangefinder_m=116.0, quat_wxyz=_rolled(18.0)
    )
    assert h == pytest.approx(88.0)


def test_a_nearer_level_rangefinder_reading_lowers_the_height() -> None:
    # something under the vehicle nearer than the site's surface: the step errs short
    h = height_above_site(
        -110.0, surface_up_m=22.0, site_d_m=-22.0, rangefinder_m=60.0, quat_wxyz=_rolled(5.0)
    )
    assert h == pytest.approx(60.0 * math.cos(math.radians(5.0)))


def test_without_a_lidar_surface_the_ipm_site_and_the_rangefinder_are_used() -> None:
    assert height_above_site(
        -50.0, surface_up_m=math.nan, site_d_m=-10.0, rangefinder_m=math.nan, quat_wxyz=LEVEL
    ) == pytest.approx(40.0)
    assert height_above_site(
        -50.0, surface_up_m=math.nan, site_d_m=math.nan, rangefinder_m=30.0, quat_wxyz=LEVEL
    ) == pytest.approx(30.0)
    assert math.isnan(
        height_above_site(
            -50.0, surface_up_m=math.nan, site_d_m=math.nan, rangefinder_m=30.0, quat_wxyz=_rolled(25)
        )
    )


OFFBOARD = 6 << 16
LOITER = 4 << 16 | 3 << 24


def _just_engaged_px4() -> Companion:
    """OFFBOARD acknowledged a moment ago over an airborne PX4 (holding in LOITER before); no heartbeat
    since has shown it; a position target set."""
    c = on_fake_link(answer=accept_commands, sensors=None, watch_battery_pct=None)
    feed(c, AUTOPILOT.heartbeat_encode(2, 12, 128 | 29, LOITER, 4), AUTOPILOT.extended_sys_state_encode(0, 2))
    asyncio.run(asyncio.wait_for(c.ctl.set_mode(Mode.GUIDED), 5.0))
    assert c.ctl.engaged_mode == OFFBOARD
    c.ctl.set_target(0.0, 0.0, -50.0, 0.0)
    return c


def _engaged_px4() -> Companion:
    """A companion whose controller holds OFFBOARD (acknowledged, and heard since) over an airborne PX4."""
    c = _just_engaged_px4()
    feed(c, AUTOPILOT.heartbeat_encode(2, 12, 128 | 29, OFFBOARD, 4))
    c.ctl.check_interruption()  # our own mode, in the air: nothing
    return c


def test_a_disarm_with_a_mode_change_is_a_touchdown_not_a_takeover() -> None:
    """PX4 auto-disarms on landing and leaves OFFBOARD in the same heartbeat: the vehicle is down."""
    c = _engaged_px4()
    feed(c, AUTOPILOT.heartbeat_encode(2, 12, 29, LOITER, 3))
    with pytest.raises(TouchedDown, match="disarmed"):
        c.ctl.check_interruption()
    assert c.ctl.target is None


def test_landed_state_on_the_ground_is_a_touchdown() -> None:
    c = _engaged_px4()
    feed(c, AUTOPILOT.extended_sys_state_encode(0, 1))
    with pytest.raises(TouchedDown, match="landed"):
        c.ctl.check_interruption()


def test_an_armed_vehicle_in_someone_elses_mode_is_still_a_takeover() -> None:
    c = _engaged_px4()
    feed(c, AUTOPILOT.heartbeat_encode(2, 12, 128 | 29, LOITER, 4))
    with pytest.raises(OperatorTakeover):
        c.ctl.check_interruption()
    assert c.ctl.target is None  # the companion stops commanding at once


def test_a_late_heartbeat_from_before_our_mode_change_is_not_a_takeover() -> None:
    """What a CI run over a lossy relay caught: the heartbeat sent just before the autopilot took
    OFFBOARD was held back and arrived after the COMMAND_ACK. Read as a takeover, the companion stopped
    commanding and the vehicle hovered in its offboard-loss hold until the test timed out."""
    c = _just_engaged_px4()
    feed(c, AUTOPILOT.heartbeat_encode(2, 12, 128 | 29, LOITER, 4))  # late: the mode before ours
    c.ctl.check_interruption()
    feed(c, AUTOPILOT.heartbeat_encode(2, 12, 128 | 29, OFFBOARD, 4))  # the next one: ours
    c.ctl.check_interruption()
    assert c.ctl.takeover is None
    assert c.ctl.target == (0.0, 0.0, -50.0, 0.0)
    feed(c, AUTOPILOT.heartbeat_encode(2, 12, 128 | 29, LOITER, 4))  # ours was heard: now one is enough
    with pytest.raises(OperatorTakeover):
        c.ctl.check_interruption()


def test_a_takeover_right_after_our_mode_change_takes_two_heartbeats() -> None:
    c = _just_engaged_px4()
    feed(c, AUTOPILOT.heartbeat_encode(2, 12, 128 | 29, LOITER, 4))
    c.ctl.check_interruption()
    feed(c, AUTOPILOT.heartbeat_encode(2, 12, 128 | 29, LOITER, 4))
    with pytest.raises(OperatorTakeover):
        c.ctl.check_interruption()


def test_a_duplicated_heartbeat_counts_once() -> None:
    """A link that duplicates datagrams delivers one heartbeat twice (the same sequence number): it is
    one heartbeat, not the two in a row a takeover right after our mode change needs."""
    c = _just_engaged_px4()
    frame = frames(AUTOPILOT.heartbeat_encode(2, 12, 128 | 29, LOITER, 4))
    link_of(c).receive(frame + frame)
    c.ctl.check_interruption()
    assert c.ctl.takeover is None
    assert c.tm.heartbeats == 2  # the one before our mode change and this one


def test_a_mode_change_whose_acks_were_all_lost_is_seen_in_the_heartbeats() -> None:
    """What a CI run over a lossy relay caught: every COMMAND_ACK of DO_SET_MODE dropped, the companion
    aborted the recovery ("no COMMAND_ACK for command 176") though the autopilot had taken the mode.
    Two heartbeats in the requested mode, received after the request, are the autopilot's answer too."""
    c = on_fake_link(sensors=None, watch_battery_pct=None)  # the link eats every answer
    feed(c, AUTOPILOT.heartbeat_encode(2, 12, 128 | 29, LOITER, 4), AUTOPILOT.extended_sys_state_encode(0, 2))
    sent = link_of(c).sent

    async def fly() -> None:
        task = asyncio.ensure_future(c.ctl.set_mode(Mode.GUIDED))
        await asyncio.sleep(0.1)
        assert sent
        assert sent[0].command == 176  # DO_SET_MODE went out
        feed(c, AUTOPILOT.heartbeat_encode(2, 12, 128 | 29, LOITER, 4))  # late: the mode before
        await asyncio.sleep(0.6)
        feed(c, AUTOPILOT.heartbeat_encode(2, 12, 128 | 29, OFFBOARD, 4))
        await asyncio.sleep(0.6)
        assert not task.done()  # one heartbeat is not yet an answer
        feed(c, AUTOPILOT.heartbeat_encode(2, 12, 128 | 29, OFFBOARD, 4))
        async with asyncio.timeout(2.0):
            await task

    asyncio.run(fly())
    assert c.ctl.engaged_mode == OFFBOARD
