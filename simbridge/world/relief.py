"""Terrain relief under a procedural place: a seeded smooth height field, and the helpers that level it
for what is built on it (roads cut level across their width, platforms, terraces) and lay a built grid
over it.

A place with relief is painted as if its ground were flat (every height metres up from the *local*
ground: a lawn at 0, a sidewalk at 0.15 m, a roof at 7 m) while a ground raster of the same shape is
shaped beside it; :func:`lay_over` then adds the ground under everything. So a building's base is the
height of the platform it stands on, and every painter written for flat places works unchanged.

The relief (:func:`make_relief`) is drawn on a coarse raster (``ReliefParams.res_m``, 2 m) and
resampled bilinearly to the grid: a valley whose floor meanders across the square and whose sides rise
``rise_m`` on either hand (a smoothstep across ``side_m``), or rolling ground without one; a few
random bumps, hollows and spurs (Gaussian, some elongated) on top; and a soft staircase
(``h - a P/2pi sin(2pi h/P)``) that turns every ``bench_step_m`` of height into a flatter bench with a
steeper rise above it. Heights are metres up from the scenario origin's level; the valley floor lies
near 0.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from simbridge.world.model import WorldError, WorldGrid

Range = tuple[float, float]
BEYOND_GRADE = 0.08  # past the top of a valley side the ground keeps rising, gently


@dataclass(frozen=True, slots=True)
class ReliefParams:
    """The relief's knobs: ranges are ``(min, max)`` drawn once per relief; lengths and heights in
    metres."""

    valley: bool = True  # a valley across the square (east-west); False: rolling ground
    rise_m: Range = (30.0, 80.0)  # each side's rise above the valley floor (rolling: the bumps' relief)
    floor_m: Range = (35.0, 60.0)  # half-width of the valley floor
    side_m: Range = (250.0, 360.0)  # horizontal run of a valley side, floor to top
    meander_m: Range = (15.0, 50.0)  # amplitude of the valley's sideways meander
    tilt: Range = (-0.012, 0.012)  # the floor's fall along the valley, metres per metre
    bumps: int = 24
    bump_m: Range = (4.0, 16.0)
    bump_sigma_m: Range = (35.0, 120.0)
    bench_step_m: Range = (14.0, 22.0)  # height between benches
    bench_strength: float = 0.75  # 0: no benches; below 1: benches flatter by this much
    res_m: float = 2.0

    def __post_init__(self) -> None:
        if not 0.0 <= self.bench_strength < 1.0:
            raise WorldError(f"ReliefParams.bench_strength must be in [0, 1), got {self.bench_strength}")
        if not 0.5 <= self.res_m <= 20.0:
            raise WorldError(f"ReliefParams.res_m must be in [0.5, 20] m, got {self.res_m}")


@dataclass(frozen=True, slots=True)
class Relief:
    """A height field on a coarse raster: ``z[i, j]`` is the height (metres up) at the centre of
    coarse cell ``(i, j)``, north ``n0 + (i + 0.5) res``, east ``e0 + (j + 0.5) res``."""

    n0: float
    e0: float
    res: float
    z: np.ndarray  # float32 (rows, cols)
    valley_n: np.ndarray | None  # float64 (cols,): the valley floor's north per coarse column, or None

    def sample(self, north_m: np.ndarray | float, east_m: np.ndarray | float) -> np.ndarray:
        """Heights at points (any broadcastable shapes), bilinear between the coarse cells' centres,
        held at the edge beyond them."""
        n, e = np.broadcast_arrays(np.asarray(north_m, np.float64), np.asarray(east_m, np.float64))
        rows, cols = self.z.shape
        fi = np.clip((n - self.n0) / self.res - 0.5, 0.0, rows - 1.0)
        fj = np.clip((e - self.e0) / self.res - 0.5, 0.0, cols - 1.0)
        i, j = np.minimum(fi.astype(np.int64), rows - 2), np.minimum(fj.astype(np.int64), cols - 2)
        a, b = fi - i, fj - j
        z = self.z.astype(np.float64)
        return np.asarray(
            (1 - a) * ((1 - b) * z[i, j] + b * z[i, j + 1])
            + a * ((1 - b) * z[i + 1, j] + b * z[i + 1, j + 1])
        )

    def valley_at(self, east_m: np.ndarray | float) -> np.ndarray:
        """The valley floor's north at ``east_m``; 0 where the relief has no valley."""
        if self.valley_n is None:
            return np.zeros_like(np.asarray(east_m, np.float64))
        cols = len(self.valley_n)
        centres = self.e0 + (np.arange(cols) + 0.5) * self.res
        return np.asarray(np.interp(east_m, centres, self.valley_n))

    def raster(self, grid: WorldGrid) -> np.ndarray:
        """The relief resampled to ``grid``'s cells: float32 (rows, cols), bilinear (``cv2.resize``
        where the coarse raster covers the grid exactly, as :func:`make_relief` draws it)."""
        rows, cols = grid.shape
        ratio = self.res / grid.res
        if (
            abs(ratio - round(ratio)) < 1e-9
            and self.z.shape[0] * round(ratio) == rows
            and self.z.shape[1] * round(ratio) == cols
            and abs(self.n0 - grid.n0) < 1e-9
            and abs(self.e0 - grid.e0) < 1e-9
        ):
            return np.asarray(cv2.resize(self.z, (cols, rows), interpolation=cv2.INTER_LINEAR), np.float32)
        out = np.empty((rows, cols), np.float32)
        e = grid.e0 + (np.arange(cols) + 0.5) * grid.res
        for i0 in range(0, rows, 512):
            n = grid.n0 + (np.arange(i0, min(i0 + 512, rows)) + 0.5) * grid.res
            out[i0 : i0 + len(n)] = self.sample(n[:, None], e[None, :])
        return out

    def slope_deg(self) -> np.ndarray:
        """The slope of the coarse raster at each coarse cell, degrees (central differences)."""
        gn, ge = np.gradient(self.z.astype(np.float64), self.res)
        return np.asarray(np.degrees(np.arctan(np.hypot(gn, ge))))


