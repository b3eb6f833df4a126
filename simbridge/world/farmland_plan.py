"""Farmland's land: the fields (a Voronoi partition, some fields in strips), what runs along their
edges (hedgerows, tree lines, open margins, farm tracks), the winding country roads, a footpath across
the fields and people on the pastures (:mod:`simbridge.world.farmland`)."""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import cv2
import numpy as np

from simbridge.world.city_parts import CityParts, Range
from simbridge.world.model import Material, SurfaceClass
from simbridge.world.suburb_plan import STEP_M, Road, as_pts
from simbridge.world.world import Lane, Walkway, Wire

Pt = tuple[float, float]

FIELD_HA_MEAN = 6.5  # the partition's seed points are spread for fields of about this size
FIELD_KINDS = ("crop", "pasture", "soil")
FIELD_WEIGHTS = (0.5, 0.3, 0.2)
STRIP_FRACTION = 0.3  # of fields over 6 ha: two to four strips, each a kind of its own
CROP_H_M: Range = (0.3, 1.6)
FURROW_M, FURROW_H_M = 0.8, 0.03  # ploughed soil: ridge spacing and height
PASTURE_H_M = 0.05
# standing crops are not a smooth surface: plants in rows ROW_M apart, each row ROW_COVER of the spacing
# wide at the crop's height (+- CANOPY_SD of it, leaf by leaf), the soil between two rows seen through
# the gap, partly hidden by leaves (GAP_FILL of the crop's height): a LiDAR or a grader finds it rough
ROW_M, ROW_COVER, CANOPY_SD, GAP_FILL = 0.75, 0.6, 0.1, 0.2
ROAD_W_M: Range = (5.0, 6.5)  # country roads: no markings, no sidewalks
ROAD_VERGE_M = 1.5
ROAD_SPEED_M_S: Range = (7.0, 14.0)
ROAD_ARRIVALS_PER_MIN: Range = (0.5, 2.0)
TRACK_W_M: Range = (3.0, 4.0)
TRACK_SPEED_M_S: Range = (2.5, 6.0)  # tractors
TRACK_ARRIVALS_PER_MIN: Range = (0.2, 0.6)
HEDGE_W_M: Range = (1.5, 2.5)
HEDGE_H_M: Range = (1.5, 3.0)
TREE_R_M: Range = (2.0, 4.5)
TREE_H_M: Range = (7.0, 15.0)
FOOTPATH_W_M = 1.5
FIELD_CLASSES = (SurfaceClass.CROP, SurfaceClass.GRASS, SurfaceClass.GROUND)
BUILT_CLASSES = (
    SurfaceClass.ROAD, SurfaceClass.ROOF_PITCHED, SurfaceClass.ROOF_FLAT, SurfaceClass.ROOF_CLUTTER,
    SurfaceClass.PARAPET, SurfaceClass.VEHICLE, SurfaceClass.MACHINERY, SurfaceClass.WATER,
)  # fmt: skip


@dataclass(frozen=True, slots=True)
class Field:
    """One field: its convex outline (k, 2) north, east metres, its kind (``"crop"``, ``"pasture"``,
    ``"soil"`` or ``"strips"``) and its area in hectares."""

    outline: np.ndarray
    kind: str
    area_ha: float


