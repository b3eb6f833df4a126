"""The suburb's lots: a row of them along each side of every street, each a lawn with a detached house
under a pitched roof (some L-shaped), a driveway with cars, and now and then a pool, a shed, hedges,
fences and garden trees. Everything in a lot is laid out in the lot's own frame (``u`` along the street,
``v`` away from it) and painted rotated with the street."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from simbridge.world.city_parts import CAR_H, CAR_L, CAR_W, Range
from simbridge.world.model import Material, SurfaceClass
from simbridge.world.suburb_plan import Pt, Road, SuburbPlan

LOT_FRONT_M: Range = (18.0, 26.0)
LOT_DEPTH_M: Range = (28.0, 40.0)
SHALLOW_LOT_M = 23.0
HOUSE_LEN_M: Range = (9.0, 16.0)  # along the street
HOUSE_WID_M: Range = (8.0, 13.0)  # away from it
EAVE_M: Range = (3.0, 7.0)
PITCH_DEG: Range = (25.0, 45.0)
ROOF_MATS = (Material.TILES, Material.SHINGLE, Material.SLATE, Material.SEAM_METAL, Material.CORRUGATED)
DRIVE_H = 0.02
EDGE_M = 1.2  # kept clear inside the lot's boundary for its hedges and fences

Box = tuple[float, float, float, float]  # u_lo, u_hi, v_lo, v_hi in a lot's frame


@dataclass(frozen=True, slots=True)
class Lot:
    """A rectangular lot: ``front_m`` along the street, ``depth_m`` away from it, ``reach_m`` from its
    front edge to the street's carriageway (what a driveway crosses)."""

    centre: Pt
    along: Pt  # unit vector along the street
    out: Pt  # unit vector away from the street
    front_m: float
    depth_m: float
    reach_m: float

    def pt(self, u: float, v: float) -> Pt:
        return (
            self.centre[0] + self.along[0] * u + self.out[0] * v,
            self.centre[1] + self.along[1] * u + self.out[1] * v,
        )

    @property
    def yaw_u(self) -> float:
        return math.atan2(self.along[1], self.along[0])

    @property
    def yaw_v(self) -> float:
        return math.atan2(self.out[1], self.out[0])


def _overlaps(a: Box, b: Box, gap_m: float) -> bool:
    return a[0] < b[1] + gap_m and b[0] < a[1] + gap_m and a[2] < b[3] + gap_m and b[2] < a[3] + gap_m


