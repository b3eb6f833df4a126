"""The landing grader: what the vehicle touched down on, and whether that was safe.

Uses ground truth only (the world grid with actors where they are at touchdown time):

* forbidden surfaces: road, highway, sidewalk, crosswalk, water (a swimming pool is graded ``pool``),
  pier, tree, vehicle, person, rail, machinery (containers, stacked material, machines in a yard),
  standing crops;
* flatness: slope of a plane fitted to the cells within ``flat_radius_m`` (<= ``max_slope_deg``) and
  the residual roughness (<= ``max_roughness_m``);
* clearance: no object (clutter, parapet, tree, guard rail, or anything standing more than
  ``object_height_m`` above the touchdown surface) and no person within ``clearance_m`` on the grid;
* what a regulator asks of a landing near third parties: no person within ``person_m`` (straight
  line from the touchdown point to their feet, from the actors' own positions where the caller gives
  them), no vehicle or machinery within ``vehicle_m`` (straight line to its top where it stands below
  the touchdown, across the ground where it stands higher), no overhead wire within ``wire_m`` of the
  line under it;
* edges: at least ``edge_m`` from a drop of more than ``drop_m`` (a roof edge).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from simbridge.terrain import TouchdownGrade
from simbridge.world.model import (
    FORBIDDEN_CLASSES,
    GRADE_SURFACE,
    OBSTACLE_CLASSES,
    Material,
    SurfaceClass,
    WorldGrid,
)
from simbridge.world.world import Wire


@dataclass(frozen=True, slots=True)
class GraderConfig:
    clearance_m: float = 2.0
    edge_m: float = 1.0
    flat_radius_m: float = 0.8
    max_slope_deg: float = 10.0
    max_roughness_m: float = 0.08
    object_height_m: float = 0.3
    drop_m: float = 1.0
    person_m: float = 10.0
    vehicle_m: float = 5.0
    wire_m: float = 5.0


_OBSTACLE_NAMES = {
    SurfaceClass.PEDESTRIAN: "person",
    SurfaceClass.VEHICLE: "vehicle",
    SurfaceClass.ROOF_CLUTTER: "rooftop object",
    SurfaceClass.PARAPET: "parapet",
    SurfaceClass.TREE: "tree",
    SurfaceClass.GUARD_RAIL: "guard rail",
}
_THIRD_PARTY = {SurfaceClass.VEHICLE: "vehicle", SurfaceClass.MACHINERY: "machinery"}  # within vehicle_m


def grade(
    grid: WorldGrid,
    north_m: float,
    east_m: float,
    cfg: GraderConfig | None = None,
    *,
    people: np.ndarray | None = None,
    wires: tuple[Wire, ...] = (),
) -> TouchdownGrade:
    """Grade a touchdown at (``north_m``, ``east_m``) on ``grid`` as it is now (actors stamped).
    ``people``: (P, 3) north, east and the surface height under each person's feet
    (:meth:`~simbridge.world.actors.Actors.people_at`); without it only the grid's person cells within
    ``clearance_m`` count. ``wires``: the world's overhead wires."""
    cfg = cfg or GraderConfig()
    ij = grid.index(north_m, east_m)
    if ij is None:
        # nothing is known there: not a landing anyone could call safe (a search that flew off the map)
        return TouchdownGrade(surface="outside", safe=False, reasons=("outside the modelled area",))
    cls = SurfaceClass(int(grid.cls[ij]))
    surface = GRADE_SURFACE[cls]
    reasons: list[str] = []
    if cls == SurfaceClass.WATER and int(grid.mat[ij]) == int(Material.POOL):
        surface = "pool"
        reasons.append("landed on a swimming pool")
    elif cls in FORBIDDEN_CLASSES:
        reasons.append(f"landed on {cls.name.lower().replace('_', ' ')}")
    r = max(cfg.clearance_m, cfg.edge_m + 0.5, cfg.flat_radius_m, cfg.vehicle_m)
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
    # clearance: people, objects
    disc = d <= cfg.clearance_m
    for klass, name in _OBSTACLE_NAMES.items():
        hit = disc & (c == int(klass))
        if hit.any() and klass != cls:
            reasons.append(f"{name} within {float(d[hit].min()):.1f} m")
    tall = disc & (h > h0 + cfg.object_height_m) & ~np.isin(c, [int(k) for k in OBSTACLE_CLASSES])
    if tall.any():
        reasons.append(f"object {float(h[tall].max() - h0):.1f} m tall within {float(d[tall].min()):.1f} m")
    # third parties: vehicles and machinery, people, wires
    gap = np.hypot(d, np.maximum(h0 - h, 0.0))  # to the top of what stands below, across to what is higher
    for klass, name in _THIRD_PARTY.items():
        hit = (gap <= cfg.vehicle_m) & (c == int(klass))
        if hit.any() and klass != cls:
            reasons.append(f"{name} within {float(gap[hit].min()):.1f} m")
    if people is not None and len(people):
        p = np.asarray(people, np.float64)
        feet = np.hypot(np.hypot(p[:, 0] - north_m, p[:, 1] - east_m), p[:, 2] - h0)
        if float(feet.min()) <= cfg.person_m:
            reasons.append(f"person {float(feet.min()):.1f} m away (at least {cfg.person_m:.0f} m)")
    for wire in wires:
        under = wire.ground_gap_m(north_m, east_m)
        if under <= cfg.wire_m:
            reasons.append(
                f"{under:.1f} m from the line under an overhead wire (at least {cfg.wire_m:.0f} m)"
            )
            break
    # edges: a drop of more than drop_m nearby
    drop = (d <= cfg.edge_m) & (h < h0 - cfg.drop_m)
    if drop.any():
        reasons.append(f"{float(d[drop].min()):.1f} m from an edge ({h0 - float(h[drop].min()):.0f} m drop)")
    return TouchdownGrade(surface=surface, safe=not reasons, reasons=tuple(reasons))
