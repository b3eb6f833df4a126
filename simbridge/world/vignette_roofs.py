"""A vignette's buildings and their roofs: pitched houses (gable or hipped, wings, dormers), flat
buildings, barns, and the objects on their roofs by clutter level."""

from __future__ import annotations

import math

import numpy as np

from simbridge.world.model import Material as M
from simbridge.world.model import SurfaceClass as C
from simbridge.world.vignette_canvas import (
    FLAT_MATS,
    NE,
    PITCH_DEG,
    PITCHED_MATS,
    PITCHED_P,
    ROOF_CLASSES,
    ROUND_R,
    ROUND_RISE,
    Canvas,
    RoofSpec,
    Window,
    gable_heights,
    hip_heights,
)


class Roofs(Canvas):
    """A vignette's buildings and their roofs: pitched houses (gable or hipped, wings, dormers), flat"""

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
                rad = self.u(*ROUND_R[kind])
                c = self._roof_point(spec, rad + 0.2)
                got = self._on(spec, c, 2 * rad, 2 * rad, 0.0, round_=True)
                if got is None:
                    continue
                win, mask = got
                mat = self.pick((M.METAL, M.TAR, M.MEMBRANE), (0.6, 0.3, 0.1)) if kind == "vent" else M.METAL
                if kind == "dish" and self.p(0.5):
                    mat = M.MEMBRANE
                self.paint(win, mask, self._top(win, mask) + self.u(*ROUND_RISE[kind]), C.ROOF_CLUTTER, mat)
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
