"""City-wide launch points from a Halton sequence (quasi-random, evenly spread, reproducible).

Launch ``k`` is point ``k + 1`` of the unscrambled Halton sequence in bases 2, 3 and 5 (point 0 is the
origin of every base; skipping it is the usual convention): the first two coordinates place it over
the city's square, inset by ``margin_m`` from its border so the camera sees city rather than the void
past its edge; the third sets the height above ground in ``[100, 120]`` m (the study's launch band).
Indices are stable: ``--start-index 20 --seeds 20`` continues where ``--seeds 20`` stopped.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["CITY_SIZE_M", "Launch", "halton_launches"]

CITY_SIZE_M = 1200.0  # simbridge's procedural city: north and east in [-600, 600] m
HEIGHT_BAND_M = (100.0, 120.0)


@dataclass(frozen=True, slots=True)
class Launch:
    index: int
    north_m: float
    east_m: float
    height_m: float  # above the ground under the launch point

    def as_tuple(self) -> tuple[float, float, float]:
        return (self.north_m, self.east_m, self.height_m)


def halton_launches(
    count: int, start_index: int = 0, *, size_m: float = CITY_SIZE_M, margin_m: float = 100.0
) -> list[Launch]:
    """Launches ``start_index`` .. ``start_index + count - 1`` over a ``size_m`` square city."""
    if count < 0 or start_index < 0:
        raise ValueError(f"count and start index must be >= 0, got {count} and {start_index}")
    half = size_m / 2 - margin_m
    if half <= 0:
        raise ValueError(f"margin {margin_m} m leaves nothing of a {size_m} m city")
    from scipy.stats import qmc  # here: scipy.stats takes about a second to import, and few runs need it

    seq = qmc.Halton(d=3, scramble=False)
    seq.fast_forward(start_index + 1)
    pts = seq.random(count) if count else []
    lo, hi = HEIGHT_BAND_M
    return [
        Launch(
            start_index + k,
            round(-half + 2 * half * float(p[0]), 2),
            round(-half + 2 * half * float(p[1]), 2),
            round(lo + (hi - lo) * float(p[2]), 2),
        )
        for k, p in enumerate(pts)
    ]
