"""The people watch through a descent onto a site off the roofs: while a descent step or the final
approach runs, a frame of its own every ``PEOPLE_WATCH_STEP_S`` and a look for people within
``people_margin_m`` of the site (:meth:`Looker.watch_people`). Someone seen stops the step where the
vehicle is, or turns the final approach into a climb to ``GO_AROUND_M`` above the site, and the
machine (:mod:`companion.recovery.machine`) looks again before the next step. The policies for what
comes next live here too: hold and look again, step aside on the same open surface, or strike the
site off; each is said and recorded as a ``people_watch`` event."""

from __future__ import annotations

import asyncio
import contextlib
import math
from collections.abc import Coroutine, Mapping
from typing import Any, TypeVar

import numpy as np

from companion.control import TargetTimeout
from companion.guidance.frames import PinholeCamera
from companion.guidance.ipm import IpmError, pixel_to_ned_flat
from companion.perception.surface_id import Candidate
from companion.reasoning.people_watch import PeopleSeen
from companion.recovery.core import (
    ASIDE_CLEAR_M,
    ASIDE_EDGE_KEEP_M,
    FALLBACK_PEOPLE_WAIT_S,
    GO_AROUND_M,
    GO_AROUND_MIN_M,
    PEOPLE_LOOK_AGAIN_S,
    PEOPLE_WATCH_STEP_S,
    FrameUnavailable,
    RecoveryContext,
    State,
)
from companion.recovery.following import SiteFollower
from companion.recovery.landing import Lander
from companion.recovery.looking import Looker
from companion.site_ledger import Hazard, LedgerSite

T = TypeVar("T")


