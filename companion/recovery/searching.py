"""When nothing in view will do: whether the search goes on (the battery, the alarm's window, the
budget) and its legs (companion/recovery/search_plan.py plans them; docs/recovery.md, "The search")."""

from __future__ import annotations

import asyncio
import contextlib
import math
import time
from typing import Any

from companion.control import (
    TargetTimeout,
)
from companion.perception.surface_id import (
    Candidate,
)
from companion.recovery.core import RecoveryBase, State
from companion.recovery.search_plan import Leg, Verdict
from companion.site_ledger import Hazard, LedgerSite


class Searching(RecoveryBase):
    """The search's limits and legs, the extra rounds past the budget and the exploring step."""

    # ------------------------------------------------------------------ when nothing was accepted
    def _clock_s(self) -> float:
        """The autopilot's clock (seconds since its boot), so that a faster-than-real-time simulation
        keeps the alarm's window; the companion's monotonic clock before any telemetry."""
        t = self.ctx.tm.state.t_boot_s
        return t if t > 0 else time.monotonic()

    def _verdict(self) -> tuple[Verdict, LedgerSite | None]:
        """The search's verdict now (:meth:`SearchPlanner.verdict`), with the site the vehicle would
        land on were it to stop (whose distance the landing's need counts)."""
        s = self.ctx.tm.state
        n, e, _ = s.pos_ned_m
        site = self.lander.fallback_site()
        to_site = math.dist(site.ned_m[:2], (n, e)) if site is not None else 0.0
        return self.search.verdict(self._clock_s(), s.battery_pct, s.rangefinder_m, to_site), site

    async def _search_instead(self, choice: Candidate) -> bool:
        """Policy: the best candidate in view, at street level or on an elevated strip, already looks
        like water or traffic from afar (the ledger's judgement of its rank crop): while the search
        may go on, it is struck off and a search leg flies instead of a round spent flying there to
        refuse it close up. A roof always gets its close look. True when it did so."""
        if choice.site_ned_m is None or (choice.elevated and not choice.strip):
            return False  # from afar a marking on a roof may be a shadow or a painted helipad
        seen = self.ctx.ledger.near((choice.site_ned_m[0], choice.site_ned_m[1]))
        if seen is None or seen.hazard < Hazard.TRAFFIC or not self._verdict()[0].search:
            return False
        what = seen.hazard.name.lower()
        self.ctx.reject(seen.ned_m, choice)
        self.ctx.record.record_event(
            "search_instead",
            {"round": self.ctx.round, "candidate": choice.to_json(), "hazard": what, "why": seen.why},
        )
        self.ctx.say(
            5, f"site {choice.index} looks like {what} from afar ({seen.why[:60]}): searching instead"
        )
        await self._search_leg()
        return True

    def _observe(self, frame: Any) -> None:
        """The frame into the search's map: the LiDAR's sweep, and with LandNet-S as the onboard judge
        what the camera shows beyond it (water and traffic). A worker-thread job."""
        self.search.observe(frame)
        net = self._onboard.landnet
        if net is not None and frame.image_rgb is not None:
            self.search.observe_camera(frame, net.presence, tuple(net.classes))

    def _go_on(self) -> bool:
        """Policy: whether another round (or search leg and round) starts. The first look always does.
        Then the battery (what the landing needs plus a reserve) and the alarm's window may end the
        search, within the round budget too; past the budget it goes on only while nothing acceptable
        was judged close up (a roof with nothing against it)."""
        if self.ctx.round == 0:
            return True
        if self.ctx.round >= self.ctx.budget and not self._may_extend():
            return False
        verdict, site = self._verdict()
        if verdict.search:
            return True
        self._ended = verdict
        self.ctx.say(4, f"search ends: {verdict.why}")
        self.ctx.record.record_event(
            "search_end",
            {
                "note": f"search ends: {verdict.why}",
                "round": self.ctx.round,
                "reason": verdict.why,
                "battery_pct": round(verdict.battery_pct, 1) if math.isfinite(verdict.battery_pct) else None,
                "need_pct": round(verdict.need_pct, 1),
                "elapsed_s": round(verdict.elapsed_s, 1),
                "legs": len(self.search.legs),
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

    async def _extra_round(self) -> bool:
        """A round past the budget: a closer look at the best roof seen only from afar (nothing seen
        against it: flown to and confirmed as any round would), or, with none, a round from here when
        the last round ended by climbing or descending to see (:meth:`_explore`), else a step outward
        to a view not yet judged and a round there. True when it landed."""
        await self._observed()  # the last round's frame, if it ended before its move
        self.extra += 1
        self.ctx.round += 1
        self._descending = None
        n, e, _ = self.ctx.tm.state.pos_ned_m
        site = self.ctx.ledger.least_bad((n, e))
        battery = self.ctx.tm.state.battery_pct
        charge = f", battery {battery:.0f} %" if math.isfinite(battery) else ""
        count = f"{self.extra}{charge}"
        look = (
            site is not None
            and site.hazard.acceptable
            and not site.closeup
            and not site.looked
            and site.candidate is not None
        )
        self.ctx.record.record_event(
            "extend",
            {
                "round": self.ctx.round,
                "extra": self.extra,
                "best": None if site is None else site.to_json(),
                "action": "closer look" if look else "look again" if self._new_vantage else "explore",
            },
        )
        if look:
            assert site is not None
            self.ctx.say(5, f"budget spent: a closer look at {site.label}, seen only from afar ({count})")
            site.looked = True  # once: a site the vehicle cannot reach is not tried again
            if not await self.lander.fly_over(site, site.label, then="next round"):
                return False  # not over it: no confirmation, no descent from elsewhere
            return await self._confirm_and_descend(site.ned_m, site.candidate)
        seen = (
            "nothing measured"
            if site is None
            else f"the best seen is {site.hazard.name.lower().replace('_', ' ')}"
        )
        if self._new_vantage:
            # the last round ended by climbing or descending to see (out of the LiDAR's reach, or too
            # low for a wide view): look from there before flying on, or the step was for nothing
            self.ctx.say(4, f"budget spent, {seen}: looking again from here ({count})")
            return await self._round()
        self.ctx.say(4, f"budget spent, {seen}: searching on ({count})")
        await self._search_leg()
        return await self._round()

    async def _search_leg(self) -> Leg:
        """Fly the planner's next leg (:meth:`SearchPlanner.next_leg`): climb first when the leg goes
        higher, descend last when it goes lower, so the level part flies at the safer height. Said,
        recorded (``search_leg``) and shown on the ground feed. The last frame goes into the search's
        map first (:meth:`_observed`): the leg is planned on it."""
        await self._observed()
        self.ctx.set_state(State.EXPLORE)
        s = self.ctx.tm.state
        n, e, d = s.pos_ned_m
        leg = await asyncio.to_thread(self.search.next_leg, (n, e, d), self.ctx.ledger, s.rangefinder_m)
        tn, te, td = leg.target_ned_m
        count = len(self.search.legs)
        note = f"search leg {count}: {leg.reason}"
        self.ctx.say(5, note)
        self.ctx.record.record_event(
            "search_leg",
            {
                "note": note,
                "round": self.ctx.round,
                "leg": count,
                "from_ned_m": [round(v, 1) for v in (n, e, d)],
                "battery_pct": round(s.battery_pct, 1) if math.isfinite(s.battery_pct) else None,
                **leg.to_json(),
            },
        )
        steps = [(n, e, td), (tn, te, td)] if td < d - 3.0 else [(tn, te, d), (tn, te, td)]
        for sn, se, sd in steps:
            with contextlib.suppress(TargetTimeout):
                await self.ctx.ctl.goto(
                    sn,
                    se,
                    sd,
                    tolerance_m=2.0,
                    speed_m_s=0.5,
                    timeout_s=self.ctx.p.move_timeout(math.dist((sn, se, sd), self.ctx.tm.state.pos_ned_m)),
                )
        return leg

    async def _explore(self, blind: bool = False) -> None:
        """Nothing survived screening: climb for a wider view, else fly a search leg
        (:meth:`_search_leg`) to roofs the LiDAR saw or to ground not yet seen.

        ``blind``: the LiDAR returned nothing at all. When the rangefinder agrees that the ground is
        far (beyond ``blind_descent_agl_m``), everything below is out of the LiDAR's range: climbing
        or moving would not help, so descend to ``blind_descent_agl_m`` first. The LiDAR's silence
        says nothing stands within its range below, so the descent has nothing to hit. A silent
        LiDAR with the ground near is a failed LiDAR: no blind descent then.

        Whenever the rangefinder puts the ground more than ``explore_max_alt_m`` below (a roof left
        behind, low ground), the step is a descent to ``explore_max_alt_m`` above it: from higher up
        the LiDAR reaches nothing flat."""
        self.ctx.set_state(State.EXPLORE)
        n, e, d = self.ctx.tm.state.pos_ned_m
        alt = self.ctx.tm.state.rangefinder_m
        beyond = math.isfinite(alt) and alt > self.ctx.p.explore_max_alt_m + 5.0
        if blind and math.isfinite(alt) and alt > self.ctx.p.blind_descent_agl_m + 5.0:
            drop = alt - self.ctx.p.blind_descent_agl_m
            target = (n, e, d + drop)
            self.ctx.say(6, f"LiDAR sees nothing, ground {alt:.0f} m below: descending {drop:.0f} m")
        elif beyond:
            # the rangefinder measured the column below clear all the way down: descend within reach
            drop = alt - self.ctx.p.explore_max_alt_m
            target = (n, e, d + drop)
            self.ctx.say(6, f"ground {alt:.0f} m below, beyond the LiDAR's reach: descending {drop:.0f} m")
        elif math.isfinite(alt) and alt + self.ctx.p.explore_climb_m <= self.ctx.p.search_agl_m:
            # low down a climb widens the view; at the search height the LiDAR's reach would shrink
            target = (n, e, d - self.ctx.p.explore_climb_m)
            self.ctx.say(6, f"no flat site in view: climbing {self.ctx.p.explore_climb_m:.0f} m")
        else:
            await self._search_leg()
            return
        with contextlib.suppress(TargetTimeout):
            await self.ctx.ctl.goto(
                *target, tolerance_m=1.0, speed_m_s=0.5, timeout_s=self.ctx.p.move_timeout_s
            )
        self._new_vantage = True  # the next round, within the budget or past it, looks from here
