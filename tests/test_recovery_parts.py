"""Each part of the recovery built alone on fakes at its boundary (tests/recovery_fakes.py), one
behaviour each: the context the parts share, the looker, the site follower, the lander, the searcher;
then the machine that owns them, and the package docstring's list of them against what it owns."""

from __future__ import annotations

import asyncio
import math
import re
import threading
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import companion.recovery
from companion.alarms import Criticality
from companion.flavour import Mode
from companion.reasoning.onboard import OnboardReasoner
from companion.recovery import Outcome, Recovery, RecoveryParams, State
from companion.recovery import landing as landing_module
from companion.recovery import looking as looking_module
from companion.recovery.core import RecoveryContext, Site
from companion.recovery.following import SiteFollower
from companion.recovery.landing import Lander
from companion.recovery.looking import UNMEASURED, Looker
from companion.recovery.search_plan import SearchPlanner
from companion.recovery.searching import Searcher
from companion.site_ledger import Hazard, LedgerSite
from tests.recovery_fakes import FakeController, FakeReasoner, KeptRecord, Said, candidate, context, frame


def _record(ctx: RecoveryContext) -> KeptRecord:
    assert isinstance(ctx.record, KeptRecord)
    return ctx.record


def _ctl(ctx: RecoveryContext) -> FakeController:
    assert isinstance(ctx.ctl, FakeController)
    return ctx.ctl


def _said(ctx: RecoveryContext) -> list[str]:
    assert isinstance(ctx.announce, Said)
    return ctx.announce.texts


def _looker(ctx: RecoveryContext, reasoner: FakeReasoner | None = None) -> Looker:
    return Looker(
        ctx,
        reasoner=reasoner or FakeReasoner(),
        onboard=OnboardReasoner(),
        plan=SearchPlanner(Criticality.HIGH),
    )


def _parts(
    ctx: RecoveryContext, plan: SearchPlanner | None = None
) -> tuple[Looker, SiteFollower, Lander, Searcher]:
    plan = plan or SearchPlanner(ctx.criticality)
    looker = Looker(ctx, reasoner=FakeReasoner(), onboard=OnboardReasoner(), plan=plan)
    follower = SiteFollower(ctx)
    lander = Lander(ctx, looker=looker, follower=follower)
    return looker, follower, lander, Searcher(ctx, plan=plan, lander=lander, onboard=OnboardReasoner())


# ---------------------------------------------------------------- the context
def test_context_reject_rules_out_water_by_its_size_and_records_states_with_the_round() -> None:
    """A site confirmed as water rules out candidates as far as half the side of its surface (20 m x
    20 m: 10 m), not only ``rejected_radius_m`` (4 m); each state change is recorded with the round and
    where the vehicle was."""
    ctx = context(pos_ned_m=(1.0, 2.0, -40.0))
    ctx.ledger.add(LedgerSite((10.0, 0.0, 0.0), Hazard.WATER, "water", 1, True))
    ctx.reject((10.0, 0.0, 0.0), candidate(0, (10.0, 0.0, 0.0), area_m2=400.0))
    assert ctx.rejected == [(10.0, 0.0, 10.0)]
    assert ctx.near_rejected(candidate(1, (18.0, 0.0, 0.0)))
    assert not ctx.near_rejected(candidate(2, (21.0, 0.0, 0.0)))
    ctx.round = 3
    ctx.set_state(State.RANK)
    assert ctx.state is State.RANK
    assert _record(ctx).of("state") == [{"state": "rank", "round": 3, "pos_ned_m": [1.0, 2.0, -40.0]}]


# ---------------------------------------------------------------- the looker
def test_looker_acquire_holds_through_a_missing_frame_and_records_it(monkeypatch: pytest.MonkeyPatch) -> None:
    """No frame the first time: recorded as a sensor fault, said once, asked again."""
    monkeypatch.setattr(looking_module, "SENSOR_RETRY_S", 0.01)
    got = frame()
    ctx = context(got, fails=1)
    assert asyncio.run(_looker(ctx).acquire()) is got
    assert [e["error"] for e in _record(ctx).of("sensor_fault")] == ["no frame in this test"]
    assert _said(ctx) == ["Landfall: no sensor frame (no frame in this test): holding, asking again"]
    assert ctx.state is State.ACQUIRE


def test_looker_rank_without_an_image_flies_to_the_first_measured_candidate() -> None:
    """Without a camera image the order is Surface ID's; a fallback crop is never flown to."""
    ctx = context()
    cands = [candidate(0, fallback=True), candidate(1, (5.0, 0.0, 0.0)), candidate(2, (9.0, 0.0, 0.0))]
    ranking, chosen = asyncio.run(_looker(ctx).rank(cands, frame()))
    assert (ranking.tier, chosen) == ("surface-id", 1)
    assert [(e["order"], e["chosen"]) for e in _record(ctx).of("rank")] == [([0, 1, 2], 1)]


def test_looker_confirm_with_neither_sensor_is_contested_and_ledgered_as_unknown() -> None:
    """No image and a LiDAR that missed the site: not judged (contested, asked again), never struck off;
    the ledger keeps it as unknown."""
    ctx = context()
    reasoner = FakeReasoner()
    site = (3.0, 4.0, 0.0)
    decision = asyncio.run(_looker(ctx, reasoner).confirm(UNMEASURED, frame(), site, candidate(7, site)))
    assert (decision.accept, decision.contested) == (False, True)
    assert reasoner.confirms == []  # nothing to show the reasoner
    kept = ctx.ledger.near((3.0, 4.0))
    assert kept is not None
    assert (kept.hazard, kept.label, kept.closeup) == (Hazard.UNKNOWN, "site 7", True)