class PeopleWatch:
    """The people watch and its policies (module docstring) on the recovery's context, with the looker
    that looks, the follower that flies the steps and the lander that flies the final approach."""

    def __init__(
        self, ctx: RecoveryContext, *, looker: Looker, follower: SiteFollower, lander: Lander
    ) -> None:
        self.ctx = ctx
        self.looker = looker
        self.follower = follower
        self.lander = lander

    async def _while_watching(
        self,
        work: Coroutine[Any, Any, T],
        target: tuple[float, float, float],
        *,
        name: str,
        floor_m: float = 0.0,
    ) -> tuple[T | None, PeopleSeen | None]:
        """``work`` (a descent step, the final approach) with the people watch running through it:
        every ``PEOPLE_WATCH_STEP_S`` a frame of its own and a look within ``people_margin_m`` of the site
        (:meth:`Looker.watch_people`), while the vehicle is more than ``floor_m`` above the site.
        Someone seen ends ``work`` there (cancelled). Returns its result and None, or None and what was
        seen."""
        task = asyncio.create_task(work, name=name)
        watch = asyncio.create_task(self._watch_through(target, floor_m), name=f"people-watch-{name}")
        try:
            await asyncio.wait((task, watch), return_when=asyncio.FIRST_COMPLETED)
            if task.done():
                return task.result(), None
            return None, watch.result()  # a watch that failed raises here: a defect, as anywhere else
        finally:
            for t in (task, watch):
                t.cancel()
            await asyncio.gather(task, watch, return_exceptions=True)

    async def step(
        self, target: tuple[float, float, float], down_m: float, timeout_s: float
    ) -> tuple[tuple[float, float, float], PeopleSeen | None]:
        """A descent step onto a site off the roofs (:meth:`SiteFollower.goto_following`) watched for people
        (:meth:`_while_watching`); someone seen stops it where the vehicle is (the position target's
        height becomes the vehicle's). Returns the target as it ended and what was seen (None: the
        step ran to its end)."""
        ctx = self.ctx
        step = self.follower.goto_following(target, down_m, timeout_s=timeout_s)
        moved, seen = await self._while_watching(step, target, name="descent-step")
        if seen is None:
            assert moved is not None
            return moved, None
        here = ctx.tm.state.pos_ned_m
        held = ctx.ctl.target
        n, e = (held[0], held[1]) if held is not None else (here[0], here[1])
        ctx.ctl.set_target(n, e, here[2])  # no lower: the vehicle stops where it is
        return (n, e, target[2]), seen

    async def landing(self, target: tuple[float, float, float]) -> PeopleSeen | None:
        """The final approach onto a site off the roofs (:meth:`Lander.land`) watched for people down
        to ``GO_AROUND_MIN_M`` above it; someone seen stops the landing: the companion takes the vehicle
        back from the autopilot's land mode where it is and climbs to ``GO_AROUND_M`` above the site,
        from where the look before the next step sees the whole margin. Returns what was seen (None:
        landed)."""
        ctx = self.ctx
        _landed, seen = await self._while_watching(
            self.lander.land(), target, name="final-approach", floor_m=GO_AROUND_MIN_M
        )
        if seen is None:
            return None
        await ctx.ctl.engage()  # holds where the vehicle is, in the companion's mode again
        n, e, _d = ctx.tm.state.pos_ned_m
        ctx.set_state(State.DESCEND)
        with contextlib.suppress(TargetTimeout):  # wherever the climb got to, the next look is from there
            await ctx.ctl.goto(
                n,
                e,
                target[2] - GO_AROUND_M,
                tolerance_m=ctx.p.arrival_tolerance_m,
                speed_m_s=ctx.p.arrival_speed_m_s,
                timeout_s=ctx.p.move_timeout_s,
            )
        return seen

    async def fallback_landing(self, target: tuple[float, float, float]) -> None:
        """Policy: the fallback's landing (:meth:`Lander.land_at_best`, a site never confirmed free of
        people) watched as a site's off the roofs is (:meth:`landing`): someone within the margin stops
        it and the vehicle climbs back ``GO_AROUND_M`` above the site, holds there and looks again every
        ``PEOPLE_LOOK_AGAIN_S`` until a look sees no one, then comes down again. Once it has held
        ``FALLBACK_PEOPLE_WAIT_S`` in all it lands on the next approach whatever is seen: the search has
        ended and the battery is the limit. Said, and recorded as ``people_watch`` events (``site``
        "fallback")."""
        ctx = self.ctx
        margin = ctx.p.people_margin_m
        held_s = 0.0
        while True:
            if held_s >= FALLBACK_PEOPLE_WAIT_S:
                ctx.say(4, f"held {held_s:.0f} s for people near the landing site: landing all the same")
                await self.lander.land()
                return
            seen = await self.landing(target)
            if seen is None:
                return
            self._fallback_watch(seen, target, held_s, "go-around")
            ctx.say(4, f"{seen.phrase(margin)}: landing stopped, back up to {GO_AROUND_M:.0f} m")
            since = ctx.clock_s() - held_s
            while held_s < FALLBACK_PEOPLE_WAIT_S:
                await asyncio.sleep(PEOPLE_LOOK_AGAIN_S)
                held_s = ctx.clock_s() - since
                looked, now = await self._look(target, "while holding")
                if not looked:
                    continue
                if now is None or not now.cells:
                    break  # no one within the margin: down again, watched
                self._fallback_watch(now, target, held_s, "hold")

    def _fallback_watch(
        self, seen: PeopleSeen, target: tuple[float, float, float], waited_s: float, action: str
    ) -> None:
        site = [round(v, 2) for v in target]
        _watch_event(self.ctx, seen, site, waited_s, action, {"site": "fallback"})

    async def _watch_through(self, target: tuple[float, float, float], floor_m: float) -> PeopleSeen:
        """Looks for people near the site until someone is seen (frames missing are skipped); the site
        where the position target has it (the follower may move it), at ``target``'s height. Below
        ``floor_m`` above the site it looks no more (and waits to be cancelled)."""
        ctx = self.ctx
        while True:
            await asyncio.sleep(PEOPLE_WATCH_STEP_S)
            if target[2] - ctx.tm.state.pos_ned_m[2] < floor_m:
                continue  # too low to turn back: the landing goes on
            held = ctx.ctl.target
            site = (held[0], held[1], target[2]) if held is not None else target
            _looked, seen = await self._look(site, "on the way down")
            if seen is not None and seen.cells:
                return seen

    async def _look(self, site: tuple[float, float, float], when: str) -> tuple[bool, PeopleSeen | None]:
        """A frame of its own and the people within the margin of ``site`` in it
        (:meth:`Looker.watch_people`: None when the watch cannot run); (False, None) when no frame
        came, said in the debug log ``when``."""
        try:
            frame = await self.ctx.frames()
        except FrameUnavailable as exc:
            self.ctx.log.debug("no look for people %s: %s", when, exc)
            return False, None
        return True, await self.looker.watch_people(frame, site)

    def paused_for_people(
        self,
        seen: PeopleSeen,
        target: tuple[float, float, float],
        choice: Candidate,
        *,
        go_around_m: float | None = None,
    ) -> None:
        """Policy: someone came within the margin while the vehicle descended onto the site: the step
        stopped where it was, or (``go_around_m``) the final approach stopped and the vehicle climbed
        back that high above the site. Said, and recorded as a ``people_watch`` event (action ``pause``
        or ``go-around``); the look before the next step decides whether to hold or go on
        (:meth:`hold_for_people`)."""
        action = "pause" if go_around_m is None else "go-around"
        _record_watch(self.ctx, seen, target, choice, 0.0, action)
        done = "descent paused" if go_around_m is None else f"landing stopped, back up to {go_around_m:.0f} m"
        self.ctx.say(4, f"site {choice.index}: {seen.phrase(self.ctx.p.people_margin_m)}: {done}")

    async def hold_for_people(
        self, seen: PeopleSeen, target: tuple[float, float, float], choice: Candidate, waited_s: float
    ) -> bool:
        """Policy: people seen within the margin of a site about to be descended onto. Hold where the
        vehicle is and look again (True) for up to ``people_wait_s``; then strike the site off, for
        the next round to choose another (False). Said, and recorded as a ``people_watch`` event."""
        ctx = self.ctx
        margin = ctx.p.people_margin_m
        give_up = waited_s >= ctx.p.people_wait_s
        _record_watch(ctx, seen, target, choice, waited_s, "another site" if give_up else "hold")
        if give_up:
            ctx.strike_off(target, choice)
            ctx.say(4, f"site {choice.index}: {seen.phrase(margin)} for {waited_s:.0f} s: another site")
            return False
        ctx.say(4, f"site {choice.index}: {seen.phrase(margin)}: holding")
        await asyncio.sleep(PEOPLE_LOOK_AGAIN_S)
        return True

    def aside_from_people(
        self, seen: PeopleSeen, frame: Any, target: tuple[float, float, float], choice: Candidate
    ) -> tuple[float, float, float] | None:
        """Policy: a point of the same open surface clear of the people seen near the site (SafeLand's
        reroute within a field): ``people_margin_m`` plus ``ASIDE_CLEAR_M`` from every person cell seen
        (placed on the site's level through the camera), no farther from the site Surface ID chose
        than its edge distance less ``ASIDE_EDGE_KEEP_M``, the nearest such point to ``target``. None
        when the people's places are not known, the surface is too small or no point is clear: the
        vehicle holds for them instead. The point is confirmed like any site before a descent."""
        margin = self.ctx.p.people_margin_m
        origin = choice.site_ned_m or target
        room = choice.edge_distance_m - ASIDE_EDGE_KEEP_M
        if not seen.cells_px or not math.isfinite(room) or room <= 0 or margin <= 0:
            return None
        camera = PinholeCamera(frame.width, frame.height, frame.fx, frame.fy, frame.cx, frame.cy)
        people = []
        for u, v in seen.cells_px:
            try:
                p = pixel_to_ned_flat(u, v, camera, frame.pos_ned_m, frame.quat_wxyz, target[2])
            except IpmError:
                return None  # one person not placed: a step may go toward them
            people.append((float(p[0]), float(p[1])))
        at = np.asarray(people)
        need = margin + ASIDE_CLEAR_M
        best: tuple[float, float] | None = None
        for r in np.arange(1.0, room + 1e-6, 1.0):  # nearest first: the smallest step that clears them
            bearings = np.linspace(0.0, 2 * math.pi, max(8, int(2 * math.pi * r)), endpoint=False)
            pts = np.stack([target[0] + r * np.cos(bearings), target[1] + r * np.sin(bearings)], axis=1)
            inside = np.hypot(pts[:, 0] - origin[0], pts[:, 1] - origin[1]) <= room
            clear = np.hypot(pts[:, None, 0] - at[None, :, 0], pts[:, None, 1] - at[None, :, 1]).min(axis=1)
            ok = inside & (clear >= need)
            if ok.any():
                k = int(np.argmax(np.where(ok, clear, -np.inf)))
                best = (float(pts[k, 0]), float(pts[k, 1]))
                break
        return None if best is None else (best[0], best[1], target[2])

    def stepped_aside(
        self,
        seen: PeopleSeen,
        target: tuple[float, float, float],
        aside: tuple[float, float, float],
        choice: Candidate,
    ) -> None:
        """Said and recorded (a ``people_watch`` event, action ``step aside``, with where to)."""
        ctx = self.ctx
        step = math.dist(target[:2], aside[:2])
        _record_watch(ctx, seen, target, choice, 0.0, "step aside", aside)
        ctx.say(4, f"site {choice.index}: {seen.phrase(ctx.p.people_margin_m)}: moving {step:.0f} m aside")


