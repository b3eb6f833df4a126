"""When nothing in view will do: whether the search goes on (the battery, the alarm's window, the
budget), its legs and the exploring step (companion/recovery/search_plan.py plans them;
docs/recovery.md, "The search"), and the search's map fed with what the rounds saw."""

from __future__ import annotations

import asyncio
import contextlib
import math
import time
from collections.abc import Callable
from typing import Any

from companion.alarms import Criticality
from companion.control import TargetTimeout
from companion.perception.surface_id import Candidate
from companion.reasoning.onboard import OnboardReasoner
from companion.recovery.core import RecoveryContext, State
from companion.recovery.landing import Lander
from companion.recovery.search_plan import Leg, SearchPlanner, Verdict
from companion.site_ledger import Hazard, LedgerSite


def _run_all(jobs: list[Callable[[], object]]) -> None:
    for job in jobs:
        job()


class Searcher:
    """The search's limits, legs and map (:class:`SearchPlanner`), the exploring step, and the round's
    work deferred until the vehicle moves (:meth:`observed`).

    Args:
        ctx: what the recovery's parts share.
        plan: the search planner (its map is also the looker's, for a site's surroundings).
        lander: the site the vehicle would land on were the search to stop (:meth:`Lander.fallback_site`).
        onboard: the onboard tier, whose LandNet-S (when it judges) reads the camera into the map.
    """

    def __init__(
        self, ctx: RecoveryContext, *, plan: SearchPlanner, lander: Lander, onboard: OnboardReasoner
    ) -> None:
        self.ctx = ctx
        self.plan = plan
        self.lander = lander
        self.onboard = onboard
        self.ended: Verdict | None = None  # why the search stopped, when the battery or the window did
        self._unobserved: Any = None  # a round's frame not yet in the search's map (:meth:`observed`)
        self._later: list[Callable[[], object]] = []  # a round's other work that waits for its setpoint

    def start(self) -> None:
        """The alarm came now, with the battery's charge now."""
        self.plan.start(self._clock_s(), self.ctx.tm.state.battery_pct)

    def raise_criticality(self, criticality: Criticality) -> None:
        self.plan.raise_criticality(criticality)

    # ------------------------------------------------------------------ the round's deferred work
    def observe_later(self, frame: Any) -> None:
        """``frame`` goes into the search's map with the round's other deferred work (:meth:`observed`)."""
        self._unobserved = frame

    def later(self, job: Callable[[], object]) -> None:
        """``job`` (a worker-thread job) runs with the round's deferred work (:meth:`observed`)."""
        self._later.append(job)

    async def observed(self) -> None:
        """The last round's frame into the search's map (:meth:`_observe`), and the round's other
        deferred work (:meth:`later`: the candidates' notes when the site chosen is a roof), once, in a
        worker thread. A round defers them: choosing and flying toward this round's site needs none
        of them, a search leg needs the map, so they run while the vehicle moves, or before a search
        leg or the next round, whichever comes first."""
        frame, self._unobserved = self._unobserved, None
        later, self._later = self._later, []
        if frame is None and not later:
            return
        t0 = time.monotonic()
        await asyncio.to_thread(
            _run_all, ([lambda: self._observe(frame)] if frame is not None else []) + later
        )
        s = round(time.monotonic() - t0, 3)
        self.ctx.record.record_event("observed", {"round": self.ctx.round, "s": s, "jobs": len(later)})

    async def observed_or_said(self) -> None:
        """:meth:`observed` before a landing at the best site measured (the deferred notes are the
        ledger's sites); a failure of its own is logged and recorded, never in the landing's way."""
        ctx = self.ctx
        try:
            await self.observed()
        except Exception as exc:
            ctx.log.error("the round's deferred work failed (%r): landing on what the ledger holds", exc)
            ctx.record.record_event("defect", {"round": ctx.round, "state": "observed", "error": repr(exc)})

    def _observe(self, frame: Any) -> None:
        """The frame into the search's map: the LiDAR's sweep, and with LandNet-S as the onboard judge
        what the camera shows beyond it (water and traffic). A worker-thread job."""
        self.plan.observe(frame)
        net = self.onboard.landnet
        if net is not None and frame.image_rgb is not None:
            self.plan.observe_camera(frame, net.presence, tuple(net.classes))

    # ------------------------------------------------------------------ when nothing was accepted
    def _clock_s(self) -> float:
        return self.ctx.clock_s()

    def _verdict(self) -> tuple[Verdict, LedgerSite | None]:
        """The search's verdict now (:meth:`SearchPlanner.verdict`), with the site the vehicle would
        land on were it to stop (whose distance the landing's need counts)."""
        s = self.ctx.tm.state
        n, e, _ = s.pos_ned_m
        site = self.lander.fallback_site()
        to_site = math.dist(site.ned_m[:2], (n, e)) if site is not None else 0.0
        return self.plan.verdict(self._clock_s(), s.battery_pct, s.rangefinder_m, to_site), site

    async def search_instead(self, choice: Candidate, *, built_up: bool = True) -> bool:
        """Policy: the best candidate in view, at street level or on an elevated strip, already looks
        like water or traffic from afar (the ledger's judgement of its rank crop): while the search
        may go on, it is struck off and a search leg flies instead of a round spent flying there to
        refuse it close up. A roof always gets its close look. So does open ground in open country
        (``built_up`` False: :meth:`Looker.built_up`) on which markings alone or asphalt alone were seen
        from afar (not both, no vehicles) and that is as large and wide as open ground a confirmation
        accepts (the onboard tier's ``open_ground_area_m2`` and ``open_ground_edge_m``): no road is that
        wide, a ploughed field's furrows read as markings from afar, and a field seen through fog or
        haze as grey paving; the close look's own markings and paving vetoes still stand. True when it
        searched instead."""
        ctx = self.ctx
        if choice.site_ned_m is None or (choice.elevated and not choice.strip):
            return False  # from afar a marking on a roof may be a shadow or a painted helipad
        seen = ctx.ledger.near((choice.site_ned_m[0], choice.site_ned_m[1]))
        if seen is None or seen.hazard < Hazard.TRAFFIC or not self._verdict()[0].search:
            return False
        if seen.hazard == Hazard.TRAFFIC and not built_up and self._wide_open(choice, seen.kinds):
            ctx.say(6, f"site {choice.index} reads as traffic from afar, but wide open ground: a close look")
            return False
        what = seen.hazard.name.lower()
        ctx.reject(seen.ned_m, choice)
        ctx.record.record_event(
            "search_instead",
            {"round": ctx.round, "candidate": choice.to_json(), "hazard": what, "why": seen.why},
        )
        ctx.say(5, f"site {choice.index} looks like {what} from afar ({seen.why[:60]}): searching instead")
        await self.leg()
        return True

    def _wide_open(self, choice: Candidate, kinds: tuple[str, ...]) -> bool:
        """Surface ID measured the candidate as large and wide as open ground the onboard tier's
        confirmation accepts (not a strip: an elevated deck or a road is long and narrow), and from
        afar the onboard tier saw markings or asphalt on it, not both (painted bays on asphalt: a car
        park), and nothing raised (a car park's vehicles): a field's furrows, or a field greyed by fog."""
        p = self.onboard.confirm_params
        return (
            len({"markings", "street_asphalt"} & set(kinds)) == 1
            and "raised" not in kinds
            and not choice.strip
            and math.isfinite(choice.area_m2)
            and math.isfinite(choice.edge_distance_m)
            and choice.area_m2 >= p.open_ground_area_m2
            and choice.edge_distance_m >= p.open_ground_edge_m
        )

    def go_on(self) -> bool:
        """Policy: whether another round (or search leg and round) starts. The first look always does.
        Then the battery (what the landing needs plus a reserve) and the alarm's window may end the
        search, within the round budget too; past the budget it goes on only while nothing acceptable
        was judged close up (a roof with nothing against it)."""
        ctx = self.ctx
        if ctx.round == 0:
            return True
        if ctx.round >= ctx.budget and not self._may_extend():
            return False
        verdict, site = self._verdict()
        if verdict.search:
            return True
        self.ended = verdict
        ctx.say(4, f"search ends: {verdict.why}")
        ctx.record.record_event(
            "search_end",
            {
                "note": f"search ends: {verdict.why}",
                "round": ctx.round,
                "reason": verdict.why,
                "battery_pct": round(verdict.battery_pct, 1) if math.isfinite(verdict.battery_pct) else None,
                "need_pct": round(verdict.need_pct, 1),
                "elapsed_s": round(verdict.elapsed_s, 1),
                "legs": len(self.plan.legs),
                "best": None if site is None else site.to_json(),
            },
        )
        return False

    def _may_extend(self) -> bool:
        """Past the round budget: nothing acceptable was judged close up (a roof with nothing against
        it), so the search goes on (the battery and the window bound it, :meth:`_go_on`)."""
        if self.ctx.best is not None:
            return False
        site = self.ctx.ledger.least_bad()
        return not (site is not None and site.hazard.acceptable and site.closeup)

    async def leg(self) -> Leg:
        """Fly the planner's next leg (:meth:`SearchPlanner.next_leg`): climb first when the leg goes
        higher, or when roofs measured near either end stand within ``TRANSIT_CLEARANCE_M`` of the
        level part (:meth:`RecoveryContext.transit_d`), descend last when it goes lower, so the level
        part flies at the safer height. Said,
        recorded (``search_leg``) and shown on the ground feed. The last frame goes into the search's
        map first (:meth:`_observed`): the leg is planned on it."""
        ctx = self.ctx
        await self.observed()
        ctx.set_state(State.EXPLORE)
        s = ctx.tm.state
        n, e, d = s.pos_ned_m
        self.plan.bounds = ctx.fence_bounds()  # read now: the fence may be read after the alarm came
        leg = await asyncio.to_thread(self.plan.next_leg, (n, e, d), ctx.ledger, s.rangefinder_m)
        tn, te, td = leg.target_ned_m
        count = len(self.plan.legs)
        note = f"search leg {count}: {leg.reason}"
        ctx.say(5, note)
        ctx.record.record_event(
            "search_leg",
            {
                "note": note,
                "round": ctx.round,
                "leg": count,
                "from_ned_m": [round(v, 1) for v in (n, e, d)],
                "battery_pct": round(s.battery_pct, 1) if math.isfinite(s.battery_pct) else None,
                **leg.to_json(),
            },
        )
        # the level part at the higher of here and the leg's end, higher still where that is less than
        # TRANSIT_CLEARANCE_M over a roof measured near either end (RecoveryContext.transit_d)
        level = min(d, td, ctx.transit_d((tn, te, math.nan)))
        if level < min(d, td) - 1.0:
            ctx.say_transit_climb(d, level, "the leg")
        steps = [(n, e, level)] if level < d - 3.0 else []
        steps.append((tn, te, level))
        if td > level + 3.0:  # descend last
            steps.append((tn, te, td))
        try:
            for sn, se, sd in steps:
                with contextlib.suppress(TargetTimeout):
                    await ctx.ctl.goto(
                        sn,
                        se,
                        sd,
                        tolerance_m=2.0,
                        speed_m_s=0.5,
                        timeout_s=ctx.p.move_timeout(math.dist((sn, se, sd), ctx.tm.state.pos_ned_m)),
                    )
        finally:
            # a leg the autopilot refused or could not fly (its setpoints rejected, a failsafe taking
            # the vehicle meanwhile) is not planned again: the map it is planned on did not change
            pn, pe, _pd = ctx.tm.state.pos_ned_m
            made = math.hypot(pn - n, pe - e)
            if leg.distance_m >= 10.0 and made < 0.25 * leg.distance_m:
                self.plan.blocked.append((tn, te))
                headway = f"{made:.0f} of {leg.distance_m:.0f} m"
                ctx.say(4, f"search leg {count} made no headway ({headway}): not again")
        return leg

    async def explore(self, blind: bool = False) -> bool:
        """Nothing survived screening: climb for a wider view, else fly a search leg
        (:meth:`_search_leg`) to roofs the LiDAR saw or to ground not yet seen.

        ``blind``: the LiDAR returned nothing at all. When the rangefinder agrees that the ground is
        far (beyond ``blind_descent_agl_m``), everything below is out of the LiDAR's range: climbing
        or moving would not help, so descend to ``blind_descent_agl_m`` first. The LiDAR's silence
        says nothing stands within its range below, so the descent has nothing to hit. A silent
        LiDAR with the ground near is a failed LiDAR: no blind descent then.

        Whenever the rangefinder puts the ground more than ``explore_max_alt_m`` below (a roof left
        behind, low ground), the step is a descent to ``explore_max_alt_m`` above it: from higher up
        the LiDAR reaches nothing flat.

        Returns:
            True when the step climbed or descended (a view from here not yet looked at), False when it
            flew a search leg."""
        ctx = self.ctx
        ctx.set_state(State.EXPLORE)
        n, e, d = ctx.tm.state.pos_ned_m
        alt = ctx.tm.state.rangefinder_m
        beyond = math.isfinite(alt) and alt > ctx.p.explore_max_alt_m + 5.0
        if blind and math.isfinite(alt) and alt > ctx.p.blind_descent_agl_m + 5.0:
            drop = alt - ctx.p.blind_descent_agl_m
            target = (n, e, d + drop)
            ctx.say(6, f"LiDAR sees nothing, ground {alt:.0f} m below: descending {drop:.0f} m")
        elif beyond:
            # the rangefinder measured the column below clear all the way down: descend within reach
            drop = alt - ctx.p.explore_max_alt_m
            target = (n, e, d + drop)
            ctx.say(6, f"ground {alt:.0f} m below, beyond the LiDAR's reach: descending {drop:.0f} m")
        elif math.isfinite(alt) and alt + ctx.p.explore_climb_m <= ctx.p.search_agl_m:
            # low down a climb widens the view; at the search height the LiDAR's reach would shrink
            target = (n, e, d - ctx.p.explore_climb_m)
            ctx.say(6, f"no flat site in view: climbing {ctx.p.explore_climb_m:.0f} m")
        else:
            await self.leg()
            return False
        with contextlib.suppress(TargetTimeout):
            await ctx.ctl.goto(*target, tolerance_m=1.0, speed_m_s=0.5, timeout_s=ctx.p.move_timeout_s)
        return True  # the next round, within the budget or past it, looks from here