class SuburbLots(SuburbPlan):
    """Lots along the streets, and everything in them."""

    def _paint_lots(self, roads: list[Road]) -> None:
        """Walk both sides of each street, taking a lot wherever the land behind the kerb is free."""
        for road in roads:
            s_end = float(road.arclength()[-1])
            for side in (-1.0, 1.0):
                at = self._u((2.0, 8.0))
                while at < s_end:
                    front, depth = self._u(LOT_FRONT_M), self._u(LOT_DEPTH_M)
                    pts, nrm = road.at(np.array([at + front / 2]))
                    out = (float(side * nrm[0, 0]), float(side * nrm[0, 1]))
                    along = (out[1], -out[0])
                    yaw = math.atan2(along[1], along[0])
                    for deep in (depth, SHALLOW_LOT_M):  # a shallow lot where a deep one does not fit
                        d = road.edge_m + 0.3 + deep / 2
                        centre = (float(pts[0, 0]) + out[0] * d, float(pts[0, 1]) + out[1] * d)
                        if self._rect_free(centre, front - 1.2, deep - 1.2, yaw):
                            self._claim_rect(centre, front, deep, yaw)
                            reach = road.edge_m + 0.3 - road.width_m / 2
                            self._paint_lot(Lot(centre, along, out, front, deep, reach))
                            at += front
                            break
                    else:
                        at += 4.0

    def _rect(
        self, lot: Lot, box: Box, height_m: float | None, cls: SurfaceClass, mat: Material, mode: str = "set"
    ) -> None:
        """Paint a box given in the lot's frame."""
        u0, u1, v0, v1 = box
        self.grid.fill_rect(
            lot.pt((u0 + u1) / 2, (v0 + v1) / 2), u1 - u0, v1 - v0, lot.yaw_u,
            height_m=height_m, cls=cls, mat=mat, mode=mode,
        )  # fmt: skip

    def _place(self, lot: Lot, size_u: float, size_v: float, v_min: float, keep: list[Box]) -> Box | None:
        """A free spot for a box (behind ``v_min``, clear of the ``keep`` boxes); None after a few tries."""
        hu, hv = lot.front_m / 2 - EDGE_M - size_u / 2, lot.depth_m / 2 - EDGE_M - size_v
        if hu <= 0 or hv <= v_min:
            return None
        for _ in range(6):
            u = self._u((-hu, hu))
            v = self._u((v_min, hv))
            box = (u - size_u / 2, u + size_u / 2, v, v + size_v)
            if not any(_overlaps(box, k, 0.6) for k in keep):
                return box
        return None

    def _paint_lot(self, lot: Lot) -> None:
        f, d = lot.front_m, lot.depth_m
        self._rect(lot, (-f / 2, f / 2, -d / 2, d / 2), 0.0, SurfaceClass.GRASS, Material.GRASS)
        drive_side = float(self.rng.choice([-1.0, 1.0]))
        drive_w = self._u((3.0, 3.6))
        length = min(self._u(HOUSE_LEN_M), f - drive_w - 3.0)
        width = min(self._u(HOUSE_WID_M), 0.4 * d)
        front_v = -d / 2 + self._u((5.5, 9.0))
        u_h = -drive_side * (f / 2 - 1.5 - length / 2)
        self._boundaries(lot, front_v)
        u_d = drive_side * (f / 2 - 0.8 - drive_w / 2)
        drive = (u_d - drive_w / 2, u_d + drive_w / 2, -d / 2 - lot.reach_m, front_v + 0.6 * width)
        mat = Material.CONCRETE if self.rng.random() < 0.6 else Material.PAVING
        self._rect(lot, drive, DRIVE_H, SurfaceClass.GROUND, mat)
        keep = [drive, *self._house(lot, u_h, front_v, length, width)]
        back_v = max(k[3] for k in keep)
        if self.rng.random() < 0.35:
            self._pool(lot, back_v, keep)
        if self.rng.random() < 0.5:
            self._shed(lot, back_v, keep)
        for k in range(int(self.rng.choice([0, 1, 1, 2]))):  # cars on the driveway, nose to the street
            v = -d / 2 + 1.0 + CAR_L / 2 + k * (CAR_L + 0.8)
            if v + CAR_L / 2 > drive[3]:
                break
            u = u_d + self._u((-0.3, 0.3))
            self._rect(lot, (u - CAR_W / 2, u + CAR_W / 2, v - CAR_L / 2, v + CAR_L / 2), DRIVE_H + CAR_H,
                       SurfaceClass.VEHICLE, Material.CAR_PAINT)  # fmt: skip
        for _ in range(int(self.rng.integers(0, 4))):
            r = self._u((1.8, 3.5))
            box = self._place(lot, 2 * r, 2 * r, -d / 2 + EDGE_M, keep)
            if box is not None:
                keep.append(box)
                self.grid.fill_disc(
                    lot.pt((box[0] + box[1]) / 2, (box[2] + box[3]) / 2), r, height_m=self._u((4.5, 10.0)),
                    dome=True, cls=SurfaceClass.TREE, mat=Material.FOLIAGE, mode="max",
                )  # fmt: skip

    def _boundaries(self, lot: Lot, front_v: float) -> None:
        """Hedges or fences (or nothing) on the back and the sides behind the house's front line."""
        f, d = lot.front_m, lot.depth_m
        for edge in ("back", "left", "right"):
            r = self.rng.random()
            if r < 0.45:
                w, h, cls, mat = self._u((0.6, 1.0)), self._u((1.2, 2.0)), SurfaceClass.TREE, Material.FOLIAGE
            elif r < 0.8:
                w, h, cls, mat = 0.3, self._u((1.5, 1.8)), SurfaceClass.GUARD_RAIL, Material.WOOD
            else:
                continue
            if edge == "back":
                box = (-f / 2, f / 2, d / 2 - w, d / 2)
            else:
                u = -f / 2 if edge == "left" else f / 2 - w
                box = (u, u + w, front_v, d / 2)
            self._rect(lot, box, h, cls, mat)

    def _house(self, lot: Lot, u_c: float, front_v: float, length: float, width: float) -> list[Box]:
        """A gable roof over the footprint (ridge along its longer side); a third of the wide ones get a
        wing out the back, its ridge square to the first. Returns the footprint boxes."""
        rid = self._new_region()
        self.n_buildings += 1
        eave = self._u(EAVE_M)
        tan_pitch = math.tan(math.radians(self._u(PITCH_DEG)))
        mat = ROOF_MATS[int(self.rng.integers(0, len(ROOF_MATS)))]
        main = (u_c - length / 2, u_c + length / 2, front_v, front_v + width)
        boxes = [main]
        self._gable(lot, main, length >= width, eave, tan_pitch, rid, mat)
        ext = self._u((4.0, 8.0))
        room = lot.depth_m / 2 - EDGE_M - 3.0 - main[3]
        if length >= width and length >= 11.0 and room > ext and self.rng.random() < 0.35:
            wing_w = self._u((5.5, min(8.0, 0.6 * length)))
            end = float(self.rng.choice([-1.0, 1.0]))
            u_w = u_c + end * (length - wing_w) / 2
            wing = (u_w - wing_w / 2, u_w + wing_w / 2, front_v + width / 2, main[3] + ext)
            self._gable(lot, wing, False, eave, tan_pitch, rid, mat)
            boxes.append(wing)
        return boxes

    def _gable(
        self, lot: Lot, box: Box, ridge_along_u: bool, eave: float, tan_pitch: float, rid: int, mat: Material
    ) -> None:
        u0, u1, v0, v1 = box
        length, width, yaw = (u1 - u0, v1 - v0, lot.yaw_u) if ridge_along_u else (v1 - v0, u1 - u0, lot.yaw_v)
        ridge = eave + tan_pitch * width / 2
        centre = lot.pt((u0 + u1) / 2, (v0 + v1) / 2)
        self.grid.fill_pitched(centre, length, width, yaw, eave, ridge, region=rid, mat=mat, mode="max")

    def _pool(self, lot: Lot, back_v: float, keep: list[Box]) -> None:
        """A pool sunk 0.3-1 m in a paved surround, behind the house."""
        pl, pw, rim = self._u((6.0, 10.0)), self._u((3.0, 5.0)), 1.2
        box = self._place(lot, pl + 2 * rim, pw + 2 * rim, back_v + 1.0, keep)
        if box is None:
            return
        keep.append(box)
        self._rect(lot, box, 0.05, SurfaceClass.GROUND, Material.PAVING)
        water = (box[0] + rim, box[1] - rim, box[2] + rim, box[3] - rim)
        self._rect(lot, water, -self._u((0.3, 1.0)), SurfaceClass.WATER, Material.POOL)

    def _shed(self, lot: Lot, back_v: float, keep: list[Box]) -> None:
        """A garden shed in the back: a flat roof about 2.2 m up, or a small gable to about 2.5 m."""
        su, sv = self._u((2.0, 3.0)), self._u((2.0, 2.4))
        box = self._place(lot, su, sv, back_v + 1.0, keep)
        if box is None:
            return
        keep.append(box)
        rid = self._new_region()
        if self.rng.random() < 0.4:
            mat = Material.METAL if self.rng.random() < 0.5 else Material.WOOD
            u0, u1, v0, v1 = box
            self.grid.fill_rect(
                lot.pt((u0 + u1) / 2, (v0 + v1) / 2), su, sv, lot.yaw_u,
                height_m=self._u((2.0, 2.4)), cls=SurfaceClass.ROOF_FLAT, mat=mat, region=rid,
            )  # fmt: skip
        else:
            tan_pitch = math.tan(math.radians(self._u((25.0, 30.0))))
            self._gable(lot, box, True, 1.9, tan_pitch, rid, Material.SHINGLE)
