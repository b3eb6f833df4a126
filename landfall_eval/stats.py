"""How sure a campaign's safe rate is: 95 % intervals and whether two campaigns differ beyond chance.

A campaign's safe landings are ``k`` successes in ``n`` launches. Its safe rate ``k / n`` is given with
a two-sided 95 % interval: the Wilson score interval, which keeps its coverage near 95 % down to small
campaigns, except when every launch (or none) was safe, where the Clopper-Pearson exact interval is
used (for ``n`` safe of ``n`` its lower bound is ``0.025 ** (1 / n)``: 20 of 20 says only "at least
83 %", 300 of 300 "at least 98.8 %"). Two campaigns are compared with Fisher's exact test on their 2 x 2
table of safe and unsafe landings: a two-sided p-value under 0.05 says they differ beyond chance.
"""

from __future__ import annotations

import math

from scipy.special import betaincinv, ndtri  # scipy.special: importing scipy.stats costs about a second

__all__ = ["CONFIDENCE", "differ_p", "safe_interval"]

CONFIDENCE = 0.95


def safe_interval(safe: int, n: int, confidence: float = CONFIDENCE) -> tuple[float, float] | None:
    """The two-sided ``confidence`` interval of the rate behind ``safe`` of ``n`` (module docstring);
    None for no launches.

    Raises:
        ValueError: counts that are negative, ``safe`` above ``n``, or a confidence outside (0, 1).
    """
    if n < 0 or not 0 <= safe <= n:
        raise ValueError(f"need 0 <= safe <= n, got {safe} of {n}")
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must lie in (0, 1), got {confidence}")
    if n == 0:
        return None
    alpha = 1.0 - confidence
    if safe in (0, n):  # Clopper-Pearson: exact where Wilson's bound is least trustworthy
        lo = 0.0 if safe == 0 else float(betaincinv(safe, n - safe + 1, alpha / 2))
        hi = 1.0 if safe == n else float(betaincinv(safe + 1, n - safe, 1 - alpha / 2))
        return (lo, hi)
    z = _z(confidence)
    p = safe / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return (max(0.0, centre - half), min(1.0, centre + half))


def differ_p(safe_a: int, n_a: int, safe_b: int, n_b: int) -> float:
    """Fisher's exact two-sided p-value that campaigns A and B have the same safe rate.

    Raises:
        ValueError: counts as :func:`safe_interval` refuses them, or a campaign with no launches.
    """
    for safe, n in ((safe_a, n_a), (safe_b, n_b)):
        if n <= 0 or not 0 <= safe <= n:
            raise ValueError(f"need 0 <= safe <= n and n > 0, got {safe} of {n}")
    from scipy.stats import fisher_exact

    _odds, p = fisher_exact([[safe_a, n_a - safe_a], [safe_b, n_b - safe_b]])
    return float(p)


def _z(confidence: float) -> float:
    return float(ndtri(1 - (1 - confidence) / 2))
