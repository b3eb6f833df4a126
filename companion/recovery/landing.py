"""The landing: on the site confirmed for descent, or, when nothing was accepted, at the site ledger's
least bad site (companion/site_ledger.py) after a last look at what is in view and at the spot below;
the fly-over and the final approach in the autopilot's land mode."""

from __future__ import annotations

import asyncio
import math
from collections.abc import Awaitable, Callable

from companion.control import TargetTimeout
from companion.guidance.frames import PinholeCamera
from companion.perception.site_check import check_site
from companion.perception.surface_id import ROOF_HEIGHT_M, Candidate
from companion.recovery.core import FrameUnavailable, Outcome, RecoveryContext, State
from companion.recovery.following import SiteFollower
from companion.recovery.looking import Looker, height_above_surroundings
from companion.site_ledger import Hazard, LedgerSite, hazard_of

FALLBACK_LOOKS = 3  # sites seen only from afar looked at from overhead before a fallback landing
# ... after which the least bad site measured close up is landed on instead of another seen only from
# afar, when it is no worse than this (level ground at street level, refused where people come back)
MEASURED_AFTER_LOOKS = Hazard.STREET
MEASURED_EXTRA_M = 50.0  # ... and no farther from the vehicle than the site it replaces plus this
# a street-level site is judged once more from this high above it before the final approach: from
# 35 m a double rail track read as plain ground (LiDAR 8 cm rough, its rails too thin for the image
# judgement), from 20 m as rough ground and road markings (town city 21, launch 10)
LOW_LOOK_M = 20.0
LOW_LOOK_KINDS = (Hazard.OFF_ROOF, Hazard.STREET)  # ground sites, where rails and roads hide from afar


