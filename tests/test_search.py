"""The search planner (companion/recovery/search_plan.py): when searching stops and where the next
leg goes."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pytest

from companion.alarms import Criticality
from companion.recovery.search_plan import CAMERA_BAD, SearchLimits, SearchPlanner
from companion.site_ledger import Hazard, LedgerSite, SiteLedger

LEVEL = (1.0, 0.0, 0.0, 0.0)  # body FRD = NED: nose north, level


@dataclass
class Frame:
    """What the planner reads of a sensor frame."""

    pos_ned_m: tuple[float, float, float]
    lidar_frd: np.ndarray | None
    rangefinder_m: float
    quat_wxyz: tuple[float, float, float, float] = LEVEL
    image_rgb: np.ndarray | None = None
    width: int = 960
    height: int = 540
    fx: float = 480.0
    fy: float = 480.0
    cx: float = 480.0
    cy: float = 270.0
    extra: dict[str, Any] = field(default_factory=dict)


def sweep(
    pos_ned_m: tuple[float, float, float],
    surfaces: list[tuple[float, float, float, float, float]],
    reach_m: float = 60.0,
    step_m: float = 2.0,
) -> np.ndarray:
    """LiDAR returns (body FRD, level vehicle) on a grid within ``reach_m`` of the vehicle: the ground at
    0 m up, raised where ``surfaces`` (north_lo, north_hi, east_lo, east_hi, up_m) say."""
    n0, e0, d0 = pos_ned_m
    g = np.arange(-reach_m, reach_m + step_m, step_m)
    nn, ee = np.meshgrid(n0 + g, e0 + g, indexing="ij")
    nn, ee = nn.ravel(), ee.ravel()
    keep = np.hypot(nn - n0, ee - e0) <= reach_m
    nn, ee = nn[keep], ee[keep]
    up = np.zeros_like(nn)
    for n_lo, n_hi, e_lo, e_hi, h in surfaces:
        up[(nn >= n_lo) & (nn < n_hi) & (ee >= e_lo) & (ee < e_hi)] = h
    return np.column_stack([nn - n0, ee - e0, -up - d0, np.ones_like(nn)]).astype(np.float32)


def planner(criticality: Criticality = Criticality.HIGH, **limits: Any) -> SearchPlanner:
    return SearchPlanner(criticality, SearchLimits(**limits))


# ---------------------------------------------------------------------------------------- when to stop
def test_verdict_battery_at_its_reserve_ends_the_search() -> None:
    p = planner(reserve_pct=25.0)
    p.start(100.0, 30.0)
    v = p.verdict(110.0, 30.0, agl_m=70.0)
    # the default drain (0.1 %/s) over a 70 s descent and a minute's margin: 13 %, on top of 25 %
    assert not v.search
    assert v.need_pct == pytest.approx(13.0)
    assert "battery 30 %" in v.why
    assert "25 % stays in reserve" in v.why


def test_verdict_full_battery_searches_on() -> None:
    p = planner()
    p.start(100.0, 95.0)
    v = p.verdict(150.0, 92.0, agl_m=75.0)
    assert v.search
    assert "battery 92 %" in v.why


def test_verdict_measures_the_drain_in_flight() -> None:
    p = planner(reserve_pct=25.0)
    p.start(0.0, 100.0)
    # 0.2 %/s measured over 100 s: the landing from 70 m up needs 0.2 x (70 + 60) = 26 %
    assert p.verdict(100.0, 80.0, agl_m=70.0).need_pct == pytest.approx(26.0)
    assert p.verdict(100.0, 80.0, agl_m=70.0).search  # 80 > 25 + 26
    assert not p.verdict(100.0, 50.0, agl_m=70.0).search  # 50 < 25 + 26 (the drain now 0.5 %/s)


def test_verdict_the_flight_to_the_site_counts_in_the_need() -> None:
    p = planner()
    p.start(0.0, 50.0)
    near = p.verdict(10.0, 50.0, agl_m=20.0, to_site_m=0.0)
    far = p.verdict(10.0, 50.0, agl_m=20.0, to_site_m=300.0)
    assert far.need_pct == pytest.approx(near.need_pct + 0.1 * 300.0 / 3.0)


@pytest.mark.parametrize(
    ("criticality", "elapsed_s", "search"),
    [
        (Criticality.CRITICAL, 59.0, True),
        (Criticality.CRITICAL, 61.0, False),
        (Criticality.HIGH, 61.0, True),
        (Criticality.HIGH, 301.0, False),
        (Criticality.LOW, 301.0, True),
    ],
)
def test_verdict_the_alarms_window_by_criticality(
    criticality: Criticality, elapsed_s: float, search: bool
) -> None:
    p = planner(criticality)
    p.start(1000.0, math.nan)
    v = p.verdict(1000.0 + elapsed_s, math.nan, agl_m=50.0)
    assert v.search is search
    if not search:
        assert f"{criticality.name.lower()} alarm's" in v.why


def test_verdict_a_raised_criticality_shortens_the_window() -> None:
    p = planner(Criticality.HIGH)
    p.start(0.0, 100.0)
    assert p.verdict(90.0, 99.0, agl_m=50.0).search
    p.raise_criticality(Criticality.CRITICAL)
    assert not p.verdict(90.0, 99.0, agl_m=50.0).search
    p.raise_criticality(Criticality.LOW)  # never less urgent
    assert p.criticality is Criticality.CRITICAL


def test_verdict_max_legs_bounds_a_search_without_a_battery_gauge() -> None:
    p = planner(max_legs=2)
    p.start(0.0, math.nan)
    ledger = SiteLedger()
    for _ in range(2):
        assert p.verdict(1.0, math.nan, agl_m=75.0).search
        p.next_leg((0.0, 0.0, -75.0), ledger)
    v = p.verdict(2.0, math.nan, agl_m=75.0)
    assert not v.search
    assert "2 search legs" in v.why


# ---------------------------------------------------------------------------------------- where next
def test_roof_leg_flies_to_raised_level_ground_the_lidar_saw_at_its_edge() -> None:
    p = planner()
    pos = (0.0, 0.0, -75.0)
    roof = (35.0, 60.0, -10.0, 20.0, 20.0)  # 25 x 30 m, 20 m up, past the middle of the view
    p.observe(Frame(pos, sweep(pos, [roof]), 75.0))
    leg = p.next_leg(pos, SiteLedger())
    assert leg.aim == "roofs"
    assert leg.target_ned_m[0] == pytest.approx(47.5, abs=6.0)
    assert leg.target_ned_m[1] == pytest.approx(5.0, abs=6.0)
    assert "roofs seen by the LiDAR" in leg.reason
    # and it flies high enough over the roof: 20 m clear of it, and the search height over the ground
    assert -leg.target_ned_m[2] >= p.search_agl_m


def test_roof_leg_ignores_roofs_already_judged_and_tree_crowns() -> None:
    p = planner()
    pos = (0.0, 0.0, -75.0)
    roof_below = (-10.0, 10.0, -10.0, 10.0, 15.0)  # under the vehicle: judged by this look
    p.observe(Frame(pos, sweep(pos, [roof_below]), 60.0))
    # a tree crown: raised but rough (each return at another height)
    rough = sweep(pos, [])
    crown = (rough[:, 0] > 40) & (rough[:, 0] < 55) & (rough[:, 1] > 0) & (rough[:, 1] < 20)
    rough[crown, 2] -= np.random.default_rng(0).uniform(3.0, 12.0, crown.sum())
    p.observe(Frame(pos, rough, 75.0))
    assert p.next_leg(pos, SiteLedger()).aim == "new ground"


def test_roof_leg_skips_an_elevated_deck() -> None:
    p = planner()
    pos = (0.0, 0.0, -75.0)
    deck = (-60.0, 60.0, 35.0, 55.0, 9.0)  # 120 x 20 m, 9 m up: a highway, not a roof
    p.observe(Frame(pos, sweep(pos, [deck]), 75.0))
    leg = p.next_leg(pos, SiteLedger())
    assert leg.aim == "new ground"


def test_roof_leg_skips_roofs_the_ledger_holds_as_obstructed() -> None:
    p = planner()
    pos = (0.0, 0.0, -75.0)
    roof = (35.0, 60.0, -10.0, 20.0, 20.0)
    p.observe(Frame(pos, sweep(pos, [roof]), 75.0))
    ledger = SiteLedger()
    for n in (40.0, 50.0, 55.0):
        for e in (-5.0, 5.0, 15.0):
            ledger.add(LedgerSite((n, e, -20.0), Hazard.OBSTRUCTED, "hvac units", 1, True))
    assert p.next_leg(pos, ledger).aim == "new ground"


def test_no_roof_leg_stays_where_it_is_and_a_ring_of_roof_is_aimed_at_a_roof_cell() -> None:
    """Seen in a camera-stream episode: a roof's middle struck off (a binding "no") leaves a ring of roof
    cells whose mean is that very site, under a vehicle too high for its looks to judge anything (the
    LiDAR's reach ends above the ground): 40 legs of 0 m to "roofs not yet judged", until the search's
    leg limit. A leg now aims at a roof cell, and never at where the vehicle already is."""
    pos = (0.0, 0.0, -105.0)  # 105 m over the street: a look from here judges nothing (LiDAR 100 m)
    roof = (-30.0, 30.0, -30.0, 30.0, 30.0)  # 60 x 60 m, 30 m up, under the vehicle
    ledger = SiteLedger()
    ledger.add(LedgerSite((0.0, 0.0, -30.0), Hazard.TRAFFIC, "painted lane markings", 1, True))
    p = planner()
    p.observe(Frame(pos, sweep(pos, [roof], reach_m=45.0), 75.0))
    p._judged = lambda ne_m: False  # type: ignore[method-assign]  # looks from too high judge nothing
    leg = p.next_leg(pos, ledger)
    assert leg.aim == "roofs", leg
    assert math.hypot(leg.target_ned_m[0], leg.target_ned_m[1]) >= 15.0  # a cell of the ring
    assert -30.0 <= leg.target_ned_m[0] <= 30.0  # on the roof
    assert -30.0 <= leg.target_ned_m[1] <= 30.0
    # nothing struck off, the vehicle above the roof's middle, which its look could not judge: no leg of 0 m
    p = planner()
    p.observe(Frame(pos, sweep(pos, [roof], reach_m=45.0), 75.0))
    p._judged = lambda ne_m: False  # type: ignore[method-assign]
    assert p.next_leg(pos, SiteLedger()).distance_m >= p.cell_m


def test_new_ground_leg_steps_a_whole_view_and_never_back() -> None:
    p = planner()
    pos = (0.0, 0.0, -75.0)
    p.observe(Frame(pos, sweep(pos, [], reach_m=66.0), 75.0))
    view = 2 * p.footprint_m(75.0)
    assert view == pytest.approx(2 * math.sqrt(100.0**2 - 75.0**2), rel=0.01)  # the LiDAR's reach bounds it
    first = p.next_leg(pos, SiteLedger())
    assert first.aim == "new ground"
    assert first.distance_m >= view - 1.0
    there = first.target_ned_m
    p.observe(Frame(there, sweep(there, [], reach_m=66.0), 75.0))
    second = p.next_leg(there, SiteLedger())
    # the second look shares little ground with the first two: it does not go back toward the start
    assert math.dist(second.target_ned_m[:2], pos[:2]) > 1.5 * view
    assert math.dist(second.target_ned_m[:2], there[:2]) >= view - 1.0


def test_new_ground_leg_turns_from_water_and_traffic_in_the_ledger() -> None:
    p = planner()
    pos = (0.0, 0.0, -75.0)
    p.observe(Frame(pos, sweep(pos, [], reach_m=66.0), 75.0))
    ledger = SiteLedger()
    for k in range(-3, 4):  # a river running north-south through the view, measured as water
        ledger.add(LedgerSite((20.0 * k, 0.0, 0.0), Hazard.WATER, "water", 1, True))
        ledger.add(LedgerSite((20.0 * k, -25.0, 0.0), Hazard.WATER, "water", 1, False))
    leg = p.next_leg(pos, ledger)
    assert math.cos(math.radians(leg.bearing_deg)) < 0.6  # not along the river, north or south
    assert math.sin(math.radians(leg.bearing_deg)) > 0.5  # east, away from the measured water


def _water_west(tile: np.ndarray) -> np.ndarray:
    """A stand-in for LandNet-S's ``presence``: water in every cell of a blue tile, else nothing."""
    classes = ("roof", *CAMERA_BAD)
    out = np.zeros((len(classes), 16, 20), bool)  # as LandNet-S reads a 320 x 270 tile
    out[classes.index("water")] = tile[..., 2].mean() > 128
    return out


def test_new_ground_leg_turns_from_water_the_camera_shows_beyond_the_lidar() -> None:
    p = planner()
    pos = (0.0, 0.0, -75.0)
    image = np.zeros((540, 960, 3), np.uint8)
    image[:, :640, 2] = 255  # the left two thirds (west: nose north) blue
    frame = Frame(pos, sweep(pos, [], reach_m=66.0), 75.0, image_rgb=image)
    p.observe(frame)
    placed = p.observe_camera(frame, _water_west, ("roof", *CAMERA_BAD))
    assert placed == 6 * 16 * 20
    # the camera's cells land on the ground where they are: water west, none east
    assert p.camera_bad((5.0, -65.0)) == 1.0
    assert p.camera_bad((5.0, 65.0)) == 0.0
    leg = p.next_leg(pos, SiteLedger())
    assert math.sin(math.radians(leg.bearing_deg)) > 0.5, leg


def test_leg_keeps_clear_of_the_tallest_structure_near_its_path() -> None:
    p = planner()
    pos = (0.0, 0.0, -75.0)
    tower = (30.0, 40.0, -5.0, 5.0, 70.0)  # 70 m up, 30 m north
    p.observe(Frame(pos, sweep(pos, [tower], reach_m=66.0), 75.0))
    ledger = SiteLedger()
    leg = p.next_leg(pos, ledger)
    n, e, d = leg.target_ned_m
    path_near_tower = abs(e) < 40.0 or n > 0  # any path whose corridor may pass the tower
    if path_near_tower:
        assert -d >= 70.0 + 20.0
    assert -d >= 75.0


def test_observe_finds_the_ground_beyond_the_lidar_by_the_rangefinder() -> None:
    """110 m above a river the LiDAR reaches only a roof: the rangefinder says where the ground is,
    so the roof counts as raised."""
    p = planner()
    pos = (0.0, 0.0, -110.0)
    pts = sweep(pos, [(30.0, 50.0, -10.0, 10.0, 20.0)], reach_m=60.0)
    roof_only = pts[pts[:, 2] < 100.0]  # returns nearer than the ground: the roof's
    p.observe(Frame(pos, roof_only, 110.0))
    assert p.ground_up_m == pytest.approx(0.0, abs=0.5)
    assert p.roof_cells()


def test_a_street_level_site_is_among_buildings_with_a_roof_in_view_or_measured_within_200_m() -> None:
    """Past a town's last roofs the fields are open country (judged on what is seen), not a plaza among
    buildings (a last resort): roofs measured anywhere in the recovery no longer make everything
    built-up (city 5 launch 47 refused five open fields 260-500 m from the city's last roofs)."""
    from companion.reasoning.onboard import OnboardReasoner
    from companion.recovery.core import BUILT_UP_RADIUS_M
    from companion.recovery.looking import Looker
    from tests.recovery_fakes import FakeReasoner, context

    p = planner()
    pos = (0.0, 0.0, -75.0)
    p.observe(Frame(pos, sweep(pos, [(35.0, 60.0, -10.0, 20.0, 20.0)]), 75.0))  # one roof, N 35-60 m
    looker = Looker(context(), reasoner=FakeReasoner(), onboard=OnboardReasoner(), plan=p)
    assert looker.built_up((0.0, 0.0))
    assert looker.built_up((-100.0, 0.0))  # 135 m from it
    far = (35.0 - BUILT_UP_RADIUS_M - 20.0, 0.0)
    assert not looker.built_up(far)
    looker.roofs_in_view = True  # a roof in this round's view: built-up wherever the site
    assert looker.built_up(far)
