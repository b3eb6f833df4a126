"""The results' episodes as the report reads them (:class:`Episode`, missing values as None), and the
report's errors."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from landfall_eval.episode_grade import describe_last_state
from landfall_eval.grading import failure_class

if TYPE_CHECKING:
    pass


class ReportError(RuntimeError):
    """The report cannot be written: a missing dependency or results that are not a results dict."""


class MatplotlibUnavailable(ReportError, ImportError):
    """matplotlib (the ``bench`` extra) is not installed."""


@dataclass(frozen=True, slots=True)
class Episode:
    """The fields of one ``episodes[]`` entry the report uses, with missing values as None."""

    number: int  # 1-based position in the results' episode list
    id: str
    scenario: str
    seed: int | None
    city_seed: int | None
    world_digest: str | None  # the static world it flew (simbridge's episode log)
    group: tuple[str, str]  # (reasoner, context)
    weather: str
    launch_ne: tuple[float, float] | None
    touchdown_ne: tuple[float, float] | None
    track_ne: np.ndarray  # (k, 2) north, east metres
    surface: str
    safe: bool
    outcome: str
    error: str | None
    reasons: tuple[str, ...]
    rounds: int | None
    time_to_touchdown_s: float | None
    kinematic_ratio: float | None
    landing_distance_m: float | None  # true touchdown to what the chosen pixel truly shows
    peak_rss_mb: float | None
    calls: tuple[tuple[str, str, float | None], ...]  # (stage, tier, latency_s)
    rationales: tuple[tuple[str, str], ...]  # (stage, text)
    last_state: str  # where an episode that never landed stood at its end ('' when unknown)
    failure: str | None  # grading.failure_class: None for a safe landing

    @property
    def verdict(self) -> str:
        """``safe``, ``unsafe`` (landed, graded unsafe) or ``none`` (no landing, timeout, error)."""
        if self.outcome != "landed" or self.touchdown_ne is None or self.surface == "no_landing":
            return "none"
        return "safe" if self.safe else "unsafe"


def read_episode(number: int, raw: Mapping[str, Any], config: Mapping[str, Any]) -> Episode:
    launch, touchdown = as_ne(raw.get("launch_ned_m")), as_ne(raw.get("touchdown_ned_m"))
    track = np.array(
        [p for p in (as_ne(q) for q in as_list(raw.get("trajectory_ne_m"))) if p is not None], np.float64
    ).reshape(-1, 2)
    companion = as_mapping(raw.get("companion"))
    rounds = as_number(raw.get("rounds"))
    return Episode(
        number=number,
        id=str(raw.get("id", "?")),
        scenario=str(raw.get("scenario", "?")),
        seed=int(s) if (s := as_number(raw.get("seed"))) is not None else None,
        city_seed=int(c) if (c := as_number(raw.get("city_seed"))) is not None else None,
        world_digest=d if isinstance(d := raw.get("world_digest"), str) else None,
        group=(
            str(raw.get("reasoner", config.get("reasoner", "?"))),
            str(raw.get("context", config.get("context", "?"))),
        ),
        weather=str(raw.get("weather", config.get("weather", "?"))),
        launch_ne=launch,
        touchdown_ne=touchdown,
        track_ne=track,
        surface=str(raw.get("surface") or "no_landing"),
        safe=raw.get("safe") is True,
        outcome=str(raw.get("outcome", "landed" if touchdown is not None else "error")),
        error=None if raw.get("error") is None else str(raw.get("error")),
        reasons=tuple(str(r) for r in as_list(raw.get("reasons"))),
        rounds=None if rounds is None else int(rounds),
        time_to_touchdown_s=as_number(raw.get("time_to_touchdown_s")),
        kinematic_ratio=as_number(raw.get("kinematic_ratio")),
        landing_distance_m=as_number(raw.get("landing_distance_m")),
        peak_rss_mb=as_number(companion.get("peak_rss_mb")),
        calls=tuple(
            (str(c.get("stage", "?")), str(c.get("tier", "?")), as_number(c.get("latency_s")))
            for c in as_list(raw.get("calls"))
            if isinstance(c, Mapping)
        ),
        rationales=tuple(
            (str(r.get("stage", "?")), str(r["text"]))
            for r in as_list(raw.get("rationales"))
            if isinstance(r, Mapping) and str(r.get("text") or "").strip()
        ),
        last_state=describe_last_state(raw.get("last_state")),
        failure=failure_class(raw),
    )


def as_number(x: object) -> float | None:
    """A finite number as float; None for anything else (missing, text, bool, NaN)."""
    if isinstance(x, bool) or not isinstance(x, int | float) or not math.isfinite(x):
        return None
    return float(x)


def as_ne(x: object) -> tuple[float, float] | None:
    if not isinstance(x, Sequence) or isinstance(x, str) or len(x) < 2:
        return None
    n, e = as_number(x[0]), as_number(x[1])
    return None if n is None or e is None else (n, e)


def as_mapping(x: object) -> Mapping[str, Any]:
    return x if isinstance(x, Mapping) else {}


def as_list(x: object) -> list[Any]:
    return x if isinstance(x, list) else []


INSTALL_HINT = "pip install 'landfall[bench]'"
