"""The descent step's height above the site, and a touchdown before the final approach."""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import common as mavlink2

from companion.control import OperatorTakeover, TouchedDown
from companion.daemon import Companion
from companion.guidance.descent import height_above_site

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


AUTOPILOT = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
OFFBOARD = 6 << 16
LOITER = 4 << 16 | 3 << 24


def _feed(c: Companion, *msgs: object) -> None:
    c.link.datagram_received(b"".join(m.pack(AUTOPILOT) for m in msgs), ("127.0.0.1", 14580))  # type: ignore[attr-defined]


def _engaged_px4() -> Companion:
    """A companion whose controller holds OFFBOARD (acknowledged) over an airborne PX4."""
    c = Companion(mavlink_url="udp:14550", sensors=None, watch_battery_pct=None)
    _feed(
        c, AUTOPILOT.heartbeat_encode(2, 12, 128 | 29, OFFBOARD, 4), AUTOPILOT.extended_sys_state_encode(0, 2)
    )
    c.ctl._engaged_mode = OFFBOARD  # what set_mode records once the autopilot acknowledges
    c.ctl._mode_set_at = 0.0
    c.ctl.check_interruption()  # our own mode, in the air: nothing
    return c


def test_a_disarm_with_a_mode_change_is_a_touchdown_not_a_takeover() -> None:
    """PX4 auto-disarms on landing and leaves OFFBOARD in the same heartbeat: the vehicle is down."""
    c = _engaged_px4()
    _feed(c, AUTOPILOT.heartbeat_encode(2, 12, 29, LOITER, 3))
    with pytest.raises(TouchedDown, match="disarmed"):
        c.ctl.check_interruption()


def test_landed_state_on_the_ground_is_a_touchdown() -> None:
    c = _engaged_px4()
    _feed(c, AUTOPILOT.extended_sys_state_encode(0, 1))
    with pytest.raises(TouchedDown, match="landed"):
        c.ctl.check_interruption()


def test_an_armed_vehicle_in_someone_elses_mode_is_still_a_takeover() -> None:
    c = _engaged_px4()
    _feed(c, AUTOPILOT.heartbeat_encode(2, 12, 128 | 29, LOITER, 4))
    with pytest.raises(OperatorTakeover):
        c.ctl.check_interruption()