def make_relief(
    rng: np.random.Generator, north_m: Range, east_m: Range, params: ReliefParams | None = None
) -> Relief:
    """A smooth height field over north ``north_m`` by east ``east_m`` (``(min, max)``, metres), drawn
    from ``rng`` alone: the same generator state, the same relief.

    Raises:
        WorldError: an extent not a whole number of ``params.res_m`` cells, or an empty one.
    """
    p = params or ReliefParams()
    rows_f, cols_f = (north_m[1] - north_m[0]) / p.res_m, (east_m[1] - east_m[0]) / p.res_m
    rows, cols = round(rows_f), round(cols_f)
    if rows < 2 or cols < 2 or abs(rows - rows_f) > 1e-6 or abs(cols - cols_f) > 1e-6:
        raise WorldError(
            f"relief extent {north_m} x {east_m} is not a whole number (>= 2) of {p.res_m} m cells"
        )

    def u(r: Range) -> float:
        return float(rng.uniform(r[0], r[1]))

    n = north_m[0] + (np.arange(rows) + 0.5) * p.res_m
    e = east_m[0] + (np.arange(cols) + 0.5) * p.res_m
    nn, ee = np.meshgrid(n, e, indexing="ij")
    size = max(north_m[1] - north_m[0], east_m[1] - east_m[0])
    valley_n: np.ndarray | None = None
    if p.valley:
        centre = (north_m[0] + north_m[1]) / 2 + u((-0.05, 0.05)) * size
        wave, phase, amp = u((0.8, 1.6)) * size, u((0.0, 2 * math.pi)), u(p.meander_m)
        valley_n = centre + amp * np.sin(2 * math.pi * e / wave + phase)
        d = nn - valley_n[None, :]
        floor, rise_n, rise_s = u(p.floor_m), u(p.rise_m), u(p.rise_m)
        run_n, run_s = u(p.side_m), u(p.side_m)
        t = np.clip((np.abs(d) - floor) / np.where(d > 0, run_n, run_s), 0.0, 1.0)
        shape = t * t * (3.0 - 2.0 * t)
        beyond = np.maximum(np.abs(d) - floor - np.where(d > 0, run_n, run_s), 0.0)
        base = np.where(d > 0, rise_n, rise_s) * shape + BEYOND_GRADE * beyond + u(p.tilt) * ee
        weight = 0.3 + 0.7 * shape  # the floor stays smoother than the sides
    else:
        base = np.zeros_like(nn)
        weight = np.ones_like(nn)
    bumps = np.zeros_like(nn)
    for _ in range(p.bumps):
        cn, ce = u(north_m), u(east_m)
        sigma, stretch, yaw = u(p.bump_sigma_m), u((1.0, 3.0)), u((0.0, math.pi))
        amp = u(p.bump_m) * float(rng.choice([-1.0, 1.0]))
        c, s = math.cos(yaw), math.sin(yaw)
        a = ((nn - cn) * c + (ee - ce) * s) / (sigma * stretch)  # spurs and gullies: elongated
        b = (-(nn - cn) * s + (ee - ce) * c) / sigma
        bumps += amp * np.exp(-0.5 * (a * a + b * b))
    if not p.valley:  # rolling ground: scale the bumps to the relief asked for
        span = float(bumps.max() - bumps.min())
        bumps *= u(p.rise_m) / max(span, 1e-6)
        bumps -= bumps.min()
    h = base + weight * bumps
    step = u(p.bench_step_m)
    h = h - p.bench_strength * step / (2 * math.pi) * np.sin(2 * math.pi * h / step)
    return Relief(north_m[0], east_m[0], p.res_m, h.astype(np.float32), valley_n)


