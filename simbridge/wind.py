"""Steady wind plus seeded gusts (a first-order Gauss-Markov process per NED axis)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from simbridge.geo import Vec3


@dataclass(frozen=True, slots=True)
class WindConfig:
    """Steady wind (NED, m/s, the direction the air moves) and gust intensity.

    ``gust_sigma_m_s`` is the standard deviation of each horizontal gust component; the vertical
    one is half of it. ``gust_tau_s`` is the correlation time of the gusts.
    """

    steady_ned_m_s: Vec3 = (0.0, 0.0, 0.0)
    gust_sigma_m_s: float = 0.0
    gust_tau_s: float = 2.0


class WindModel:
    """Deterministic for a seed: the same seed and step count give the same wind."""

    def __init__(self, config: WindConfig, rng: np.random.Generator) -> None:
        if config.gust_sigma_m_s < 0 or config.gust_tau_s <= 0:
            raise ValueError(
                f"wind: gust_sigma_m_s must be >= 0 and gust_tau_s > 0, got "
                f"{config.gust_sigma_m_s} and {config.gust_tau_s}"
            )
        self._config = config
        self._rng = rng
        self._gust = [0.0, 0.0, 0.0]

    def step(self, dt_s: float) -> Vec3:
        """Advance the gusts by ``dt_s`` and return the total wind (NED, m/s)."""
        c = self._config
        if c.gust_sigma_m_s > 0:
            a = math.exp(-dt_s / c.gust_tau_s)
            noise = self._rng.standard_normal(3)
            for i, sigma in enumerate((c.gust_sigma_m_s, c.gust_sigma_m_s, c.gust_sigma_m_s / 2)):
                self._gust[i] = a * self._gust[i] + sigma * math.sqrt(1 - a * a) * float(noise[i])
        s = c.steady_ned_m_s
        return (s[0] + self._gust[0], s[1] + self._gust[1], s[2] + self._gust[2])
