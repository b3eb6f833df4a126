"""The recovery loop (DESIGN.md section 2): acquire, Surface ID, rank, move, confirm, descend, land.

One :class:`Recovery` per alarm. Its state is explicit (:class:`State`); every decision is announced
(STATUSTEXT), recorded, and taken from telemetry, never from sleeps. A round that finds nothing
explores (climbs, or flies a search leg); a target never reached or a site rejected at confirmation
ends the round. When the round budget runs out with nothing acceptable seen, the vehicle searches on,
leg by leg (:mod:`companion.recovery.search_plan`), while the battery holds more than the landing
needs plus a reserve and the alarm's window allows; then it lands at the least bad site it measured
(:mod:`companion.site_ledger`), never "here" blindly. The battery and the window also end the rounds
within the budget: a battery at its reserve lands at the least bad site after the first look. A
defect of the companion's own (any unexpected exception) never leaves the vehicle without a
commander: it is announced, recorded with its traceback, and the vehicle lands
(:meth:`Recovery._fail_safe`).

The machine decides; its parts (:mod:`companion.recovery` lists them) look, follow the site, land,
search, watch for people on the way down and take the autopilot's failsafes and a lost link, each on
the context they share. One module over 600 lines: the states and every way out of each (a round's
end, a resume after a failsafe or a lost link, the fail-safe landing) read together, as one machine;
what each state does is in the parts.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import time
import traceback
from collections.abc import Awaitable, Callable
from typing import Any, TypeVar

from companion.alarms import Alarm, Criticality
from companion.control import (
    AutopilotFailsafe,
    ControlError,
    OperatorTakeover,
    TargetTimeout,
    TelemetryLost,
    TouchedDown,
    VehicleController,
)
from companion.faults import FaultHook
from companion.guidance.descent import height_above_site
from companion.guidance.frames import PinholeCamera, compass_point
from companion.memory import trim_malloc
from companion.perception.site_check import check_site
from companion.perception.surface_id import Candidate
from companion.reasoning.base import Reasoner
from companion.reasoning.people_watch import PeopleSeen
from companion.recovery.core import (
    ASIDE_MAX,
    GO_AROUND_M,
    MAX_REENGAGE,
    MAX_RESUMES,
    PEOPLE_LOOK_AGAIN_S,
    QUIET_LOOKS,
    SEVERITY_CRITICAL,
    FrameSource,
    NoRecord,
    Outcome,
    Record,
    RecoveryContext,
    RecoveryParams,
    SensorsLost,
    Site,
    State,
)
from companion.recovery.following import SiteFollower
from companion.recovery.handover import Handover
from companion.recovery.landing import Lander
from companion.recovery.looking import Looker, lidar_silent, onboard_tier
from companion.recovery.search_plan import SearchPlanner
from companion.recovery.searching import Searcher
from companion.recovery.watching import PeopleWatch
from companion.telemetry import TelemetryCache

TAKEOVER_TEXTS_S = 5.0  # the autopilot's texts this recent go with a takeover into the record

T = TypeVar("T")


class Recovery:
    """One recovery, from the alarm to the ground (module docstring): the state machine. It owns its
    parts, each built on the context they share (:class:`RecoveryContext`) and given the parts it
    calls: ``looker`` (:class:`Looker`), ``follower`` (:class:`SiteFollower`), ``lander``
    (:class:`Lander`), ``searcher`` (:class:`Searcher`), ``watch`` (:class:`PeopleWatch`) and
    ``handover`` (:class:`Handover`)."""

    def __init__(
        self,
        alarm: Alarm,
        *,
        control: VehicleController,
        telemetry: TelemetryCache,
        frames: FrameSource,
        reasoner: Reasoner,
        announce: Callable[[int, str], None],
        params: RecoveryParams | None = None,
        record: Record | None = None,
        logger: logging.Logger | None = None,
    ) -> None:
        self.ctx = ctx = RecoveryContext(
            alarm,
            control,
            telemetry,
            frames,
            announce,
            params or RecoveryParams(),
            record or NoRecord(),
            logger or logging.getLogger("companion.recovery"),
            FaultHook.from_env(),
        )
        p = ctx.p
        plan = SearchPlanner(
            alarm.criticality, p.search, search_agl_m=p.search_agl_m, lidar_range_m=p.lidar_range_m
        )
        ctx.path_top = plan.highest_near_path  # a level move's clearance (RecoveryContext.transit_d)
        onboard = onboard_tier(reasoner)
        self.looker = Looker(ctx, reasoner=reasoner, onboard=onboard, plan=plan)
        self.follower = SiteFollower(ctx)
        self.lander = Lander(ctx, looker=self.looker, follower=self.follower)
        self.searcher = Searcher(ctx, plan=plan, lander=self.lander, onboard=onboard)
        self.watch = PeopleWatch(ctx, looker=self.looker, follower=self.follower, lander=self.lander)
        self.lander.watched_landing = self.watch.fallback_landing
        self.handover = Handover(ctx)
        # the site a descent is on, confirmed again first when a lost link comes back
        self._descending: tuple[tuple[float, float, float], Candidate] | None = None
        self._resumes = 0  # descents gone on with after a failsafe or a lost link (MAX_RESUMES)
        self.extra = 0  # rounds flown past the budget (nothing acceptable seen)
        # the last round ended on an exploring climb or descent: a view from here not yet looked at
        self._new_vantage = False
        self._first_look: asyncio.Task[Any] | None = None  # the first frame, asked for while engaging

    def raise_criticality(self, criticality: Criticality) -> None:
        """A repeated alarm can make the recovery more urgent (a shorter budget), never less."""
        ctx = self.ctx
        if criticality > ctx.criticality:
            ctx.criticality = criticality
            self.searcher.raise_criticality(criticality)
            ctx.say(5, f"alarm raised to {criticality.name.lower()}: {ctx.budget} rounds")

    # ------------------------------------------------------------------ the loop
    async def run(self) -> Outcome:
        ctx = self.ctx
        ctx.say(5, f"alarm '{ctx.alarm.reason}' ({ctx.criticality.name.lower()}), {ctx.budget} rounds")
        self.searcher.start()
        try:
            held = self.handover.in_charge()
            if held is not None:  # an alarm after the autopilot's own failsafe took the vehicle
                self.ctx.record.record_event(
                    "autopilot_failsafe", {"round": 0, "state": "idle", "mode": held}
                )
                return await self.handover.leave_to_autopilot(held)
            await self._engage_and_look()
            resume: tuple[tuple[float, float, float], Candidate] | None = None
            while resume is not None or self.searcher.go_on():
                try:
                    if resume is not None:  # the vehicle is back mid-descent: same site, confirm first
                        landed = await self._confirm_and_descend(*resume)
                    elif self.ctx.round >= self.ctx.budget:
                        landed = await self._extra_round()
                    else:
                        self.ctx.round += 1
                        self._descending = None
                        landed = await self._round()
                    resume = None
                except AutopilotFailsafe as exc:
                    # ridden out or re-engaged, the vehicle is held where it was: a descent goes on at
                    # its site, confirmed again first, as after a lost link (town, launch 29 in rain:
                    # a new round after PX4's offboard-loss POSCTL lost a lawn confirmed 14 m below)
                    resume = self._resume()
                    ended = await self.handover.on_failsafe(exc)
                    if ended is not None:
                        return ended
                    continue
                except TelemetryLost as exc:
                    resume = self._resume()
                    ended = await self.handover.ride_out_link_loss(exc)
                    if ended is not None:
                        return ended
                    continue
                except SensorsLost as exc:
                    # policy: no sensors, no new site; the alarm still stands, so come down: at the
                    # best site measured so far (flown to on the autopilot's position hold), else here
                    self.ctx.say(3, f"{exc}: landing without them")
                    return await self._land_at_best("sensors lost", measure_here=False)
                if landed:
                    return Outcome(State.LANDED, self.ctx.round, self.ctx.site_ned(), "landed")
            if self.searcher.ended is not None:
                return await self._land_at_best(f"search ended ({self.searcher.ended.why})")
            return await self._land_at_best("round budget spent")
        except TouchedDown as exc:
            # the surface came sooner than measured: the vehicle is down, and says so
            self.ctx.set_state(State.LANDED)
            self.ctx.say(4, f"touched down before the final approach: {exc}")
            await self.ctx.ctl.release()
            return Outcome(
                State.LANDED, self.ctx.round, self.ctx.site_ned(), "touched down during a descent step"
            )
        except OperatorTakeover as exc:
            self.ctx.set_state(State.ABORTED)
            self.ctx.say(4, "operator took over: stopped commanding")
            await self.ctx.ctl.release()
            # what the autopilot said just before may be the real cause: ArduCopter's fence breach
            # switches to LAND or RTL without the critical status of its other failsafes
            said = [text for t, _, text in self.ctx.tm.texts if time.monotonic() - t < TAKEOVER_TEXTS_S]
            said = [t for t in said if not t.startswith("Landfall:")]
            self.ctx.record.record_event(
                "takeover", {"round": self.ctx.round, "mode": str(exc), "autopilot_said": said}
            )
            why = f"{exc} (the autopilot said: {'; '.join(said)})" if said else str(exc)
            return Outcome(State.ABORTED, self.ctx.round, None, why)
        except ControlError as exc:
            self.ctx.set_state(State.ABORTED)
            self.ctx.say(2, f"aborted: {exc}")
            await self.ctx.ctl.release()
            return Outcome(State.ABORTED, self.ctx.round, None, str(exc))
        except Exception as exc:  # a defect of the companion's own: never leave the vehicle uncommanded
            return await self._fail_safe(exc)
        finally:
            if self._first_look is not None:  # ended before the first round used it
                self._first_look.cancel()
                with contextlib.suppress(asyncio.CancelledError, Exception):
                    await self._first_look
                self._first_look = None

    async def _fail_safe(self, exc: Exception) -> Outcome:
        """Policy for a defect of the companion's own (an exception no stage expects): announce it
        (STATUSTEXT, critical), record it with its traceback, and land: at the best site already
        measured (accepted, else the ledger's least bad; nothing is measured anew), else with the
        autopilot's land mode where the vehicle is. The autopilot's own failsafe or a lost link on the
        way is met as in a round (:meth:`_through_handovers`): ridden out or re-engaged, the landing
        starts again from where the vehicle is. Should that landing fail otherwise, land mode once
        more, then the vehicle is left to the autopilot."""
        ctx = self.ctx
        where = ctx.state.value
        text = f"{type(exc).__name__}: {exc}"
        ctx.log.error("defect in the recovery (%s): %s", where, text, exc_info=exc)
        ctx.record.record_event(
            "defect",
            {
                "round": ctx.round,
                "state": where,
                "error": text,
                "traceback": "".join(traceback.format_exception(exc)),
            },
        )
        # a STATUSTEXT holds 50 characters: what happened and what the vehicle does come first
        ctx.say(SEVERITY_CRITICAL, f"internal error, landing: {type(exc).__name__} in {where}: {exc}"[:150])
        await self.searcher.observed_or_said()  # the round's candidates noted from afar: sites to land at
        site = self.lander.fallback_site()
        self.follower.forget()  # nothing measured anew, the camera's view of a site included
        landed = Outcome(
            State.LANDED, ctx.round, site.ned_m if site is not None else None, f"defect ({text}): landed"
        )

        async def land() -> Outcome:
            if site is not None:
                await self.lander.fly_over(site, "best site measured")
            await self.lander.final_land()
            return landed

        ended = landed
        try:
            try:
                # the autopilot's own failsafe or a lost link on the way: met as in a round
                ended = await self._through_handovers(land, "fail-safe landing")
            except (TouchedDown, OperatorTakeover):
                raise
            except Exception as again:  # the landing itself failed: the autopilot's land mode, once more
                ctx.log.error("fail-safe landing failed (%r): autopilot land mode", again)
                ctx.record.record_event("defect", {"round": ctx.round, "state": "land", "error": repr(again)})
                await self.lander.final_land()
        except TouchedDown:
            ctx.set_state(State.LANDED)
        except OperatorTakeover as taken:
            ctx.set_state(State.ABORTED)
            await ctx.ctl.release()
            return Outcome(State.ABORTED, ctx.round, None, f"defect ({text}), then {taken}")
        except Exception as last:
            ctx.set_state(State.ABORTED)
            ctx.say(SEVERITY_CRITICAL, "fail-safe landing failed: the autopilot has the vehicle")
            with contextlib.suppress(Exception):
                await ctx.ctl.release()
            return Outcome(State.ABORTED, ctx.round, None, f"defect ({text}); landing failed ({last!r})")
        if ended is landed:
            return landed
        return Outcome(ended.state, ended.rounds, ended.site_ned_m, f"defect ({text}), then {ended.reason}")

    def _resume(self) -> tuple[tuple[float, float, float], Candidate] | None:
        """The descent to go on with once the vehicle is back from a failsafe or a lost link (its
        site, confirmed again first), at most ``MAX_RESUMES`` times in a recovery: a failsafe that
        clears and comes back at every try (setpoint stalls on a loaded computer) then meets a new
        round, whose search verdict checks the battery and the alarm's window first."""
        if self._descending is None or self._resumes >= MAX_RESUMES:
            return None
        self._resumes += 1
        return self._descending

    async def _land_at_best(self, reason: str, *, measure_here: bool = True) -> Outcome:
        """:meth:`Lander.land_at_best` once the round's deferred work is done (the candidates noted
        from afar are sites to land at). The autopilot's own failsafe or a lost link on the way is met
        by the same policies as in a round (:class:`Handover`): ridden out or re-engaged (a bounded
        number of times), and the landing at the least bad site starts again from where the vehicle
        is; a failsafe that lands or flies home keeps the vehicle."""
        await self.searcher.observed_or_said()
        return await self._through_handovers(
            lambda: self.lander.land_at_best(reason, measure_here=measure_here), reason
        )

    async def _through_handovers(self, land: Callable[[], Awaitable[Outcome]], reason: str) -> Outcome:
        """Run ``land`` through the autopilot's failsafes and lost links (:class:`Handover`): one that
        is ridden out or re-engaged starts ``land`` again from where the vehicle is; one that lands or
        flies home ends the recovery with its outcome. Interrupted ``MAX_REENGAGE + 1`` times, the
        autopilot's land mode where the vehicle is."""
        for _ in range(MAX_REENGAGE + 1):
            try:
                return await land()
            except AutopilotFailsafe as exc:
                ended = await self.handover.on_failsafe(exc)
            except TelemetryLost as exc:
                ended = await self.handover.ride_out_link_loss(exc)
            if ended is not None:
                return ended
        # interrupted again and again (a setpoint the autopilot keeps refusing): its land mode here
        self.ctx.say(4, f"{reason}: the landing was interrupted {MAX_REENGAGE + 1} times: landing here")
        self.follower.forget()
        await self.lander.final_land()
        return Outcome(State.LANDED, self.ctx.round, None, f"{reason}, then landed where it was")

    async def _engage_and_look(self) -> None:
        """Take control and ask for the first round's frame at the same time: the frame (render,
        transfer) takes longer than the mode switch, and the vehicle holds either way."""
        look = asyncio.create_task(self.looker.acquire(first_round=True), name="first-frame")
        try:
            await self.ctx.ctl.engage()
        except BaseException:
            look.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await look
            raise
        self._first_look = look

    async def _extra_round(self) -> bool:
        """A round past the budget: a closer look at the best roof seen only from afar (nothing seen
        against it: flown to and confirmed as any round would), or, with none, a round from here when
        the last round ended by climbing or descending to see (:meth:`Searcher.explore`), else a step
        outward to a view not yet judged and a round there. True when it landed."""
        ctx = self.ctx
        await self.searcher.observed()  # the last round's frame, if it ended before its move
        self.extra += 1
        ctx.round += 1
        self._descending = None
        n, e, _ = ctx.tm.state.pos_ned_m
        site = ctx.ledger.least_bad((n, e))
        battery = ctx.tm.state.battery_pct
        charge = f", battery {battery:.0f} %" if math.isfinite(battery) else ""
        count = f"{self.extra}{charge}"
        look = (
            site is not None
            and site.hazard.acceptable
            and not site.closeup
            and not site.looked
            and site.candidate is not None
        )
        ctx.record.record_event(
            "extend",
            {
                "round": ctx.round,
                "extra": self.extra,
                "best": None if site is None else site.to_json(),
                "action": "closer look" if look else "look again" if self._new_vantage else "explore",
            },
        )
        if look:
            assert site is not None
            ctx.say(5, f"budget spent: a closer look at {site.label}, seen only from afar ({count})")
            site.looked = True  # once: a site the vehicle cannot reach is not tried again
            if not await self.lander.fly_over(site, site.label, then="next round"):
                return False  # not over it: no confirmation, no descent from elsewhere
            return await self._confirm_and_descend(site.ned_m, site.candidate)
        seen = "nothing measured" if site is None else f"the best seen is {site.hazard.phrase}"
        if self._new_vantage:
            # the last round ended by climbing or descending to see (out of the LiDAR's reach, or too
            # low for a wide view): look from there before flying on, or the step was for nothing
            ctx.say(4, f"budget spent, {seen}: looking again from here ({count})")
            return await self._round()
        ctx.say(4, f"budget spent, {seen}: searching on ({count})")
        await self.searcher.leg()
        return await self._round()

    async def _round(self) -> bool:
        ctx = self.ctx
        await self.searcher.observed()  # a round that ended before its move leaves its frame here
        look, self._first_look = self._first_look, None
        self._new_vantage = False  # this round looks from here
        self.follower.forget()  # a new round, a new site
        frame = await (look if look is not None else self.looker.acquire())
        ctx.set_state(State.SURFACE_ID)
        camera = PinholeCamera(frame.width, frame.height, frame.fx, frame.fy, frame.cx, frame.cy)
        candidates = await asyncio.to_thread(self.looker.surface_id, frame, camera)
        self.searcher.observe_later(frame)  # the search's map of what was seen: after the first setpoint
        # a roof in view makes it a built-up area; so do roofs the LiDAR saw near a site (Looker.built_up)
        self.looker.roofs_in_view = any(c.elevated for c in candidates)
        candidates = [c for c in candidates if not ctx.near_rejected(c)]
        candidates = self._within_fence(candidates, frame, camera)
        if frame.image_rgb is not None:  # JPEG encoding off the event loop: the setpoint stream runs there
            # (before the ranking: a ground feed boxes the ranking's candidates on this frame)
            await asyncio.to_thread(ctx.record.save_image, f"round{ctx.round:02d}-acquire", frame.image_rgb)
        if not candidates or all(c.fallback for c in candidates):
            await self.searcher.observed()  # the search's next leg is planned on it
            self._new_vantage = await self.searcher.explore(blind=lidar_silent(frame.lidar_frd))
            return False
        ctx.set_state(State.RANK)
        ranking, chosen = await self.looker.rank(candidates, frame)
        choice = candidates[chosen] if chosen is not None else None
        if frame.image_rgb is not None:  # the ledger's view of every candidate from afar
            notes = self.looker.notes_job(candidates, frame, camera)
            if choice is not None and choice.elevated and not choice.strip:
                self.searcher.later(notes)  # a roof: nothing before its move reads the notes
            else:
                await asyncio.to_thread(notes)  # whether to search instead reads them
        if choice is None:
            await self.searcher.observed()  # the search's next leg is planned on it
            self._new_vantage = await self.searcher.explore()
            return False
        if await self.searcher.search_instead(choice, built_up=self._built_up(choice)):
            return False
        target = await asyncio.to_thread(self.looker.ipm, choice, frame, camera)
        if target is None:
            ctx.say(4, f"site {choice.index} cannot be placed in the world: next round")
            await self.searcher.observed()  # the search's verdict before the next round reads the notes
            return False
        self.follower.follow_from(frame, target)
        n, e, d = ctx.tm.state.pos_ned_m
        dist = math.hypot(target[0] - n, target[1] - e)
        bearing = compass_point(math.degrees(math.atan2(target[1] - e, target[0] - n)))
        kind = "roof" if choice.height_above_m >= 3.0 else "ground"
        ctx.say(6, f"site {choice.index} {kind} {dist:.0f} m {bearing}")
        ctx.say(6, ranking.rationale[:200])
        ctx.set_state(State.MOVE)
        ctx.fault.check("move", ctx.round)
        observing = asyncio.create_task(self._observe_and_trim(), name="observe")  # once the setpoint is out
        try:
            d = await ctx.climb_for_transit(target)
            await ctx.ctl.goto(
                target[0],
                target[1],
                d,
                tolerance_m=ctx.p.arrival_tolerance_m,
                speed_m_s=ctx.p.arrival_speed_m_s,
                timeout_s=ctx.p.move_timeout(dist),
            )
        except TargetTimeout as exc:
            ctx.say(4, f"target not reached ({exc.error_m:.1f} m off): next round")
            return False
        finally:
            await observing
        return await self._confirm_and_descend(target, choice)

    def _within_fence(
        self, candidates: list[Candidate], frame: Any, camera: PinholeCamera
    ) -> list[Candidate]:
        """The candidates whose sites lie inside what the autopilot's fence leaves the recovery, those
        beyond it moved inside where their surface reaches in (:meth:`Looker.pull_inside_fence`), the
        rest left out; each said."""
        ctx = self.ctx
        kept, beyond = [], []
        for c in candidates:
            if not ctx.outside_fence(c):
                kept.append(c)
                continue
            pulled = self.looker.pull_inside_fence(c, frame, camera)
            if pulled is None:
                beyond.append(c.index)
                continue
            moved = c.edge_distance_m - pulled.edge_distance_m
            ctx.say(
                6, f"site {c.index} beyond the autopilot's fence, its surface within: moved {moved:.0f} m in"
            )
            kept.append(pulled)
        if beyond:
            ctx.say(6, f"site {', '.join(map(str, beyond))} beyond the autopilot's fence: not considered")
        return kept

    def _built_up(self, choice: Candidate) -> bool:
        site = choice.site_ned_m
        return True if site is None else self.looker.built_up((site[0], site[1]))

    async def _observe_and_trim(self) -> None:
        """During the move: the search's map of this round's frame, then what the round's reads freed
        handed back to the system (:func:`companion.memory.trim_malloc`, a few milliseconds in a worker
        thread while nothing waits on it), so that the next round's reads build on less."""
        await self.searcher.observed()
        await asyncio.to_thread(trim_malloc)

    async def _step_aside(
        self,
        seen: PeopleSeen,
        frame: Any,
        target: tuple[float, float, float],
        aside: tuple[float, float, float],
        choice: Candidate,
    ) -> tuple[float, float, float]:
        """Fly level to ``aside`` (:meth:`PeopleWatch.aside_from_people`), the site followed from there on
        in the frame the people were seen in; the target as it ended (``aside``, or where the vehicle
        stopped when it was not reached)."""
        ctx = self.ctx
        self.watch.stepped_aside(seen, target, aside, choice)
        self.follower.follow_from(frame, aside)
        self._descending = (aside, choice)
        n, e, d = ctx.tm.state.pos_ned_m
        try:
            await ctx.ctl.goto(
                aside[0],
                aside[1],
                d,
                tolerance_m=ctx.p.arrival_tolerance_m,
                speed_m_s=ctx.p.arrival_speed_m_s,
                timeout_s=ctx.p.move_timeout(math.dist((n, e), aside[:2])),
            )
        except TargetTimeout as exc:
            ctx.say(4, f"site {choice.index}: not reached aside ({exc.error_m:.1f} m off)")
        return aside

    async def _confirm_and_descend(self, target: tuple[float, float, float], choice: Candidate) -> bool:
        ctx = self.ctx
        self._descending = (target, choice)  # what a link loss resumes: this site, confirmed again
        people_since: float | None = None  # when people were first seen near the site, autopilot seconds
        quiet_looks = 0  # looks in a row without anyone since people were seen there
        asides = 0  # steps aside from people on this site
        while True:
            frame, check = await self.looker.measure_site(target)
            followed = await self.follower.follow(frame, target)
            if followed != target:  # the site where the camera sees it now: measured there
                target = followed
                self._descending = (target, choice)
                check = await asyncio.to_thread(
                    check_site, frame.lidar_frd, frame.pos_ned_m, frame.quat_wxyz, (target[0], target[1])
                )
            decision = await self.looker.confirm(check, frame, target, choice)
            if not decision.accept and decision.contested:
                # a lone "no" on a clear site: ask again next round (the cascade's lone-"no" rule)
                ctx.say(4, f"site {choice.index} contested: {decision.rationale[:110]}")
                return False
            if not decision.accept:
                ctx.strike_off(target, choice)
                ctx.say(4, f"site {choice.index} {decision.rationale[:120]}")
                return False
            # off the roofs, people walk: none within the margin (people_margin_m); so they do on open
            # ground measured above its surroundings (a terrace on a slope)
            on_roof = choice.elevated and not decision.open_ground
            if not on_roof:
                seen = await self.looker.watch_people(frame, target)
                if seen is not None and seen.cells:
                    now = ctx.clock_s()
                    people_since = now if people_since is None else people_since
                    quiet_looks = 0
                    aside = None
                    if asides < ASIDE_MAX:
                        aside = self.watch.aside_from_people(seen, frame, target, choice)
                    if aside is not None:  # room on the same open surface: there instead, looked at again
                        asides += 1
                        target = await self._step_aside(seen, frame, target, aside, choice)
                        continue
                    if not await self.watch.hold_for_people(seen, target, choice, now - people_since):
                        return False
                    continue
                if people_since is not None and quiet_looks + 1 < QUIET_LOOKS:
                    quiet_looks += 1  # one look without them is not yet proof they left: another look
                    await asyncio.sleep(PEOPLE_LOOK_AGAIN_S)
                    continue
                people_since, quiet_looks = None, 0
            ctx.best = Site(target, choice)
            _n, _e, d = ctx.tm.state.pos_ned_m
            rng_m, rng_quat = frame.rangefinder_m, frame.quat_wxyz
            if not math.isfinite(rng_m):
                rng_m, rng_quat = ctx.tm.state.rangefinder_m, ctx.tm.state.quat_wxyz
            height_m = height_above_site(
                d,
                surface_up_m=check.surface_up_m,
                site_d_m=target[2],
                rangefinder_m=rng_m,
                quat_wxyz=rng_quat,
            )
            if not math.isfinite(height_m):
                ctx.say(4, "no height above the site measured: next round")
                return False
            settled = await self.follower.settle(target)
            if settled != target:  # held over a drifting site: measured and confirmed again there
                target = settled
                self._descending = (target, choice)
                continue
            if height_m <= ctx.p.final_land_m:
                if on_roof or ctx.p.people_margin_m <= 0:
                    return await self.lander.land()
                seen = await self.watch.landing(target)
                if seen is None:
                    return True
                now = ctx.clock_s()
                people_since, quiet_looks = (now if people_since is None else people_since), 0
                self.watch.paused_for_people(seen, target, choice, go_around_m=GO_AROUND_M)
                continue
            ctx.set_state(State.DESCEND)
            ctx.fault.check("descend", ctx.round)
            # an unsure judgement: half the step, so that the next look is from closer
            step_m = ctx.p.descent_fraction * height_m * (0.5 if decision.unsure else 1.0)
            new_d = d + step_m
            closer = " (unsure: a closer look first)" if decision.unsure else ""
            ctx.say(6, f"descending {step_m:.0f} m{closer}, {decision.rationale[:80]}")
            timeout_s = ctx.p.move_timeout_s + rng_m
            seen = None
            try:
                if on_roof or ctx.p.people_margin_m <= 0:
                    target = await self.follower.goto_following(target, new_d, timeout_s=timeout_s)
                else:  # off the roofs: the people watch goes on through the step
                    target, seen = await self.watch.step(target, new_d, timeout_s)
            except TargetTimeout as exc:
                ctx.say(4, f"descent target not reached ({exc.error_m:.1f} m off): next round")
                return False
            self._descending = (target, choice)
            if seen is not None:  # someone came within the margin on the way down: stopped, look again
                now = ctx.clock_s()
                people_since, quiet_looks = (now if people_since is None else people_since), 0
                self.watch.paused_for_people(seen, target, choice)
