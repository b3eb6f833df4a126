"""Vignettes: small, fine-grained worlds for training the onboard landing-site judge (one module over
600 lines: the scene kinds share one builder and its layout).

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

Kept whole (about 700 lines): the scene kinds, each a short recipe over the same parts
(:mod:`~simbridge.world.vignette_canvas`, :mod:`~simbridge.world.vignette_props`,
:mod:`~simbridge.world.vignette_roofs`); side by side they show what varies between kinds.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from simbridge.world.model import Material as M
from simbridge.world.model import SurfaceClass as C
from simbridge.world.vignette_canvas import (
    CLUTTER_LEVELS,
    NE,
    SUN_ELEVATION_DEG,
    VIGNETTE_KINDS,
    RoofSpec,
    gable_heights,
    hip_heights,
)
from simbridge.world.vignette_props import Props
from simbridge.world.vignette_roofs import Roofs
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


class _Builder(Props, Roofs):
    """One scene of a kind (module docstring), from its seed."""

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
