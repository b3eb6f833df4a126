"""What stands on the ground in a vignette: trees, hedges, fences, people, cars, bicycles, tractors,
furniture, bales, pipe stacks and pallets."""

from __future__ import annotations

import math

import numpy as np

from simbridge.world.model import Material as M
from simbridge.world.model import SurfaceClass as C
from simbridge.world.vignette_canvas import NE, Canvas


class Props(Canvas):
    """What stands on the ground in a vignette: trees, hedges, fences, people, cars, bicycles, tractors,"""

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
