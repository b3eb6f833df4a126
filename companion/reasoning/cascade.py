"""The tier cascade: the first valid answer within the stage deadline wins, and the onboard tier always
answers last (DESIGN.md section 8).

Each stage (rank, confirm) has its own tier order, e.g. cloud -> edge -> onboard, and a deadline (rank
10 s, confirm 6 s by default; a critical alarm multiplies both by ``critical_deadline_factor``, 0.5 by
default). The remote tiers share the deadline minus a small reserve kept for the onboard tier, which
needs milliseconds: a tier that errs (typed: refused, malformed, rate-limited...) hands over at once to
the next; a tier that is still thinking when its share of time is up is cancelled. So an answer always
comes, and always within the deadline.

A tier may be *hedged*: when it has not answered after ``hedge_after_s``, a second tier is started on the
same request and the first valid answer of the two wins (the other is cancelled).

**Confirmation arbitration.** Descent is allowed only with the reasoner's "yes" and no geometric veto
(the LiDAR site check: slope/roughness, an obstacle in the rotor-clearance disc, an edge too close).
The *lone-"no" rule*: a model may see hazards that are not there (the reference study saw "birds on the
roof"). When a remote tier says "no" to a site that the LiDAR check finds clear and the onboard tier's
image cues also pass, that "no" is counted against the site; after ``override_after`` such lone "no"s
for the same site (within ``same_site_m``; 1 for a critical alarm), the site is accepted and the record
says so. A "no" backed by anything (the geometry or the onboard cues) is never overridden, and without a
LiDAR check there is nothing to back an override, so it never happens.

The rule runs the other way too, where a mistake is not recoverable: a remote "yes" does not overrule a
*binding* onboard "no" (``Decision.binding``): water or lane markings on the site, or any rejection of a
site measured at street level. A model taken in by an empty road or an elevated highway deck is
outvoted there. On a roof its judgement stands over the onboard tier's softer doubts (a hazard score, a
blob the LiDAR shows is flat), and the LiDAR check decides: a model that believes a "LAND HERE" painted
on a cluttered roof descends only where the rotor disc is clear.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import time
from collections.abc import Awaitable, Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any, TypeVar

from companion.reasoning.base import (
    ConfirmRequest,
    DeadlineExceeded,
    Decision,
    Ranking,
    RankRequest,
    Reasoner,
    ReasonerError,
)

__all__ = ["Cascade", "CascadeParams", "Hedged"]

_log = logging.getLogger(__name__)

T = TypeVar("T", Ranking, Decision)
Q = TypeVar("Q", RankRequest, ConfirmRequest)


@dataclass(frozen=True, slots=True)
class CascadeParams:
    rank_deadline_s: float = 10.0
    confirm_deadline_s: float = 6.0
    critical_deadline_factor: float = 0.5
    reserve_s: float = 0.3  # kept back from the remote tiers for the onboard tier
    override_after: int = 2  # lone "no"s for one geometrically clear site before it is accepted
    same_site_m: float = 4.0


class Hedged:
    """``primary``, and ``secondary`` too when ``primary`` has not answered after ``after_s``."""

    def __init__(self, primary: Reasoner, secondary: Reasoner, after_s: float) -> None:
        self.primary, self.secondary, self.after_s = primary, secondary, after_s

    @property
    def name(self) -> str:
        return f"{self.primary.name}|{self.secondary.name}"

    async def rank(self, request: RankRequest) -> Ranking:
        return await self._race(lambda r: r.rank(request))

    async def confirm(self, request: ConfirmRequest) -> Decision:
        return await self._race(lambda r: r.confirm(request))

    async def _race(self, call: Callable[[Reasoner], Awaitable[T]]) -> T:
        tasks = [asyncio.ensure_future(call(self.primary))]
        errors: list[ReasonerError] = []
        try:
            done, _ = await asyncio.wait(tasks, timeout=self.after_s)
            if not done or tasks[0].exception() is not None:  # slow, or already failed: hedge now
                tasks.append(asyncio.ensure_future(call(self.secondary)))
            pending = set(tasks)
            while pending:
                done, pending = await asyncio.wait(pending, return_when=asyncio.FIRST_COMPLETED)
                for task in sorted(done, key=tasks.index):
                    exc = task.exception()
                    if exc is None:
                        return task.result()
                    if not isinstance(exc, ReasonerError):
                        raise exc
                    errors.append(exc)
            raise errors[-1]
        finally:
            for task in tasks:
                task.cancel()
            for task in tasks:
                with contextlib.suppress(BaseException):
                    await task


@dataclass
class _LoneNo:
    site_ne_m: tuple[float, float]
    count: int


class Cascade:
    """Ask tiers in order until one answers validly; arbitrate confirmations (module docstring).

    ``rank_tiers`` / ``confirm_tiers`` are the remote tiers in order; ``onboard`` answers when they
    cannot (it must not fail: it is deterministic local code). ``record(kind, fields)`` receives one
    ``"exchange"`` entry per tier call.
    """

    def __init__(
        self,
        rank_tiers: Sequence[Reasoner],
        confirm_tiers: Sequence[Reasoner],
        onboard: Reasoner,
        params: CascadeParams | None = None,
        record: Callable[[str, dict[str, Any]], None] | None = None,
    ) -> None:
        self.rank_tiers = tuple(rank_tiers)
        self.confirm_tiers = tuple(confirm_tiers)
        self.onboard = onboard
        self.p = params or CascadeParams()
        self._record = record or (lambda kind, fields: None)
        self._lone_no: list[_LoneNo] = []

    async def aclose(self) -> None:
        """Close the HTTP clients of the tiers that have one."""
        seen: set[int] = set()
        for tier in (*self.rank_tiers, *self.confirm_tiers):
            for t in (tier.primary, tier.secondary) if isinstance(tier, Hedged) else (tier,):
                close = getattr(t, "aclose", None)
                if close is not None and id(t) not in seen:
                    seen.add(id(t))
                    await close()

    @property
    def name(self) -> str:
        tiers = dict.fromkeys(t.name for t in (*self.rank_tiers, *self.confirm_tiers, self.onboard))
        return " > ".join(tiers)

    def deadline_s(self, stage: str, critical: bool) -> float:
        base = self.p.rank_deadline_s if stage == "rank" else self.p.confirm_deadline_s
        return base * (self.p.critical_deadline_factor if critical else 1.0)

    # ------------------------------------------------------------------ rank
    async def rank(self, request: RankRequest) -> Ranking:
        t0 = time.monotonic()
        deadline = t0 + self.deadline_s("rank", request.critical)
        answer = await self._first_valid(
            "rank", self.rank_tiers, request, deadline, lambda tier, req: tier.rank(req)
        )
        return replace(answer, latency_s=time.monotonic() - t0)

    # ------------------------------------------------------------------ confirm
    async def confirm(self, request: ConfirmRequest) -> Decision:
        t0 = time.monotonic()
        deadline = t0 + self.deadline_s("confirm", request.critical)
        answer = await self._first_valid(
            "confirm", self.confirm_tiers, request, deadline, lambda tier, req: tier.confirm(req)
        )
        decision = await self._arbitrate(answer, request)
        return replace(decision, latency_s=time.monotonic() - t0)

    async def _arbitrate(self, answer: Decision, request: ConfirmRequest) -> Decision:
        check = request.check
        if check is not None and not check.clear:
            veto = "; ".join(check.reasons)
            if answer.accept:
                why = f"geometric veto ({veto}) over {answer.tier}'s yes: {answer.rationale}"
            else:
                why = f"{answer.rationale} (and the LiDAR check: {veto})"
            return replace(answer, accept=False, rationale=why)
        if answer.tier == self.onboard.name or (not answer.accept and check is None):
            return answer
        # a remote answer on a site the LiDAR finds clear (or without a LiDAR): the onboard tier's view
        onboard = await self.onboard.confirm(replace(request, transcript=None))
        if answer.accept:
            if not onboard.binding:
                return answer
            return replace(
                answer,
                accept=False,
                rationale=f"onboard veto ({onboard.rationale}) over {answer.tier}'s yes: {answer.rationale}",
            )
        # a remote "no": is it a lone "no"? the onboard cues decide
        if not onboard.accept:
            return replace(answer, rationale=f"{answer.rationale} (onboard agrees: {onboard.rationale})")
        count = self._count_lone_no(request.site_ne_m)
        needed = 1 if request.critical else self.p.override_after
        if count < needed:
            return replace(
                answer,
                contested=True,
                rationale=(
                    f"{answer.rationale} (a lone no: LiDAR and onboard find the site clear; {count}/{needed})"
                ),
            )
        return replace(
            answer,
            accept=True,
            rationale=(
                f"accepted over {count} lone no from {answer.tier} ({answer.rationale[:120]}): "
                f"LiDAR clear and {onboard.rationale}"
            ),
        )

    def _count_lone_no(self, site: tuple[float, float] | None) -> int:
        if site is None:
            return 0
        for entry in self._lone_no:
            if math.dist(entry.site_ne_m, site) < self.p.same_site_m:
                entry.count += 1
                return entry.count
        self._lone_no.append(_LoneNo(site, 1))
        return 1

    # ------------------------------------------------------------------ the tier walk
    async def _first_valid(
        self,
        stage: str,
        tiers: Sequence[Reasoner],
        request: Q,
        deadline: float,
        call: Callable[[Reasoner, Q], Awaitable[T]],
    ) -> T:
        remote_deadline = deadline - self.p.reserve_s
        for tier in tiers:
            left = remote_deadline - time.monotonic()
            if left <= 0:
                break
            transcript: list[dict[str, Any]] = []
            req = replace(request, deadline=remote_deadline, transcript=transcript)
            t0 = time.monotonic()
            try:
                async with asyncio.timeout(left):
                    answer = await call(tier, req)
            except TimeoutError:
                self._log_exchange(stage, tier.name, t0, transcript, error=DeadlineExceeded("stage deadline"))
                continue
            except ReasonerError as exc:
                self._log_exchange(stage, tier.name, t0, transcript, error=exc)
                continue
            self._log_exchange(stage, tier.name, t0, transcript, answer=answer)
            return answer
        transcript = []
        t0 = time.monotonic()
        answer = await call(self.onboard, replace(request, deadline=deadline, transcript=transcript))
        self._log_exchange(stage, self.onboard.name, t0, transcript, answer=answer)
        return answer

    def _log_exchange(
        self,
        stage: str,
        tier: str,
        t0: float,
        transcript: list[dict[str, Any]],
        *,
        answer: Ranking | Decision | None = None,
        error: ReasonerError | None = None,
    ) -> None:
        fields: dict[str, Any] = {
            "stage": stage,
            "tier": tier,
            "latency_s": round(time.monotonic() - t0, 4),
            "transcript": transcript,
        }
        if isinstance(answer, Ranking):
            fields["parsed"] = {
                "order": list(answer.order),
                "rationale": answer.rationale,
                "tier": answer.tier,
            }
        elif isinstance(answer, Decision):
            fields["parsed"] = {"accept": answer.accept, "rationale": answer.rationale, "tier": answer.tier}
        if error is not None:
            fields["error"] = {"kind": error.kind, "message": str(error)}
            _log.warning("%s tier %s: %s: %s", stage, tier, error.kind, error)
        self._record("exchange", fields)
