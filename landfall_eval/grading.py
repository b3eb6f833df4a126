"""Grading a landing from simbridge's ground truth, the kinematic lower bound, and run summaries.

Nothing here reads the companion's beliefs: the surface and the verdict come from simbridge's touchdown
event (``simbridge/world/grader.py`` on the world grid at touchdown time).

**Surface classes** (``SURFACES``): simbridge's own class names, with one refinement: a touchdown on a
clear flat roof that the grader failed for an object within the rotor-clearance disc (clutter, a
parapet, a person, a vehicle, a tree, a rail or any object taller than 0.3 m) is ``rooftop_obstructed``,
which is what the study counted as a "cluttered roof". A flight into a building's wall (or anything
standing taller than the vehicle flew) is ``collision``: simbridge ends the episode with the wreck's
touchdown, unsafe. An episode that never touched down is ``no_landing``.

**Kinematic lower bound**: the shortest time in which the vehicle could have gone from where it was
when the companion took control to where it touched down, at its limits (simbridge's ``ControlLimits``:
5 m/s and 3 m/s^2 horizontally, 1.5 m/s down): a straight flight to above the site, accelerating and
braking at the limit, plus the descent at the maximum sink rate. No real landing can beat it; the ratio
of the real time to it (``kinematic_ratio``) measures what rounds, confirmations and hovering cost.
"""

from __future__ import annotations

import math
import statistics
from collections import Counter
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

from landfall_eval.stats import safe_interval
from simbridge.control import ControlLimits

__all__ = [
    "SURFACES",
    "failure_class",
    "kinematic_lower_bound_s",
    "summarise",
    "surface_class",
    "trapezoid_time_s",
]

SURFACES = (
    "rooftop_clear",
    "rooftop_obstructed",
    "road",
    "highway",
    "sidewalk",
    "parking",
    "park",
    "water",
    "pool",
    "pier",
    "ground",
    "rail",
    "machinery",
    "crops",
    "outside",
    "collision",
    "no_landing",
)
PERSON_MARGIN_M = 10.0  # the grader's person rule (simbridge GraderConfig.person_m)
_OBSTRUCTION_WORDS = (
    "within", "rooftop object", "parapet", "person", "vehicle", "tree", "guard rail", "machinery",
)  # fmt: skip


def surface_class(touchdown: Mapping[str, Any] | None) -> str:
    """The graded surface class of a touchdown event (``None``: no touchdown, ``no_landing``)."""
    if touchdown is None:
        return "no_landing"
    surface = str(touchdown.get("surface", "no_landing"))
    if surface not in SURFACES:
        raise ValueError(f"unknown touchdown surface {surface!r}; known: {', '.join(SURFACES)}")
    reasons = [str(r) for r in touchdown.get("reasons", ())]
    if surface == "rooftop_clear" and any(w in r for r in reasons for w in _OBSTRUCTION_WORDS):
        return "rooftop_obstructed"
    return surface


def failure_class(entry: Mapping[str, Any]) -> str | None:
    """What went wrong in one results.json entry, as a class to count campaigns by (None: a safe
    landing): ``error (infrastructure)`` (never got to the alarm), ``error`` (a process died during the
    episode), ``no touchdown`` (a timeout), ``unsafe: SURFACE`` for a landing graded unsafe (on a
    surface that may be safe, such as a clear roof or open ground, with what made it unsafe:
    ``unsafe: rooftop_clear (slope)``)."""
    if entry.get("safe") is True:
        return None
    outcome = entry.get("outcome")
    if outcome == "error":
        return "error (infrastructure)" if entry.get("error_kind") == "infrastructure" else "error"
    surface = str(entry.get("surface") or "no_landing")
    if outcome != "landed" or surface == "no_landing":
        return "no touchdown"
    if surface in ("rooftop_clear", "ground", "park", "parking"):
        reasons = " ".join(str(r) for r in entry.get("reasons") or ())
        words = ("edge", "slope", "rough", "outside", "person", "vehicle", "machinery", "wire")
        why = next((w for w in words if w in reasons), None)
        if why is not None:
            return f"unsafe: {surface} ({why})"
    return f"unsafe: {surface}"


def trapezoid_time_s(dist_m: float, v_max: float, a_max: float) -> float:
    """Shortest time to cover ``dist_m`` from rest to rest at speed <= v_max and |acceleration| <= a_max."""
    if dist_m < 0 or v_max <= 0 or a_max <= 0:
        raise ValueError(f"need dist >= 0 and positive limits, got {dist_m}, {v_max}, {a_max}")
    ramp_m = v_max * v_max / a_max  # accelerate to v_max and brake again
    if dist_m <= ramp_m:
        return 2.0 * math.sqrt(dist_m / a_max)
    return 2.0 * v_max / a_max + (dist_m - ramp_m) / v_max


def kinematic_lower_bound_s(
    start_ned_m: Sequence[float], touchdown_ned_m: Sequence[float], limits: ControlLimits | None = None
) -> float:
    """Straight flight to above the touchdown point plus the descent, both at the vehicle's limits."""
    lim = limits or ControlLimits()
    horiz = math.hypot(touchdown_ned_m[0] - start_ned_m[0], touchdown_ned_m[1] - start_ned_m[1])
    down = max(touchdown_ned_m[2] - start_ned_m[2], 0.0)
    return trapezoid_time_s(horiz, lim.max_speed_xy_m_s, lim.max_accel_xy_m_s2) + trapezoid_time_s(
        down, lim.max_speed_down_m_s, lim.max_accel_z_m_s2
    )


