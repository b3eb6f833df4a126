"""What every reasoning tier takes and gives, and how it fails (DESIGN.md section 8).

A tier answers two questions. **Rank**: given up to 5 candidate crops (and, when Surface ID had depth,
their geometry), which is the safest place to land, best first. **Confirm**: given a close-up of the site
the vehicle now hovers over (and, with a LiDAR, the geometric site check), is it still safe to descend.

Tiers are the onboard scorer (no network, milliseconds) and OpenAI-compatible vision-language models.
Every failure a tier can have is a :class:`ReasonerError` subclass, so the cascade can tell a slow answer
from a refusal from a malformed one and the flight record can say which it was.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from companion.perception.site_check import SiteCheck
from companion.perception.surface_id import Candidate

__all__ = [
    "HAZARD_KINDS",
    "ConfirmRequest",
    "DeadlineExceeded",
    "Decision",
    "EmptyAnswer",
    "EndpointError",
    "ErrorBody",
    "InvalidIndices",
    "MalformedAnswer",
    "NotConfigured",
    "RankRequest",
    "Ranking",
    "RateLimited",
    "Reasoner",
    "ReasonerError",
    "Refusal",
    "TruncatedAnswer",
    "Unreachable",
]


@dataclass(frozen=True, slots=True)
class RankRequest:
    """Candidates to order, best landing site first.

    ``crops`` are RGB uint8 images, one per candidate, in candidate order (index k is crop k).
    ``candidates`` carries Surface ID's geometry for the same indices, or is ``None`` when only images are
    known (degraded mode: no depth, or ``companion-eval rank`` on image files). ``context`` is the whole
    frame when the configured context variant sends it. ``critical`` is set for a critical alarm.
    ``cores``, with padded crops, gives each candidate's own box inside its crop (x0, y0, x1, y1 pixels):
    the padding is context around the site, not part of it.
    """

    crops: tuple[np.ndarray, ...]
    candidates: tuple[Candidate, ...] | None = None
    context: np.ndarray | None = None
    critical: bool = False
    cores: tuple[tuple[int, int, int, int], ...] | None = None
    deadline: float | None = None  # time.monotonic() by which the answer is needed (set by the cascade)
    transcript: list[dict[str, Any]] | None = field(default=None, compare=False)  # exchanges are appended

    def __post_init__(self) -> None:
        if not self.crops:
            raise ValueError("a rank request needs at least one candidate crop")
        if self.candidates is not None and len(self.candidates) != len(self.crops):
            raise ValueError(f"{len(self.crops)} crops but {len(self.candidates)} candidates")
        if self.cores is not None:
            if len(self.cores) != len(self.crops):
                raise ValueError(f"{len(self.crops)} crops but {len(self.cores)} cores")
            for k, (img, (x0, y0, x1, y1)) in enumerate(zip(self.crops, self.cores, strict=True)):
                h, w = np.shape(img)[:2]
                if not (0 <= x0 < x1 <= w and 0 <= y0 < y1 <= h):
                    raise ValueError(f"core {k} {(x0, y0, x1, y1)} is not a box inside its {w} x {h} crop")


@dataclass(frozen=True, slots=True)
class ConfirmRequest:
    """A close-up of the site under the vehicle: safe to descend onto, or not.

    ``check`` is the geometric site check from the LiDAR (``None`` without one); the reasoner's answer
    is its own, and the cascade applies the geometric veto on top.

    Both requests carry an optional ``deadline`` (a ``time.monotonic()`` instant: remote tiers size their
    attempts and retries to it) and ``transcript``, a list each tier appends its exchanges to (prompt,
    image references, raw answer, status, latency, error) for the flight record.
    """

    image: np.ndarray
    check: SiteCheck | None = None
    critical: bool = False
    site_ne_m: tuple[float, float] | None = None  # where the site is, for the lone-"no" rule
    site_up_m: float | None = None  # the site's height above its surroundings (Surface ID), if measured
    site_strip: bool = False  # Surface ID measured the site on an elevated strip (a deck, not a roof)
    built_up: bool = False  # roofs in view or measured near the site: a town, where streets carry people
    site_area_m2: float | None = None  # the landable area of the site's surface (Surface ID), if measured
    site_edge_m: float | None = None  # the site's distance from its surface's edge (Surface ID), if measured
    deadline: float | None = None
    transcript: list[dict[str, Any]] | None = field(default=None, compare=False)


@dataclass(frozen=True, slots=True)
class Ranking:
    order: tuple[int, ...]  # candidate indices, best first (may omit candidates judged unlandable)
    rationale: str
    tier: str
    latency_s: float


@dataclass(frozen=True, slots=True)
class Decision:
    accept: bool
    rationale: str
    tier: str
    latency_s: float
    # a "no" from a remote tier alone, on a site the LiDAR and the onboard cues find clear: the site stays
    # eligible, and the lone-"no" rule (companion/reasoning/cascade.py) may accept it on a later round
    contested: bool = False
    # an onboard "no" that no other tier's "yes" may overrule: water or lane markings on the site, or any
    # rejection of a site measured at street level or on an elevated strip (DESIGN.md: roads stay risky
    # even when empty)
    binding: bool = False
    # what the onboard tier saw against the site, by kind (``HAZARD_KINDS``); empty from other tiers
    hazards: tuple[str, ...] = ()
    # the image judgement was unsure (the onboard tier's net: its clear-site probability near its
    # threshold, or its views disagreeing): the rationale says so, and an accepted site is looked at
    # again from closer before the full descent step (companion/recovery/machine.py)
    unsure: bool = False
    # accepted as open ground (a field, a lawn, a terrace on a slope: the onboard tier's net judge), not
    # as a roof: people may walk onto it, so the descent watches for them even where Surface ID measured
    # the site above its surroundings (companion/recovery/machine.py)
    open_ground: bool = False


# The kinds of ``Decision.hazards``: what the recovery's least-bad-site policy ranks sites by.
HAZARD_KINDS = (
    "lidar_obstacle",  # the LiDAR check: an object in the rotor disc
    "lidar_rough",
    "lidar_slope",  # the surface's plane sloped over the limit (8 degrees)
    "lidar_edge",
    "water",
    "vegetation",
    "canopy",  # a tree's crown over the site: green and textured (the net judge's pixel measure)
    "markings",  # lane markings (a painted line at street level or on a deck)
    "street_asphalt",  # asphalt at street level or on a deck: a road, a car park
    "street_level",  # street level among buildings: sidewalks, plazas (people), kept as a last resort
    "cramped",  # open ground, but too small or too near its edge (where people pass): a small garden
    "raised",  # people, vehicles, rooftop objects
    "raised_lines",  # pipes, rails
    "hazard",  # the total hazard score over its limit, or the net's clear-site confidence under its threshold
    "not_clear",  # the net sure it is no clear roof (its clear-site confidence under 0.2): something is there
)


class Reasoner(Protocol):
    """One tier. ``name`` is what the flight record and the JSON outputs call it."""

    @property
    def name(self) -> str: ...

    async def rank(self, request: RankRequest) -> Ranking: ...

    async def confirm(self, request: ConfirmRequest) -> Decision: ...


# --------------------------------------------------------------------------------------------- failures
class ReasonerError(Exception):
    """A tier gave no usable answer. ``kind`` is a stable short name for records and JSON."""

    kind = "error"


class DeadlineExceeded(ReasonerError):
    kind = "deadline"


class NotConfigured(ReasonerError):
    """The tier cannot be called as configured (no API key in its environment variable)."""

    kind = "not_configured"


class Unreachable(ReasonerError):
    """No HTTP exchange completed (connection refused, DNS, TLS, reset)."""

    kind = "unreachable"


class EndpointError(ReasonerError):
    """An HTTP status other than 200."""

    kind = "http"

    def __init__(self, message: str, status: int, retry_after_s: float | None = None) -> None:
        super().__init__(message)
        self.status = status
        self.retry_after_s = retry_after_s

    @property
    def retryable(self) -> bool:
        return self.status in (408, 409, 425, 429) or self.status >= 500


class RateLimited(EndpointError):
    kind = "rate_limited"


class ErrorBody(ReasonerError):
    """HTTP 200 whose body is an error object, not a completion."""

    kind = "error_body"


class Refusal(ReasonerError):
    kind = "refusal"


class EmptyAnswer(ReasonerError):
    kind = "empty"


class TruncatedAnswer(ReasonerError):
    """The answer stopped early (``finish_reason`` "length", or JSON cut off)."""

    kind = "truncated"


class MalformedAnswer(ReasonerError):
    """The answer cannot be read as the schema asks."""

    kind = "malformed"


class InvalidIndices(MalformedAnswer):
    """A ranking with out-of-range or repeated candidate indices."""

    kind = "invalid_indices"
