"""A level move after a descent stopped low among taller buildings: it climbs first to 10 m over every roof
measured near its ends (RecoveryContext.transit_d, climb_for_transit), so that it cannot fly into a wall.
City 0 launch 19 with LandNet-E's rank cells (2026-12-03): a site refused 35 m above the street, a closer
look at another flown level at that height, into the side of a 42 m building."""

from __future__ import annotations

import asyncio
from typing import Any

import pytest

from companion.alarms import Criticality
from companion.recovery.core import TRANSIT_CLEARANCE_M, TRANSIT_CORRIDOR_M, TRANSIT_NEAR_M
from companion.recovery.landing import Lander
from companion.recovery.searching import Searcher
from companion.site_ledger import Hazard, LedgerSite
from tests.recovery_fakes import Said, context


def test_a_move_from_below_the_roofs_near_climbs_over_them_first() -> None:
    ctx = context(pos_ned_m=(0.0, 0.0, -35.0))
    ctx.ledger.add(
        LedgerSite((20.0, 0.0, -42.0), Hazard.OBSTRUCTED, "a roof with HVAC", 3, False, 4.0, "site 0")
    )
    ctx.ledger.add(LedgerSite((60.0, 30.0, -17.0), Hazard.ACCEPTED, "a clear roof", 4, True, 7.0, "site 2"))
    far = (TRANSIT_NEAR_M + 80.0, 0.0, -90.0)  # a tower far from both ends counts for nothing
    ctx.ledger.add(LedgerSite(far, Hazard.OBSTRUCTED, "a tower", 2, False, 3.0, "site 5"))
    assert ctx.transit_d((60.0, 30.0, -17.0)) == -42.0 - TRANSIT_CLEARANCE_M
    level = asyncio.run(ctx.climb_for_transit((60.0, 30.0, -17.0)))
    assert level == -52.0
    assert ctx.ctl.gotos == [(0.0, 0.0, -52.0)]  # straight up, where it was
    assert isinstance(ctx.announce, Said)
    assert any("climbing 17 m before flying on" in t for t in ctx.announce.texts)
    assert ctx.record.of("transit_climb") == [{"from_d_m": -35.0, "to_d_m": -52.0}]


def test_a_move_already_high_enough_flies_level_at_once() -> None:
    ctx = context(pos_ned_m=(0.0, 0.0, -110.0))
    ctx.ledger.add(LedgerSite((20.0, 0.0, -42.0), Hazard.OBSTRUCTED, "a roof", 1, False, 4.0, "site 0"))
    assert asyncio.run(ctx.climb_for_transit((40.0, 0.0, -22.0))) == -110.0
    assert ctx.ctl.gotos == []


def test_flying_over_the_least_bad_site_climbs_over_the_roofs_near_first() -> None:
    ctx = context(pos_ned_m=(0.0, 0.0, -35.0))
    roof = LedgerSite((20.0, 0.0, -42.0), Hazard.OBSTRUCTED, "a roof", 1, False, 4.0, "site 0")
    site = LedgerSite((50.0, 0.0, -20.0), Hazard.DOUBTED, "a roof, doubted", 2, False, 6.0, "site 3")
    ctx.ledger.add(roof)
    ctx.ledger.add(site)
    nothing: Any = None  # fly_over looks at nothing and follows nothing
    lander = Lander(ctx, looker=nothing, follower=nothing)
    assert asyncio.run(lander.fly_over(site, site.label))
    assert ctx.ctl.gotos == [(0.0, 0.0, -52.0), (50.0, 0.0, -52.0)]


def _leg_to(ctx: Any, target: tuple[float, float, float]) -> list[tuple[float, float, float]]:
    """A search leg to ``target`` flown on the fakes (the planner's choice given): the gotos."""
    from companion.reasoning.onboard import OnboardReasoner
    from companion.recovery.search_plan import Leg, SearchPlanner

    nothing: Any = None
    plan = SearchPlanner(ctx.criticality)
    searcher = Searcher(
        ctx, plan=plan, lander=Lander(ctx, looker=nothing, follower=nothing), onboard=OnboardReasoner()
    )
    leg = Leg(target, "new ground", "a test's leg", 100.0, 90.0)
    plan.next_leg = lambda *args: leg  # type: ignore[method-assign]
    asyncio.run(searcher.leg())
    return list(ctx.ctl.gotos)