def _median(values: Iterable[float | None]) -> float | None:
    got = [v for v in values if v is not None]
    return round(statistics.median(got), 3) if got else None


def _mean(values: Iterable[float | None]) -> float | None:
    got = [v for v in values if v is not None]
    return round(statistics.fmean(got), 3) if got else None


def summarise(episodes: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """``summary`` of results.json: safe rate, rounds, times, surfaces, per group and per weather."""
    n = len(episodes)
    safe = [e for e in episodes if e.get("safe")]
    by_surface = Counter(str(e.get("surface", "no_landing")) for e in episodes)
    calls: dict[str, dict[str, list[float]]] = {}
    for e in episodes:
        for c in e.get("calls", ()):
            calls.setdefault(str(c["stage"]), {}).setdefault(str(c["tier"]), []).append(float(c["latency_s"]))
    groups: dict[tuple[str, str, str, int], list[Mapping[str, Any]]] = {}
    for e in episodes:
        city = e.get("city_seed")
        key = (
            str(e.get("reasoner")),
            str(e.get("context")),
            str(e.get("weather")),
            -1 if city is None else int(city),
        )
        groups.setdefault(key, []).append(e)
    failures: dict[str, list[str]] = {}
    for e in episodes:
        if (cls := failure_class(e)) is not None:
            failures.setdefault(cls, []).append(str(e.get("id")))

    def rate(items: Sequence[Mapping[str, Any]]) -> float | None:
        return round(sum(bool(e.get("safe")) for e in items) / len(items), 4) if items else None

    def interval(items: Sequence[Mapping[str, Any]]) -> list[float] | None:
        got = safe_interval(sum(bool(e.get("safe")) for e in items), len(items))
        return None if got is None else [round(got[0], 4), round(got[1], 4)]

    def by(key: str) -> dict[str, dict[str, Any]]:
        """The safe rate and its interval for each value ``key`` takes among the episodes."""
        split: dict[str, list[Mapping[str, Any]]] = {}
        for e in episodes:
            split.setdefault(str(e.get(key)), []).append(e)
        return {
            value: {"episodes": len(items), "safe": sum(bool(e.get("safe")) for e in items),
                    "safe_rate": rate(items), "safe_rate_interval_95": interval(items)}
            for value, items in sorted(split.items())
        }  # fmt: skip

    def mean_rounds(items: Sequence[Mapping[str, Any]]) -> float | None:
        got = [int(e["rounds"]) for e in items if e.get("safe")]
        return round(statistics.fmean(got), 3) if got else None

    near = [float(e["nearest_person_m"]) for e in episodes if e.get("nearest_person_m") is not None]
    rss = [float(e["companion"]["peak_rss_mb"]) for e in episodes if e.get("companion")]
    anon = [
        float(e["companion"]["peak_anon_mb"])
        for e in episodes
        if "peak_anon_mb" in (e.get("companion") or {})
    ]
    return {
        "episodes": n,
        "safe": len(safe),
        "safe_rate": rate(episodes),
        "safe_rate_interval_95": interval(episodes),
        "by": {key: by(key) for key in ("place", "weather", "autopilot", "criticality")},
        "mean_rounds_safe": mean_rounds(episodes),
        "within_2_rounds_safe": (
            round(sum(int(e["rounds"]) <= 2 for e in safe) / len(safe), 4) if safe else None
        ),
        "outcomes": dict(Counter(str(e.get("outcome")) for e in episodes)),
        "by_surface": {s: by_surface[s] for s in SURFACES if by_surface[s]},
        # people: the nearest at touchdown over the touchdowns that had people in their world
        "nearest_person_min_m": min(near) if near else None,
        "touchdowns_within_10m_of_a_person": sum(d <= PERSON_MARGIN_M for d in near),
        "median_time_to_touchdown_s": _median(e.get("time_to_touchdown_s") for e in episodes),
        "median_kinematic_ratio": _median(e.get("kinematic_ratio") for e in episodes),
        "median_touchdown_to_site_m": _median(e.get("touchdown_to_site_m") for e in episodes),
        "median_landing_distance_m": _median(e.get("landing_distance_m") for e in episodes),
        "mean_landing_distance_m": _mean(e.get("landing_distance_m") for e in episodes),
        "companion_peak_rss_mb": round(max(rss), 1) if rss else None,
        "companion_peak_anon_mb": round(max(anon), 1) if anon else None,  # results before 2026-11-27: none
        "latency_s": {
            stage: {
                tier: {
                    "calls": len(v),
                    "median": round(statistics.median(v), 4),
                    "p90": round(sorted(v)[min(len(v) - 1, math.ceil(0.9 * len(v)) - 1)], 4),
                }
                for tier, v in sorted(tiers.items())
            }
            for stage, tiers in sorted(calls.items())
        },
        "recoveries_with_defect": sum(int(e.get("defects") or 0) > 0 for e in episodes),
        "failures": {cls: sorted(ids) for cls, ids in sorted(failures.items())},
        "groups": [
            {
                "reasoner": r,
                "context": c,
                "weather": w,
                "city_seed": None if city < 0 else city,
                "episodes": len(items),
                "safe": sum(bool(e.get("safe")) for e in items),
                "safe_rate": rate(items),
                "safe_rate_interval_95": interval(items),
                "mean_rounds_safe": mean_rounds(items),
                "median_kinematic_ratio": _median(e.get("kinematic_ratio") for e in items),
            }
            for (r, c, w, city), items in sorted(groups.items())
        ],
    }