# ---------------------------------------------------------------- the site follower
def test_follower_moves_the_target_with_an_estimate_reset_and_records_it() -> None:
    """The autopilot's estimate jumps 3 m north and 1 m west after the site was chosen: the descent's
    target moves with it (the site did not), even with no camera view to look in."""
    ctx = context()
    follower = SiteFollower(ctx)
    seen = frame(image=np.zeros((48, 64, 3), np.uint8), time_boot_ms=10_000)
    follower.follow_from(seen, (4.0, 3.0, 0.0))
    ctx.tm.position_resets.resets.append((11.0, (3.0, -1.0)))
    target = asyncio.run(follower.follow(frame(image=None, time_boot_ms=12_000), (4.0, 3.0, 0.0)))
    assert target == (7.0, 2.0, 0.0)
    assert follower.track is not None
    assert follower.track[1] == (7.0, 2.0, 0.0)
    assert _record(ctx).of("estimate_reset") == [{"round": 0, "t_boot_s": 11.0, "shift_m": [3.0, -1.0]}]


def test_follower_does_not_look_in_a_frame_taken_while_the_vehicle_turned_fast() -> None:
    """50 m over the site, rolling 20 degrees a second when the frame was taken: a pose 50 ms off
    could place the site 0.9 m off, so the frame is not looked in, the target stays and the record
    says why; the same frame taken while the vehicle was steady is looked in."""
    ctx = context()
    follower = SiteFollower(ctx)
    follower.follow_from(frame(image=np.zeros((48, 64, 3), np.uint8), time_boot_ms=10_000), (4.0, 3.0, 0.0))
    rate = math.radians(20.0)
    for k in range(21):  # 11.0 .. 13.0 s, rolling
        a = rate * 0.1 * k / 2
        ctx.tm.poses.add_attitude(11.0 + 0.1 * k, (math.cos(a), math.sin(a), 0.0, 0.0))
    texture = np.random.default_rng(0).integers(0, 255, (48, 64, 3), dtype=np.uint8)
    target = asyncio.run(follower.follow(frame(image=texture, time_boot_ms=12_000), (4.0, 3.0, 0.0)))
    assert target == (4.0, 3.0, 0.0)
    (event,) = _record(ctx).of("site_track")
    assert not event["found"]
    assert event["reason"] == "the vehicle was turning 20 deg/s: its pose may place the site 0.9 m off"
    for k in range(10):  # then steady from 13.1 s
        ctx.tm.poses.add_attitude(13.1 + 0.1 * k, (math.cos(2 * rate / 2), math.sin(2 * rate / 2), 0.0, 0.0))
    asyncio.run(follower.follow(frame(image=texture, time_boot_ms=13_500), (4.0, 3.0, 0.0)))
    looked = _record(ctx).of("site_track")[-1]
    assert "turning" not in looked["reason"]


def test_follower_draws_each_landing_target_with_the_attitude_at_the_time_it_stamps() -> None:
    """ArduPilot's LANDING_TARGET: where the site is from the newest position, in the body axes of the
    estimate's attitude at that position's time (not the newest attitude, heard later and turned since),
    stamped with that time on the autopilot's boot clock: the autopilot turns it with its pose then."""
    ctx = context(pos_ned_m=(1.0, 2.0, -10.0))
    tm = ctx.tm
    tm.state.t_boot_s = 20.0
    for t in (19.9, 20.0):
        tm.poses.add_position(t, (1.0, 2.0, -10.0), (0.0, 0.0, 0.0))
    level = (1.0, 0.0, 0.0, 0.0)
    yawed = (math.cos(math.pi / 4), 0.0, 0.0, math.sin(math.pi / 4))  # 90 degrees right
    tm.poses.add_attitude(19.9, level)
    tm.poses.add_attitude(20.0, level)
    tm.poses.add_attitude(20.05, yawed)
    tm.state.quat_wxyz = yawed  # the newest attitude heard
    follower = SiteFollower(ctx)
    stats: dict[str, Any] = {"seen": (19.5, np.array([4.0, 6.0, 0.0])), "sent": 0}

    async def feed() -> None:
        with pytest.raises(TimeoutError):
            await asyncio.wait_for(follower._send_landing_targets(stats, local_ned=False), 0.2)

    asyncio.run(feed())
    ((frd, stamp),) = _ctl(ctx).landing_targets  # once: the clock did not move on
    assert frd == pytest.approx((3.0, 4.0, 10.0))  # level: body axes are north, east, down
    assert stamp == 20_000_000
    assert stats["sent"] == 1


def test_follower_forgotten_lands_on_the_absolute_target_in_land_mode() -> None:
    ctx = context()
    follower = SiteFollower(ctx)
    follower.follow_from(frame(image=np.zeros((48, 64, 3), np.uint8)), (1.0, 1.0, 0.0))
    follower.forget()
    asyncio.run(follower.land_on_site(None))
    assert _ctl(ctx).lands == [Mode.LAND]
    (event,) = _record(ctx).of("precision_landing")
    assert (event["used"], event["targets_sent"]) == (False, 0)


# ---------------------------------------------------------------- the lander
def test_lander_flies_to_the_least_bad_site_when_nothing_was_accepted() -> None:
    """Water 10 m away and an unknown roof 30 m away: it lands on the roof, says why, records the
    choice among every site measured."""
    ctx = context(pos_ned_m=(0.0, 0.0, -50.0))
    ctx.ledger.add(LedgerSite((10.0, 0.0, 0.0), Hazard.WATER, "water", 1, True, label="site 0"))
    ctx.ledger.add(LedgerSite((0.0, 30.0, -12.0), Hazard.UNKNOWN, "not judged", 2, False, label="site 1"))
    lander = _parts(ctx)[2]
    outcome = asyncio.run(lander.land_at_best("round budget spent", measure_here=False))
    assert outcome == Outcome(State.LANDED, 0, (0.0, 30.0, -12.0), "round budget spent")
    assert _ctl(ctx).gotos == [(0.0, 30.0, -50.0)]
    (event,) = _record(ctx).of("fallback_site")
    assert (event["chosen"]["label"], len(event["sites"])) == ("site 1", 2)
    assert "Landfall: round budget spent: landing at site 1 (unknown: not judged)" in _said(ctx)
    assert ctx.state is State.LANDED


