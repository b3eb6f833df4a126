"""The autopilot's circular fence (companion/fence.py): read from its parameters, kept by the search's
legs and by the sites a round considers."""

from __future__ import annotations

import asyncio
import math

import pytest
from pymavlink.dialects.v20 import common as mavlink2

from companion.fence import KEEP_IN_M, Fence, read_fence
from companion.recovery.core import RecoveryContext
from companion.site_ledger import SiteLedger
from companion.telemetry import MAV_AUTOPILOT_ARDUPILOTMEGA, MAV_AUTOPILOT_PX4, TelemetryCache
from tests.recovery_fakes import candidate, context, frame
from tests.test_precision_landing import _Params
from tests.test_search import Frame, planner, sweep


def _read(autopilot: int = MAV_AUTOPILOT_ARDUPILOTMEGA, **values: float) -> Fence:
    return asyncio.run(read_fence(_Params(**values), autopilot))


def test_arducopters_circle_is_read_with_its_margin_and_type() -> None:
    fence = _read(FENCE_ENABLE=1, FENCE_TYPE=7, FENCE_RADIUS=300, FENCE_MARGIN=2)
    assert (fence.radius_m, fence.keep_in_m()) == (300, 300 - KEEP_IN_M)
    assert fence.why == "FENCE_RADIUS 300 m: searches and sites keep within 285 m of home"
    wide = _read(FENCE_ENABLE=1, FENCE_TYPE=3, FENCE_RADIUS=300, FENCE_MARGIN=40)  # its own margin is wider
    assert wide.keep_in_m() == 260
    assert _read(FENCE_ENABLE=1, FENCE_RADIUS=150).keep_in_m() == 135  # no FENCE_TYPE: the default, 7
    # disabled, no circle in the type, no radius: not bounded
    assert _read(FENCE_ENABLE=0, FENCE_TYPE=7, FENCE_RADIUS=300).radius_m is None
    polygon = _read(FENCE_ENABLE=1, FENCE_TYPE=5, FENCE_RADIUS=300)
    assert (polygon.radius_m, polygon.why) == (None, "FENCE_TYPE 5 has no circle: the search is not bounded")
    assert _read().radius_m is None  # an autopilot without a fence at all


def test_px4s_horizontal_limit_is_read_and_zero_is_none() -> None:
    fence = _read(MAV_AUTOPILOT_PX4, GF_MAX_HOR_DIST=500)
    assert (fence.radius_m, fence.keep_in_m()) == (500, 485)
    assert _read(MAV_AUTOPILOT_PX4, GF_MAX_HOR_DIST=0).radius_m is None
    assert _read(0, FENCE_ENABLE=1, FENCE_RADIUS=300).radius_m is None  # another autopilot: unknown


def test_legs_end_inside_the_fence_and_say_so() -> None:
    """140 m east of home in a 150 m circle, a roof seen just beyond the circle to the north: without
    the fence the leg flies to it; with it, no leg ends outside the circle (a heading that would is
    shortened, or left, and says so); hemmed in every way, the leg goes back toward home."""
    pos = (0.0, 140.0, -75.0)
    roof = (40.0, 60.0, 150.0, 165.0, 20.0)  # its middle about 160 m from home
    seen = Frame(pos, sweep(pos, [roof], reach_m=66.0), 75.0)
    unbounded = planner()
    unbounded.observe(seen)
    free = unbounded.next_leg(pos, SiteLedger())
    assert free.aim == "roofs"
    assert math.dist(free.target_ned_m[:2], (0.0, 0.0)) > 150.0
    p = planner()
    p.bounds = ((0.0, 0.0), 150.0)
    p.observe(seen)
    leg = p.next_leg(pos, SiteLedger())
    assert leg.aim == "new ground"
    assert math.dist(leg.target_ned_m[:2], (0.0, 0.0)) <= 150.0 + 1e-6
    # from home in a 100 m circle every heading's view-wide step (132 m) is cut short at its edge
    short = planner()
    short.bounds = ((0.0, 0.0), 100.0)
    home = (0.0, 0.0, -75.0)
    short.observe(Frame(home, sweep(home, [], reach_m=66.0), 75.0))
    cut = short.next_leg(home, SiteLedger())
    assert cut.distance_m == pytest.approx(100.0)
    assert cut.reason.endswith("as far as the autopilot's fence allows)"), cut.reason
    tight = planner()
    tight.bounds = ((0.0, 0.0), 35.0)
    here = (0.0, 30.0, -75.0)
    tight.observe(Frame(here, sweep(here, [], reach_m=66.0), 75.0))
    back = tight.next_leg(here, SiteLedger())
    assert back.reason.endswith("back inside the autopilot's fence")
    assert math.dist(back.target_ned_m[:2], (0.0, 0.0)) < 1e-6


def test_roofs_beyond_the_fence_are_no_legs_aim() -> None:
    p = planner()
    pos = (0.0, 0.0, -75.0)
    roof = (35.0, 60.0, -10.0, 20.0, 20.0)  # about 48 m north
    p.observe(Frame(pos, sweep(pos, [roof]), 75.0))
    p.bounds = ((0.0, 0.0), 30.0)
    assert p.next_leg(pos, SiteLedger()).aim == "new ground"
    p.bounds = ((0.0, 0.0), 100.0)
    assert p.next_leg(pos, SiteLedger()).aim == "roofs"


def _ctx(fence: Fence | None, home: tuple[float, float, float] | None = None) -> RecoveryContext:
    ctx = context()
    ctx.ctl.fence = fence
    ctx.tm.state.home_ned_m = home
    return ctx