class Lander:
    """The landing and the least bad site (docs/recovery.md, "When it ends without an accepted site").

    Args:
        ctx: what the recovery's parts share.
        looker: the last look at what is in view and the judgement of the spot below.
        follower: the site followed down during the autopilot's land mode (precision landing).
    """

    def __init__(self, ctx: RecoveryContext, *, looker: Looker, follower: SiteFollower) -> None:
        self.ctx = ctx
        self.looker = looker
        self.follower = follower
        # the fallback's final approach watched for people (PeopleWatch.fallback_landing, given the site
        # as NED with its surface's height); None: the autopilot's land mode unwatched
        self.watched_landing: Callable[[tuple[float, float, float]], Awaitable[None]] | None = None

    async def land(self) -> bool:
        """The final approach where the vehicle is (over the site); True once down."""
        ctx = self.ctx
        ctx.set_state(State.LAND)
        ctx.fault.check("land", ctx.round)
        await self.final_land()
        return True

    async def final_land(self) -> None:
        """The autopilot's land mode, with its precision landing on the followed site when it can."""
        ctx = self.ctx
        ctx.set_state(State.LAND)
        ctx.say(5, "final approach: autopilot land mode")
        await self.follower.land_on_site(ctx.ctl.precision)
        ctx.set_state(State.LANDED)
        ctx.say(5, "landed")

    async def land_at_best(self, reason: str, *, measure_here: bool = True) -> Outcome:
        """Land at the accepted site, else at the least bad one measured (:mod:`companion.site_ledger`),
        judging the spot under the vehicle too when sensors allow (``measure_here``); "here" only when
        nothing at all was measured, and said so. A site only seen from afar is judged again from
        overhead before the landing (:meth:`_look_over`): one that proves worse than another is left for
        the next least bad, up to ``FALLBACK_LOOKS`` sites. The round's deferred candidate notes are
        the ledger's sites: the caller has them taken first (``Searcher.observed_or_said``)."""
        ctx = self.ctx
        self.follower.forget()  # the site it lands on may not be the one last followed
        if measure_here and ctx.best is None:
            await self._look_around()
            await self._measure_at(None, "here")
        site = self.fallback_site()
        if site is None and not ctx.ledger.sites:
            ctx.say(4, f"{reason} with nothing measured: landing here")
        elif site is None:
            ctx.say(4, f"{reason}, only water or traffic measured elsewhere: landing here")
        else:
            where = "here" if site.label == "here" else f"at {ctx.ledger.name(site)}"
            ctx.say(4, f"{reason}: landing {where} ({site.hazard.phrase}: {site.why})")
            self._record_choice(reason, site)
            if measure_here:
                site = await self._look_low(reason, await self._look_over(reason, site))
            else:
                await self.fly_over(site, "the chosen site")
        await self._final_approach(site)
        return Outcome(State.LANDED, ctx.round, site.ned_m if site is not None else None, reason)

    async def _final_approach(self, site: LedgerSite | None) -> None:
        """The fallback's landing where the vehicle is, over ``site``: watched for people
        (``watched_landing``) when there is a watch and the site's surface height is known (the site's,
        or the ground under the vehicle by the rangefinder), else the autopilot's land mode alone. The
        site was never confirmed free of people, and a person may walk onto it as the vehicle comes down
        (farmland in fog: a lawn landed on after the search ended, a person 3 m away at touchdown)."""
        ctx = self.ctx
        target: tuple[float, float, float] | None = None
        if site is not None:
            target = site.ned_m
        else:
            n, e, d = ctx.tm.state.pos_ned_m
            if math.isfinite(ctx.tm.state.rangefinder_m):
                target = (n, e, d + ctx.tm.state.rangefinder_m)
        if self.watched_landing is None or target is None or ctx.p.people_margin_m <= 0:
            await self.land()
            return
        await self.watched_landing(target)

    def _record_choice(self, reason: str, site: LedgerSite, looked_at: LedgerSite | None = None) -> None:
        ctx = self.ctx
        event: dict[str, object] = {
            "round": ctx.round,
            "reason": reason,
            "chosen": site.to_json(),
            "sites": [s.to_json() for s in ctx.ledger.sites],
        }
        if looked_at is not None:
            event["instead_of"] = looked_at.to_json()
        ctx.record.record_event("fallback_site", event)

    async def _look_over(self, reason: str, site: LedgerSite) -> LedgerSite:
        """Fly over ``site`` and, when it was only seen from afar (a rank crop, or home), judge it from
        overhead (the LiDAR's check and the image judgement, as the spot below); when that look makes
        another site the least bad (a field seen as grass from afar found to be standing crops), say
        so and go there instead, until a site is looked at and stays the least bad, one was judged
        close up before, or ``FALLBACK_LOOKS`` were spent. Then a site seen only from afar is no surer
        than the ones that proved worse: the least bad site measured close up is landed on instead
        when it is no worse than ``MEASURED_AFTER_LOOKS`` (farmland: three fields that were crops from
        overhead, a fourth one landed on unseen, also crops, and level ground measured at street level
        passed over). The site landed on."""
        ctx = self.ctx
        for _ in range(FALLBACK_LOOKS):
            if not await self.fly_over(site, "the chosen site") or site.closeup:
                return site
            name = ctx.ledger.name(site)  # before the look replaces it in the ledger
            seen = await self._measure_at((site.ned_m[0], site.ned_m[1]), site.label, site.candidate)
            if seen is None:
                return site  # no frame: land on what was chosen
            now = self.fallback_site()
            if now is None or math.dist(now.ned_m[:2], site.ned_m[:2]) < ctx.ledger.same_site_m:
                return site
            ctx.say(
                4,
                f"{name} from overhead: {seen.hazard.phrase} ({seen.why}); "
                f"landing at {ctx.ledger.name(now)} instead",
            )
            self._record_choice(reason, now, seen)
            site = now
        measured = self._measured_instead(site)
        if measured is not None:
            ctx.say(
                4,
                f"{ctx.ledger.name(site)} only seen from afar after {FALLBACK_LOOKS} looks that proved "
                f"worse: landing at {ctx.ledger.name(measured)} instead, measured close up "
                f"({measured.hazard.name.lower()}: {measured.why})",
            )
            self._record_choice(reason, measured, site)
            site = measured
        await self.fly_over(site, "the chosen site")
        return site

    async def _look_low(self, reason: str, site: LedgerSite) -> LedgerSite:
        """Over a ground site (``LOW_LOOK_KINDS``) more than ``LOW_LOOK_M`` + 5 m below the vehicle:
        come down to ``LOW_LOOK_M`` above it and judge it once more, as :meth:`_look_over` does from
        overhead. When it proves worse there (a rail track that read as plain ground from 35 m), step
        aside (:meth:`_aside`): what is in view from that height goes into the ledger
        (:meth:`_look_around`), and the least bad site better than what was found, judged close up or
        at ground level, is flown to and judged from that height in turn: within ``MEASURED_EXTRA_M``
        (the search's end counted the battery for the site chosen, and a margin), farther only away
        from traffic or water; up to ``FALLBACK_LOOKS`` steps aside, then the last site is landed on.
        Water found with nothing better measured: home, as :meth:`fallback_site` would.
        Nothing measured from that height (no frame, no LiDAR return, no image): the site stays.
        Not over the site (its fly-over fell short): no descent on a slant, the site stays. Said and
        recorded as the looks from overhead are; the final approach starts from there. The site
        landed on."""
        ctx = self.ctx
        for k in range(FALLBACK_LOOKS + 1):
            if site.hazard not in LOW_LOOK_KINDS or site.label == "home":
                return site
            n, e, site_d = site.ned_m
            pn, pe, pd = ctx.tm.state.pos_ned_m
            if math.dist((pn, pe), (n, e)) > ctx.ledger.same_site_m:
                return site
            high = site_d - pd > LOW_LOOK_M + 5.0
            if k == 0 and not high:
                return site  # the vehicle is low already: the look it had from here was close
            if high:
                try:
                    await ctx.ctl.goto(
                        n,
                        e,
                        site_d - LOW_LOOK_M,
                        tolerance_m=ctx.p.arrival_tolerance_m,
                        speed_m_s=ctx.p.arrival_speed_m_s,
                        timeout_s=ctx.p.move_timeout(site_d - LOW_LOOK_M - pd),
                    )
                except TargetTimeout as exc:
                    ctx.say(4, f"the low look's height not reached ({exc.error_m:.1f} m off): landing here")
                    return site
            name = ctx.ledger.name(site)
            seen = await self._measure_at((n, e), site.label, site.candidate)
            if seen is None or seen.hazard is Hazard.UNKNOWN or seen.hazard <= Hazard.STREET:
                return site  # nothing measured (land on what was chosen), or still ground to land on
            found = f"{name} from {LOW_LOOK_M:.0f} m: {seen.hazard.phrase} ({seen.why})"
            if k == FALLBACK_LOOKS:
                ctx.say(4, f"{found}; {FALLBACK_LOOKS} steps aside spent: landing here")
                return seen
            await self._look_around()
            here = (n, e)
            aside = self._aside(here, seen.hazard, MEASURED_EXTRA_M)
            if aside is None and seen.hazard >= Hazard.TRAFFIC:  # a road, a railway, water: farther
                aside = self._aside(here, seen.hazard)
            if aside is None and seen.hazard >= Hazard.WATER:
                aside = self.home_site(here)
            if aside is None or math.dist(aside.ned_m[:2], here) < ctx.ledger.same_site_m:
                ctx.say(4, f"{found}; nothing better measured: landing here")
                return seen
            away = math.dist(aside.ned_m[:2], here)
            ctx.say(4, f"{found}; landing at {ctx.ledger.name(aside)} instead, {away:.0f} m away")
            self._record_choice(reason, aside, seen)
            site = aside
            if not await self.fly_over(site, "the chosen site"):
                return site
        return site

    def _aside(
        self, here: tuple[float, float], worse: Hazard, reach_m: float | None = None
    ) -> LedgerSite | None:
        """The least bad site better than ``worse`` that was judged close up or lies at ground level
        (where the low look judges it next), within the fence and ``reach_m`` of ``here`` (None: any
        distance), or None."""
        ctx = self.ctx
        return ctx.ledger.least_bad(
            here,
            allowed=lambda s: (
                s.hazard < worse
                and (s.closeup or s.hazard in LOW_LOOK_KINDS)
                and (reach_m is None or math.dist(s.ned_m[:2], here) <= reach_m)
                and not ctx.beyond_fence(s.ned_m)
            ),
        )

    def _measured_instead(self, site: LedgerSite) -> LedgerSite | None:
        """Once the looks are spent: the least bad site measured close up, within the fence, no worse
        than ``MEASURED_AFTER_LOOKS`` and at most ``MEASURED_EXTRA_M`` farther than ``site`` (the
        search's end counted the battery for that far), when ``site`` was only seen from afar; else
        None."""
        ctx = self.ctx
        if site.closeup or site.label == "home":
            return None
        n, e, _ = ctx.tm.state.pos_ned_m
        reach_m = math.dist(site.ned_m[:2], (n, e)) + MEASURED_EXTRA_M
        return ctx.ledger.least_bad(
            (n, e),
            allowed=lambda s: (
                s.closeup
                and s.hazard <= MEASURED_AFTER_LOOKS
                and math.dist(s.ned_m[:2], (n, e)) <= reach_m
                and not ctx.beyond_fence(s.ned_m)
            ),
        )

    def fallback_site(self) -> LedgerSite | None:
        """The accepted site, else the ledger's least bad, else None."""
        ctx = self.ctx
        if ctx.best is not None:
            label = f"site {ctx.best.candidate.index}"
            return LedgerSite(
                ctx.best.ned_m,
                Hazard.ACCEPTED,
                "confirmed for descent",
                ctx.round,
                True,
                label=label,
            )
        n, e, _ = ctx.tm.state.pos_ned_m
        # a site beyond the autopilot's fence is none: its setpoints are refused (PX4 then leaves offboard)
        site = ctx.ledger.least_bad((n, e), allowed=lambda s: not ctx.beyond_fence(s.ned_m))
        if site is not None and site.hazard >= Hazard.WATER:
            home = self.home_site((n, e))
            if home is not None:
                return home  # where it took off beats ditching
        if site is not None and site.hazard > Hazard.UNKNOWN and not ctx.ledger.near((n, e)):
            return None  # only water or traffic measured, and not here: unknown beats known bad
        return site

    def home_site(self, here_ne_m: tuple[float, float]) -> LedgerSite | None:
        """Home (the autopilot's HOME_POSITION, where the vehicle took off) as a site of last resort:
        it was land enough to take off from, so it beats water as the least bad measured (a traffic
        lane measured stays before it: a street is near and the battery may be low; with nothing
        measured at all the vehicle lands where it is). None when home is not known, is here already
        (within the ledger's ``same_site_m``), or was itself measured as water or traffic."""
        ctx = self.ctx
        home = ctx.tm.state.home_ned_m
        if home is None or math.dist(home[:2], here_ne_m) < ctx.ledger.same_site_m:
            return None
        there = ctx.ledger.near((home[0], home[1]))
        if there is not None and there.hazard > Hazard.UNKNOWN:
            return None
        return LedgerSite(home, Hazard.UNKNOWN, "where the vehicle took off", ctx.round, False, label="home")

    async def fly_over(self, site: LedgerSite, what: str, then: str = "landing here") -> bool:
        """Fly over ``site`` at the current altitude, or higher where roofs measured near stand above
        it (:meth:`RecoveryContext.climb_for_transit`); False (said, with what happens ``then``) when it
        was not reached in time."""
        ctx = self.ctx
        n, e, _ = site.ned_m
        n0, e0, _d = ctx.tm.state.pos_ned_m
        try:
            d = await ctx.climb_for_transit(site.ned_m)
            await ctx.ctl.goto(
                n,
                e,
                d,
                tolerance_m=ctx.p.arrival_tolerance_m,
                speed_m_s=ctx.p.arrival_speed_m_s,
                timeout_s=ctx.p.move_timeout(math.hypot(n - n0, e - e0)),
            )
        except TargetTimeout as exc:
            ctx.say(4, f"{what} target not reached ({exc.error_m:.1f} m off): {then}")
            return False
        return True

    async def _look_around(self) -> None:
        """One look at what is in view now (Surface ID's candidates, judged from afar into the
        ledger), so that the least bad site is chosen among what can be reached at once, not only
        among what earlier rounds measured: a search that ends after a blind first look, a battery
        at its reserve. One frame, no waiting: a missing frame skips it."""
        try:
            frame = await self.ctx.frames()
        except FrameUnavailable:
            return
        camera = PinholeCamera(frame.width, frame.height, frame.fx, frame.fy, frame.cx, frame.cy)
        candidates = await asyncio.to_thread(self.looker.surface_id, frame, camera)
        await asyncio.to_thread(self.looker.notes_job(candidates, frame, camera))

    async def _measure_at(
        self, ne_m: tuple[float, float] | None, label: str, candidate: Candidate | None = None
    ) -> LedgerSite | None:
        """Judge the spot at ``ne_m`` (None: under the vehicle) from one frame (no waiting: a missing
        frame skips it) into the ledger as a close look labelled ``label``, so that it competes with the
        sites measured before on what is there; the site as kept, or None when nothing was measured.
        It is judged as a confirmation would judge it: among buildings or not, and with the surface's
        area and edge distance when Surface ID measured it (``candidate``)."""
        ctx = self.ctx
        try:
            frame = await ctx.frames()
        except FrameUnavailable:
            return None
        n, e, d = ctx.tm.state.pos_ned_m
        if ne_m is not None:
            n, e = ne_m
        check = await asyncio.to_thread(check_site, frame.lidar_frd, frame.pos_ned_m, frame.quat_wxyz, (n, e))
        rng = frame.rangefinder_m if math.isfinite(frame.rangefinder_m) else ctx.tm.state.rangefinder_m
        ground_d = -check.surface_up_m if check.measured else d + rng
        if not math.isfinite(ground_d):
            return None
        target = (n, e, ground_d)
        up_m = height_above_surroundings(frame, check) if check.measured else None
        among = self.looker.built_up((n, e))
        kinds = await asyncio.to_thread(self.looker.judge, frame, check, target, up_m, candidate, among)
        hazard = hazard_of(
            kinds,
            accepted=False,
            street_level=up_m is None or up_m < ROOF_HEIGHT_M,
            strip=False,
            judged=check.measured or frame.image_rgb is not None,
        )
        return ctx.ledger.add(
            LedgerSite(
                target,
                hazard,
                ", ".join(kinds) or "nothing seen against it",
                ctx.round,
                True,
                label=label,
            )
        )