def _record_watch(
    ctx: RecoveryContext,
    seen: PeopleSeen,
    target: tuple[float, float, float],
    choice: Candidate,
    waited_s: float,
    action: str,
    aside: tuple[float, float, float] | None = None,
) -> None:
    """A ``people_watch`` event: what the look saw near the site, how long the vehicle has waited, and
    what it does (``pause``, ``step aside``, ``hold``, ``another site``). The site ledger keeps the site
    as obstructed by people, and the site confirmed for descent, when it is this one, is forgotten: its
    confirmation said nothing of them, and a landing where nothing else was accepted must not come down
    among them (its next confirmation and a quiet watch make it the accepted site again)."""
    why, label = seen.phrase(ctx.p.people_margin_m), f"site {choice.index}"
    site = LedgerSite(target, Hazard.OBSTRUCTED, why, ctx.round, True, choice.edge_distance_m, label, choice)
    ctx.ledger.add(site)
    if ctx.best is not None and math.dist(ctx.best.ned_m[:2], target[:2]) < ctx.p.rejected_radius_m:
        ctx.best = None  # no longer the site confirmed for descent: not a fallback's first choice either
    extra = {"aside_ned_m": [round(v, 2) for v in aside]} if aside is not None else {}
    _watch_event(ctx, seen, list(target), waited_s, action, extra)


def _watch_event(
    ctx: RecoveryContext,
    seen: PeopleSeen,
    site_ned_m: list[float],
    waited_s: float,
    action: str,
    extra: Mapping[str, object],
) -> None:
    """The ``people_watch`` event of one look, with ``extra`` keys."""
    ctx.record.record_event(
        "people_watch",
        {
            "round": ctx.round,
            "site_ned_m": site_ned_m,
            "person_cells": seen.cells,
            "nearest_m": None if seen.nearest_m is None else round(seen.nearest_m, 1),
            "seen_share": round(seen.seen_share, 2),
            "waited_s": round(waited_s, 1),
            "action": action,
            **extra,
        },
    )
