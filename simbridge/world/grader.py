"""The landing grader: what the vehicle touched down on, and whether that was safe.

Uses ground truth only (the world grid with actors where they are at touchdown time):

* forbidden surfaces: road, highway, sidewalk, crosswalk, water, pier, tree, vehicle, person, rail,
  machinery (containers, stacked material, machines in a yard);
* flatness: slope of a plane fitted to the cells within ``flat_radius_m`` (<= ``max_slope_deg``) and
  the residual roughness (<= ``max_roughness_m``);
* clearance: no person, vehicle or object (clutter, parapet, tree, rail, or anything standing more
  than ``object_height_m`` above the touchdown surface) within ``clearance_m``;
* edges: at least ``edge_m`` from a drop of more than ``drop_m`` (a roof edge).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from simbridge.terrain import TouchdownGrade
from simbridge.world.model import FORBIDDEN_CLASSES, GRADE_SURFACE, OBSTACLE_CLASSES, SurfaceClass, WorldGrid


@dataclass(frozen=True, slots=True)
class GraderConfig:
    clearance_m: float = 2.0
    edge_m: float = 1.0
    flat_radius_m: float = 0.8
    max_slope_deg: float = 10.0
    max_roughness_m: float = 0.08
    object_height_m: float = 0.3
    drop_m: float = 1.0


_OBSTACLE_NAMES = {
    SurfaceClass.PEDESTRIAN: "person",
    SurfaceClass.VEHICLE: "vehicle",
    SurfaceClass.ROOF_CLUTTER: "rooftop object",
    SurfaceClass.PARAPET: "parapet",
    SurfaceClass.TREE: "tree",
    SurfaceClass.GUARD_RAIL: "guard rail",
    SurfaceClass.MACHINERY: "machinery",
}


def grade(grid: WorldGrid, north_m: float, east_m: float, cfg: GraderConfig | None = None) -> TouchdownGrade:
    cfg = cfg or GraderConfig()
    ij = grid.index(north_m, east_m)
    if ij is None:
        return TouchdownGrade(surface="ground", safe=True, reasons=("outside the modelled area",))
    cls = SurfaceClass(int(grid.cls[ij]))
    surface = GRADE_SURFACE[cls]
    reasons: list[str] = []
    if cls in FORBIDDEN_CLASSES:
        reasons.append(f"landed on {cls.name.lower().replace('_', ' ')}")
    r = max(cfg.clearance_m, cfg.edge_m + 0.5, cfg.flat_radius_m)
    got = grid.window(north_m - r, north_m + r, east_m - r, east_m + r)
    assert got is not None  # the centre cell is inside
    i0, i1, j0, j1 = got
    n, e = grid.cell_centres(i0, i1, j0, j1)
    d = np.hypot(n - north_m, e - east_m)
    h = grid.height[i0:i1, j0:j1].astype(np.float64)
    c = grid.cls[i0:i1, j0:j1]
    h0 = float(grid.height[ij])
    # flatness
    near = d <= cfg.flat_radius_m
    if near.sum() >= 3:
        a = np.column_stack([n[near] - north_m, e[near] - east_m, np.ones(int(near.sum()))])
        coef, *_ = np.linalg.lstsq(a, h[near], rcond=None)
        slope = math.degrees(math.atan(math.hypot(coef[0], coef[1])))
        rough = float(np.sqrt(np.mean((a @ coef - h[near]) ** 2)))
        if slope > cfg.max_slope_deg:
            reasons.append(f"slope {slope:.0f} deg")
        if rough > cfg.max_roughness_m:
            reasons.append(f"rough surface ({100 * rough:.0f} cm)")
    # clearance: people, vehicles, objects
    disc = d <= cfg.clearance_m
    for klass, name in _OBSTACLE_NAMES.items():
        hit = disc & (c == int(klass))
        if hit.any() and klass != cls:
            reasons.append(f"{name} within {float(d[hit].min()):.1f} m")
    tall = disc & (h > h0 + cfg.object_height_m) & ~np.isin(c, [int(k) for k in OBSTACLE_CLASSES])
    if tall.any():
        reasons.append(f"object {float(h[tall].max() - h0):.1f} m tall within {float(d[tall].min()):.1f} m")
    # edges: a drop of more than drop_m nearby
    drop = (d <= cfg.edge_m) & (h < h0 - cfg.drop_m)
    if drop.any():
        reasons.append(f"{float(d[drop].min()):.1f} m from an edge ({h0 - float(h[drop].min()):.0f} m drop)")
    return TouchdownGrade(surface=surface, safe=not reasons, reasons=tuple(reasons))