def test_over_water_with_only_water_measured_the_lander_flies_home_and_lands_there() -> None:
    """Water under the vehicle and water 40 m off, home (where it took off) 200 m away: it lands at
    home, not on the water; without a home, on the water here as before; with home itself measured as
    water, not there either."""
    ctx = context(pos_ned_m=(0.0, 0.0, -60.0))
    ctx.ledger.add(LedgerSite((0.0, 0.0, 0.0), Hazard.WATER, "water", 1, True, label="here"))
    ctx.ledger.add(LedgerSite((40.0, 0.0, 0.0), Hazard.WATER, "water", 1, False, label="site 0"))
    lander = _parts(ctx)[2]
    assert lander.fallback_site() is not None
    assert lander.fallback_site().label == "here"  # type: ignore[union-attr]  # no home heard: as before
    ctx.tm.state.home_ned_m = (-120.0, 160.0, 2.0)
    outcome = asyncio.run(lander.land_at_best("search ended (window)", measure_here=False))
    assert outcome == Outcome(State.LANDED, 0, (-120.0, 160.0, 2.0), "search ended (window)")
    assert _ctl(ctx).gotos == [(-120.0, 160.0, -60.0)]
    (event,) = _record(ctx).of("fallback_site")
    assert event["chosen"]["label"] == "home"
    assert "landing at home (unknown: where the vehicle took off)" in " ".join(_said(ctx))
    ctx.tm.state.pos_ned_m = (0.0, 0.0, -60.0)  # back over the water
    ctx.ledger.add(LedgerSite((-118.0, 161.0, 2.0), Hazard.WATER, "water", 2, True, label="site 3"))
    assert lander.fallback_site().label == "here"  # type: ignore[union-attr]
    ctx.ledger.sites[-1] = LedgerSite((-118.0, 161.0, 2.0), Hazard.OFF_ROOF, "lawn", 2, True, label="site 3")
    assert lander.fallback_site().label == "site 3"  # type: ignore[union-attr]  # measured land first


def _ground_sweep(site_ne_m: tuple[float, float], height_m: float, crop: bool, seed: int) -> Any:
    """A level frame ``height_m`` over ``site_ne_m`` whose LiDAR sees flat ground there, or a crop in
    rows 0.75 m apart (the ground seen between the rows); no camera image."""
    rng = np.random.default_rng(seed)
    north, east = rng.uniform(-4.0, 4.0, (2, 6000))
    up = rng.normal(0.0, 0.02, north.size)
    if crop:
        up += np.where((east % 0.75) < 0.45, 0.6, 0.12)
    frd = np.stack([north, east, height_m - up, np.full_like(up, 0.5)], axis=1).astype(np.float32)
    pos = (site_ne_m[0], site_ne_m[1], -height_m)
    return frame(lidar_frd=frd, pos_ned_m=pos, rangefinder_m=height_m)


def test_lander_looks_at_a_site_seen_from_afar_and_leaves_crops_for_the_next_least_bad() -> None:
    """Nothing accepted; two fields seen only from afar ("nothing seen against it"), the nearer first.
    Over it the LiDAR finds a crop's rows: the lander says so, records the change and flies to the
    other field, finds it level and lands there. Nothing measured under the vehicle at the start (no
    frame to measure with)."""
    ctx = context(
        frame(),  # the look around: no image, no LiDAR (nothing noted)
        frame(),  # the spot below: nothing measured
        _ground_sweep((30.0, 0.0), 40.0, crop=True, seed=1),
        _ground_sweep((0.0, 60.0), 40.0, crop=False, seed=2),
        _ground_sweep((0.0, 60.0), 20.0, crop=False, seed=4),  # the low look: level still
        pos_ned_m=(0.0, 0.0, -40.0),
    )
    far = "nothing seen against it from afar"
    ctx.ledger.add(LedgerSite((30.0, 0.0, 0.0), Hazard.OFF_ROOF, far, 1, False, label="site 0"))
    ctx.ledger.add(LedgerSite((0.0, 60.0, 0.0), Hazard.OFF_ROOF, far, 2, False, label="site 3"))
    outcome = asyncio.run(_parts(ctx)[2].land_at_best("search ended (window)"))
    assert _ctl(ctx).gotos == [(30.0, 0.0, -40.0), (0.0, 60.0, -40.0), (0.0, 60.0, -20.0)]
    assert outcome.site_ned_m is not None
    assert outcome.site_ned_m[:2] == (0.0, 60.0)
    first, second = _record(ctx).of("fallback_site")
    assert first["chosen"]["label"] == "site 0"
    assert (second["chosen"]["label"], second["instead_of"]["label"]) == ("site 3", "site 0")
    assert second["instead_of"]["hazard"] == "obstructed"
    assert second["instead_of"]["closeup"]
    assert any(t.startswith("Landfall: site 0 from overhead: obstructed (lidar_rough") for t in _said(ctx)), (
        _said(ctx)
    )
    kept = ctx.ledger.near((0.0, 60.0))
    assert kept is not None
    assert (kept.hazard, kept.closeup) == (Hazard.OFF_ROOF, True)
    assert ctx.state is State.LANDED


def _paving_over(site_ne_m: tuple[float, float], height_m: float) -> Any:
    """A level frame ``height_m`` over ``site_ne_m``: light, even paving in a 640 x 480 camera (90 deg)
    and a LiDAR that finds it level."""
    from companion.guidance.frames import PinholeCamera

    image = np.clip(np.random.default_rng(5).normal(150, 6, (480, 640, 3)), 0, 255).astype(np.uint8)
    sweep = _ground_sweep(site_ne_m, height_m, crop=False, seed=6)
    return frame(
        image=image,
        lidar_frd=sweep.lidar_frd,
        pos_ned_m=sweep.pos_ned_m,
        rangefinder_m=height_m,
        camera=PinholeCamera.from_hfov(640, 480, 90.0),
    )