def clip_to_box(poly: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """A convex polygon (k, 2) clipped to the square ``[lo, hi]`` on both axes (Sutherland-Hodgman)."""
    out = poly
    for axis in (0, 1):
        for bound, keep_low in ((hi, True), (lo, False)):
            if len(out) == 0:
                return out
            pts = []
            for k in range(len(out)):
                a, b = out[k - 1], out[k]
                ina = a[axis] <= bound if keep_low else a[axis] >= bound
                inb = b[axis] <= bound if keep_low else b[axis] >= bound
                if ina != inb:
                    t = (bound - a[axis]) / (b[axis] - a[axis])
                    pts.append(a + t * (b - a))
                if inb:
                    pts.append(b)
            out = np.array(pts).reshape(-1, 2)
    return out


def polygon_area_m2(poly: np.ndarray) -> float:
    n, e = poly[:, 0], poly[:, 1]
    return float(abs(np.dot(n, np.roll(e, 1)) - np.dot(e, np.roll(n, 1))) / 2)


class FarmPlan(CityParts):
    """The fields, their edges, the roads and the people on open ground."""

    def __init__(self, seed: int, size_m: float, res: float, params: object) -> None:
        super().__init__(seed, size_m, res, params)  # type: ignore[arg-type]
        self.grid.cls.fill(int(SurfaceClass.GRASS))  # a margin no field reaches is grass
        self.grid.mat.fill(int(Material.GRASS))
        self.fields: list[Field] = []
        self.wires: list[Wire] = []
        self.n_poles = 0
        self.n_houses = 0

    # ------------------------------------------------------------------ fields
    def _field_seeds(self) -> np.ndarray:
        """Seed points of the partition, kept apart so that the fields come out of similar size."""
        target = max(4, round(self.size**2 / (FIELD_HA_MEAN * 1e4)))
        gap = 0.75 * math.sqrt(FIELD_HA_MEAN * 1e4)
        pts: list[Pt] = []
        for _ in range(40 * target):
            p = (self._u((-self.half, self.half)), self._u((-self.half, self.half)))
            if all(math.dist(p, q) >= gap for q in pts):
                pts.append(p)
                if len(pts) == target:
                    break
        return np.array(pts)

    def _fields(self) -> None:
        """Voronoi cells of the seed points, clipped to the place, painted one by one."""
        seeds = self._field_seeds()
        big = 4.0 * self.size
        sub = cv2.Subdiv2D((int(-big), int(-big), int(2 * big), int(2 * big)))
        sub.insert([(float(e), float(n)) for n, e in seeds])  # (x, y) = (east, north)
        facets, _ = sub.getVoronoiFacetList([])
        for facet in facets:
            poly = clip_to_box(np.asarray(facet, np.float64)[:, ::-1], -self.half, self.half)
            if len(poly) < 3:
                continue
            area = polygon_area_m2(poly)
            kind = FIELD_KINDS[int(self.rng.choice(3, p=FIELD_WEIGHTS))]
            strips = area > 6e4 and self.rng.random() < STRIP_FRACTION
            self.fields.append(Field(poly, "strips" if strips else kind, area / 1e4))
            self._paint_field(poly, kind, int(self.rng.integers(2, 5)) if strips else 1)

    def _poly_window(self, poly: np.ndarray) -> tuple[tuple[int, int, int, int], np.ndarray] | None:
        """The grid window around a polygon and the mask of the cells whose centres it covers."""
        g = self.grid
        win = g.window(poly[:, 0].min(), poly[:, 0].max(), poly[:, 1].min(), poly[:, 1].max())
        if win is None:
            return None
        i0, i1, j0, j1 = win
        mask = np.zeros((i1 - i0, j1 - j0), np.uint8)
        x = (poly[:, 1] - g.e0) / g.res - 0.5 - j0
        y = (poly[:, 0] - g.n0) / g.res - 0.5 - i0
        pts = np.round(np.stack([x, y], axis=1) * 16).astype(np.int32)
        cv2.fillPoly(mask, [pts], 1, lineType=cv2.LINE_8, shift=4)
        return win, mask.astype(bool)

    def _paint_field(self, poly: np.ndarray, kind: str, n_strips: int) -> None:
        got = self._poly_window(poly)
        if got is None:
            return
        win, mask = got
        n, e = self.grid.cell_centres(*win)
        heading = self._u((0.0, math.pi))  # the way the rows, furrows and strips run
        across = (n - poly[:, 0].mean()) * -math.sin(heading) + (e - poly[:, 1].mean()) * math.cos(heading)
        if n_strips > 1:
            lo, hi = float(across[mask].min()), float(across[mask].max())
            strip = np.clip(((across - lo) / max(hi - lo, 1e-6) * n_strips).astype(np.int32), 0, n_strips - 1)
            kinds = [FIELD_KINDS[int(self.rng.choice(3, p=FIELD_WEIGHTS))] for _ in range(n_strips)]
        else:
            strip, kinds = np.zeros(mask.shape, np.int32), [kind]
        for k, kind_k in enumerate(kinds):
            part = mask & (strip == k)
            if kind_k == "crop":
                canopy = crop_canopy(across, self._u(CROP_H_M), win)
                self.grid.paint(win, part, canopy, SurfaceClass.CROP, Material.CROP)
            elif kind_k == "pasture":
                self.grid.paint(win, part, PASTURE_H_M, SurfaceClass.GRASS, Material.GRASS)
            else:
                ridges = FURROW_H_M * (0.5 + 0.5 * np.sin(2 * math.pi * across / FURROW_M))
                self.grid.paint(win, part, ridges.astype(np.float32), SurfaceClass.GROUND, Material.SOIL)

    # ------------------------------------------------------------------ field edges
    def _edges(self) -> list[tuple[Pt, Pt]]:
        """Each inner field edge once (the place's own border left out)."""
        seen: set[tuple[tuple[int, int], ...]] = set()
        out: list[tuple[Pt, Pt]] = []
        lim = self.half - 0.5
        for f in self.fields:
            for k in range(len(f.outline)):
                a, b = f.outline[k - 1], f.outline[k]
                if any(abs(a[ax]) >= lim and abs(b[ax]) >= lim and a[ax] * b[ax] > 0 for ax in (0, 1)):
                    continue
                key = tuple(sorted((tuple(np.round(a).astype(int)), tuple(np.round(b).astype(int)))))
                if key in seen or math.dist(a, b) < 5.0:
                    continue
                seen.add(key)
                out.append(((float(a[0]), float(a[1])), (float(b[0]), float(b[1]))))
        return out

    def _field_edges(self) -> None:
        """Hedgerows, hedgerows with trees, tree lines, open margins and farm tracks on the edges."""
        g = self.grid
        for a, b in self._edges():
            x = self.rng.random()
            if x < 0.55:
                g.fill_polyline([a, b], self._u(HEDGE_W_M), height_m=self._u(HEDGE_H_M),
                                cls=SurfaceClass.TREE, mat=Material.FOLIAGE)  # fmt: skip
                if x >= 0.35:
                    self._tree_line(a, b, (18.0, 40.0))
            elif x < 0.7:
                self._tree_line(a, b, (8.0, 14.0))
            elif x < 0.85:
                g.fill_polyline([a, b], 3.0, height_m=PASTURE_H_M, cls=SurfaceClass.GRASS, mat=Material.GRASS)
            else:
                self._track(a, b)

    def _tree_line(self, a: Pt, b: Pt, spacing_m: Range) -> None:
        length = math.dist(a, b)
        at = self._u((0.0, spacing_m[0]))
        while at < length:
            t = at / length
            pt = (
                a[0] + t * (b[0] - a[0]) + self._u((-1.0, 1.0)),
                a[1] + t * (b[1] - a[1]) + self._u((-1.0, 1.0)),
            )
            self.grid.fill_disc(pt, self._u(TREE_R_M), height_m=self._u(TREE_H_M), dome=True,
                                cls=SurfaceClass.TREE, mat=Material.FOLIAGE, mode="max")  # fmt: skip
            at += self._u(spacing_m)

    def _track(self, a: Pt, b: Pt) -> None:
        """A gravel or earth farm track along a field edge; a tractor now and then on a long one."""
        mat = Material.GRAVEL if self.rng.random() < 0.6 else Material.SOIL
        self.grid.fill_polyline([a, b], self._u(TRACK_W_M), height_m=0.0, cls=SurfaceClass.GROUND, mat=mat)
        if math.dist(a, b) >= 60.0 and self.rng.random() < 0.5:
            ends = (self._clip_pt(a, 1.0), self._clip_pt(b, 1.0))
            pts = ends if self.rng.random() < 0.5 else ends[::-1]
            self.lanes.append(Lane(pts, TRACK_SPEED_M_S, self._u(TRACK_ARRIVALS_PER_MIN)))

    # ------------------------------------------------------------------ roads
    def _winding(self, a: Pt, b: Pt) -> np.ndarray:
        """A gently winding line from ``a`` to ``b``: points every ``STEP_M``."""
        length = math.dist(a, b)
        k = max(2, round(length / 110.0))
        t = np.linspace(0.0, 1.0, k + 1)
        side = np.cumsum(self.rng.normal(0.0, 18.0, k + 1))
        side = np.clip(side - side[0] - t * (side[-1] - side[0]), -45.0, 45.0)
        ux, uy = (b[0] - a[0]) / length, (b[1] - a[1]) / length
        pts = np.stack([a[0] + t * (b[0] - a[0]) - side * uy, a[1] + t * (b[1] - a[1]) + side * ux], axis=1)
        for _ in range(4):  # Chaikin: cut the corners
            q = 0.75 * pts[:-1] + 0.25 * pts[1:]
            r = 0.25 * pts[:-1] + 0.75 * pts[1:]
            pts = np.concatenate([pts[:1], np.stack([q, r], axis=1).reshape(-1, 2), pts[-1:]])
        s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(pts, axis=0).T))])
        at = np.linspace(0.0, s[-1], max(2, round(s[-1] / STEP_M)))
        return np.stack([np.interp(at, s, pts[:, 0]), np.interp(at, s, pts[:, 1])], axis=1)

    def _roads(self) -> list[Road]:
        """A road east-west and one north-south across the whole place, and on a large place a third
        leaving the first for the northern or southern edge."""
        h, out = self.half + 10.0, 0.3 * self.size
        ew = self._winding((self._u((-out, out)), -h), (self._u((-out, out)), h))
        ns = self._winding((-h, self._u((-out, out))), (h, self._u((-out, out))))
        roads = [Road(ew, self._u(ROAD_W_M)), Road(ns, self._u(ROAD_W_M))]
        if self.size >= 800.0:
            s = roads[0].arclength()
            # the branch leaves the first road well away from the second (where the village lies)
            cross = int(
                np.argmin(np.hypot(*(ew[:, None, :] - ns[None, :, :]).transpose(2, 0, 1)).min(axis=1))
            )
            far = [i for i in range(len(s)) if abs(s[i] - s[cross]) > 300.0 and 150.0 < s[i] < s[-1] - 150.0]
            if far:
                i = far[int(self.rng.integers(0, len(far)))]
                start = (float(ew[i, 0]), float(ew[i, 1]))
                north = h if start[0] < 0 else -h
                end = (north, start[1] + self._u((-0.15, 0.15)) * self.size)
                roads.append(Road(self._winding(start, end), self._u(ROAD_W_M) - 0.5))
        return roads

    def _paint_road(self, road: Road) -> None:
        """Asphalt between grass verges, a lane each way (keeping right)."""
        pts = as_pts(road.points)
        self.grid.fill_polyline(pts, road.width_m + 2 * ROAD_VERGE_M, height_m=PASTURE_H_M,
                                cls=SurfaceClass.GRASS, mat=Material.GRASS)  # fmt: skip
        self.grid.fill_polyline(pts, road.width_m, height_m=0.0, cls=SurfaceClass.ROAD, mat=Material.ASPHALT)
        lo, hi = ROAD_SPEED_M_S
        for fwd in (True, False):
            lane = road.offset(road.width_m / 4 if fwd else -road.width_m / 4)
            lane = lane[(np.abs(lane) <= self.half - 0.5).all(axis=1)]
            if len(lane) < 2:
                continue
            speed = (self._u((lo, (lo + hi) / 2)), self._u(((lo + hi) / 2, hi)))
            pts_l = as_pts(lane if fwd else lane[::-1])
            self.lanes.append(Lane(tuple(pts_l), speed, self._u(ROAD_ARRIVALS_PER_MIN)))

    # ------------------------------------------------------------------ people on open ground
    def _on_fields(self, pts: list[Pt], width_m: float, cls: SurfaceClass, mat: Material) -> None:
        """Paint a strip along ``pts`` where it crosses fields only (never over a road or a building)."""
        for a, b in itertools.pairwise(pts):
            length = math.dist(a, b)
            if length == 0:
                continue
            yaw = math.atan2(b[1] - a[1], b[0] - a[0])
            got = self.grid.rect_mask(((a[0] + b[0]) / 2, (a[1] + b[1]) / 2), length, width_m, yaw)
            if got is None:
                continue
            win, mask, _, _ = got
            i0, i1, j0, j1 = win
            on = mask & np.isin(self.grid.cls[i0:i1, j0:j1], [int(c) for c in FIELD_CLASSES])
            self.grid.paint(win, on, 0.0, cls, mat)

    def _footpath(self, start: Pt) -> None:
        """A public footpath of trodden earth from near the village out across the fields, with walkers."""
        heading = self._u((0.0, 2 * math.pi))
        pts = [start]
        for leg in (self._u((30.0, 60.0)), self._u((150.0, 250.0)), self._u((150.0, 250.0))):
            heading += self._u((-0.5, 0.5))
            nxt = self._clip_pt(
                (pts[-1][0] + leg * math.cos(heading), pts[-1][1] + leg * math.sin(heading)), 2.0
            )
            pts.append(nxt)
        self._on_fields(pts, FOOTPATH_W_M, SurfaceClass.GROUND, Material.SOIL)
        self.walkways.append(Walkway(tuple(pts[1:]), int(self.rng.integers(2, 6)), 0.0, FOOTPATH_W_M))

    def _pasture_walks(self) -> None:
        """Walkers (and a farmer) crossing some of the larger pastures."""
        for f in self.fields:
            if f.kind != "pasture" or f.area_ha < 2.0 or self.rng.random() >= 0.6:
                continue
            c = f.outline.mean(axis=0)
            k = self.rng.choice(len(f.outline), 2, replace=False)
            ends = [c + 0.6 * (f.outline[i] - c) for i in k]
            pts = tuple((float(p[0]), float(p[1])) for p in ends)
            if all(self.grid.class_at(*p) == SurfaceClass.GRASS for p in pts):
                self.walkways.append(Walkway(pts, int(self.rng.integers(1, 4)), PASTURE_H_M, 2.0))


def crop_canopy(across: np.ndarray, height_m: float, window: tuple[int, int, int, int]) -> np.ndarray:
    """The top of a standing crop over cells ``across`` metres across its rows (``ROW_M``, ``ROW_COVER``,
    ``CANOPY_SD``, ``GAP_FILL``), its leaves drawn from a generator of the field's own ``window`` (the
    place's generator is left as it was: the rest of the place does not move)."""
    in_row = np.cos(2 * math.pi * across / ROW_M) > math.cos(math.pi * ROW_COVER)
    leaves = height_m * (1.0 + CANOPY_SD * np.random.default_rng(list(window)).standard_normal(across.shape))
    return np.where(in_row, leaves, GAP_FILL * height_m).astype(np.float32)
