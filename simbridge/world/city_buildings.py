"""The city's buildings: heights, flat and pitched roofs, parapets, helipads and rooftop clutter."""

from __future__ import annotations

import math

import numpy as np

from simbridge.world.city_parts import CityParts, Roof
from simbridge.world.model import ROOF_MATERIALS, Material, SurfaceClass


class Buildings(CityParts):
    """The city's buildings: heights, flat and pitched roofs, parapets, helipads and rooftop clutter."""

    def _paint_building_block(self, n0: float, n1: float, e0: float, e1: float, base: bool = True) -> None:
        p = self.p
        if base:
            self._fill(n0, n1, e0, e1, 0.0, SurfaceClass.GROUND, Material.CONCRETE)
        stack = [(n0 + 1.0, n1 - 1.0, e0 + 1.0, e1 - 1.0)]
        lots: list[tuple[float, float, float, float]] = []
        while stack:
            a0, a1, b0, b1 = stack.pop()
            dn, de = a1 - a0, b1 - b0
            big = max(dn, de)
            if big <= p.lot_m[1] or big < 2 * p.lot_m[0]:
                lots.append((a0, a1, b0, b1))
                continue
            f = float(self.rng.uniform(0.35, 0.65))
            if dn >= de:
                cut = min(max(a0 + f * dn, a0 + p.lot_m[0]), a1 - p.lot_m[0])
                stack += [(a0, cut, b0, b1), (cut, a1, b0, b1)]
            else:
                cut = min(max(b0 + f * de, b0 + p.lot_m[0]), b1 - p.lot_m[0])
                stack += [(a0, a1, b0, cut), (a0, a1, cut, b1)]
        for a0, a1, b0, b1 in lots:
            if self.rng.random() < 0.05:
                continue  # an empty yard
            gap = 0.0 if self.rng.random() < 0.35 else float(self.rng.uniform(1.0, 4.0))
            self._paint_building(a0 + gap / 2, a1 - gap / 2, b0 + gap / 2, b1 - gap / 2)

    def _building_height(self, dn: float, de: float) -> float:
        mix = self.p.height_mix
        w = np.array([b[2] for b in mix], float)
        k = int(self.rng.choice(len(mix), p=w / w.sum()))
        h = float(self.rng.uniform(mix[k][0], mix[k][1]))
        return min(h, max(mix[0][0], 5.0 * min(dn, de)))  # no needles

    def _paint_building(self, n0: float, n1: float, e0: float, e1: float) -> None:
        p = self.p
        dn, de = n1 - n0, e1 - e0
        if dn < 5.0 or de < 5.0:
            return
        rid = self._new_region()
        self.n_buildings += 1
        h = self._building_height(dn, de)
        if h <= 20.0 and min(dn, de) <= 30.0 and self.rng.random() < p.pitched_fraction:
            length, width, yaw = (dn, de, 0.0) if dn >= de else (de, dn, math.pi / 2)
            ridge = h + float(self.rng.uniform(0.25, 0.6)) * width / 2
            mat = Material.TILES if self.rng.random() < 0.75 else Material.METAL
            self._fill(n0, n1, e0, e1, h, SurfaceClass.ROOF_PITCHED, mat, rid)  # covers rect_mask edge cells
            self.grid.fill_pitched(
                ((n0 + n1) / 2, (e0 + e1) / 2), length, width, yaw, h, ridge, region=rid, mat=mat
            )
            if self.rng.random() < 0.4:  # a chimney
                v = float(self.rng.uniform(-0.3, 0.3)) * width
                u = float(self.rng.uniform(-0.35, 0.35)) * length
                local = h + (ridge - h) * (1.0 - abs(v) / (width / 2))
                cn, ce = (
                    ((n0 + n1) / 2 + u, (e0 + e1) / 2 + v)
                    if yaw == 0.0
                    else ((n0 + n1) / 2 + v, (e0 + e1) / 2 + u)
                )
                self._fill(
                    cn - 0.4,
                    cn + 0.4,
                    ce - 0.4,
                    ce + 0.4,
                    local + 1.2,
                    SurfaceClass.ROOF_CLUTTER,
                    Material.BRICK,
                )
            return
        weights = np.array([0.3, 0.25, 0.2, 0.2, 0.05])
        roof_mat = ROOF_MATERIALS[int(self.rng.choice(len(ROOF_MATERIALS), p=weights))]
        margin = 0.5
        if self.rng.random() < p.parapet_fraction:
            pw = self._line_w(float(self.rng.uniform(0.3, 0.5)))
            ph = float(self.rng.uniform(0.8, 1.2))
            pmat = Material.CONCRETE if self.rng.random() < 0.7 else Material.BRICK
            self._fill(n0, n1, e0, e1, h + ph, SurfaceClass.PARAPET, pmat, rid)
            self._fill(n0 + pw, n1 - pw, e0 + pw, e1 - pw, h, SurfaceClass.ROOF_FLAT, roof_mat, rid)
            margin += pw
        else:
            self._fill(n0, n1, e0, e1, h, SurfaceClass.ROOF_FLAT, roof_mat, rid)
        roof = Roof(rid, n0, n1, e0, e1, h, margin)
        x = self.rng.random()
        if x < p.clear_roof_fraction:
            self.clear_roofs.append(roof)
            if h >= 25.0 and min(dn, de) >= 18.0 and self.rng.random() < p.helipad_fraction:
                self._paint_helipad(roof)
        elif x < p.clear_roof_fraction + p.heavy_clutter_fraction:
            self._paint_clutter(
                roof, (n0 + margin, n1 - margin, e0 + margin, e1 - margin), p.clutter_per_m2[1]
            )
        else:
            zn0, zn1, ze0, ze1 = n0 + margin, n1 - margin, e0 + margin, e1 - margin
            f = float(self.rng.uniform(0.3, 0.55))
            side = int(self.rng.integers(0, 4))
            if side == 0:
                zn1 = zn0 + f * (zn1 - zn0)
            elif side == 1:
                zn0 = zn1 - f * (zn1 - zn0)
            elif side == 2:
                ze1 = ze0 + f * (ze1 - ze0)
            else:
                ze0 = ze1 - f * (ze1 - ze0)
            self._paint_clutter(roof, (zn0, zn1, ze0, ze1), p.clutter_per_m2[0])

    def _paint_helipad(self, roof: Roof) -> None:
        cn, ce = (roof.n_lo + roof.n_hi) / 2, (roof.e_lo + roof.e_hi) / 2
        r = min(9.0, min(roof.n_hi - roof.n_lo, roof.e_hi - roof.e_lo) / 2 - roof.margin - 1.0)
        got = self._box(cn - r, cn + r, ce - r, ce + r)
        if got is None or r < 4.0:
            return
        win, n, e = got
        dn, de = n - cn, e - ce
        d = np.hypot(dn, de)
        lw = self._line_w(0.4)
        ring = np.abs(d - (r - lw)) <= lw / 2
        hs = 0.55 * r
        bars = (np.abs(np.abs(de) - 0.4 * hs) <= lw) & (np.abs(dn) <= hs)
        cross = (np.abs(dn) <= lw) & (np.abs(de) <= 0.4 * hs)
        self._paint_mask(win, ring | bars | cross, None, None, Material.PAINT_TEXT)

    def _paint_clutter(self, roof: Roof, zone: tuple[float, float, float, float], density: float) -> None:
        """Rooftop objects inside ``zone``, ``density`` per m2; heights absolute (roof + object)."""
        zn0, zn1, ze0, ze1 = zone
        zdn, zde = zn1 - zn0, ze1 - ze0
        if zdn < 1.0 or zde < 1.0:
            return
        h = roof.height
        rng = self.rng
        count = min(80, max(1, round(zdn * zde * density)))
        kinds = ("hvac", "vent", "pipe", "dome", "antenna", "dish", "solar", "rubble", "penthouse")
        weights = np.array([0.33, 0.17, 0.1, 0.06, 0.07, 0.05, 0.11, 0.04, 0.07])
        thin = self._line_w(0.3)
        have_penthouse = False
        for _ in range(count):
            kind = kinds[int(rng.choice(len(kinds), p=weights))]
            if kind == "penthouse" and (have_penthouse or h < 20.0):
                kind = "hvac"  # one stair / lift housing, on taller buildings only
            have_penthouse |= kind == "penthouse"
            if kind in ("vent", "dish", "dome"):
                r_range = {"vent": (0.2, 0.5), "dish": (0.5, 1.2), "dome": (1.0, 3.0)}[kind]
                r = min(max(self._u(r_range), 0.75 * self.grid.res), zdn / 2, zde / 2)
                cn, ce = self._place(zone, 2 * r, 2 * r)
                if kind == "dome":
                    self._dome(cn, ce, r, h, float(rng.uniform(0.8, 2.5)))
                else:
                    top = h + (float(rng.uniform(0.5, 1.5)) if kind == "vent" else 1.2)
                    self.grid.fill_disc(
                        (cn, ce), r, height_m=top, cls=SurfaceClass.ROOF_CLUTTER, mat=Material.METAL
                    )
                continue
            # box-shaped objects: footprint (north, east) metres, height above the roof, material
            if kind == "hvac":
                sn, se, dh, mat = (
                    self._u((1.5, 4.0)),
                    self._u((1.5, 4.0)),
                    self._u((1.0, 2.5)),
                    Material.METAL,
                )
            elif kind == "penthouse":
                sn, se, dh, mat = (
                    self._u((3.0, 6.0)),
                    self._u((3.0, 6.0)),
                    self._u((2.5, 4.0)),
                    Material.CONCRETE,
                )
            elif kind == "pipe":
                length, dh, mat = self._u((4.0, 15.0)), self._u((0.4, 0.8)), Material.METAL
                sn, se = (length, thin) if rng.random() < 0.5 else (thin, length)
            elif kind == "antenna":
                sn, se, dh, mat = thin, thin, self._u((3.0, 8.0)), Material.METAL
            elif kind == "solar":
                sn, se, dh, mat = self._u((4.0, 14.0)), self._u((3.0, 10.0)), 0.0, Material.SOLAR
            else:  # rubble
                sn, se, dh, mat = self._u((2.0, 6.0)), self._u((2.0, 6.0)), 0.0, Material.RUBBLE
            sn, se = min(sn, zdn), min(se, zde)
            cn, ce = self._place(zone, sn, se)
            box = (cn - sn / 2, cn + sn / 2, ce - se / 2, ce + se / 2)
            if kind == "solar":
                self._solar(*box, h)
            elif kind == "rubble":
                self._rubble(*box, h)
            else:
                self._fill(*box, h + dh, SurfaceClass.ROOF_CLUTTER, mat)

    def _place(self, zone: tuple[float, float, float, float], sn: float, se: float) -> tuple[float, float]:
        """A centre for an ``sn`` x ``se`` object inside the zone."""
        zn0, zn1, ze0, ze1 = zone
        return (
            float(self.rng.uniform(zn0 + sn / 2, max(zn1 - sn / 2, zn0 + sn / 2 + 1e-6))),
            float(self.rng.uniform(ze0 + se / 2, max(ze1 - se / 2, ze0 + se / 2 + 1e-6))),
        )

    def _dome(self, cn: float, ce: float, r: float, base: float, dome_h: float) -> None:
        """A spherical cap of height ``dome_h`` standing on a roof at ``base`` (painted with mode max)."""
        got = self._box(cn - r, cn + r, ce - r, ce + r)
        if got is None:
            return
        win, n, e = got
        d2 = (n - cn) ** 2 + (e - ce) ** 2
        heights = (base + dome_h * np.sqrt(np.clip(1.0 - d2 / r**2, 0.0, 1.0))).astype(np.float32)
        self._paint_mask(win, d2 <= r**2, heights, SurfaceClass.ROOF_CLUTTER, Material.METAL, mode="max")

    def _rubble(self, n0: float, n1: float, e0: float, e1: float, roof_h: float) -> None:
        """A patch of debris, 0.05-0.6 m above the roof, cell by cell."""
        got = self._box(n0, n1, e0, e1)
        if got is None:
            return
        win = got[0]
        shape = (win[1] - win[0], win[3] - win[2])
        heights = (roof_h + self.rng.uniform(0.05, 0.6, shape)).astype(np.float32)
        self._paint_mask(win, np.ones(shape, bool), heights, SurfaceClass.ROOF_CLUTTER, Material.RUBBLE)

    def _solar(self, n0: float, n1: float, e0: float, e1: float, roof_h: float) -> None:
        """Rows of tilted panels (1.2 m deep, 0.8 m apart) rising 0.3 -> 1.0 m above the roof."""
        got = self._box(n0, n1, e0, e1)
        if got is None:
            return
        win, n, _ = got
        phase = np.mod(n - n0, 2.0)
        mask = np.broadcast_to(phase < 1.2, (win[1] - win[0], win[3] - win[2]))
        heights = (roof_h + 0.3 + 0.7 * np.minimum(phase, 1.2) / 1.2).astype(np.float32)
        self._paint_mask(win, mask, heights, SurfaceClass.ROOF_CLUTTER, Material.SOLAR)
