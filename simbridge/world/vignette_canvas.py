"""The vignette builder's canvas: its generator and grid, the random draws, and the painting and
placing primitives every part of a scene uses (:mod:`simbridge.world.vignettes` builds scenes with it)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TypeVar

import numpy as np

from simbridge.world.model import Material as M
from simbridge.world.model import SurfaceClass as C
from simbridge.world.model import WorldGrid

VIGNETTE_KINDS: tuple[str, ...] = (
    "house", "hip_house", "barn", "flat_roof", "garden", "street", "car_park", "pond", "yard",
)  # fmt: skip
CLUTTER_LEVELS: tuple[str, ...] = ("clear", "single", "some", "heavy")
CLUTTER_P = (0.5, 0.17, 0.2, 0.13)
RES_M = (0.04, 0.08)
SIZE_M = (30.0, 50.0)
SUN_ELEVATION_DEG = (15.0, 80.0)
PITCH_DEG = (15.0, 45.0)

T = TypeVar("T")
Window = tuple[int, int, int, int]
NE = tuple[float, float]
PITCHED_MATS = (M.TILES, M.SLATE, M.SHINGLE, M.SEAM_METAL, M.CORRUGATED, M.METAL)
PITCHED_P = (0.32, 0.18, 0.2, 0.12, 0.08, 0.1)
FLAT_MATS = (M.GRAVEL, M.TAR, M.MEMBRANE, M.CONCRETE)
ROOF_CLASSES = (int(C.ROOF_FLAT), int(C.ROOF_PITCHED))
GROUND_OK = (int(C.GROUND), int(C.GRASS), int(C.SIDEWALK))
# round roof objects: radius and rise above the roof (metres)
ROUND_R = {"vent": (0.05, 0.15), "mushroom": (0.18, 0.35), "dish": (0.28, 0.45), "turbine": (0.2, 0.35)}
ROUND_RISE = {"vent": (0.2, 0.9), "mushroom": (0.3, 0.6), "dish": (0.3, 0.7), "turbine": (0.35, 0.6)}


@dataclass(frozen=True, slots=True)
class RoofSpec:
    """One roof of a vignette: its region id, style, clutter level and (main) footprint.

    ``style``: ``gable``, ``hip``, ``flat`` or ``barn``; ``clutter``: one of :data:`CLUTTER_LEVELS`
    (``clear`` roofs hold no ``ROOF_CLUTTER`` cell of their region). ``height_m`` is the eave height
    (pitched) or the roof height (flat); the footprint is the main wing (without parapet for flat roofs).
    """

    region: int
    style: str
    material: M
    clutter: str
    centre_ne: NE
    length_m: float
    width_m: float
    yaw_rad: float
    height_m: float
    pitch_deg: float = 0.0


def gable_heights(v: np.ndarray, width_m: float, eave_m: float, pitch_deg: float) -> np.ndarray:
    """Gable roof heights at across-ridge offsets ``v``: eaves at ``eave_m``, slope ``tan(pitch)``."""
    run = np.clip(width_m / 2 - np.abs(v), 0.0, None)
    return np.asarray(eave_m + math.tan(math.radians(pitch_deg)) * run, np.float32)


def hip_heights(
    u: np.ndarray, v: np.ndarray, length_m: float, width_m: float, eave_m: float, pitch_deg: float
) -> np.ndarray:
    """Hipped roof heights: four planes of slope ``tan(pitch)`` rising from the eaves of a
    ``length_m`` x ``width_m`` footprint (``u`` along the length, ``v`` across); height is the eave
    plus the slope times the distance to the nearest footprint edge, which caps it at the ridge
    (``eave + tan(pitch) * min(length, width) / 2``)."""
    run = np.clip(np.minimum(length_m / 2 - np.abs(u), width_m / 2 - np.abs(v)), 0.0, None)
    return np.asarray(eave_m + math.tan(math.radians(pitch_deg)) * run, np.float32)


class Canvas:
    """One vignette's generator, grid and painting primitives."""

    def __init__(self, seed: int, kind: str) -> None:
        self.rng = np.random.default_rng(seed)
        self.seed = seed
        self.kind = kind
        rng = self.rng
        self.res = round(float(rng.uniform(*RES_M)), 4)
        self.hn = round(float(rng.uniform(*SIZE_M)) / 2, 1)
        self.he = round(float(np.clip(2 * self.hn * rng.uniform(0.85, 1.15), *SIZE_M)) / 2, 1)
        self.grid = WorldGrid.empty((-self.hn, self.hn), (-self.he, self.he), self.res, C.GRASS, M.GRASS)
        self.roofs: list[RoofSpec] = []
        self._region = 1

    # ------------------------------------------------------------------ small helpers
    def u(self, lo: float, hi: float) -> float:
        return float(self.rng.uniform(lo, hi))

    def p(self, prob: float) -> bool:
        return bool(self.rng.random() < prob)

    def pick(self, seq: Sequence[T], probs: Sequence[float] | None = None) -> T:
        if probs is None:
            return seq[int(self.rng.integers(0, len(seq)))]
        p = np.asarray(probs, float)
        return seq[int(self.rng.choice(len(seq), p=p / p.sum()))]

    def level(self) -> str:
        return CLUTTER_LEVELS[int(self.rng.choice(len(CLUTTER_LEVELS), p=CLUTTER_P))]

    def region(self) -> int:
        rid = self._region
        self._region += 1
        return rid

    def actor(self) -> int:
        """A negative region id: the camera colours CAR_PAINT / CLOTH cells by it."""
        return -int(self.rng.integers(1, 4096))

    def w(self, width: float) -> float:
        """At least one cell wide."""
        return max(width, self.res * 1.01)

    @staticmethod
    def at(c: NE, yaw: float, u: float, v: float) -> NE:
        """World (north, east) of local (u along yaw, v across) about ``c``."""
        cs, sn = math.cos(yaw), math.sin(yaw)
        return (c[0] + u * cs - v * sn, c[1] + u * sn + v * cs)

    def frame(
        self, c: NE, length: float, width: float, yaw: float
    ) -> tuple[Window, np.ndarray, np.ndarray, np.ndarray] | None:
        return self.grid.rect_mask(c, self.w(length), self.w(width), yaw)

    def rect(
        self, c: NE, length: float, width: float, yaw: float, h: float | None, cls: C | None, mat: M | None,
        region: int | None = None, mode: str = "set",
    ) -> None:  # fmt: skip
        self.grid.fill_rect(
            c, self.w(length), self.w(width), yaw, height_m=h, cls=cls, mat=mat, region=region, mode=mode
        )

    def disc(
        self, c: NE, r: float, h: float | None, cls: C | None, mat: M | None,
        region: int | None = None, mode: str = "set", dome: bool = False,
    ) -> None:  # fmt: skip
        self.grid.fill_disc(
            c, max(r, 0.75 * self.res), height_m=h, dome=dome, cls=cls, mat=mat, region=region, mode=mode
        )

    def paint(
        self, win: Window, mask: np.ndarray, h: np.ndarray | float | None, cls: C | None, mat: M | None,
        region: int | None = None, mode: str = "set",
    ) -> None:  # fmt: skip
        self.grid.paint(win, mask, h, cls, mat, region, mode)

    def inside(self, c: NE, margin: float) -> bool:
        return abs(c[0]) <= self.hn - margin and abs(c[1]) <= self.he - margin

    def free(self, c: NE, radius: float, allowed: tuple[int, ...] = GROUND_OK) -> bool:
        """Whether the square of half side ``radius`` about ``c`` is open ground of the allowed classes."""
        g = self.grid
        win = g.window(c[0] - radius, c[0] + radius, c[1] - radius, c[1] + radius)
        if win is None:
            return False
        i0, i1, j0, j1 = win
        return bool(
            np.isin(g.cls[i0:i1, j0:j1], allowed).all()
            and (g.region[i0:i1, j0:j1] == 0).all()
            and (g.height[i0:i1, j0:j1] < 0.3).all()
        )

    def spot(
        self, radius: float, allowed: tuple[int, ...] = GROUND_OK, tries: int = 40, margin: float = 0.5,
        near: tuple[NE, float] | None = None,
    ) -> NE | None:  # fmt: skip
        """A random free spot (inside the grid, or within ``near = (centre, distance)``)."""
        for _ in range(tries):
            if near is None:
                c = (self.u(-self.hn + margin, self.hn - margin), self.u(-self.he + margin, self.he - margin))
            else:
                a, d = self.u(0, 2 * math.pi), self.u(0, near[1])
                c = (near[0][0] + d * math.cos(a), near[0][1] + d * math.sin(a))
            if self.inside(c, radius) and self.free(c, radius, allowed):
                return c
        return None

    def blob(self, c: NE, radius: float, wobble: float) -> tuple[Window, np.ndarray, np.ndarray] | None:
        """An irregular round shape (pond, flower bed): window, mask and normalised radius (<= 1 inside)."""
        g = self.grid
        r_max = radius * (1 + wobble * 2.2)
        win = g.window(c[0] - r_max, c[0] + r_max, c[1] - r_max, c[1] + r_max)
        if win is None:
            return None
        n, e = g.cell_centres(*win)
        th = np.arctan2(e - c[1], n - c[0])
        rr = np.full(th.shape, radius)
        for k in (2, 3, 4, 5):
            rr = rr * (1 + wobble / k * np.cos(k * th + self.u(0, 2 * math.pi)))
        rel = np.hypot(n - c[0], e - c[1]) / rr
        return win, rel <= 1.0, rel