# ---------------------------------------------------------------------- shaping a ground raster
def level_rect(
    ground: np.ndarray,
    grid: WorldGrid,
    centre_ne: tuple[float, float],
    length_m: float,
    width_m: float,
    yaw_rad: float,
    height_m: float,
    shoulder_m: float = 0.0,
) -> None:
    """Level a rotated rectangle of ``ground`` (float32, ``grid``'s shape) to ``height_m``, blending
    back to the ground as it was over ``shoulder_m`` around it (a cutting or an embankment); with no
    shoulder its edges are walls (a vertical step in the raster)."""
    got = grid.rect_mask(centre_ne, length_m + 2 * shoulder_m, width_m + 2 * shoulder_m, yaw_rad)
    if got is None:
        return
    (i0, i1, j0, j1), mask, uu, vv = got
    out = np.hypot(np.maximum(np.abs(uu) - length_m / 2, 0.0), np.maximum(np.abs(vv) - width_m / 2, 0.0))
    t = np.clip(out / shoulder_m, 0.0, 1.0) if shoulder_m > 0 else (out > 0).astype(np.float64)
    t = t * t * (3.0 - 2.0 * t)
    win = ground[i0:i1, j0:j1]
    win[mask] = (height_m + t * (win - height_m))[mask]


def level_strip(
    ground: np.ndarray,
    grid: WorldGrid,
    points_ne: np.ndarray,
    heights_m: np.ndarray,
    width_m: float,
    shoulder_m: float,
    *,
    part: str = "both",
) -> None:
    """Cut a strip (a road) into ``ground``: level across its ``width_m``, its height along the centre
    line ``points_ne`` ((k, 2) north, east) linear between ``heights_m`` ((k,)), blending back to the
    ground beside it over ``shoulder_m`` (cuttings and embankments). ``part``: "shoulders", "core" or
    "both" (shape every strip's shoulders first and then the cores, so that where strips meet, the
    carriageways stay level)."""
    if part not in ("shoulders", "core", "both"):
        raise WorldError(f"level_strip part must be shoulders, core or both, got {part!r}")
    pts, z = np.asarray(points_ne, np.float64), np.asarray(heights_m, np.float64)
    half = width_m / 2
    if part != "shoulders":  # the joints first, so that no wedge is left on the outside of a bend
        for k in range(1, len(pts) - 1):
            _level_joint(ground, grid, pts[k - 1 : k + 2], z[k - 1 : k + 2], half)
    for k in range(len(pts) - 1):
        (n1, e1), (n2, e2) = pts[k], pts[k + 1]
        seg = math.hypot(n2 - n1, e2 - e1)
        if seg == 0:
            continue
        yaw = math.atan2(e2 - e1, n2 - n1)
        reach = half + (shoulder_m if part != "core" else 0.0)
        got = grid.rect_mask(((n1 + n2) / 2, (e1 + e2) / 2), seg + 0.02 * width_m, 2 * reach, yaw)
        if got is None:
            continue
        (i0, i1, j0, j1), mask, uu, vv = got
        prof = z[k] + np.clip(uu / seg + 0.5, 0.0, 1.0) * (z[k + 1] - z[k])
        win = ground[i0:i1, j0:j1]
        side = np.abs(vv) - half
        if part != "core" and shoulder_m > 0:
            t = np.clip(side / shoulder_m, 0.0, 1.0)
            t = t * t * (3.0 - 2.0 * t)
            m = mask & (side > 0)
            win[m] = (prof + t * (win - prof))[m]
        if part != "shoulders":
            m = mask & (side <= 0)
            win[m] = prof[m]


def _level_joint(
    ground: np.ndarray, grid: WorldGrid, pts: np.ndarray, z: np.ndarray, radius_m: float
) -> None:
    """A disc of ``radius_m`` round the middle of three points, level across the strip and rising
    along it at the strip's grade there."""
    (cn, ce), d = pts[1], pts[2] - pts[0]
    run = math.hypot(d[0], d[1])
    if run == 0:
        return
    tn, te, grade = d[0] / run, d[1] / run, (z[2] - z[0]) / run
    win = grid.window(cn - radius_m, cn + radius_m, ce - radius_m, ce + radius_m)
    if win is None:
        return
    n, e = grid.cell_centres(*win)
    mask = (n - cn) ** 2 + (e - ce) ** 2 <= radius_m**2
    height = z[1] + grade * ((n - cn) * tn + (e - ce) * te)
    ground[win[0] : win[1], win[2] : win[3]][mask] = height[mask]


def lay_over(grid: WorldGrid, ground: np.ndarray) -> None:
    """Set ``grid`` (painted with heights up from its local ground) on ``ground`` (float32 metres
    up, the grid's shape): every cell's height rises by the ground under it."""
    if ground.shape != grid.shape:
        raise WorldError(f"ground raster shape {ground.shape} does not match the grid's {grid.shape}")
    grid.height += ground.astype(np.float32, copy=False)
