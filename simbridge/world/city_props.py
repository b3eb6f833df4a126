"""What stands between the buildings: parks with trees, plazas, parking lots and parking structures."""

from __future__ import annotations

import math

import numpy as np

from simbridge.world.city_parts import AISLE_W, CAR_H, CAR_L, CAR_W, SIDEWALK_H, STALL_D, STALL_W, CityParts
from simbridge.world.model import Material, SurfaceClass
from simbridge.world.world import Walkway


class Props(CityParts):
    """What stands between the buildings: parks with trees, plazas, parking lots and parking structures."""

    def _paint_bays(
        self, n_lo: float, n_hi: float, e_lo: float, e_hi: float, surf_h: float, cls: SurfaceClass
    ) -> None:
        """Stall markings and parked cars: double rows of stalls facing aisles along the longer side."""
        got = self._box(n_lo, n_hi, e_lo, e_hi)
        if got is None:
            return
        win, n, e = got
        along_n = (n_hi - n_lo) >= (e_hi - e_lo)
        a, c = (n - n_lo, e - e_lo) if along_n else (e - e_lo, n - n_lo)
        a_len, c_len = (n_hi - n_lo, e_hi - e_lo) if along_n else (e_hi - e_lo, n_hi - n_lo)
        module = 2 * STALL_D + AISLE_W
        n_mod = math.floor((c_len - 1.0) / module)
        n_stalls = math.floor((a_len - 12.0) / STALL_W)
        if n_mod < 1 or n_stalls < 1:
            return
        c = c - 1.0
        m_idx = np.floor(c / module)
        cm = c - m_idx * module
        second = cm >= STALL_D + AISLE_W
        in_row = ((cm < STALL_D) | second) & (m_idx >= 0) & (m_idx < n_mod)
        s = a - 6.0
        in_a = (s >= 0) & (s < n_stalls * STALL_W)
        rows = in_row & in_a
        sm = np.mod(s, STALL_W)
        lw = self._line_w(0.12)
        line = np.minimum(sm, STALL_W - sm) <= lw / 2
        depth = np.where(second, cm - (STALL_D + AISLE_W), cm)
        head = np.abs(depth - np.where(second, STALL_D, 0.0)) <= lw / 2  # back line of each row
        self._paint_mask(win, rows & (line | head), None, cls, Material.LANE_MARKING)
        occ_p = self._u(self.p.parked_occupancy) if self.p.parked_occupancy[1] > 0 else 0.0
        n_rows = 2 * n_mod
        occupied = self.rng.random((n_rows, n_stalls)) < occ_p
        jit_a = self.rng.uniform(-0.2, 0.2, (n_rows, n_stalls))
        jit_c = self.rng.uniform(-0.2, 0.2, (n_rows, n_stalls))
        row_i = np.clip(2 * m_idx + second, 0, n_rows - 1).astype(np.intp)
        st_i = np.clip(np.floor(s / STALL_W), 0, n_stalls - 1).astype(np.intp)
        row_i, st_i = np.broadcast_arrays(row_i, st_i)
        car = (
            rows
            & occupied[row_i, st_i]
            & (np.abs(sm - STALL_W / 2 - jit_a[row_i, st_i]) <= CAR_W / 2)
            & (np.abs(depth - STALL_D / 2 - jit_c[row_i, st_i]) <= CAR_L / 2)
        )
        self._paint_mask(win, car, surf_h + CAR_H, SurfaceClass.VEHICLE, Material.CAR_PAINT)

    def _paint_park(self, n0: float, n1: float, e0: float, e1: float) -> None:
        p = self.p
        self._fill(n0, n1, e0, e1, 0.05, SurfaceClass.GRASS, Material.GRASS)
        cn, ce = (n0 + n1) / 2, (e0 + e1) / 2
        paths: list[tuple[tuple[float, float], tuple[float, float]]] = []
        if self.rng.random() < 0.6:
            paths.append(((n0, e0), (n1, e1)) if self.rng.random() < 0.5 else ((n0, e1), (n1, e0)))
        paths.append(((n0, ce), (n1, ce)))
        if self.rng.random() < 0.6:
            paths.append(((cn, e0), (cn, e1)))
        for a, b in paths:
            w = float(self.rng.uniform(2.5, 4.0))
            self.grid.fill_polyline([a, b], w, height_m=0.05, cls=SurfaceClass.SIDEWALK, mat=Material.PAVING)
            if self.rng.random() < 0.7:
                count = int(self.rng.integers(p.walkway_count[0], p.walkway_count[1] + 1))
                pts = (self._clip_pt(a, 1.0), self._clip_pt(b, 1.0))
                self.walkways.append(Walkway(pts, count, 0.05, w))
        if self.rng.random() < 0.3:  # a pond
            r = float(self.rng.uniform(6.0, min(15.0, 0.25 * min(n1 - n0, e1 - e0))))
            pn = float(self.rng.uniform(n0 + r + 3, n1 - r - 3))
            pe = float(self.rng.uniform(e0 + r + 3, e1 - r - 3))
            self.grid.fill_disc((pn, pe), r, height_m=-0.5, cls=SurfaceClass.WATER, mat=Material.WATER)
        n_trees = round((n1 - n0) * (e1 - e0) * p.tree_per_m2)
        for _ in range(n_trees):
            r = self._u(p.tree_radius_m)
            h = self._u(p.tree_height_m)
            if n1 - n0 < 2 * r + 2 or e1 - e0 < 2 * r + 2:
                continue
            for _try in range(4):
                tn = float(self.rng.uniform(n0 + r + 0.5, n1 - r - 0.5))
                te = float(self.rng.uniform(e0 + r + 0.5, e1 - r - 0.5))
                if self.grid.class_at(tn, te) in (SurfaceClass.GRASS, SurfaceClass.TREE):
                    self.grid.fill_disc(
                        (tn, te),
                        r,
                        height_m=h,
                        dome=True,
                        cls=SurfaceClass.TREE,
                        mat=Material.FOLIAGE,
                        mode="max",
                    )
                    break

    def _paint_plaza(self, n0: float, n1: float, e0: float, e1: float) -> None:
        p = self.p
        self._fill(n0, n1, e0, e1, SIDEWALK_H, SurfaceClass.SIDEWALK, Material.PAVING)
        cn, ce = (n0 + n1) / 2, (e0 + e1) / 2
        r = float(self.rng.uniform(3.0, 6.0))
        self.grid.fill_disc((cn, ce), r + 0.5, height_m=0.5, cls=SurfaceClass.GROUND, mat=Material.CONCRETE)
        self.grid.fill_disc((cn, ce), r, height_m=-0.1, cls=SurfaceClass.WATER, mat=Material.WATER)
        for fn, fe in ((0.2, 0.2), (0.2, 0.8), (0.8, 0.2), (0.8, 0.8), (0.5, 0.15), (0.5, 0.85)):
            if self.rng.random() < 0.8:
                tr = float(self.rng.uniform(2.0, 3.5))
                tn, te = n0 + fn * (n1 - n0), e0 + fe * (e1 - e0)
                h = self._u(p.tree_height_m)
                self.grid.fill_disc(
                    (tn, te),
                    tr,
                    height_m=h,
                    dome=True,
                    cls=SurfaceClass.TREE,
                    mat=Material.FOLIAGE,
                    mode="max",
                )
        for a, b in (((n0 + 3, e0 + 3), (n1 - 3, e1 - 3)), ((n0 + 3, e1 - 3), (n1 - 3, e0 + 3))):
            count = int(self.rng.integers(p.walkway_count[0], p.walkway_count[1] + 1))
            self.walkways.append(
                Walkway((self._clip_pt(a, 1.0), self._clip_pt(b, 1.0)), count, SIDEWALK_H, 3.0)
            )

    def _paint_garage_block(self, n0: float, n1: float, e0: float, e1: float) -> None:
        """A parking structure at one end of the block, buildings on the rest."""
        p = self.p
        along_n = (n1 - n0) >= (e1 - e0)
        length = float(self.rng.uniform(45.0, 70.0))
        lo, hi = (n0, n1) if along_n else (e0, e1)
        if hi - lo - length < 25.0:
            length = hi - lo
        at_start = bool(self.rng.random() < 0.5)
        g_lo, g_hi = (lo, lo + length) if at_start else (hi - length, hi)
        if along_n:
            gn0, gn1, ge0, ge1 = g_lo + 2.0, g_hi - 2.0, e0 + 2.0, e1 - 2.0
        else:
            gn0, gn1, ge0, ge1 = n0 + 2.0, n1 - 2.0, g_lo + 2.0, g_hi - 2.0
        self._fill(n0, n1, e0, e1, 0.0, SurfaceClass.GROUND, Material.CONCRETE)
        h = self._u(p.parking_structure_height_m)
        rid = self._new_region()
        self.n_buildings += 1
        self._fill(gn0, gn1, ge0, ge1, h + 1.0, SurfaceClass.PARAPET, Material.CONCRETE, rid)
        pw = self._line_w(0.3)
        self._fill(
            gn0 + pw, gn1 - pw, ge0 + pw, ge1 - pw, h, SurfaceClass.PARKING_ROOF, Material.CONCRETE, rid
        )
        self._paint_bays(gn0 + pw, gn1 - pw, ge0 + pw, ge1 - pw, h, SurfaceClass.PARKING_ROOF)
        # stair / lift core in a corner
        cn = gn0 + pw + 3.0 if self.rng.random() < 0.5 else gn1 - pw - 3.0
        ce = ge0 + pw + 2.5 if self.rng.random() < 0.5 else ge1 - pw - 2.5
        self._fill(
            cn - 3.0, cn + 3.0, ce - 2.5, ce + 2.5, h + 3.0, SurfaceClass.ROOF_CLUTTER, Material.CONCRETE
        )
        if length < hi - lo:
            r_lo, r_hi = (g_hi, hi) if at_start else (lo, g_lo)
            if along_n:
                self._paint_building_block(r_lo, r_hi, e0, e1, base=False)
            else:
                self._paint_building_block(n0, n1, r_lo, r_hi, base=False)
