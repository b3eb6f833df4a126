"""Vignettes: small, fine-grained worlds for training the onboard landing-site judge.

The procedural city (:mod:`simbridge.world.city`) is painted at 0.1-0.2 m cells: too coarse for the
2-5 cm per pixel the judge sees in the last metres of a descent, and its roofs are gable-only with boxy
clutter. A vignette is one near-nadir scene of the kind a real aerial photograph shows at 1-10 cm/px,
about 30-50 m a side at 0.04-0.08 m cells, built from a seed with the :class:`WorldGrid` primitives:

- ``house`` / ``hip_house``: a village or suburban house (gable or hipped roof, sometimes L-shaped,
  sometimes with dormers), maybe a flat-roofed garage and a neighbour, a lawn, trees, hedges, fences,
  a driveway with a car, a terrace with furniture, people and bicycles next to (rarely on) the house;
- ``barn``: a long (15-40 m) farm barn with a corrugated or seam-metal roof in a dirt/gravel yard with
  bales, pallets, pipe stacks, a tractor and crop rows;
- ``flat_roof``: a commercial or apartment block with a gravel/tar/membrane/concrete roof, with or
  without a parapet, sometimes a lower annex, parking, paving and lawns around it;
- ``garden``: part of a house and a back garden: lawn, swimming pool in a paved surround, terrace,
  garden furniture and parasols, trampoline, vegetable beds, a shed, trees, people standing, sitting
  and lying on the grass;
- ``street``: an asphalt street with lane markings, a zebra crossing, manholes and drain grates,
  sidewalks, moving and parked cars, cyclists and pedestrians, and front gardens with houses;
- ``car_park``: marked bays with parked cars, people walking, tree islands and a flat-roofed shop;
- ``pond``: a pond (brown-green water) with reeds, a jetty, paths, benches, trees and people;
- ``yard``: dirt and gravel with bales, pipe stacks, pallets, a vehicle, crop rows and a shed.

**What varies.** Everything is drawn from ``np.random.default_rng(seed)``: the cell size (0.04-0.08 m),
the extent, the sun (azimuth any, elevation 15-80 deg), every footprint's size and heading (roofs are
rotated rectangles at any yaw), roof style (gable / hipped), pitch (15-45 deg; barns 15-28), eave height,
roof materials (TILES, SLATE, SHINGLE, CORRUGATED, SEAM_METAL, METAL pitched; GRAVEL, TAR, MEMBRANE,
CONCRETE flat), gutters, parapets, dormers, the layout of the surroundings and the actors' colours.

**Clear and cluttered roofs.** Every roof independently draws a clutter level (:data:`CLUTTER_LEVELS`):
``clear`` (half the roofs: nothing on them), ``single`` (exactly one small object: a vent pipe, a
chimney, a roof window, a hatch), ``some`` (2-5 objects) or ``heavy`` (many), on the same roof types
and materials, so the label, not the material, tells them apart. Pitched-roof objects: chimneys (with
pots), roof windows (GLASS in a metal frame), PV arrays, vent pipes (r 5-15 cm), satellite dishes, TV
antennas. Flat-roof objects: HVAC units (with fans), vent pipes, mushroom vents, hatches, skylights
(flat or domed), pipes, cable trays, ducts, solar rows. Barns: ridge vents, turbine vents, skylight
strips. Objects on a roof are ``ROOF_CLUTTER`` and carry the roof's region id;
:func:`build_vignette_roofs` returns each roof's :class:`RoofSpec` (region id, style, clutter level).

**Labels.** The world follows the city's conventions (see :mod:`landfall_train.labels`): roof tops
``ROOF_FLAT`` / ``ROOF_PITCHED``, parapets ``PARAPET``, fences ``GUARD_RAIL`` (the ``edge`` label),
cars / tractors / bicycles ``VEHICLE``, people ``PEDESTRIAN``, lawns and crops ``GRASS``, trees and
hedges ``TREE``, ponds and pools ``WATER`` (material ``WATER`` or ``POOL``), streets ``ROAD``, zebras
``CROSSWALK``, car parks ``PARKING_LOT``, paths and sidewalks ``SIDEWALK``, yards, driveways and objects
standing on the ground (furniture, bales, pipe stacks, pallets, trampolines) ``GROUND``. Cars, people's
clothes and parasols carry negative region ids, so the camera gives them varied actor colours.

**Picking views.** A vignette has no lanes or walkways: everything is painted into the static grid, so
a training generator picks view centres from ``grid.cls`` like :mod:`landfall_train.patches` does
(strata by the class under the centre; ``vehicle``/``person`` strata read the same static grid). Every
kind holds hundreds of cells or more of each class it names;
one house roof at 0.06 m is ~25 000 cells, a person ~40, a vent pipe 1-20.

Build with ``LiveWorld(build_vignette(seed))`` (empty lanes and walkways are fine): the pyramid is
built at once and shadows tile by tile on demand. Build plus LiveWorld: 10-50 ms (median), under 0.2 s.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TypeVar

import numpy as np

from simbridge.world.model import Material as M
from simbridge.world.model import SurfaceClass as C
from simbridge.world.model import WorldGrid
from simbridge.world.world import Sun, World

__all__ = [
    "CLUTTER_LEVELS",
    "VIGNETTE_KINDS",
    "RoofSpec",
    "build_vignette",
    "build_vignette_roofs",
    "gable_heights",
    "hip_heights",
]

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
_ROUND_R = {"vent": (0.05, 0.15), "mushroom": (0.18, 0.35), "dish": (0.28, 0.45), "turbine": (0.2, 0.35)}
_ROUND_RISE = {"vent": (0.2, 0.9), "mushroom": (0.3, 0.6), "dish": (0.3, 0.7), "turbine": (0.35, 0.6)}


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


class _Builder:
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

    # ------------------------------------------------------------------ vegetation
    def tree(self, c: NE, r: float, h: float, conifer: bool = False) -> None:
        g = self.grid
        trunk = h * self.u(0.3, 0.5)
        lobes = [(c, r, h)]
        if not conifer:
            for _ in range(int(self.rng.integers(3, 7))):
                a, d = self.u(0, 2 * math.pi), self.u(0.25, 0.55) * r
                lobes.append(
                    (
                        (c[0] + d * math.cos(a), c[1] + d * math.sin(a)),
                        r * self.u(0.4, 0.65),
                        h * self.u(0.82, 0.97),
                    )
                )
        for lc, lr, lh in lobes:
            win = g.window(lc[0] - lr, lc[0] + lr, lc[1] - lr, lc[1] + lr)
            if win is None:
                continue
            n, e = g.cell_centres(*win)
            d2 = ((n - lc[0]) ** 2 + (e - lc[1]) ** 2) / lr**2
            if conifer:
                prof = 1.0 - np.sqrt(d2)
            else:
                prof = np.sqrt(np.clip(1.0 - d2, 0.0, 1.0))
            hh = trunk + (lh - trunk) * prof + self.rng.uniform(0.0, 0.12 * lr / 2, d2.shape)
            self.paint(win, d2 <= 1.0, hh.astype(np.float32), C.TREE, M.FOLIAGE, None, "max")

    def trees(
        self, count: int, r: tuple[float, float] = (1.5, 4.5), h: tuple[float, float] = (4.0, 12.0)
    ) -> None:
        for _ in range(count):
            rad = self.u(*r)
            c = self.spot(rad * 0.5, (int(C.GRASS), int(C.GROUND)))
            if c is not None:
                self.tree(c, rad, max(self.u(*h), rad * 1.2), conifer=self.p(0.15))

    def hedge(self, a: NE, b: NE, width: float, h: float) -> None:
        length = math.hypot(b[0] - a[0], b[1] - a[1])
        yaw = math.atan2(b[1] - a[1], b[0] - a[0])
        got = self.frame(((a[0] + b[0]) / 2, (a[1] + b[1]) / 2), length, width, yaw)
        if got is None:
            return
        win, mask, _, v = got
        prof = np.sqrt(np.clip(1 - (2 * v / width) ** 2, 0, 1)) * 0.3 + 0.7
        hh = h * prof + self.rng.uniform(0, 0.12, v.shape)
        free = self.grid.region[win[0] : win[1], win[2] : win[3]] == 0
        self.paint(win, mask & free, hh.astype(np.float32), C.TREE, M.FOLIAGE, None, "max")

    def fence(self, a: NE, b: NE) -> None:
        mat = M.WOOD if self.p(0.6) else M.METAL
        h = self.u(0.9, 1.8)
        self.grid.fill_polyline(
            [a, b], self.w(self.u(0.04, 0.1)), height_m=h, cls=C.GUARD_RAIL, mat=mat, mode="max"
        )

    # ------------------------------------------------------------------ actors and objects
    def person(self, c: NE, yaw: float, base: float = 0.0, pose: str = "stand") -> None:
        """A person seen from above: shoulders (CLOTH, actor colour) and a head (hair)."""
        rid = self.actor()
        hair = self.pick((M.TAR, M.WOOD, M.SOIL, M.GRAVEL))
        sw, sd = self.u(0.21, 0.29), self.u(0.11, 0.15)
        if pose == "lie":
            self.rect(c, self.u(1.4, 1.6), 2 * sw * 0.8, yaw, base + 0.22, C.PEDESTRIAN, M.CLOTH, rid)
            self.disc(self.at(c, yaw, 0.85, 0.0), 0.1, base + 0.2, C.PEDESTRIAN, hair, rid)
            return
        top = base + (self.u(1.35, 1.5) if pose == "stand" else self.u(0.95, 1.1))
        got = self.frame(c, 2 * sd, 2 * sw, yaw)
        if got is not None:
            win, _, uu, vv = got
            self.paint(win, (uu / sd) ** 2 + (vv / sw) ** 2 <= 1.0, top, C.PEDESTRIAN, M.CLOTH, rid)
        if pose == "sit":  # legs forward
            self.rect(
                self.at(c, yaw, 0.3, 0.0), 0.45, 2 * sw * 0.7, yaw, base + 0.55, C.PEDESTRIAN, M.CLOTH, rid
            )
        head = top + self.u(0.2, 0.3)
        self.disc(
            self.at(c, yaw, self.u(-0.02, 0.04), 0.0), self.u(0.08, 0.11), head, C.PEDESTRIAN, hair, rid
        )

    def group(self, c: NE, count: int, base: float = 0.0, pose: str = "stand", spread: float = 1.2) -> None:
        for k in range(count):
            a = 2 * math.pi * k / max(count, 1) + self.u(-0.3, 0.3)
            d = 0.0 if count == 1 else spread * self.u(0.5, 1.0)
            p = (c[0] + d * math.cos(a), c[1] + d * math.sin(a))
            self.person(p, a + math.pi + self.u(-0.5, 0.5), base, pose)

    def car(self, c: NE, yaw: float, base: float = 0.0, van: bool = False) -> None:
        """A car (or van) from above: rounded body, bonnet, windscreen, roof, rear window, boot."""
        rid = self.actor()
        length = self.u(5.0, 5.6) if van else self.u(4.1, 4.9)
        width = self.u(1.9, 2.05) if van else self.u(1.72, 1.9)
        got = self.frame(c, length, width, yaw)
        if got is None:
            return
        win, _, uu, vv = got
        body = (np.abs(uu) / (length / 2)) ** 6 + (np.abs(vv) / (width / 2)) ** 6 <= 1.0
        x = uu / length + 0.5  # 0 rear .. 1 front
        roof_h = base + (self.u(1.9, 2.4) if van else self.u(1.38, 1.55))
        if van:
            prof = np.where(x > 0.85, base + 1.2, np.where(x > 0.75, roof_h - (x - 0.75) * 6, roof_h))
            glass = (x > 0.75) & (x <= 0.85)
        else:
            hood, boot = base + self.u(0.9, 1.05), base + self.u(0.95, 1.1)
            f0, f1 = self.u(0.62, 0.68), self.u(0.72, 0.78)  # windscreen from f0 (roof) to f1 (bonnet)
            r0, r1 = self.u(0.12, 0.2), self.u(0.25, 0.3)  # rear window from r0 (boot) to r1 (roof)
            prof = np.select(
                [x >= f1, x >= f0, x >= r1, x >= r0],
                [
                    np.full_like(x, hood),
                    roof_h + (hood - roof_h) * (x - f0) / (f1 - f0),
                    np.full_like(x, roof_h),
                    boot + (roof_h - boot) * (x - r0) / (r1 - r0),
                ],
                boot,
            )  # fmt: skip
            glass = ((x >= f0) & (x < f1)) | ((x >= r0) & (x < r1))
        self.paint(win, body, prof.astype(np.float32), C.VEHICLE, M.CAR_PAINT, rid)
        self.paint(win, body & glass & (np.abs(vv) < width * 0.42), None, None, M.GLASS)

    def bicycle(self, c: NE, yaw: float, base: float = 0.0) -> None:
        rid = self.actor()
        thin = self.w(0.05)
        self.rect(c, 1.0, thin, yaw, base + 0.85, C.VEHICLE, M.CAR_PAINT, rid)
        for s in (-1, 1):
            self.rect(self.at(c, yaw, s * 0.55, 0), 0.68, thin, yaw, base + 0.68, C.VEHICLE, M.TAR, rid)
        self.rect(self.at(c, yaw, 0.45, 0), thin, 0.56, yaw, base + 1.0, C.VEHICLE, M.METAL, rid)
        self.rect(self.at(c, yaw, -0.3, 0), 0.26, 0.12, yaw, base + 0.95, C.VEHICLE, M.TAR, rid)

    def tractor(self, c: NE, yaw: float) -> None:
        rid = self.actor()
        self.rect(c, 3.6, 1.2, yaw, 1.6, C.VEHICLE, M.CAR_PAINT, rid)  # bonnet and body
        for s in (-1, 1):
            self.rect(self.at(c, yaw, -0.9, s * 0.95), 1.6, 0.55, yaw, 1.7, C.VEHICLE, M.TAR, rid)
            self.rect(self.at(c, yaw, 1.1, s * 0.8), 1.0, 0.35, yaw, 1.0, C.VEHICLE, M.TAR, rid)
        self.rect(self.at(c, yaw, -0.8, 0), 1.5, 1.4, yaw, 2.8, C.VEHICLE, M.CAR_PAINT, rid)  # cab roof

    def furniture(self, c: NE, yaw: float) -> None:
        """A garden table with chairs (sometimes a parasol and people sitting)."""
        mat = M.WOOD if self.p(0.6) else self.pick((M.METAL, M.MEMBRANE))
        tl, tw = self.u(0.8, 1.8), self.u(0.7, 1.0)
        if self.p(0.3):
            self.disc(c, tw / 2 + 0.1, 0.75, C.GROUND, mat)
        else:
            self.rect(c, tl, tw, yaw, 0.75, C.GROUND, mat)
        for s in (-1, 1):
            for k in range(int(self.rng.integers(1, 3))):
                pc = self.at(c, yaw, (k - 0.5) * 0.7 if tl > 1.2 else 0.0, s * (tw / 2 + 0.4))
                if self.p(0.35):
                    self.person(pc, yaw - s * math.pi / 2, 0.0, "sit")
                else:
                    self.rect(pc, 0.5, 0.5, yaw, self.u(0.45, 0.9), C.GROUND, mat)
        if self.p(0.4):  # parasol above it all
            self.disc(c, self.u(1.0, 1.5), 2.2, C.GROUND, M.CLOTH, self.actor(), mode="max")

    def bale(self, c: NE, yaw: float) -> None:
        mat = self.pick((M.GRAVEL, M.WOOD, M.MEMBRANE, M.TAR), (0.45, 0.2, 0.2, 0.15))
        r = self.u(0.6, 0.9)
        if self.p(0.5):  # upright round bale
            self.disc(c, r, 2 * r * self.u(0.8, 1.0), C.GROUND, mat)
            return
        length = self.u(1.2, 1.6)
        got = self.frame(c, length, 2 * r, yaw)
        if got is not None:
            win, mask, _, vv = got
            self.paint(
                win, mask, (r + np.sqrt(np.clip(r * r - vv * vv, 0, None))).astype(np.float32), C.GROUND, mat
            )

    def pipe_stack(self, c: NE, yaw: float) -> None:
        rp = self.u(0.08, 0.5)
        n = int(self.rng.integers(3, 8))
        length = self.u(3.0, 8.0)
        mat = self.pick((M.METAL, M.CONCRETE, M.TAR)) if rp > 0.25 else self.pick((M.METAL, M.TAR))
        got = self.frame(c, length, 2 * rp * n, yaw)
        if got is None:
            return
        win, mask, _, vv = got
        x = vv + rp * n
        hh = np.zeros(vv.shape)
        for layer in range(min(n, 3)):
            off = layer * rp
            k = np.floor((x - off) / (2 * rp))
            ok = (k >= 0) & (k < n - layer)
            dx = x - off - (2 * k + 1) * rp
            top = rp + layer * rp * math.sqrt(3) + np.sqrt(np.clip(rp * rp - dx * dx, 0, None))
            hh = np.where(ok, np.maximum(hh, top), hh)
        self.paint(win, mask & (hh > 0), hh.astype(np.float32), C.GROUND, mat)

    def pallets(self, c: NE, yaw: float) -> None:
        for k in range(int(self.rng.integers(1, 5))):
            pc = self.at(c, yaw, k * 1.3, self.u(-0.1, 0.1))
            self.rect(pc, 1.2, 0.8, yaw + self.u(-0.1, 0.1), self.u(0.15, 1.4), C.GROUND, M.WOOD)

    # ------------------------------------------------------------------ roofs
    def pitched_house(
        self, c: NE, length: float, width: float, yaw: float, style: str, *, mat: M | None = None,
        eave: float | None = None, pitch: float | None = None, wing: bool = False, dormers: bool = False,
        clutter: str | None = None,
    ) -> RoofSpec:  # fmt: skip
        rid = self.region()
        mat = mat if mat is not None else self.pick(PITCHED_MATS, PITCHED_P)
        eave = eave if eave is not None else self.u(2.6, 6.0)
        pitch = pitch if pitch is not None else self.u(*PITCH_DEG)
        self._wing(c, length, width, yaw, style, eave, pitch, mat, rid, "set")
        if wing:  # an L: a perpendicular wing at one end, same eaves and pitch (mode max makes the valleys)
            ww = width * self.u(0.6, 1.0)
            ext = self.u(2.5, 6.0)
            side, end = self.pick((-1.0, 1.0)), self.pick((-1.0, 1.0))
            wl = ext + width * 0.75
            wc = self.at(c, yaw, end * (length / 2 - ww / 2), side * (width / 2 + ext - wl / 2))
            self._wing(wc, wl, ww, yaw + math.pi / 2, style, eave, pitch, mat, rid, "max")
        if self.p(0.5):  # gutters along the eaves
            got = self.frame(c, length, width, yaw)
            if got is not None:
                win, mask, uu, vv = got
                gw = self.w(0.12)
                edge = (
                    (np.abs(vv) >= width / 2 - gw)
                    if style == "gable"
                    else (np.minimum(length / 2 - np.abs(uu), width / 2 - np.abs(vv)) <= gw)
                )
                own = self.grid.region[win[0] : win[1], win[2] : win[3]] == rid
                self.paint(win, mask & edge & own, None, None, M.METAL)
        if dormers:
            self._dormers(c, length, width, yaw, eave, pitch, mat, rid)
        spec = RoofSpec(rid, style, mat, clutter or self.level(), c, length, width, yaw, eave, pitch)
        self.roofs.append(spec)
        self.pitched_clutter(spec)
        return spec

    def _wing(
        self, c: NE, length: float, width: float, yaw: float, style: str, eave: float, pitch: float, mat: M,
        rid: int, mode: str,
    ) -> None:  # fmt: skip
        got = self.frame(c, length, width, yaw)
        if got is None:
            return
        win, mask, uu, vv = got
        if style == "hip":
            hh = hip_heights(uu, vv, length, width, eave, pitch)
        else:
            hh = gable_heights(vv, width, eave, pitch)
        self.paint(win, mask, hh, C.ROOF_PITCHED, mat, rid, mode)

    def _dormers(
        self, c: NE, length: float, width: float, yaw: float, eave: float, pitch: float, mat: M, rid: int
    ) -> None:
        side = self.pick((-1.0, 1.0))
        count = int(self.rng.integers(1, 4))
        dw = self.u(1.2, 2.4)
        usable = length - width - dw if length > width + dw else length * 0.5 - dw
        slope = math.tan(math.radians(pitch))
        dmat = mat if self.p(0.6) else self.pick((M.SEAM_METAL, M.SHINGLE, M.METAL))
        gable = self.p(0.6)
        v_out, v_in = width / 2 - self.u(0.4, 0.9), width * self.u(0.05, 0.2)
        top = eave + slope * (width / 2 - v_in)
        for k in range(count):
            uc = (k - (count - 1) / 2) * usable / max(count, 1) if count > 1 else self.u(-0.2, 0.2) * usable
            dc = self.at(c, yaw, uc, side * (v_out + v_in) / 2)
            got = self.frame(dc, dw, v_out - v_in, yaw)
            if got is None:
                continue
            win, mask, uu, vv = got
            if gable:
                dp = math.tan(math.radians(self.u(30, 45)))
                hh = top - 0.05 - dp * np.abs(uu) + 0.0 * vv
            else:  # shed dormer: a shallow slope down toward the eaves
                hh = top - 0.1 - math.tan(math.radians(8)) * (side * vv + (v_out - v_in) / 2)
            own = self.grid.region[win[0] : win[1], win[2] : win[3]] == rid
            self.paint(win, mask & own, np.asarray(hh, np.float32), C.ROOF_PITCHED, dmat, rid, "max")

    def flat_building(
        self, c: NE, length: float, width: float, yaw: float, *, h: float | None = None, mat: M | None = None,
        parapet: bool | None = None, clutter: str | None = None,
    ) -> RoofSpec:  # fmt: skip
        rid = self.region()
        h = h if h is not None else self.u(3.0, 12.0)
        mat = mat if mat is not None else self.pick(FLAT_MATS, (0.35, 0.25, 0.25, 0.15))
        parapet = parapet if parapet is not None else self.p(0.55)
        il, iw = length, width
        if parapet:
            pw = self.w(self.u(0.2, 0.45))
            pmat = self.pick((M.CONCRETE, M.BRICK, M.METAL), (0.5, 0.3, 0.2))
            self.rect(c, length, width, yaw, h + self.u(0.2, 1.0), C.PARAPET, pmat, rid)
            il, iw = length - 2 * pw, width - 2 * pw
        self.rect(c, il, iw, yaw, h, C.ROOF_FLAT, mat, rid)
        if mat == M.GRAVEL and self.p(0.35):  # a line of concrete pavers across the gravel: roof, not clutter
            self.rect(
                self.at(c, yaw, 0, self.u(-0.3, 0.3) * iw),
                il - 0.4,
                0.6,
                yaw,
                h + 0.03,
                C.ROOF_FLAT,
                M.CONCRETE,
                rid,
            )
        spec = RoofSpec(rid, "flat", mat, clutter or self.level(), c, il, iw, yaw, h)
        self.roofs.append(spec)
        self.flat_clutter(spec)
        return spec

    def barn(self, c: NE, length: float, width: float, yaw: float) -> RoofSpec:
        mat = self.pick((M.CORRUGATED, M.SEAM_METAL, M.METAL), (0.7, 0.2, 0.1))
        spec = self.pitched_house(
            c, length, width, yaw, "gable", mat=mat, eave=self.u(3.5, 6.5), pitch=self.u(15.0, 28.0),
            clutter="clear",
        )  # fmt: skip
        spec = RoofSpec(
            spec.region, "barn", mat, self.level(), c, length, width, yaw, spec.height_m, spec.pitch_deg
        )
        self.roofs[-1] = spec
        self.barn_clutter(spec)
        return spec

    # ------------------------------------------------------------------ clutter
    def _roof_mask(self, win: Window, rid: int) -> np.ndarray:
        i0, i1, j0, j1 = win
        own = (self.grid.region[i0:i1, j0:j1] == rid) & np.isin(self.grid.cls[i0:i1, j0:j1], ROOF_CLASSES)
        return np.asarray(own, bool)

    def _on(
        self, spec: RoofSpec, c: NE, length: float, width: float, yaw: float, round_: bool = False
    ) -> tuple[Window, np.ndarray] | None:
        """Cells of an object footprint that lie on the roof, or None when it would hang off it."""
        if round_:
            r = max(length / 2, 0.75 * self.res)
            got = self.grid.rect_mask(c, 2 * r, 2 * r, 0.0)
            if got is None:
                return None
            win, _, uu, vv = got
            mask = uu**2 + vv**2 <= r * r
        else:
            got = self.frame(c, length, width, yaw)
            if got is None:
                return None
            win, mask, _, _ = got
        on = mask & self._roof_mask(win, spec.region)
        if not on.any() or on.sum() < 0.9 * mask.sum():
            return None
        return win, on

    def _roof_point(self, spec: RoofSpec, size: float, v_range: tuple[float, float] = (0.1, 0.85)) -> NE:
        """A point on a roof's main footprint, ``size`` from its edges (on a long face of pitched roofs)."""
        half_l = max(spec.length_m / 2 - size, 0.1)
        half_w = max(spec.width_m / 2 - size, 0.1)
        if spec.style == "flat":
            return self.at(spec.centre_ne, spec.yaw_rad, self.u(-half_l, half_l), self.u(-half_w, half_w))
        v = self.pick((-1.0, 1.0)) * self.u(*v_range) * half_w
        if spec.style == "hip":  # stay on the long faces
            half_l = max(spec.length_m / 2 - (spec.width_m / 2 - abs(v)) - size, 0.1)
        return self.at(spec.centre_ne, spec.yaw_rad, self.u(-half_l, half_l), v)

    def _top(self, win: Window, mask: np.ndarray) -> float:
        i0, i1, j0, j1 = win
        return float(self.grid.height[i0:i1, j0:j1][mask].max())

    def _object(self, spec: RoofSpec, kind: str) -> bool:
        """Paint one object of ``kind`` on a roof; False when it found no room."""
        rng, yaw, thin = self.rng, spec.yaw_rad, self.w(0.06)
        yaw_obj = yaw + (math.pi / 2 if self.p(0.3) else 0.0)
        for _ in range(12):
            if kind in ("vent", "mushroom", "dish", "turbine"):
                rad = self.u(*_ROUND_R[kind])
                c = self._roof_point(spec, rad + 0.2)
                got = self._on(spec, c, 2 * rad, 2 * rad, 0.0, round_=True)
                if got is None:
                    continue
                win, mask = got
                mat = self.pick((M.METAL, M.TAR, M.MEMBRANE), (0.6, 0.3, 0.1)) if kind == "vent" else M.METAL
                if kind == "dish" and self.p(0.5):
                    mat = M.MEMBRANE
                self.paint(win, mask, self._top(win, mask) + self.u(*_ROUND_RISE[kind]), C.ROOF_CLUTTER, mat)
                return True
            if kind == "chimney":
                sl, sw = self.u(0.4, 1.1), self.u(0.4, 0.8)
                c = self._roof_point(spec, max(sl, sw), (0.0, 0.6))
                got = self._on(spec, c, sl, sw, yaw)
                if got is None:
                    continue
                win, mask = got
                top = self._top(win, mask) + self.u(0.4, 1.3)
                mat = self.pick((M.BRICK, M.CONCRETE, M.METAL), (0.7, 0.2, 0.1))
                self.paint(win, mask, top, C.ROOF_CLUTTER, mat)
                for k in range(int(rng.integers(0, 3))):
                    pc = self.at(c, yaw, (k - 0.5) * sl * 0.4, 0.0)
                    self.disc(pc, self.u(0.08, 0.14), top + self.u(0.15, 0.35), C.ROOF_CLUTTER, M.TILES)
                return True
            if kind in ("roof_window", "pv"):
                if kind == "pv":
                    cols, rows = int(rng.integers(2, 8)), int(rng.integers(1, 4))
                    pu, pv_ = (1.0, 1.7) if self.p(0.7) else (1.7, 1.0)
                    sl, sw = cols * pu, rows * pv_
                else:
                    sl, sw = self.u(0.55, 1.2), self.u(0.8, 1.5)
                if sl > spec.length_m - 1.0 or sw > spec.width_m / 2 - 0.4:
                    return False
                v = self.pick((-1.0, 1.0)) * self.u(sw / 2 + 0.2, spec.width_m / 2 - sw / 2 - 0.2)
                half_l = spec.length_m / 2 - sl / 2 - 0.3
                if spec.style == "hip":
                    half_l -= spec.width_m / 2 - abs(v) + sw / 2
                if half_l <= 0:
                    continue
                c = self.at(spec.centre_ne, yaw, self.u(-half_l, half_l), v)
                got = self._on(spec, c, sl, sw, yaw)
                if got is None:
                    continue
                win, mask = got
                if kind == "pv":
                    self.paint(win, mask, self.u(0.08, 0.16), C.ROOF_CLUTTER, M.SOLAR, mode="add")
                    inner = self.frame(c, sl - 0.08, sw - 0.08, yaw)
                    if inner is not None and inner[0] == win:
                        _, _, uu, vv = inner
                        fw = self.w(0.04) / 2
                        cu = np.abs(np.mod(uu + sl / 2 + pu / 2, pu) - pu / 2) <= fw
                        cv = np.abs(np.mod(vv + sw / 2 + pv_ / 2, pv_) - pv_ / 2) <= fw
                        self.paint(win, mask & (cu | cv), None, None, M.METAL)
                else:
                    self.paint(win, mask, self.u(0.06, 0.12), C.ROOF_CLUTTER, M.METAL, mode="add")
                    inner = self.frame(c, sl - 0.14, sw - 0.14, yaw)
                    if inner is not None and inner[0] == win:
                        self.paint(win, mask & inner[1], -0.03, None, M.GLASS, mode="add")
                return True
            if kind == "antenna":
                c = self._roof_point(spec, 1.0, (0.0, 0.3))
                la = self.u(1.0, 2.2)
                ya = self.u(0, math.pi)
                got = self._on(spec, c, la, thin, ya)
                if got is None:
                    continue
                win, mask = got
                top = self._top(win, mask) + self.u(1.2, 3.0)
                self.paint(win, mask, top, C.ROOF_CLUTTER, M.METAL)
                for k in range(int(rng.integers(3, 7))):
                    bc = self.at(c, ya, (k / 5 - 0.5) * la, 0.0)
                    self.rect(bc, thin, self.u(0.3, 0.9), ya, top, C.ROOF_CLUTTER, M.METAL, mode="max")
                return True
            # flat-roof boxes: (length, width, rise, material)
            if kind == "hvac":
                sl, sw, rise, mat = self.u(0.8, 3.0), self.u(0.7, 2.0), self.u(0.6, 1.8), M.METAL
            elif kind == "hatch":
                sl, sw, rise, mat = self.u(0.7, 1.3), self.u(0.7, 1.0), self.u(0.25, 0.6), M.METAL
            elif kind == "skylight":
                sl, sw, rise, mat = self.u(0.9, 4.0), self.u(0.9, 2.2), self.u(0.2, 0.45), M.METAL
            elif kind == "duct":
                sl, sw, rise, mat = self.u(2.0, 9.0), self.u(0.35, 0.9), self.u(0.35, 0.9), M.METAL
            elif kind in ("pipe", "tray"):
                sl = self.u(2.0, 12.0)
                sw = self.u(0.06, 0.3) if kind == "pipe" else self.u(0.25, 0.6)
                rise, mat = self.u(0.12, 0.6), M.METAL if self.p(0.8) else M.TAR
            elif kind == "solar":
                sl, sw, rise, mat = self.u(3.0, 10.0), self.u(2.5, 7.0), 0.0, M.SOLAR
            else:
                raise ValueError(f"unknown roof object {kind!r}")
            sl, sw = min(sl, spec.length_m - 0.6), min(sw, spec.width_m - 0.6)
            if sl < self.res or sw < self.res:
                return False
            c = self._roof_point(spec, max(sl, sw) / 2 + 0.3 if kind != "duct" else sw + 0.3)
            got = self._on(spec, c, sl, sw, yaw_obj)
            if got is None:
                continue
            win, mask = got
            base = spec.height_m
            if kind == "solar":  # tilted rows
                fr = self.frame(c, sl, sw, yaw_obj)
                if fr is None or fr[0] != win:
                    continue
                ph = np.mod(fr[3] + sw / 2, 2.0)
                tilt = (base + 0.3 + 0.7 * np.minimum(ph, 1.2) / 1.2).astype(np.float32)
                self.paint(win, mask & (ph < 1.2), tilt, C.ROOF_CLUTTER, M.SOLAR)
                return True
            self.paint(win, mask, base + rise, C.ROOF_CLUTTER, mat)
            if kind == "hvac" and self.p(0.6):  # condenser fans on top
                for k in range(int(rng.integers(1, 3))):
                    fc = self.at(c, yaw_obj, (k - 0.5) * sl * 0.45 if sl > 1.6 else 0.0, 0.0)
                    self.disc(
                        fc, min(self.u(0.25, 0.45), sw * 0.4), base + rise + 0.03, C.ROOF_CLUTTER, M.TAR
                    )
            elif kind == "skylight":
                inner = self.frame(c, sl - 0.2, sw - 0.2, yaw_obj)
                if inner is not None and inner[0] == win:
                    self.paint(win, mask & inner[1], base + rise + 0.03, C.ROOF_CLUTTER, M.GLASS)
            return True
        return False

    def _clutter(
        self, spec: RoofSpec, kinds: tuple[str, ...], weights: tuple[float, ...], singles: tuple[str, ...],
        some: tuple[int, int], heavy: tuple[int, int],
    ) -> None:  # fmt: skip
        if spec.clutter == "clear":
            return
        if spec.clutter == "single":
            self._object(spec, singles[int(self.rng.integers(0, len(singles)))])
            return
        lo, hi = some if spec.clutter == "some" else heavy
        area = spec.length_m * spec.width_m
        count = min(int(self.rng.integers(lo, hi + 1)), max(1, int(area / 4)))
        p = np.asarray(weights) / sum(weights)
        for _ in range(count):
            self._object(spec, kinds[int(self.rng.choice(len(kinds), p=p))])

    def pitched_clutter(self, spec: RoofSpec) -> None:
        self._clutter(
            spec,
            ("chimney", "roof_window", "pv", "vent", "dish", "antenna"),
            (0.3, 0.2, 0.14, 0.22, 0.08, 0.06),
            ("vent", "chimney", "vent", "roof_window"), (2, 4), (5, 9),
        )  # fmt: skip

    def flat_clutter(self, spec: RoofSpec) -> None:
        self._clutter(
            spec,
            ("hvac", "vent", "mushroom", "hatch", "skylight", "pipe", "tray", "duct", "solar"),
            (0.22, 0.2, 0.08, 0.1, 0.12, 0.1, 0.06, 0.06, 0.06),
            ("vent", "vent", "hatch", "hvac", "mushroom"), (2, 5), (6, 20),
        )  # fmt: skip

    def barn_clutter(self, spec: RoofSpec) -> None:
        if spec.clutter == "clear":
            return
        if spec.clutter == "single":
            self._object(spec, self.pick(("turbine", "vent")))
            return
        c, yaw, length = spec.centre_ne, spec.yaw_rad, spec.length_m
        if self.p(0.5):  # a ridge vent along most of the ridge
            got = self._on(spec, c, length * self.u(0.5, 0.9), self.u(0.4, 0.8), yaw)
            if got is not None:
                win, mask = got
                self.paint(win, mask, self._top(win, mask) + self.u(0.15, 0.35), C.ROOF_CLUTTER, M.METAL)
        if self.p(0.6):  # skylight strips from eave to near the ridge
            n = int(self.rng.integers(2, 7))
            sw = self.u(0.6, 1.2)
            depth = spec.width_m / 2 * self.u(0.5, 0.85)
            for s in (-1.0, 1.0):
                for k in range(n):
                    uc = (k + 0.5) / n * length - length / 2
                    sc = self.at(c, yaw, uc, s * (spec.width_m / 2 - 0.3 - depth / 2))
                    got = self._on(spec, sc, sw, depth, yaw)
                    if got is not None:
                        self.paint(got[0], got[1], 0.02, C.ROOF_CLUTTER, M.GLASS, mode="add")
        for _ in range(int(self.rng.integers(1, 6 if spec.clutter == "heavy" else 3))):
            self._object(spec, self.pick(("turbine", "vent", "roof_window", "pv"), (0.4, 0.3, 0.15, 0.15)))

    def ensure_clutter(self) -> None:
        """Every cluttered roof keeps at least one clutter cell (trees or people may have covered it)."""
        g = self.grid
        for spec in self.roofs:
            own = g.region == spec.region
            if spec.clutter == "clear" or (own & (g.cls == int(C.ROOF_CLUTTER))).any():
                continue
            cells = np.flatnonzero(own & np.isin(g.cls, ROOF_CLASSES))
            if cells.size == 0:
                continue
            i, j = divmod(int(cells[int(self.rng.integers(0, cells.size))]), g.shape[1])
            g.height[i, j] += self.u(0.3, 0.8)
            g.cls[i, j] = int(C.ROOF_CLUTTER)
            g.mat[i, j] = int(M.METAL)

    # ------------------------------------------------------------------ ground pieces
    def driveway(self, start: NE, yaw: float, width: float) -> None:
        """A strip from ``start`` to past the grid's edge along ``yaw``."""
        mat = self.pick((M.PAVING, M.CONCRETE, M.GRAVEL, M.ASPHALT))
        span = 2 * max(self.hn, self.he)
        self.rect(self.at(start, yaw, span / 2, 0.0), span, width, yaw, 0.02, C.GROUND, mat, mode="max")

    def house_surroundings(self, spec: RoofSpec, side: float) -> None:
        """Driveway with maybe a car, a path, a terrace with furniture, people and a bicycle near a house."""
        c, yaw, length, width = spec.centre_ne, spec.yaw_rad, spec.length_m, spec.width_m
        if self.p(0.75):
            dc = self.at(c, yaw, self.pick((-1.0, 1.0)) * (length / 2 - 2.0), side * (width / 2 + 0.2))
            dw = self.u(2.8, 5.5)
            self.driveway(dc, yaw + side * math.pi / 2, dw)
            if self.p(0.65):
                cc = self.at(dc, yaw + side * math.pi / 2, self.u(3.0, 5.0), 0.0)
                if self.free(cc, 1.0, (int(C.GROUND),)):
                    self.car(cc, yaw + side * math.pi / 2 + self.pick((0.0, math.pi)) + self.u(-0.1, 0.1))
        if self.p(0.5):  # terrace on the other side
            tc = self.at(c, yaw, self.u(-0.2, 0.2) * length, -side * (width / 2 + 1.8))
            tl, tw = min(length * 0.7, self.u(4.0, 8.0)), self.u(2.5, 4.0)
            self.rect(
                tc, tl, tw, yaw, 0.05, C.SIDEWALK, self.pick((M.PAVING, M.WOOD, M.CONCRETE)), mode="max"
            )
            if self.p(0.8):
                self.furniture(self.at(tc, yaw, self.u(-0.2, 0.2) * tl, 0.0), yaw + self.u(-0.2, 0.2))
        if self.p(0.45):
            pc = self.at(
                c, yaw, self.u(-0.5, 0.5) * length, self.pick((-1.0, 1.0)) * (width / 2 + self.u(0.8, 2.5))
            )
            if self.free(pc, 0.3):
                self.group(pc, int(self.rng.integers(1, 4)))
        if self.p(0.3):
            s = self.pick((-1.0, 1.0))
            bc = self.at(c, yaw, self.u(-0.4, 0.4) * length, float(s) * (width / 2 + 0.45))
            if self.free(bc, 0.3):
                self.bicycle(bc, yaw + self.u(-0.2, 0.2))
        if self.p(0.08) and spec.style in ("gable", "hip"):  # someone on the roof
            got = self.frame(self._roof_point(spec, 0.8, (0.2, 0.7)), 0.6, 0.6, 0.0)
            if got is not None:
                win, mask, _, _ = got
                if self._roof_mask(win, spec.region)[mask].all():
                    i0, i1, j0, j1 = win
                    top = float(self.grid.height[i0:i1, j0:j1][mask].max())
                    n, e = self.grid.cell_centres(i0, i0 + 1, j0, j0 + 1)
                    self.person((float(n[0, 0]) + 0.3, float(e[0, 0]) + 0.3), self.u(0, 6.3), top - 0.1)

    def garden_edges(self, count: int) -> None:
        """Hedges and fences along a few straight lines through the lawn."""
        for _ in range(count):
            vertical = self.p(0.5)
            x = self.u(-0.9, 0.9) * (self.he if vertical else self.hn)
            if vertical:
                a, b = (-self.hn, x), (self.hn, x)
            else:
                a, b = (x, -self.he), (x, self.he)
            if self.p(0.5):
                self.hedge(a, b, self.u(0.6, 1.2), self.u(1.0, 2.2))
            else:
                self.fence(a, b)

    # ------------------------------------------------------------------ the kinds
    def house(self, style: str) -> None:
        yaw = self.u(0, math.pi)
        length = self.u(8.0, 15.0)
        width = min(self.u(6.0, 10.5), length - 0.5)
        c = (self.u(-3, 3), self.u(-3, 3))
        spec = self.pitched_house(
            c, length, width, yaw, style, wing=self.p(0.35), dormers=self.p(0.3 if style == "gable" else 0.15)
        )
        side = self.pick((-1.0, 1.0))
        if self.p(0.4):  # a flat-roofed garage beside it
            gc = self.at(c, yaw, float(side) * (length / 2 + 1.8), 0.0)
            gmat = self.pick((M.TAR, M.MEMBRANE, M.GRAVEL, M.CORRUGATED))
            gh = self.u(2.5, 3.1)
            self.flat_building(
                gc, 3.4, self.u(5.5, 7.0), yaw + math.pi / 2, h=gh, mat=gmat, parapet=self.p(0.3)
            )
        if self.p(0.5):  # a neighbour near the edge
            nc = self.at(c, yaw, self.pick((-1.0, 1.0)) * (length / 2 + self.u(7, 11)), self.u(-3, 3))
            nl = self.u(8, 13)
            self._maybe_house(nc, nl, min(self.u(6, 10), nl - 0.5), yaw + self.u(-0.3, 0.3))
        self.house_surroundings(spec, float(side))
        self.garden_edges(int(self.rng.integers(0, 3)))
        self.trees(int(self.rng.integers(1, 6)))
        if self.p(0.3):
            c2 = self.spot(1.0)
            if c2 is not None:
                self.furniture(c2, self.u(0, 3))

    def _maybe_house(self, c: NE, length: float, width: float, yaw: float) -> RoofSpec | None:
        """A house whose footprint overlaps no other building (any roof style)."""
        r = math.hypot(length, width) / 2
        g = self.grid
        win = g.window(c[0] - r, c[0] + r, c[1] - r, c[1] + r)
        if not self.inside(c, 0.5 * r) or win is None:
            return None
        if (g.region[win[0] : win[1], win[2] : win[3]] != 0).any():
            return None
        x = self.rng.random()
        if x < 0.4:
            return self.pitched_house(c, length, width, yaw, "gable")
        if x < 0.8:
            return self.pitched_house(c, length, width, yaw, "hip")
        return self.flat_building(c, length, width, yaw, h=self.u(3, 7))

    def garden(self) -> None:
        yaw = self.u(0, math.pi)
        # the house stands at one edge, partly outside the grid
        edge = self.pick((-1.0, 1.0))
        length, width = self.u(9, 15), self.u(7, 10)
        c = self.at(
            (0.0, 0.0), yaw, 0.0, float(edge) * (min(self.hn, self.he) - width / 2 - self.u(1.0, 3.0))
        )
        spec = self._maybe_house(c, length, width, yaw)
        side = -float(edge)
        if spec is not None:
            tc = self.at(c, yaw, 0.0, side * (width / 2 + 1.6))
            self.rect(tc, length * 0.8, 3.2, yaw, 0.05, C.SIDEWALK, self.pick((M.PAVING, M.WOOD, M.CONCRETE)))
            self.furniture(self.at(tc, yaw, self.u(-0.25, 0.25) * length, 0.0), yaw)
        if self.p(0.6):  # pool
            pl, pw = self.u(5, 11), self.u(3, 5)
            pc = self.at(c, yaw, self.u(-2, 2), side * (width / 2 + 4.5 + pw / 2))
            ss = self.u(0.8, 2.0)
            self.rect(
                pc, pl + 2 * ss, pw + 2 * ss, yaw, 0.05, C.SIDEWALK, self.pick((M.PAVING, M.CONCRETE, M.WOOD))
            )
            if self.p(0.7):
                self.rect(pc, pl, pw, yaw, -0.12, C.WATER, M.POOL)
            else:  # kidney / oval
                got = self.frame(pc, pl, pw, yaw)
                if got is not None:
                    win, _, uu, vv = got
                    wob = 1 + 0.25 * np.sin(uu / pl * 2 * math.pi + self.u(0, 6))
                    self.paint(
                        win, (2 * uu / pl) ** 2 + (2 * vv / (pw * wob)) ** 2 <= 1, -0.12, C.WATER, M.POOL
                    )
            for _ in range(int(self.rng.integers(0, 4))):  # sun loungers
                lc = self.at(pc, yaw, self.u(-pl / 2, pl / 2), self.pick((-1.0, 1.0)) * (pw / 2 + ss / 2))
                if self.p(0.4):
                    self.person(lc, yaw + math.pi / 2, 0.35, "lie")
                else:
                    self.rect(
                        lc,
                        0.7,
                        1.9,
                        yaw,
                        self.u(0.3, 0.45),
                        C.GROUND,
                        self.pick((M.WOOD, M.MEMBRANE, M.CLOTH)),
                        self.actor(),
                    )
            if self.p(0.4):
                self.person(self.at(pc, yaw, self.u(-pl / 3, pl / 3), 0.0), self.u(0, 6), -0.6)  # swimming
        if self.p(0.5):  # trampoline
            tp = self.spot(2.2, (int(C.GRASS),))
            if tp is not None:
                r = self.u(1.5, 2.2)
                self.disc(tp, r, 0.95, C.GROUND, M.METAL)
                self.disc(tp, r - 0.25, 0.9, C.GROUND, M.TAR)
        for _ in range(int(self.rng.integers(0, 3))):  # vegetable / flower beds
            bc = self.spot(1.5, (int(C.GRASS),))
            if bc is not None:
                by = self.u(0, math.pi)
                self.rect(bc, self.u(2, 6), self.u(1, 2.5), by, 0.1, C.GROUND, M.SOIL)
                got = self.frame(bc, 6, 2.5, by)
                if got is not None and self.p(0.6):
                    win, mask, uu, vv = got
                    rows = np.mod(vv, 0.5) < 0.2
                    soil = self.grid.mat[win[0] : win[1], win[2] : win[3]] == int(M.SOIL)
                    self.paint(win, mask & rows & soil, 0.1, C.GRASS, M.FOLIAGE)
        if self.p(0.5):  # a garden shed
            sc = self.spot(2.0)
            if sc is not None:
                if self.p(0.5):
                    smat = self.pick((M.TAR, M.CORRUGATED, M.MEMBRANE))
                    sl, sw, sy = self.u(2, 3.5), self.u(2, 3), self.u(0, 3)
                    self.flat_building(sc, sl, sw, sy, h=self.u(2, 2.5), mat=smat, parapet=False)
                else:
                    smat = self.pick((M.SHINGLE, M.CORRUGATED, M.WOOD))
                    sl, sw, sy = self.u(2.5, 3.5), self.u(2, 2.5), self.u(0, 3)
                    self.pitched_house(sc, sl, sw, sy, "gable", mat=smat, eave=2.0)
        for _ in range(int(self.rng.integers(1, 4))):
            pg = self.spot(0.5, (int(C.GRASS),))
            if pg is not None:
                x = self.rng.random()
                if x < 0.2:
                    self.person(pg, self.u(0, 6.3), 0.0, "lie")
                else:
                    self.group(pg, int(self.rng.integers(1, 4)), pose="sit" if x < 0.35 else "stand")
        self.garden_edges(int(self.rng.integers(1, 4)))
        self.trees(int(self.rng.integers(2, 8)))

    def barn_kind(self) -> None:
        self.grid.cls[:] = int(C.GROUND)
        self.grid.mat[:] = int(M.SOIL)
        yaw = self.u(0, math.pi)
        length = self.u(15.0, min(40.0, 2 * min(self.hn, self.he) + 5))
        width = self.u(8.0, 16.0)
        c = (self.u(-4, 4), self.u(-4, 4))
        self.yard_patches()
        spec = self.barn(c, length, width, yaw)
        if self.p(0.4):  # a lean-to along one side, same material, shallower
            lc = self.at(c, yaw, 0.0, self.pick((-1.0, 1.0)) * (width / 2 + 2.0))
            got = self.frame(lc, length * self.u(0.4, 0.9), 4.0, yaw)
            if got is not None:
                win, mask, _, _ = got
                own = self.grid.region[win[0] : win[1], win[2] : win[3]] == 0
                self.paint(win, mask & own, spec.height_m - 0.6, C.ROOF_PITCHED, spec.material, spec.region)
        self.yard_objects(int(self.rng.integers(3, 10)))
        if self.p(0.5):
            t = self.spot(2.5, (int(C.GROUND),))
            if t is not None:
                self.tractor(t, self.u(0, 6.3))
        if self.p(0.4):
            p = self.spot(0.4, (int(C.GROUND),))
            if p is not None:
                self.group(p, int(self.rng.integers(1, 3)))
        self.trees(int(self.rng.integers(0, 4)))

    def yard_patches(self) -> None:
        """Gravel areas, grass patches and crop rows over a dirt ground."""
        for _ in range(int(self.rng.integers(1, 4))):
            got = self.blob((self.u(-self.hn, self.hn), self.u(-self.he, self.he)), self.u(4, 12), 0.3)
            if got is not None:
                win, mask, _ = got
                mat = self.pick((M.GRAVEL, M.GRASS, M.RUBBLE), (0.5, 0.35, 0.15))
                self.paint(win, mask, 0.02, C.GRASS if mat == M.GRASS else C.GROUND, mat)
        if self.p(0.6):  # a field of crop rows along one edge
            yaw = self.u(0, math.pi)
            fc = self.at((0.0, 0.0), yaw, 0.0, self.pick((-1.0, 1.0)) * min(self.hn, self.he) * 0.8)
            fr = self.frame(fc, 200.0, min(self.hn, self.he) * 0.7, yaw)
            if fr is not None:
                win, mask, _, vv = fr
                period = self.u(0.5, 0.9)
                rows = np.mod(vv, period) < period * self.u(0.3, 0.6)
                self.paint(win, mask, 0.0, C.GROUND, M.SOIL)
                self.paint(win, mask & rows, 0.0, C.GRASS, self.pick((M.GRASS, M.FOLIAGE)))

    def yard_objects(self, count: int) -> None:
        for _ in range(count):
            c = self.spot(2.0, (int(C.GROUND),))
            if c is None:
                continue
            yaw = self.u(0, math.pi)
            x = self.rng.random()
            if x < 0.45:
                for k in range(int(self.rng.integers(1, 6))):
                    self.bale(self.at(c, yaw, k * 1.9, self.u(-0.2, 0.2)), yaw + math.pi / 2)
            elif x < 0.7:
                self.pipe_stack(c, yaw)
            elif x < 0.9:
                self.pallets(c, yaw)
            else:
                self.car(c, yaw, van=self.p(0.5))

    def yard(self) -> None:
        self.grid.cls[:] = int(C.GROUND)
        self.grid.mat[:] = int(self.pick((M.SOIL, M.GRAVEL), (0.7, 0.3)))
        self.yard_patches()
        if self.p(0.7):  # a shed or barn at one side
            yaw = self.u(0, math.pi)
            c = self.at((0.0, 0.0), yaw, self.u(-5, 5), self.pick((-1.0, 1.0)) * min(self.hn, self.he) * 0.55)
            length, width = self.u(8, 22), self.u(6, 12)
            if self.p(0.6):
                self.barn(c, length, width, yaw)
            else:
                self.flat_building(
                    c, length, width, yaw, h=self.u(3, 6), mat=self.pick((M.CORRUGATED, M.TAR, M.CONCRETE))
                )
        self.yard_objects(int(self.rng.integers(4, 12)))
        if self.p(0.5):
            t = self.spot(2.5, (int(C.GROUND),))
            if t is not None:
                self.tractor(t, self.u(0, 6.3))
        for _ in range(int(self.rng.integers(0, 3))):
            p = self.spot(0.4, (int(C.GROUND),))
            if p is not None:
                self.group(p, int(self.rng.integers(1, 3)))
        if self.p(0.4):
            self.fence((-self.hn, self.u(-self.he, self.he)), (self.hn, self.u(-self.he, self.he)))
        self.trees(int(self.rng.integers(0, 4)))

    def flat_roof(self) -> None:
        self.grid.cls[:] = int(C.SIDEWALK)
        self.grid.mat[:] = int(self.pick((M.PAVING, M.CONCRETE)))
        yaw = self.u(0, math.pi)
        span = 2 * min(self.hn, self.he)
        length = self.u(12.0, min(34.0, span - 6))
        width = min(self.u(9.0, 22.0), length)
        c = (self.u(-3, 3), self.u(-3, 3))
        spec = self.flat_building(c, length, width, yaw)
        if self.p(0.35):  # an annex, lower or higher, another material
            s = self.pick((-1.0, 1.0))
            al = self.u(4.0, 9.0)
            ac = self.at(c, yaw, float(s) * (length / 2 + al / 2), self.u(-0.2, 0.2) * width)
            self.flat_building(
                ac, al, width * self.u(0.5, 0.9), yaw, h=max(2.8, spec.height_m + self.u(-4, 3))
            )
        if self.p(0.2):  # someone on the roof
            c2 = self._roof_point(spec, 1.0)
            got = self.frame(c2, 0.6, 0.6, 0.0)
            if (
                got is not None
                and self._roof_mask(got[0], spec.region)[got[1]].all()
                and self._top(got[0], got[1]) <= spec.height_m + 0.05
            ):
                self.person(c2, self.u(0, 6.3), spec.height_m)
        # around it: a lawn strip, parking, trees
        for _ in range(int(self.rng.integers(1, 4))):
            bl = self.blob((self.u(-self.hn, self.hn), self.u(-self.he, self.he)), self.u(3, 8), 0.2)
            if bl is not None:
                win, mask, _ = bl
                free = self.grid.region[win[0] : win[1], win[2] : win[3]] == 0
                self.paint(win, mask & free, 0.03, C.GRASS, M.GRASS)
        if self.p(0.7):
            py = yaw + self.pick((0.0, math.pi / 2))
            pc = self.at(c, py, 0.0, self.pick((-1.0, 1.0)) * (max(length, width) / 2 + 6.0))
            self.bays(pc, py, 60.0, 12.0, (0.2, 0.8))
        self.trees(int(self.rng.integers(0, 5)))
        for _ in range(int(self.rng.integers(0, 3))):
            p = self.spot(0.4)
            if p is not None:
                self.group(p, int(self.rng.integers(1, 4)))
        if self.p(0.3):
            b = self.spot(0.5)
            if b is not None:
                self.bicycle(b, self.u(0, 6.3))

    def bays(self, c: NE, yaw: float, length: float, depth: float, occ: tuple[float, float]) -> None:
        """A strip of parking: ``depth`` m across (one or two rows of 5 m bays with an aisle)."""
        got = self.frame(c, length, depth, yaw)
        if got is None:
            return
        win, mask, uu, vv = got
        free = self.grid.region[win[0] : win[1], win[2] : win[3]] == 0
        mask = mask & free
        self.paint(win, mask, 0.0, C.PARKING_LOT, M.ASPHALT)
        bw = self.u(2.4, 2.7)
        lw = self.w(0.12) / 2
        rows = [-depth / 2 + 2.5] if depth < 11 else [-depth / 2 + 2.5, depth / 2 - 2.5]
        p = self.u(*occ)
        for rv in rows:
            band = np.abs(vv - rv) <= 2.5
            lines = np.abs(np.mod(uu, bw) - bw / 2) >= bw / 2 - lw
            back = np.abs(vv - (rv + math.copysign(2.5, rv))) <= lw
            self.paint(win, mask & band & (lines | back), None, None, M.LANE_MARKING)
            for k in range(-int(length / bw / 2), int(length / bw / 2)):
                cc = self.at(c, yaw, (k + 0.5) * bw, rv)
                if self.inside(cc, -2.0) and self.rng.random() < p:
                    ok = self.free(cc, 0.9, (int(C.PARKING_LOT),))
                    if ok:
                        self.car(self.at(cc, yaw, self.u(-0.15, 0.15), self.u(-0.2, 0.2)),
                                 yaw + math.pi / 2 + self.pick((0.0, math.pi)) + self.u(-0.06, 0.06),
                                 van=self.p(0.1))  # fmt: skip

    def car_park(self) -> None:
        self.grid.cls[:] = int(C.PARKING_LOT)
        self.grid.mat[:] = int(M.ASPHALT)
        yaw = self.u(0, math.pi)
        span = 2 * max(self.hn, self.he) + 20
        if self.p(0.5):  # a shop along one side
            sc = self.at(
                (0.0, 0.0),
                yaw,
                self.u(-5, 5),
                self.pick((-1.0, 1.0)) * (min(self.hn, self.he) + self.u(-2, 4)),
            )
            self.flat_building(sc, self.u(20, 40), 16.0, yaw, h=self.u(4, 8))
        module = 16.5  # two rows of bays and an aisle
        off = self.u(0, module)
        for k in range(-4, 5):
            vc = k * (module + 1.5) + off
            bc = self.at((0.0, 0.0), yaw, 0.0, vc)
            self.bays(bc, yaw, span, module, (0.2, 0.95))
            if self.p(0.4):  # a planted island between modules
                ic = self.at((0.0, 0.0), yaw, 0.0, vc + module / 2 + 0.75)
                got = self.frame(ic, span, 1.5, yaw)
                if got is not None:
                    win, mask, _, _ = got
                    free = self.grid.region[win[0] : win[1], win[2] : win[3]] == 0
                    self.paint(win, mask & free, 0.15, C.GRASS, M.GRASS)
                    for t in range(-3, 4):
                        tc = self.at(ic, yaw, t * self.u(7, 10), 0.0)
                        if self.inside(tc, 0.0) and self.p(0.6) and self.free(tc, 0.5, (int(C.GRASS),)):
                            self.tree(tc, self.u(1.5, 3.5), self.u(4, 9))
        for _ in range(int(self.rng.integers(1, 6))):
            p = self.spot(0.5, (int(C.PARKING_LOT),))
            if p is not None:
                self.group(p, int(self.rng.integers(1, 3)), spread=0.6)
        if self.p(0.3):  # shopping trolleys / a trolley bay: metal on the asphalt
            tb = self.spot(1.0, (int(C.PARKING_LOT),))
            if tb is not None:
                self.rect(tb, self.u(2, 4), 0.6, self.u(0, 3), 1.0, C.GROUND, M.METAL)

    def street(self) -> None:
        g = self.grid
        yaw = self.u(0, math.pi)
        rw = self.u(5.5, 10.0)
        sw = self.u(1.5, 3.0)
        span = 3 * max(self.hn, self.he)
        off = self.u(-3, 3)
        c = self.at((0.0, 0.0), yaw, 0.0, off)
        # front gardens with houses on both sides
        for s in (-1.0, 1.0):
            for k in range(-2, 3):
                hl, hw = self.u(8, 13), self.u(7, 10)
                hc = self.at(
                    c, yaw, k * self.u(14, 18) + self.u(-2, 2), s * (rw / 2 + sw + self.u(4, 8) + hw / 2)
                )
                if self.inside(hc, 1.0):
                    self._maybe_house(hc, hl, hw, yaw + self.u(-0.1, 0.1) + (math.pi / 2 if hl < hw else 0.0))
        for s in (-1.0, 1.0):
            if self.p(0.6):
                a = self.at(c, yaw, -span / 2, s * (rw / 2 + sw + 0.3))
                b = self.at(c, yaw, span / 2, s * (rw / 2 + sw + 0.3))
                if self.p(0.5):
                    self.hedge(a, b, self.u(0.5, 1.0), self.u(0.8, 1.8))
                else:
                    self.fence(a, b)
        self.rect(c, span, rw + 2 * sw, yaw, 0.12, C.SIDEWALK, self.pick((M.PAVING, M.CONCRETE)))
        self.rect(c, span, rw, yaw, 0.0, C.ROAD, M.ASPHALT)
        got = self.frame(c, span, rw, yaw)
        if got is None:
            return
        win, mask, uu, vv = got
        lw = self.w(0.12) / 2
        dash, gap = self.u(1.5, 3.0), self.u(3.0, 6.0)
        centre = (np.abs(vv) <= lw) & (np.mod(uu, dash + gap) < dash) if self.p(0.8) else np.abs(vv) <= lw
        edges = (np.abs(np.abs(vv) - (rw / 2 - 0.3)) <= lw) if self.p(0.5) else np.zeros_like(mask)
        self.paint(win, mask & (centre | edges), None, None, M.LANE_MARKING)
        zu = self.u(-10, 10)
        if self.p(0.75):  # zebra crossing
            zd = self.u(2.5, 4.0)
            band = np.abs(uu - zu) <= zd / 2
            stripes = np.mod(vv + rw / 2, 1.0) < 0.5
            self.paint(win, mask & band, None, C.CROSSWALK, M.ASPHALT)
            self.paint(win, mask & band & stripes, None, None, M.ZEBRA)
            for _ in range(int(self.rng.integers(0, 4))):
                self.person(
                    self.at(c, yaw, zu + self.u(-1, 1), self.u(-rw / 2, rw / 2)),
                    yaw + math.pi / 2 + self.u(-0.3, 0.3),
                )
        if self.p(0.4):  # a side road
            sc = self.at(c, yaw, zu + self.pick((-1.0, 1.0)) * self.u(8, 14), 0.0)
            sr = self.u(5, 7)
            s = self.pick((-1.0, 1.0))
            self.rect(
                self.at(sc, yaw, 0.0, float(s) * span / 4),
                sr + 2 * sw,
                span / 2 - rw / 2,
                yaw,
                0.12,
                C.SIDEWALK,
                M.PAVING,
            )
            self.rect(self.at(sc, yaw, 0.0, float(s) * span / 4), sr, span / 2, yaw, 0.0, C.ROAD, M.ASPHALT)
        for _ in range(int(self.rng.integers(1, 4))):  # manholes and drain grates
            mc = self.at(c, yaw, self.u(-15, 15), self.u(-0.3, 0.3) * rw)
            if g.class_at(*mc) == C.ROAD:
                self.disc(mc, self.u(0.3, 0.4), 0.0, C.ROAD, self.pick((M.METAL, M.TAR)))
        for _ in range(int(self.rng.integers(0, 4))):
            dc = self.at(c, yaw, self.u(-15, 15), self.pick((-1.0, 1.0)) * (rw / 2 - 0.25))
            self.rect(dc, 0.5, 0.35, yaw, 0.0, C.ROAD, M.METAL)
        for _ in range(int(self.rng.integers(1, 6))):  # cars: parked at the kerb or in a lane
            s = self.pick((-1.0, 1.0))
            parked = self.p(0.5)
            vc = self.at(
                c, yaw, self.u(-span / 3, span / 3), float(s) * (rw / 2 - (1.1 if parked else rw / 4))
            )
            if self.inside(vc, -2.0) and self.free(vc, 1.0, (int(C.ROAD), int(C.CROSSWALK))):
                self.car(vc, yaw + (0.0 if s > 0 else math.pi) + self.u(-0.04, 0.04), van=self.p(0.12))
        for _ in range(int(self.rng.integers(0, 3))):
            s = self.pick((-1.0, 1.0))
            bc = self.at(c, yaw, self.u(-15, 15), float(s) * (rw / 2 - 0.6))
            if self.free(bc, 0.4, (int(C.ROAD),)):
                self.bicycle(bc, yaw)
                if self.p(0.7):
                    self.person(bc, yaw, 0.3)  # the rider
        for _ in range(int(self.rng.integers(1, 6))):  # pedestrians on the sidewalks
            s = self.pick((-1.0, 1.0))
            pc = self.at(c, yaw, self.u(-18, 18), float(s) * (rw / 2 + sw / 2 + self.u(-0.4, 0.4)))
            if self.free(pc, 0.3, (int(C.SIDEWALK),)) or g.class_at(*pc) == C.SIDEWALK:
                self.group(pc, int(self.rng.integers(1, 3)), 0.12, spread=0.5)
        for k in range(-3, 4):  # street trees
            if self.p(0.3):
                tc = self.at(c, yaw, k * 8.0 + self.u(-1, 1), self.pick((-1.0, 1.0)) * (rw / 2 + sw * 0.6))
                if self.inside(tc, 0.0) and self.free(tc, 0.5, (int(C.SIDEWALK),)):
                    self.tree(tc, self.u(1.5, 3.5), self.u(5, 10))
        self.trees(int(self.rng.integers(0, 4)))

    def pond(self) -> None:
        c = (self.u(-4, 4), self.u(-4, 4))
        r = self.u(5.0, min(12.0, min(self.hn, self.he) - 4))
        got = self.blob(c, r + self.u(0.4, 1.2), 0.25)
        if got is not None:  # muddy / gravel bank
            win, mask, _ = got
            self.paint(win, mask, 0.0, C.GROUND, self.pick((M.SOIL, M.GRAVEL)))
        got = self.blob(c, r, 0.25)
        if got is None:
            return
        win, mask, rel = got
        self.paint(win, mask, -0.3, C.WATER, M.WATER)
        if self.p(0.7):  # reeds along part of the shore
            a0 = self.u(0, 2 * math.pi)
            n, e = self.grid.cell_centres(*win)
            th = np.mod(np.arctan2(e - c[1], n - c[0]) - a0, 2 * math.pi)
            reeds = (rel > 0.82) & (rel <= 1.05) & (th < self.u(0.8, 3.0))
            hh = (self.u(0.8, 1.6) + self.rng.uniform(-0.1, 0.1, rel.shape)).astype(np.float32)
            self.paint(win, reeds, hh, C.TREE, M.FOLIAGE)
        if self.p(0.5):  # a jetty
            a = self.u(0, 2 * math.pi)
            jl = r * self.u(0.5, 0.8)
            jc = (c[0] + (r - jl / 2 + 0.5) * math.cos(a), c[1] + (r - jl / 2 + 0.5) * math.sin(a))
            self.rect(jc, jl, self.u(1.2, 2.0), a, 0.35, C.PIER, M.WOOD)
            if self.p(0.5):
                self.person(
                    self.at(jc, a, -jl / 2 + 0.6, 0.0), a + math.pi, 0.35, self.pick(("stand", "sit"))
                )
        # a path around it with benches and people
        a0 = self.u(0, math.pi)
        pts = [
            (c[0] + (r + 3.0) * math.cos(a0 + t), c[1] + (r + 3.0) * 1.1 * math.sin(a0 + t))
            for t in np.linspace(0, 4.5, 12)
        ]
        self.grid.fill_polyline(
            pts, self.u(1.5, 2.5), height_m=0.03, cls=C.SIDEWALK, mat=self.pick((M.GRAVEL, M.PAVING, M.SOIL))
        )
        for _ in range(int(self.rng.integers(0, 3))):
            bc = pts[int(self.rng.integers(1, len(pts) - 1))]
            bc = (bc[0] + 1.6, bc[1])
            if self.free(bc, 0.8):
                self.rect(bc, 1.8, 0.6, self.u(0, 3), 0.85, C.GROUND, M.WOOD)
        for _ in range(int(self.rng.integers(1, 4))):
            pc = pts[int(self.rng.integers(0, len(pts)))]
            if self.free(pc, 0.4):
                self.group(pc, int(self.rng.integers(1, 3)), 0.03, spread=0.5)
        if self.p(0.3):
            self._maybe_house(
                self.at((0.0, 0.0), self.u(0, 6.3), min(self.hn, self.he) - 6, 0.0),
                self.u(8, 12),
                self.u(6, 9),
                self.u(0, 3),
            )
        self.trees(int(self.rng.integers(3, 10)))

    def build(self) -> World:
        k = self.kind
        scenes: dict[str, Callable[[], None]] = {
            "house": lambda: self.house("gable"),
            "hip_house": lambda: self.house("hip"),
            "barn": self.barn_kind,
            "flat_roof": self.flat_roof,
            "garden": self.garden,
            "street": self.street,
            "car_park": self.car_park,
            "pond": self.pond,
            "yard": self.yard,
        }
        scenes[k]()
        self.ensure_clutter()
        sun = Sun(self.u(0.0, 360.0), self.u(*SUN_ELEVATION_DEG))
        levels = ", ".join(f"{r.style}:{r.clutter}" for r in self.roofs) or "no roofs"
        desc = (
            f"vignette {k!r} seed {self.seed}: {2 * self.hn:.1f} x {2 * self.he:.1f} m at {self.res:.3f} m, "
            f"roofs {levels}"
        )
        return World(
            name=f"vignette-{k}",
            seed=self.seed,
            grid=self.grid,
            launch_height_m=30.0,
            sun=sun,
            description=desc,
        )


