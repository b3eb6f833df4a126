"""The onboard tier: deterministic, no network, milliseconds (issue 6 adds image cues and the
LVLM cascade). It ranks by geometry and always explains itself."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any, Protocol

from companion.perception.site_check import SiteCheck
from companion.perception.surface_id import Candidate

ROOF_HEIGHT_M = 3.0  # a surface this far above the lowest in view is taken for a roof, not a street


@dataclass(frozen=True, slots=True)
class Ranking:
    order: tuple[int, ...]  # candidate indices, best first
    rationale: str
    tier: str
    latency_s: float


@dataclass(frozen=True, slots=True)
class Decision:
    accept: bool
    rationale: str
    tier: str
    latency_s: float


class Reasoner(Protocol):
    name: str

    async def rank(self, candidates: list[Candidate], context: Any) -> Ranking: ...

    async def confirm(self, check: SiteCheck, context: Any) -> Decision: ...


def _score(c: Candidate) -> tuple[float, str]:
    if c.fallback:
        return -10.0 + 0.1 * (c.index == 4), "no flat surface measured there"
    notes = []
    s = math.log(max(c.area_m2, 1.0))
    s += 0.8 * min(c.edge_distance_m, 6.0)
    if c.height_above_m >= ROOF_HEIGHT_M:
        s += 4.0
        notes.append(f"elevated {c.height_above_m:.0f} m (a roof: away from traffic)")
    else:
        s -= 4.0
        notes.append("at street level (roads stay risky even when empty)")
    if math.isfinite(c.roughness_m):
        s -= 10.0 * max(c.roughness_m - 0.05, 0.0)
    notes.append(f"{c.area_m2:.0f} m2 flat, {c.edge_distance_m:.1f} m clear to its edge")
    return s, ", ".join(notes)


class OnboardReasoner:
    name = "onboard"

    async def rank(self, candidates: list[Candidate], context: Any = None) -> Ranking:
        t0 = time.monotonic()
        scored = sorted(((*_score(c), c.index) for c in candidates), key=lambda x: -x[0])
        _best_score, best_note, best = scored[0]
        rationale = f"site {best}: {best_note}"
        if len(scored) > 1:
            rationale += f"; next site {scored[1][2]}: {scored[1][1]}"
        return Ranking(tuple(int(s[2]) for s in scored), rationale, self.name, time.monotonic() - t0)

    async def confirm(self, check: SiteCheck, context: Any = None) -> Decision:
        t0 = time.monotonic()
        if check.clear:
            edge = (
                "no edge in view"
                if math.isinf(check.edge_distance_m)
                else f"{check.edge_distance_m:.1f} m to an edge"
            )
            why = f"clear: {check.points} returns, {100 * check.roughness_m:.0f} cm rough, {edge}"
        else:
            why = "rejected: " + "; ".join(check.reasons)
        return Decision(check.clear, why, self.name, time.monotonic() - t0)