def test_lander_judges_a_site_from_overhead_as_a_confirmation_would_among_buildings() -> None:
    """Two street-level sites seen only from afar with nothing against them, the nearer among roofs the
    LiDAR measured, the other in open country 300 m away. From overhead the same even paving is a
    sidewalk or a plaza among buildings (refused as street level: people come back), and level open
    ground out in the country: the lander leaves the first for the second and lands there. (Hillside,
    launch 9: the first was judged as if in open country and the vehicle landed on a sidewalk.)"""
    from tests.test_search import Frame, sweep

    plan = SearchPlanner(Criticality.HIGH)
    pos = (0.0, 0.0, -60.0)
    plan.observe(Frame(pos, sweep(pos, [(40.0, 60.0, -10.0, 10.0, 12.0)]), 60.0))  # a roof 40-60 m N
    ctx = context(
        frame(), frame(), _paving_over((30.0, 0.0), 40.0), _paving_over((0.0, 300.0), 40.0), pos_ned_m=pos
    )
    far = "nothing seen against it from afar"
    ctx.ledger.add(LedgerSite((30.0, 0.0, 0.0), Hazard.OFF_ROOF, far, 1, False, label="site 0"))
    ctx.ledger.add(LedgerSite((0.0, 300.0, 0.0), Hazard.OFF_ROOF, far, 2, False, label="site 3"))
    outcome = asyncio.run(_parts(ctx, plan)[2].land_at_best("search ended (window)"))
    assert outcome.site_ned_m is not None
    assert outcome.site_ned_m[:2] == (0.0, 300.0)
    first, second = _record(ctx).of("fallback_site")
    assert first["chosen"]["label"] == "site 0"  # the nearer, both seen from afar alike
    assert (second["chosen"]["label"], second["instead_of"]["label"]) == ("site 3", "site 0")
    assert second["instead_of"]["hazard"] == "street"
    assert "street_level" in second["instead_of"]["why"]
    kept = ctx.ledger.near((0.0, 300.0))
    assert kept is not None
    assert (kept.hazard, kept.closeup) == (Hazard.OFF_ROOF, True)


def test_lander_looks_at_a_ground_site_again_from_20_m_and_steps_aside_from_rails() -> None:
    """The least bad site is level ground measured close up from 40 m; from 20 m over it the LiDAR
    finds it rough (a double rail track read as plain ground from 35 m: town city 21, launch 10). The
    lander says so, records the change and steps aside to level ground measured 15 m away, judged
    from 20 m in turn, and lands there; not on the track."""
    ctx = context(
        frame(),  # the look around: nothing noted
        frame(),  # the spot below: nothing measured
        _ground_sweep((30.0, 0.0), 20.0, crop=True, seed=7),  # the low look: rough
        frame(),  # the look around from 20 m: nothing new
        _ground_sweep((45.0, 0.0), 20.0, crop=False, seed=8),  # the low look aside: level
        pos_ned_m=(0.0, 0.0, -40.0),
    )
    seen = "nothing seen against it"
    ctx.ledger.add(LedgerSite((30.0, 0.0, 0.0), Hazard.OFF_ROOF, seen, 1, True, label="site 0"))
    ctx.ledger.add(LedgerSite((45.0, 0.0, 0.0), Hazard.OFF_ROOF, seen, 2, True, label="site 1"))
    outcome = asyncio.run(_parts(ctx)[2].land_at_best("search ended (window)"))
    assert _ctl(ctx).gotos == [(30.0, 0.0, -40.0), (30.0, 0.0, -20.0), (45.0, 0.0, -20.0)]
    assert outcome.site_ned_m == (45.0, 0.0, 0.0)
    first, second = _record(ctx).of("fallback_site")
    assert first["chosen"]["label"] == "site 0"
    assert (second["chosen"]["label"], second["instead_of"]["label"]) == ("site 1", "site 0")
    assert second["instead_of"]["hazard"] == "obstructed"
    said = " ".join(_said(ctx))
    assert "site 0 from 20 m: obstructed (lidar_rough" in said, said
    assert "landing at site 1 instead, 15 m away" in said, said
    kept = ctx.ledger.near((30.0, 0.0))
    assert kept is not None
    assert kept.hazard is Hazard.OBSTRUCTED
    assert ctx.state is State.LANDED


def _low_looks(
    monkeypatch: pytest.MonkeyPatch, ctx: RecoveryContext, verdicts: dict[tuple[float, float], Hazard | None]
) -> Lander:
    """A lander whose look at a spot gives ``verdicts[spot]`` (None: no frame), kept in the ledger
    as a close look, and whose look around adds nothing."""
    lander = _parts(ctx)[2]

    async def measure_at(ne_m: Any, label: str, candidate: Any = None) -> LedgerSite | None:
        hazard = verdicts[ne_m]
        if hazard is None:
            return None
        return ctx.ledger.add(
            LedgerSite((*ne_m, 0.0), hazard, hazard.name.lower(), ctx.round, True, label=label)
        )

    async def look_around() -> None:
        return None

    monkeypatch.setattr(lander, "_measure_at", measure_at)
    monkeypatch.setattr(lander, "_look_around", look_around)
    return lander