def build_vignette_roofs(seed: int, kind: str | None = None) -> tuple[World, tuple[RoofSpec, ...]]:
    """:func:`build_vignette` and the :class:`RoofSpec` of each roof painted in it."""
    if kind is None:
        kind = VIGNETTE_KINDS[int(np.random.default_rng([seed, 0x5EED]).integers(0, len(VIGNETTE_KINDS)))]
    if kind not in VIGNETTE_KINDS:
        raise ValueError(f"unknown vignette kind {kind!r}; expected one of {', '.join(VIGNETTE_KINDS)}")
    b = _Builder(int(seed), kind)
    world = b.build()
    return world, tuple(b.roofs)


def build_vignette(seed: int, kind: str | None = None) -> World:
    """A small fine-grained world (the module docstring says what it holds and what varies).

    Args:
        seed: seeds the one ``np.random.default_rng`` the build draws from; the same seed (and kind)
            gives the same grid.
        kind: one of :data:`VIGNETTE_KINDS`; None picks one from the seed.

    Returns:
        A :class:`World` named ``vignette-KIND`` with the painted grid (about 30-50 m a side at
        0.04-0.08 m cells, centred on the origin) and a random sun; no lanes, walkways or safe zones.

    Raises:
        ValueError: an unknown kind.
    """
    return build_vignette_roofs(seed, kind)[0]
