"""The people watch through a descent onto a site off the roofs: while a descent step or the final
approach runs, a frame of its own every ``PEOPLE_WATCH_STEP_S`` and a look for people within
``people_margin_m`` of the site (:meth:`Looker.watch_people`). Someone seen stops the step where the
vehicle is, or turns the final approach into a climb to ``GO_AROUND_M`` above the site, and the
machine (:mod:`companion.recovery.machine`) looks again before the next step."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Coroutine
from typing import Any, TypeVar

from companion.control import TargetTimeout
from companion.reasoning.people_watch import PeopleSeen
from companion.recovery.core import (
    GO_AROUND_M,
    GO_AROUND_MIN_M,
    PEOPLE_WATCH_STEP_S,
    FrameUnavailable,
    RecoveryContext,
    State,
)
from companion.recovery.following import SiteFollower
from companion.recovery.landing import Lander
from companion.recovery.looking import Looker

T = TypeVar("T")


class PeopleWatch:
    """The people watch (module docstring) on the recovery's context, with the looker that looks, the
    follower that flies the steps and the lander that flies the final approach."""

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
            try:
                frame = await ctx.frames()
            except FrameUnavailable as exc:
                ctx.log.debug("no look for people on the way down: %s", exc)
                continue
            seen = await self.looker.watch_people(frame, site)
            if seen is not None and seen.cells:
                return seen