def test_a_site_beyond_the_fence_is_outside_and_home_comes_from_home_position() -> None:
    far = candidate(0, site_ned_m=(0.0, 120.0, -5.0))
    near = candidate(1, site_ned_m=(0.0, 60.0, -5.0))
    fence = Fence(100.0, "test")
    ctx = _ctx(fence)
    assert ctx.outside_fence(far)
    assert not ctx.outside_fence(near)
    moved = _ctx(fence, home=(0.0, 50.0, 0.0))  # HOME_POSITION 50 m east of the local origin
    assert not moved.outside_fence(far)
    assert not _ctx(None).outside_fence(far)
    tm = TelemetryCache(1)
    assert tm.state.home_ned_m is None
    mav = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
    home = mav.home_position_encode(0, 0, 0, 3.0, -4.0, 0.5, [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0)
    tm.on_message(mav.decode(bytearray(home.pack(mav))))
    assert tm.state.home_ned_m == (3.0, -4.0, 0.5)


def test_a_fence_read_after_the_alarm_bounds_the_next_leg() -> None:
    """The daemon reads the fence a few seconds after the autopilot is first heard, and an alarm may
    come first: the searcher takes the fence as it is at each leg (an emulated PX4 refused every
    setpoint of a leg planned without it, 40 legs running, and the flight ended on a road)."""
    from companion.recovery.searching import Searcher
    from tests.test_recovery_parts import _parts

    ctx = context(pos_ned_m=(0.0, 90.0, -75.0))
    searcher: Searcher = _parts(ctx)[3]
    assert ctx.fence_bounds() is None
    ctx.ctl.fence = Fence(115.0, "read late")  # legs end within 100 m of home
    ctx.tm.state.home_ned_m = (0.0, 0.0, 0.0)
    leg = asyncio.run(searcher.leg())
    assert searcher.plan.bounds == ((0.0, 0.0), 100.0)
    assert math.dist(leg.target_ned_m[:2], (0.0, 0.0)) <= 100.0 + 1e-6
    assert math.dist(ctx.ctl.gotos[-1][:2], (0.0, 0.0)) <= 100.0 + 1e-6


def test_a_leg_that_makes_no_headway_is_not_planned_again() -> None:
    """The autopilot does not fly a leg (its setpoints refused): the searcher says so and the next leg
    goes another way, where before it repeated the same leg until the search ran out."""
    from companion.recovery.searching import Searcher
    from tests.test_recovery_parts import _parts

    ctx = context(pos_ned_m=(0.0, 0.0, -75.0))
    searcher: Searcher = _parts(ctx)[3]

    async def refuse(n: float, e: float, d: float, **_kw: float) -> None:
        ctx.ctl.gotos.append((n, e, d))  # asked, never flown: the vehicle stays where it is

    ctx.ctl.goto = refuse  # type: ignore[method-assign]
    first = asyncio.run(searcher.leg())
    second = asyncio.run(searcher.leg())
    assert math.dist(first.target_ned_m[:2], second.target_ned_m[:2]) > 0.5 * first.distance_m
    said = " ".join(ctx.announce.texts)  # type: ignore[attr-defined]
    assert "search leg 1 made no headway (0 of 132 m): not again" in said
    assert searcher.plan.blocked[0] == first.target_ned_m[:2]  # and the second, refused as well


def test_a_field_cut_by_the_fence_is_kept_with_its_site_moved_inside_on_the_same_surface() -> None:
    """A pasture whose widest point lies 20 m beyond the circle the fence leaves the recovery, 40 m
    from its edge: its site moves 22 m toward home (2 m inside), its pixel with it (IPM places that
    pixel back on the moved site) and its edge distance less the move; one only 25 m from its edge is
    left out (moved in, less than the open-ground 10 m would stay), as is one out of the camera's
    view. (Farmland launch 15 flew beside a 17,700 m2 pasture for 300 s, its site beyond the fence.)"""
    from companion.guidance.frames import PinholeCamera
    from tests.test_recovery_parts import _parts

    ctx = context(pos_ned_m=(0.0, 90.0, -75.0))
    ctx.ctl.fence = Fence(115.0, "test")  # sites keep within 100 m of home
    ctx.tm.state.home_ned_m = (0.0, 0.0, 0.0)
    looker = _parts(ctx)[0]
    seen = frame(
        pos_ned_m=(0.0, 90.0, -75.0), rangefinder_m=75.0, camera=PinholeCamera.from_hfov(640, 480, 90.0)
    )
    camera = PinholeCamera(seen.width, seen.height, seen.fx, seen.fy, seen.cx, seen.cy)
    field = candidate(0, site_ned_m=(0.0, 120.0, 0.0), edge_distance_m=40.0, area_m2=6000.0)
    assert ctx.outside_fence(field)
    pulled = looker.pull_inside_fence(field, seen, camera)
    assert pulled is not None
    assert pulled.site_ned_m is not None
    assert pulled.site_ned_m == pytest.approx((0.0, 98.0, 0.0))
    assert not ctx.outside_fence(pulled)
    assert pulled.edge_distance_m == pytest.approx(18.0)
    placed = looker.ipm(pulled, seen, camera)  # no LiDAR: flat ground at the rangefinder's 75 m
    assert placed is not None
    assert placed[:2] == pytest.approx((0.0, 98.0), abs=0.05)
    narrow = candidate(1, site_ned_m=(0.0, 120.0, 0.0), edge_distance_m=25.0, area_m2=3000.0)
    assert looker.pull_inside_fence(narrow, seen, camera) is None
    unseen = candidate(2, site_ned_m=(200.0, 120.0, 0.0), edge_distance_m=400.0, area_m2=9e5)
    assert looker.pull_inside_fence(unseen, seen, camera) is None