def test_a_search_leg_from_below_the_roofs_near_climbs_over_them_first() -> None:
    """A leg flown level from 35 m after a refused descent, with a 42 m roof measured 20 m away: straight
    up to 10 m over it, across at that height, then down to the leg's own height."""
    ctx = context(pos_ned_m=(0.0, 0.0, -35.0))
    ctx.ledger.add(LedgerSite((20.0, 0.0, -42.0), Hazard.OBSTRUCTED, "a roof", 1, False, 4.0, "site 0"))
    assert _leg_to(ctx, (0.0, 100.0, -30.0)) == [(0.0, 0.0, -52.0), (0.0, 100.0, -52.0), (0.0, 100.0, -30.0)]
    assert ctx.record.of("transit_climb") == [{"from_d_m": -35.0, "to_d_m": -52.0}]


def test_a_search_leg_with_no_roof_near_climbs_or_descends_as_before() -> None:
    """Nothing measured near: a leg that goes higher climbs first, one that goes lower descends last."""
    ctx = context(pos_ned_m=(0.0, 0.0, -35.0))
    assert _leg_to(ctx, (0.0, 100.0, -60.0)) == [(0.0, 0.0, -60.0), (0.0, 100.0, -60.0)]
    ctx = context(pos_ned_m=(0.0, 0.0, -60.0))
    assert _leg_to(ctx, (0.0, 100.0, -35.0)) == [(0.0, 100.0, -60.0), (0.0, 100.0, -35.0)]
    assert ctx.record.of("transit_climb") == []


def test_a_move_between_two_sites_climbs_over_a_tower_the_lidar_measured_between_them() -> None:
    """City 35 in fog (2026-12-05): the fallback flew from a roof 31 m up, 41 m high, toward ground 100 m
    on, through a 46 m building the ledger never held. The search's LiDAR map had swept it: the level
    move now keeps TRANSIT_CLEARANCE_M over it, and a move beside it, off the corridor, does not climb."""
    from companion.recovery.search_plan import SearchPlanner
    from tests.recovery_fakes import frame
    from tests.test_search import sweep

    plan = SearchPlanner(Criticality.HIGH)
    seen_from = (0.0, 50.0, -75.0)  # the search's altitude, earlier
    tower = (-10.0, 10.0, 44.0, 56.0, 46.0)  # north 20 m by east 12 m, 46 m up, half way along the move
    plan.observe(
        frame(lidar_frd=sweep(seen_from, [tower, (-10.0, 10.0, -10.0, 10.0, 31.0)]), pos_ned_m=seen_from)
    )
    ctx = context(pos_ned_m=(0.0, 0.0, -41.0))
    ctx.ledger.add(LedgerSite((0.0, 0.0, -31.0), Hazard.DOUBTED, "a roof, doubted", 7, False, 4.0, "site 1"))
    ground = LedgerSite((0.0, 100.0, -0.5), Hazard.STREET, "level ground", 2, False, 6.0, "site 0")
    ctx.ledger.add(ground)
    assert ctx.transit_d(ground.ned_m) == -41.0  # the ledger alone: level at 41 m, into the tower
    ctx.path_top = plan.highest_near_path
    assert ctx.transit_d(ground.ned_m) == pytest.approx(-46.0 - TRANSIT_CLEARANCE_M)
    # a move north, 40 m and more from the tower: the ledger's roof near its start is all it clears
    assert ctx.transit_d((60.0, 0.0, -0.5)) == -41.0
    assert plan.highest_near_path((40.0, 0.0), (40.0, 100.0), TRANSIT_CORRIDOR_M) == pytest.approx(0.0)
    nothing: Any = None
    assert asyncio.run(Lander(ctx, looker=nothing, follower=nothing).fly_over(ground, ground.label))
    assert ctx.ctl.gotos == [(0.0, 0.0, pytest.approx(-56.0)), (0.0, 100.0, pytest.approx(-56.0))]
