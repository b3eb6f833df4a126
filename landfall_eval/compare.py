"""``companion-bench compare A B``: whether two campaigns' safe rates differ beyond chance.

A and B are results.json files (or the folders holding them). Each campaign's safe landings among its
episodes are printed with the 95 % interval of its safe rate, then Fisher's exact two-sided p-value
that both come from the same rate (:mod:`landfall_eval.stats`): under 0.05, the campaigns differ beyond
chance; otherwise these launch counts cannot tell them apart. Episodes that never reached their alarm
(``error_kind`` infrastructure) are left out: they say nothing about a landing.

Exit status: 0 (the verdict is printed), 2 when a file cannot be read or holds no episode.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

from landfall_eval.stats import differ_p, safe_interval

__all__ = ["campaign_counts", "run_compare"]

SIGNIFICANT_P = 0.05


def campaign_counts(path: Path) -> tuple[int, int]:
    """(safe landings, episodes) of the campaign at ``path`` (results.json, or the folder holding it),
    infrastructure failures left out.

    Raises:
        ValueError: not readable as a companion-bench results.json, or no episode in it.
    """
    file = path / "results.json" if path.is_dir() else path
    try:
        results: Any = json.loads(file.read_text())
        episodes = [e for e in results["episodes"] if e.get("error_kind") != "infrastructure"]
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as exc:
        raise ValueError(f"{file}: not a companion-bench results.json ({exc})") from None
    if not episodes:
        raise ValueError(f"{file}: no episode to count")
    return sum(bool(e.get("safe")) for e in episodes), len(episodes)


def _line(name: str, safe: int, n: int) -> str:
    lo, hi = safe_interval(safe, n) or (0.0, 1.0)
    return f"{name}: {safe}/{n} safe ({100 * safe / n:.1f} %, 95 % interval {100 * lo:.1f}-{100 * hi:.1f} %)"


def run_compare(a: Path, b: Path) -> int:
    try:
        (sa, na), (sb, nb) = campaign_counts(a), campaign_counts(b)
    except ValueError as exc:
        print(f"companion-bench compare: {exc}", file=sys.stderr)
        return 2
    p = differ_p(sa, na, sb, nb)
    print(_line(f"A {a}", sa, na))
    print(_line(f"B {b}", sb, nb))
    verdict = (
        "they differ beyond chance" if p < SIGNIFICANT_P else "these launch counts cannot tell them apart"
    )
    print(f"Fisher's exact test, two-sided: p = {p:.3g}: {verdict} (at {SIGNIFICANT_P})")
    return 0
