"""What a campaign cost this machine: wall time, CPU seconds and episodes per core-hour.

Each command run into a campaign directory keeps its own figures in its ``runs`` entry of results.json
(``usage``), updated as each episode ends, so a campaign stopped part-way and resumed later still adds
up: :func:`campaign_usage` sums the runs. A core-hour is an hour of one of this machine's cores (those
this process may run on), busy or not: two cores for half an hour are one core-hour, and a campaign that
keeps them half idle pays for the idle half too. The CPU seconds are this process's and its children's
once they have ended (the episodes' simbridge and companion processes on the local executor); with
``--executor ray`` the episodes run in Ray's workers, and neither the CPU nor the cores are counted
(``cores`` and ``episodes_per_core_hour`` null).
"""

from __future__ import annotations

import os
import resource
import time
from collections.abc import Iterable
from typing import Any

__all__ = ["RunUsage", "campaign_usage", "cpu_seconds", "machine_cores"]


def cpu_seconds() -> float:
    """User plus system CPU seconds of this process and of the children it has waited for."""
    own, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def machine_cores() -> int:
    """The cores this process may run on (a ``taskset`` narrows them), else all of the machine's."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def _rate(episodes: int, wall_s: float, cores: int | None) -> float | None:
    core_h = wall_s * (cores or 0) / 3600.0
    return round(episodes / core_h, 1) if core_h > 0 else None


class RunUsage:
    """One command's figures from its start: :meth:`entry` as results.json keeps them."""

    def __init__(self, local: bool = True) -> None:
        self.cores = machine_cores() if local else None
        self._t0 = time.monotonic()
        self._cpu0 = cpu_seconds()

    def entry(self, episodes: int) -> dict[str, Any]:
        """``episodes`` ended in this command so far: its wall time, CPU and episodes per core-hour."""
        wall = time.monotonic() - self._t0
        return {
            "episodes": episodes,
            "wall_s": round(wall, 1),
            "cpu_s": round(cpu_seconds() - self._cpu0, 1) if self.cores else None,
            "cores": self.cores,
            "episodes_per_core_hour": _rate(episodes, wall, self.cores),
        }


def campaign_usage(runs: Iterable[dict[str, Any]]) -> dict[str, Any] | None:
    """The sum over the runs that kept their figures (each its own cores): episodes, wall time, CPU
    seconds, core-hours and episodes per core-hour; None when no run kept them."""
    kept = [u for u in (r.get("usage") for r in runs) if u and u.get("cores")]
    if not kept:
        return None
    episodes = sum(int(u["episodes"]) for u in kept)
    core_h = sum(float(u["wall_s"]) * int(u["cores"]) for u in kept) / 3600.0
    return {
        "runs": len(kept),
        "episodes": episodes,
        "wall_s": round(sum(float(u["wall_s"]) for u in kept), 1),
        "cpu_s": round(sum(float(u["cpu_s"] or 0.0) for u in kept), 1),
        "core_hours": round(core_h, 3),
        "episodes_per_core_hour": round(episodes / core_h, 1) if core_h > 0 else None,
    }