def test_the_low_look_steps_aside_only_to_sites_judged_and_farther_only_from_traffic(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The low look's choices, its judgements set: a roof seen only from afar 10 m away is no step
    aside (landed on unjudged), level ground measured close up 30 m away is; from traffic (a railway
    read as markings) level ground 120 m away is flown to, from rough ground it is not (farther than
    the search counted the battery for); nothing measured from 20 m leaves the site as it was; a
    vehicle not over the site (its fly-over fell short) does not come down on a slant."""
    ground = "nothing seen against it"
    for found, far_ok in ((Hazard.TRAFFIC, True), (Hazard.OBSTRUCTED, False)):
        ctx = context(pos_ned_m=(0.0, 0.0, -40.0))
        site = ctx.ledger.add(LedgerSite((0.0, 0.0, 0.0), Hazard.OFF_ROOF, ground, 1, True, label="site 0"))
        ctx.ledger.add(LedgerSite((10.0, 0.0, 0.0), Hazard.DOUBTED, "from afar", 1, False, label="site 1"))
        ctx.ledger.add(LedgerSite((0.0, 120.0, 0.0), Hazard.STREET, "street_level", 1, True, label="site 2"))
        verdicts = {(0.0, 0.0): found, (0.0, 120.0): Hazard.STREET}
        landed = asyncio.run(_low_looks(monkeypatch, ctx, verdicts)._look_low("window", site))
        assert _ctl(ctx).gotos[0] == (0.0, 0.0, -20.0)
        assert landed.ned_m[:2] == ((0.0, 120.0) if far_ok else (0.0, 0.0)), (found, _said(ctx))
        if not far_ok:
            assert "nothing better measured: landing here" in _said(ctx)[-1]
        ctx = context(pos_ned_m=(0.0, 0.0, -40.0))
        site = ctx.ledger.add(LedgerSite((0.0, 0.0, 0.0), Hazard.OFF_ROOF, ground, 1, True, label="site 0"))
        ctx.ledger.add(LedgerSite((30.0, 0.0, 0.0), Hazard.OFF_ROOF, ground, 1, True, label="site 3"))
        verdicts = {(0.0, 0.0): found, (30.0, 0.0): Hazard.OFF_ROOF}
        landed = asyncio.run(_low_looks(monkeypatch, ctx, verdicts)._look_low("window", site))
        assert landed.ned_m[:2] == (30.0, 0.0)
        assert _ctl(ctx).gotos == [(0.0, 0.0, -20.0), (30.0, 0.0, -20.0)]

    for verdict in (None, Hazard.UNKNOWN):
        ctx = context(pos_ned_m=(0.0, 0.0, -40.0))
        site = ctx.ledger.add(LedgerSite((0.0, 0.0, 0.0), Hazard.OFF_ROOF, ground, 1, True, label="site 0"))
        landed = asyncio.run(_low_looks(monkeypatch, ctx, {(0.0, 0.0): verdict})._look_low("window", site))
        assert landed is site

    ctx = context(pos_ned_m=(0.0, -30.0, -40.0))  # the fly-over stopped 30 m short
    site = ctx.ledger.add(LedgerSite((0.0, 0.0, 0.0), Hazard.OFF_ROOF, ground, 1, True, label="site 0"))
    landed = asyncio.run(_low_looks(monkeypatch, ctx, {})._look_low("window", site))
    assert (landed, _ctl(ctx).gotos) == (site, [])


FIELDS = [(30.0 * (k + 1), 0.0) for k in range(landing_module.FALLBACK_LOOKS + 1)]  # one more than looked at


def _fields_all_crops(measured: LedgerSite | None = None, low: Any = None) -> Any:
    """A context 40 m up at the origin whose ledger holds ``FIELDS``, each seen only from afar and a
    crop from overhead (their LiDAR sweeps queued in that order, the last one's being the low look's
    too), and ``measured`` when given; ``low``: the frame of the low look after those looked at, in
    place of the last field's."""
    sweeps = [_ground_sweep(ne, 40.0, crop=True, seed=10 + k) for k, ne in enumerate(FIELDS)]
    if low is not None:
        sweeps[-1] = low
    ctx = context(frame(), frame(), *sweeps, pos_ned_m=(0.0, 0.0, -40.0))
    for k, (n, e) in enumerate(FIELDS):
        ctx.ledger.add(LedgerSite((n, e, 0.0), Hazard.OFF_ROOF, "from afar", 1, False, label=f"site {k}"))
    if measured is not None:
        ctx.ledger.add(measured)
    return ctx


def test_lander_lands_on_a_site_that_stays_the_least_bad_from_overhead_and_bounds_its_looks() -> None:
    """A field seen from afar and level from overhead is landed on after one look; with every field a
    crop the lander stops after FALLBACK_LOOKS sites and lands on the last one chosen, not looking on."""
    ctx = context(
        frame(),
        frame(),
        _ground_sweep((30.0, 0.0), 40.0, crop=False, seed=3),
        _ground_sweep((30.0, 0.0), 20.0, crop=False, seed=4),
        pos_ned_m=(0.0, 0.0, -40.0),
    )
    ctx.ledger.add(LedgerSite((30.0, 0.0, 0.0), Hazard.OFF_ROOF, "from afar", 1, False, label="site 0"))
    asyncio.run(_parts(ctx)[2].land_at_best("round budget spent"))
    assert _ctl(ctx).gotos == [(30.0, 0.0, -40.0), (30.0, 0.0, -20.0)]  # down to the low look: level
    assert len(_record(ctx).of("fallback_site")) == 1

    ctx = _fields_all_crops()
    asyncio.run(_parts(ctx)[2].land_at_best("round budget spent"))
    looked = landing_module.FALLBACK_LOOKS
    # the last one, seen only from afar, is looked at from 20 m: a crop too, nothing better near
    assert [g[:2] for g in _ctl(ctx).gotos] == [*FIELDS[: looked + 1], FIELDS[looked]]
    assert _ctl(ctx).gotos[-1][2] == -20.0
    assert len(_record(ctx).of("fallback_site")) == looked + 1
    assert any("from 20 m: obstructed" in t and "nothing better measured" in t for t in _said(ctx)), _said(
        ctx
    )


def test_lander_after_its_looks_lands_on_level_ground_measured_close_up_not_on_another_unseen_field() -> None:
    """Every field seen from afar is a crop from overhead; level ground at street level was measured
    close up earlier (refused then as among buildings, people coming back). After FALLBACK_LOOKS crops
    the fourth field, seen only from afar, is no surer: the lander says so and lands on the measured
    ground. (Farmland city 21, launch 8: the fourth field was a crop too, 36 m from safe ground.)"""
    street = LedgerSite((60.0, 40.0, 0.0), Hazard.STREET, "street_level", 2, True, 20.0, label="site 7")
    ctx = _fields_all_crops(street, low=_ground_sweep((60.0, 40.0), 20.0, crop=False, seed=20))
    outcome = asyncio.run(_parts(ctx)[2].land_at_best("search ended (window)"))
    looked = landing_module.FALLBACK_LOOKS
    assert [g[:2] for g in _ctl(ctx).gotos] == [*FIELDS[:looked], (60.0, 40.0), (60.0, 40.0)]
    assert outcome.site_ned_m == street.ned_m
    last = _record(ctx).of("fallback_site")[-1]
    assert (last["chosen"]["label"], last["instead_of"]["label"]) == ("site 7", f"site {looked}")
    said = " ".join(_said(ctx))
    assert "only seen from afar after 3 looks that proved worse: landing at site 7 instead" in said, said

    # measured close up only as traffic, or level ground 170 m farther than the fourth field (the
    # battery was counted for the field): the fourth field it is, as before
    for measured in (
        LedgerSite((60.0, 40.0, 0.0), Hazard.TRAFFIC, "street_asphalt", 2, True, label="site 7"),
        LedgerSite((-80.0, 0.0, 0.0), Hazard.STREET, "street_level", 2, True, 20.0, label="site 7"),
    ):
        ctx = _fields_all_crops(measured)
        asyncio.run(_parts(ctx)[2].land_at_best("search ended (window)"))
        assert [g[:2] for g in _ctl(ctx).gotos] == [*FIELDS[: looked + 1], FIELDS[looked]]  # + the low look


def test_lander_never_falls_back_to_a_site_beyond_the_autopilots_fence() -> None:
    """A field seen 140 m from home with a 130 m fence: PX4 refuses setpoints beyond its fence and
    leaves offboard, over and over (a farmland launch looped so until it timed out). The nearer car
    park, worse on its own, is the fallback; with no fence known the field is again."""
    from companion.fence import Fence

    ctx = context(pos_ned_m=(100.0, 0.0, -50.0))
    ctx.ledger.add(LedgerSite((140.0, 0.0, 0.0), Hazard.OFF_ROOF, "a field", 1, True, label="site 0"))
    ctx.ledger.add(LedgerSite((60.0, 0.0, 0.0), Hazard.OBSTRUCTED, "a car park", 1, True, label="site 1"))
    ctx.ctl.fence = Fence(130.0, "test")  # keeps sites within 115 m of home
    lander = _parts(ctx)[2]
    site = lander.fallback_site()
    assert site is not None
    assert site.label == "site 1"
    ctx.ctl.fence = None
    site = lander.fallback_site()
    assert site is not None
    assert site.label == "site 0"


def test_lander_fallback_is_the_accepted_site_before_any_ledger_site() -> None:
    ctx = context()
    ctx.ledger.add(LedgerSite((0.0, 5.0, 0.0), Hazard.DOUBTED, "a bit rough", 1, True))
    ctx.best = Site((8.0, 8.0, -3.0), candidate(4, (8.0, 8.0, -3.0)))
    site = _parts(ctx)[2].fallback_site()
    assert site is not None
    assert (site.ned_m, site.hazard, site.label) == ((8.0, 8.0, -3.0), Hazard.ACCEPTED, "site 4")


# ---------------------------------------------------------------- the searcher
def test_searcher_ends_the_search_at_the_battery_reserve_and_says_why() -> None:
    ctx = context()
    ctx.tm.state.battery_pct = 26.0  # the reserve is 25 %, and the landing needs more than 1 %
    searcher = _parts(ctx)[3]
    searcher.start()
    ctx.round = 1
    assert not searcher.go_on()
    assert searcher.ended is not None
    assert searcher.ended.why.startswith("battery 26 %")
    assert [e["reason"] for e in _record(ctx).of("search_end")] == [searcher.ended.why]


@pytest.mark.parametrize(
    ("hazard", "kinds", "area_m2", "edge_m", "built_up", "searched"),
    [
        (Hazard.TRAFFIC, ("markings",), 1000.0, 15.0, False, False),  # a ploughed field: a close look
        (Hazard.TRAFFIC, ("markings",), 1000.0, 15.0, True, True),  # among buildings: trusted
        (Hazard.TRAFFIC, ("markings",), 1000.0, 4.0, False, True),  # narrow enough for a road
        (Hazard.TRAFFIC, ("markings",), 300.0, 15.0, False, True),  # smaller than open ground accepted
        (Hazard.TRAFFIC, ("street_asphalt",), 1000.0, 15.0, False, False),  # a field greyed by fog
        (Hazard.TRAFFIC, ("street_asphalt",), 1000.0, 15.0, True, True),  # among buildings: a square
        (Hazard.TRAFFIC, ("street_asphalt",), 1000.0, 4.0, False, True),  # a country road
        (Hazard.TRAFFIC, ("markings", "street_asphalt"), 4000.0, 13.0, False, True),  # a car park
        (Hazard.TRAFFIC, ("markings", "raised"), 4000.0, 13.0, False, True),  # vehicles on it
        (Hazard.WATER, ("water",), 5000.0, 40.0, False, True),  # a lake is wide: water is trusted
    ],
)
def test_searcher_gives_wide_open_ground_read_as_traffic_from_afar_its_close_look_in_open_country(
    hazard: Hazard, kinds: tuple[str, ...], area_m2: float, edge_m: float, built_up: bool, searched: bool
) -> None:
    """The farmland flight that fell back onto crops had struck off a 942 m2 ploughed field, 14.6 m
    from its edge, as "traffic from afar (markings)"; a ploughed field's furrows read so from 75 m. In
    fog, farmland's fields read from afar as asphalt, and flights that struck every one of them off
    landed where they were, on crops."""
    ctx = context()
    searcher = _parts(ctx)[3]
    searcher.start()
    site = (40.0, 0.0, 0.0)
    ctx.ledger.add(LedgerSite(site, hazard, ", ".join(kinds), 1, False, edge_m, "site 0", kinds=kinds))
    choice = candidate(0, site, area_m2=area_m2, edge_distance_m=edge_m)
    assert asyncio.run(searcher.search_instead(choice, built_up=built_up)) is searched
    assert bool(_record(ctx).of("search_instead")) is searched
    assert ctx.near_rejected(choice) is searched  # struck off only when searched instead


def test_searcher_runs_the_deferred_work_once_in_one_worker_with_the_maps_frame() -> None:
    """A round's frame for the map and its deferred notes run together, once, in one worker thread."""
    ctx = context()
    searcher = _parts(ctx)[3]
    threads: list[Any] = []
    searcher.observe_later(frame(lidar_frd=np.zeros((0, 4), np.float32)))
    for _ in range(2):
        searcher.later(lambda: threads.append(threading.current_thread()))

    async def twice() -> None:
        await searcher.observed()
        await searcher.observed()  # nothing left: no second run, no second event

    asyncio.run(twice())
    assert len(threads) == 2
    assert threads[0] is threads[1]
    assert [e["jobs"] for e in _record(ctx).of("observed")] == [2]


def test_searcher_explore_low_down_climbs_for_a_wider_view() -> None:
    """30 m above the ground, well below the search height (75 m): a 15 m climb, a new vantage."""
    ctx = context(pos_ned_m=(0.0, 0.0, -30.0))
    assert asyncio.run(_parts(ctx)[3].explore()) is True
    assert _ctl(ctx).gotos == [(0.0, 0.0, -45.0)]
    assert ctx.state is State.EXPLORE


# ---------------------------------------------------------------- the machine and its parts
def _recovery(ctx: RecoveryContext) -> Recovery:
    return Recovery(
        ctx.alarm,
        control=ctx.ctl,
        telemetry=ctx.tm,
        frames=ctx.frames,
        reasoner=FakeReasoner(),
        announce=ctx.announce,
        params=ctx.p,
        record=ctx.record,
    )


def test_recovery_without_any_frame_lands_where_it_is_and_says_so() -> None:
    """The sensors give nothing for ``sensor_loss_s``: nothing measured, so it lands here, said."""
    ctx = context(params=RecoveryParams(sensor_loss_s=0.0))
    rec = _recovery(ctx)
    outcome = asyncio.run(rec.run())
    assert outcome == Outcome(State.LANDED, 1, None, "sensors lost")
    assert _ctl(ctx).lands == [Mode.LAND]
    assert "Landfall: sensors lost with nothing measured: landing here" in _said(ctx)
    assert rec.ctx.state is State.LANDED
    assert _record(ctx).of("state")[-1]["state"] == "landed"


def test_an_autopilot_failsafe_during_the_fallback_landing_is_met_as_in_a_round(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """PX4's offboard-loss failsafe while the vehicle flies to the least bad site: not an abort. The
    failsafe policy runs (here it clears) and the landing at the least bad site starts again; a
    failsafe that lands the vehicle ends the recovery with the autopilot's outcome instead."""
    from companion.control import AutopilotFailsafe

    ctx = context()
    rec = _recovery(ctx)
    tries: list[str] = []
    landed = Outcome(State.LANDED, 3, (1.0, 2.0, 0.0), "search ended")

    async def land_at_best(reason: str, *, measure_here: bool = True) -> Outcome:
        tries.append(reason)
        if len(tries) == 1:
            raise AutopilotFailsafe(196608)
        return landed

    met: list[int] = []

    async def cleared(exc: AutopilotFailsafe) -> Outcome | None:
        met.append(exc.custom_mode)
        return None

    monkeypatch.setattr(rec.lander, "land_at_best", land_at_best)
    monkeypatch.setattr(rec.handover, "on_failsafe", cleared)
    assert asyncio.run(rec._land_at_best("search ended")) is landed
    assert (tries, met) == (["search ended", "search ended"], [196608])

    handed = Outcome(State.ABORTED, 3, None, "the autopilot lands")

    async def lands(exc: AutopilotFailsafe) -> Outcome | None:
        return handed

    tries.clear()
    monkeypatch.setattr(rec.handover, "on_failsafe", lands)
    assert asyncio.run(rec._land_at_best("search ended")) is handed
    assert tries == ["search ended"]


def test_a_fallback_landing_interrupted_again_and_again_ends_in_the_autopilots_land_mode_here(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The failsafe clears each time and comes back at once (a setpoint the autopilot refuses): after
    MAX_REENGAGE + 1 tries the companion asks for the autopilot's land mode where the vehicle is
    instead of trying the same site forever."""
    from companion.control import AutopilotFailsafe
    from companion.recovery.core import MAX_REENGAGE

    ctx = context()
    rec = _recovery(ctx)
    tries: list[str] = []

    async def land_at_best(reason: str, *, measure_here: bool = True) -> Outcome:
        tries.append(reason)
        raise AutopilotFailsafe(196608)

    async def cleared(exc: AutopilotFailsafe) -> Outcome | None:
        return None

    monkeypatch.setattr(rec.lander, "land_at_best", land_at_best)
    monkeypatch.setattr(rec.handover, "on_failsafe", cleared)
    outcome = asyncio.run(rec._land_at_best("search ended"))
    assert len(tries) == MAX_REENGAGE + 1
    assert outcome == Outcome(State.LANDED, 0, None, "search ended, then landed where it was")
    assert _ctl(ctx).lands == [Mode.LAND]
    assert any(f"interrupted {MAX_REENGAGE + 1} times: landing here" in t for t in _said(ctx))


def test_an_autopilot_failsafe_during_the_defect_landing_is_ridden_out_not_given_up(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A defect of the companion's own starts the fail-safe landing; on the way PX4's offboard-loss
    failsafe (POSCTL) holds the vehicle. The landing meets it as a round would: the handover's policy
    runs (here the failsafe clears) and the landing starts again, so the vehicle comes down; a
    failsafe that lands the vehicle itself ends the recovery with its outcome, the defect named."""
    from companion.control import AutopilotFailsafe

    ctx = context()
    rec = _recovery(ctx)
    ctl = _ctl(ctx)
    held = [True]
    land_mode = ctl.land

    async def land(timeout_s: float, mode: Mode = Mode.LAND) -> None:
        if held[0]:
            raise AutopilotFailsafe(196608)  # PX4 POSCTL
        await land_mode(timeout_s, mode)

    met: list[int] = []

    async def cleared(exc: AutopilotFailsafe) -> Outcome | None:
        met.append(exc.custom_mode)
        held[0] = False
        return None

    monkeypatch.setattr(ctl, "land", land)
    monkeypatch.setattr(rec.handover, "on_failsafe", cleared)
    outcome = asyncio.run(rec._fail_safe(RuntimeError("boom")))
    assert outcome == Outcome(State.LANDED, 0, None, "defect (RuntimeError: boom): landed")
    assert (met, ctl.lands) == ([196608], [Mode.LAND])
    assert not any("the autopilot has the vehicle" in t for t in _said(ctx))

    handed = Outcome(State.LANDED, 0, None, "the autopilot's failsafe landed it (AUTO.LAND)")

    async def lands(exc: AutopilotFailsafe) -> Outcome | None:
        return handed

    held[0] = True
    rec = _recovery(ctx)
    monkeypatch.setattr(rec.handover, "on_failsafe", lands)
    outcome = asyncio.run(rec._fail_safe(RuntimeError("boom")))
    assert outcome == Outcome(
        State.LANDED,
        0,
        None,
        "defect (RuntimeError: boom), then the autopilot's failsafe landed it (AUTO.LAND)",
    )


def test_an_autopilot_failsafe_ridden_out_mid_descent_goes_on_at_the_same_site(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """PX4's offboard-loss failsafe (POSCTL) in a descent onto a confirmed lawn, ridden out: the
    recovery goes on at that site, confirmed again first, as after a lost link; not a new round that
    may choose another site (town city 21, launch 29 in rain: the lawn 14 m below was lost and a
    sidewalk landed on). A failsafe before any descent starts the next round."""
    from companion.control import AutopilotFailsafe

    ctx = context()
    rec = _recovery(ctx)
    lawn = ((5.0, 6.0, 0.0), candidate(0, (5.0, 6.0, 0.0)))
    rounds: list[int] = []
    resumed: list[tuple[float, float, float]] = []

    async def engage_and_look() -> None:
        return None

    async def a_round() -> bool:
        rounds.append(rec.ctx.round)
        if len(rounds) == 1:
            rec._descending = lawn  # confirmed, descending
            raise AutopilotFailsafe(196608)
        return True

    async def confirm_and_descend(target: tuple[float, float, float], choice: Any) -> bool:
        resumed.append(target)
        return True

    async def cleared(exc: AutopilotFailsafe) -> Outcome | None:
        return None

    monkeypatch.setattr(rec, "_engage_and_look", engage_and_look)
    monkeypatch.setattr(rec, "_round", a_round)
    monkeypatch.setattr(rec, "_confirm_and_descend", confirm_and_descend)
    monkeypatch.setattr(rec.handover, "on_failsafe", cleared)
    outcome = asyncio.run(rec.run())
    assert (rounds, resumed) == ([1], [(5.0, 6.0, 0.0)])
    assert outcome.state is State.LANDED

    rec = _recovery(context())
    rounds.clear()
    resumed.clear()

    async def before_descent() -> bool:
        rounds.append(rec.ctx.round)
        if len(rounds) == 1:
            raise AutopilotFailsafe(196608)  # nothing confirmed yet
        return True

    monkeypatch.setattr(rec, "_engage_and_look", engage_and_look)
    monkeypatch.setattr(rec, "_round", before_descent)
    monkeypatch.setattr(rec, "_confirm_and_descend", confirm_and_descend)
    monkeypatch.setattr(rec.handover, "on_failsafe", cleared)
    asyncio.run(rec.run())
    assert (rounds, resumed) == ([1, 2], [])

    # a failsafe that clears and comes back in every resumed descent: MAX_RESUMES of them, then a
    # new round (whose search verdict checks the battery and the alarm's window first)
    from companion.recovery.core import MAX_RESUMES

    rec = _recovery(context())
    rounds.clear()
    resumed.clear()

    async def again(target: tuple[float, float, float], choice: Any) -> bool:
        resumed.append(target)
        raise AutopilotFailsafe(196608)

    monkeypatch.setattr(rec, "_engage_and_look", engage_and_look)
    monkeypatch.setattr(rec, "_round", a_round)
    monkeypatch.setattr(rec, "_confirm_and_descend", again)
    monkeypatch.setattr(rec.handover, "on_failsafe", cleared)
    asyncio.run(rec.run())
    assert (rounds, len(resumed)) == ([1, 2], MAX_RESUMES)


def test_recovery_search_flies_the_height_and_lidar_range_of_its_params() -> None:
    """The search plan is built from the recovery's parameters (``recovery.search_agl_m``,
    ``perception.lidar_range_m``), not from defaults of its own."""
    rec = _recovery(context(params=RecoveryParams(search_agl_m=60.0, lidar_range_m=120.0)))
    assert (rec.searcher.plan.search_agl_m, rec.searcher.plan.lidar_range_m) == (60.0, 120.0)


def test_recovery_parts_share_its_context_and_the_package_docstring_lists_them() -> None:
    """The parts ``companion.recovery``'s docstring names (``- ``attr``: :class:`~module.Class```) are
    the parts a Recovery owns, each of that class, all on the one context; and every module it names
    exists, and every module of the package is named."""
    rec = _recovery(context())
    owned = {name: f"{type(v).__module__}.{type(v).__qualname__}" for name, v in vars(rec).items()
             if getattr(v, "ctx", None) is rec.ctx}  # fmt: skip
    doc = companion.recovery.__doc__ or ""
    listed = dict(re.findall(r"^- ``(\w+)``: :class:`~([\w.]+)`", doc, re.MULTILINE))
    assert listed == owned
    assert set(owned) == {"looker", "follower", "lander", "searcher", "watch", "handover"}
    named = set(re.findall(r":(?:mod|class):`~(companion\.recovery\.\w+)", doc))
    package = Path(companion.recovery.__file__).parent
    assert named == {f"companion.recovery.{p.stem}" for p in package.glob("*.py") if p.stem != "__init__"}
    for part in owned:  # the machine's class docstring names the same parts
        assert f"``{part}``" in (Recovery.__doc__ or "")


def test_a_moves_map_is_built_before_freed_memory_is_handed_back_off_the_event_loop(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """During a round's move: the search's map of the round's frame, then companion.memory.trim_malloc
    in a worker thread (the setpoint stream runs on the event loop: it must not wait on the walk)."""
    from companion.recovery import machine

    ctx = context()
    rec = Recovery(
        ctx.alarm, control=ctx.ctl, telemetry=ctx.tm, frames=ctx.frames, reasoner=FakeReasoner(),
        announce=ctx.announce, params=ctx.p, record=ctx.record,
    )  # fmt: skip
    done: list[tuple[str, threading.Thread]] = []

    async def observed() -> None:
        done.append(("map", threading.current_thread()))

    monkeypatch.setattr(rec.searcher, "observed", observed)
    monkeypatch.setattr(machine, "trim_malloc", lambda: done.append(("trim", threading.current_thread())))
    asyncio.run(rec._observe_and_trim())
    assert [what for what, _ in done] == ["map", "trim"]
    assert done[0][1] is threading.main_thread()
    assert done[1][1] is not threading.main_thread()
