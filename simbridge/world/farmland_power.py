"""Farmland's power lines: wooden poles standing in the grid and the conductors strung between them as
:class:`~simbridge.world.world.Wire`\\ s, sagging as a parabola between each two poles.

A pole is a 0.3 m disc (at least one cell) 8-12 m tall painted ``MACHINERY`` over ``WOOD``: a fixed,
man-made obstacle that the grader keeps a touchdown 5 m from, like a parked machine (no class of its
own: nothing else in the model tells a pole from a machine). A transmission line crosses the whole
place on poles 9.5-12 m tall 60-85 m apart with three 2 cm conductors (one on the pole's top, two on a
crossarm 1.2 m either side; the crossarm is not painted, being thinner than a cell); a distribution
line on 8-9.5 m poles 45-65 m apart brings two 1.2 cm conductors from the edge to the village."""

from __future__ import annotations

import math

import numpy as np

from simbridge.world.city_parts import Range
from simbridge.world.farmland_plan import BUILT_CLASSES, FarmPlan, Pt
from simbridge.world.model import Material, SurfaceClass
from simbridge.world.world import Wire

POLE_R_M = 0.15
SAG_M: Range = (1.0, 2.0)
SPAN_SAMPLES = 16  # straight pieces per span
# (pole height, span, conductors as (across offset, height below the pole top), diameter)
TRANSMISSION = ((9.5, 12.0), (60.0, 85.0), ((-1.2, 0.5), (0.0, -0.2), (1.2, 0.5)), 0.02)
DISTRIBUTION = ((8.0, 9.5), (45.0, 65.0), ((-0.5, 0.3), (0.5, 0.3)), 0.012)
LineSpec = tuple[Range, Range, tuple[tuple[float, float], ...], float]


def sagging_span(a: np.ndarray, b: np.ndarray, sag_m: float, samples: int) -> np.ndarray:
    """(samples + 1, 3) points of a conductor from ``a`` to ``b`` (north, east, up), hanging ``sag_m``
    below the straight chord at mid-span (a parabola, close to the catenary for so shallow a sag)."""
    t = np.linspace(0.0, 1.0, samples + 1)[:, None]
    pts = a[None, :] + t * (b - a)[None, :]
    pts[:, 2] -= 4.0 * sag_m * (t[:, 0] * (1.0 - t[:, 0]))
    return np.asarray(pts, np.float64)


class FarmPower(FarmPlan):
    """Power lines: poles in the grid, conductors in ``self.wires``."""

    def _power_lines(self, village: Pt | None) -> int:
        """A transmission line across the whole place and a distribution line to the village."""
        theta = self._u((0.0, math.pi))
        through = (self._u((-0.25, 0.25)) * self.size, self._u((-0.25, 0.25)) * self.size)
        a, b = self._chord(through, theta)
        self._line(a, b, TRANSMISSION)
        if village is None:
            return 1
        edge_theta = self._u((0.0, 2 * math.pi))
        start, _ = self._chord(village, edge_theta)
        end = (village[0] + 25.0 * math.cos(edge_theta + 0.6), village[1] + 25.0 * math.sin(edge_theta + 0.6))
        self._line(start, self._clip_pt(end, 3.0), DISTRIBUTION)
        return 2

    def _chord(self, through: Pt, theta: float) -> tuple[Pt, Pt]:
        """Where the line through ``through`` at heading ``theta`` meets the place's edges (3 m in)."""
        d = (math.cos(theta), math.sin(theta))
        lim = self.half - 3.0
        ts = []
        for k in (0, 1):
            if abs(d[k]) > 1e-9:
                ts += [(lim - through[k]) / d[k], (-lim - through[k]) / d[k]]
        fwd = min(t for t in ts if t > 0)
        back = max(t for t in ts if t < 0)
        pa = self._clip_pt((through[0] + back * d[0], through[1] + back * d[1]), 3.0)
        pb = self._clip_pt((through[0] + fwd * d[0], through[1] + fwd * d[1]), 3.0)
        return pa, pb

    def _pole_spot(self, p: Pt, along: Pt) -> Pt:
        """``p``, or the nearest spot along the line within 12 m that stands on neither road nor building."""
        for shift in (0.0, 3.0, -3.0, 6.0, -6.0, 9.0, -9.0, 12.0, -12.0):
            q = self._clip_pt((p[0] + shift * along[0], p[1] + shift * along[1]), 3.0)
            if self.grid.class_at(*q) not in BUILT_CLASSES:
                return q
        return p

    def _line(self, a: Pt, b: Pt, spec: LineSpec) -> None:
        pole_h, span_m, conductors, diameter = spec
        length = math.dist(a, b)
        if length < span_m[0]:
            return
        along = ((b[0] - a[0]) / length, (b[1] - a[1]) / length)
        across = (-along[1], along[0])
        n_spans = max(1, math.ceil(length / self._u(span_m)))
        poles: list[tuple[float, float, float]] = []
        for k in range(n_spans + 1):
            t = k / n_spans
            spot = (a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]))
            if 0 < k < n_spans:
                spot = self._pole_spot(spot, along)
            h = self._u(pole_h)
            self.grid.fill_disc(spot, max(POLE_R_M, 0.76 * self.grid.res), height_m=h,
                                cls=SurfaceClass.MACHINERY, mat=Material.WOOD)  # fmt: skip
            poles.append((spot[0], spot[1], h))
            self.n_poles += 1
        sags = [self._u(SAG_M) for _ in range(n_spans)]
        for off, below in conductors:
            ends = np.array([(n + off * across[0], e + off * across[1], h - below) for n, e, h in poles])
            pieces = [sagging_span(ends[k], ends[k + 1], sags[k], SPAN_SAMPLES)[:-1] for k in range(n_spans)]
            pts = np.concatenate([*pieces, ends[-1:]])
            self.wires.append(Wire(tuple((float(p[0]), float(p[1]), float(p[2])) for p in pts), diameter))
