"""A minimal, metric Surface ID from the LiDAR (issue 5 deepens it).

LiDAR returns (body FRD) are rotated into NED and binned on a horizontal grid whose cell grows with
altitude (the returns spread out). A cell is flat when the heights in its 3 x 3 neighbourhood span
at most ``flat_span_m``; flat cells are cleaned (morphological open and close), split into connected
components, and components of at least ``min_area_m2`` become candidates, each with its geometry:
area, roughness, height above the lowest surfaces in view, distance from its most interior point to
its edge, and that interior point as the landing site. Boxes are the components projected into the
image. With no candidate, the image's four quadrants and its centre are proposed (no geometry), so
the reasoner can still point a direction.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from companion.guidance.frames import PinholeCamera, quat_to_matrix


@dataclass(frozen=True, slots=True)
class Candidate:
    index: int
    box_px: tuple[int, int, int, int]  # x0, y0, x1, y1
    centre_px: tuple[float, float]  # the landing site's pixel
    area_m2: float = 0.0
    roughness_m: float = math.nan
    height_above_m: float = math.nan  # above the lowest surfaces in view
    edge_distance_m: float = 0.0  # from the site to the region's edge
    site_ned_m: tuple[float, float, float] | None = None
    fallback: bool = False  # a quadrant or the centre: no geometry behind it


def _world_points(
    lidar_frd: np.ndarray, pos_ned_m: tuple[float, float, float], quat: tuple[float, ...]
) -> np.ndarray:
    pts = np.asarray(lidar_frd, dtype=np.float64)[:, :3]
    pts = pts[np.isfinite(pts).all(axis=1)]
    return np.asarray(pts @ quat_to_matrix(quat).T + np.asarray(pos_ned_m))


def quadrant_fallback(camera: PinholeCamera) -> list[Candidate]:
    w, h = camera.width, camera.height
    boxes = [
        (0, 0, w // 2, h // 2),
        (w // 2, 0, w, h // 2),
        (0, h // 2, w // 2, h),
        (w // 2, h // 2, w, h),
        (w // 4, h // 4, 3 * w // 4, 3 * h // 4),
    ]
    return [
        Candidate(k, b, ((b[0] + b[2]) / 2, (b[1] + b[3]) / 2), fallback=True) for k, b in enumerate(boxes)
    ]


def surface_id(
    lidar_frd: np.ndarray | None,
    pos_ned_m: tuple[float, float, float],
    quat: tuple[float, float, float, float],
    camera: PinholeCamera,
    *,
    min_area_m2: float = 30.0,
    flat_span_m: float = 0.25,
    max_candidates: int = 5,
) -> list[Candidate]:
    """Candidates, best-first by area x clearance; the quadrant fallback when none qualifies."""
    if lidar_frd is None or len(lidar_frd) < 50:
        return quadrant_fallback(camera)
    world = _world_points(lidar_frd, pos_ned_m, quat)
    if len(world) < 50:
        return quadrant_fallback(camera)
    altitude = max(-(pos_ned_m[2] - float(np.median(world[:, 2]))), 5.0)
    cell = float(np.clip(altitude / 45.0, 0.5, 2.5))
    n0, e0 = world[:, 0].min(), world[:, 1].min()
    i = ((world[:, 0] - n0) / cell).astype(np.int64)
    j = ((world[:, 1] - e0) / cell).astype(np.int64)
    rows, cols = int(i.max()) + 1, int(j.max()) + 1
    up = -world[:, 2]
    hmax = np.full((rows, cols), -np.inf)
    hmin = np.full((rows, cols), np.inf)
    np.maximum.at(hmax, (i, j), up)
    np.minimum.at(hmin, (i, j), up)
    valid = np.isfinite(hmax)
    kernel = np.ones((3, 3), np.uint8)
    filled_max = np.where(valid, hmax, -1e6).astype(np.float32)
    filled_min = np.where(valid, hmin, 1e6).astype(np.float32)
    span = cv2.dilate(filled_max, kernel) - cv2.erode(filled_min, kernel)
    flat = (valid & (span <= flat_span_m)).astype(np.uint8)
    flat = cv2.morphologyEx(flat, cv2.MORPH_CLOSE, kernel)  # fill single empty cells
    flat = cv2.morphologyEx(flat, cv2.MORPH_OPEN, kernel)  # drop slivers
    count, labels, stats, _ = cv2.connectedComponentsWithStats(flat, connectivity=4)
    ground = float(np.percentile(up, 10))
    r_nb = quat_to_matrix(quat)
    found: list[tuple[float, Candidate]] = []
    for c in range(1, count):
        area = float(stats[c, cv2.CC_STAT_AREA]) * cell * cell
        if area < min_area_m2:
            continue
        mask = (labels == c).astype(np.uint8)
        dist = cv2.distanceTransform(np.pad(mask, 1), cv2.DIST_L2, 5)[1:-1, 1:-1]
        bi, bj = np.unravel_index(int(np.argmax(dist)), dist.shape)
        edge = float(dist[bi, bj]) * cell
        heights = np.where(mask.astype(bool) & valid, hmax, np.nan)
        h = float(np.nanmedian(heights))
        rough = float(np.nanstd(heights))
        site = (n0 + (bi + 0.5) * cell, e0 + (bj + 0.5) * cell, -h)
        ci, cj = np.nonzero(mask)
        cell_pts = np.stack([n0 + (ci + 0.5) * cell, e0 + (cj + 0.5) * cell, np.full(len(ci), -h)], axis=1)
        body = (cell_pts - np.asarray(pos_ned_m)) @ r_nb
        uv, front = camera.project_frd(body)
        uv = uv[front]
        site_uv, site_front = camera.project_frd(((np.asarray(site) - np.asarray(pos_ned_m)) @ r_nb)[None, :])
        if len(uv) == 0 or not site_front[0]:
            continue
        x0, y0 = np.clip(uv.min(axis=0), 0, [camera.width - 1, camera.height - 1]).astype(int)
        x1, y1 = np.clip(uv.max(axis=0), 0, [camera.width - 1, camera.height - 1]).astype(int)
        su, sv = float(site_uv[0, 0]), float(site_uv[0, 1])
        if x1 - x0 < 4 or y1 - y0 < 4 or not (0 <= su < camera.width and 0 <= sv < camera.height):
            continue
        cand = Candidate(
            0, (int(x0), int(y0), int(x1), int(y1)), (su, sv), area, rough, h - ground, edge, site
        )
        found.append((area * min(edge, 5.0), cand))
    if not found:
        return quadrant_fallback(camera)
    found.sort(key=lambda sc: -sc[0])
    out = []
    for k, (_, cand) in enumerate(found[:max_candidates]):
        out.append(
            Candidate(
                k,
                cand.box_px,
                cand.centre_px,
                cand.area_m2,
                cand.roughness_m,
                cand.height_above_m,
                cand.edge_distance_m,
                cand.site_ned_m,
            )
        )
    return out


@dataclass(frozen=True, slots=True)
class SiteCheck:
    """Geometry of a landing site from a close-up LiDAR sweep (the geometric veto)."""

    points: int
    surface_up_m: float
    roughness_m: float
    obstacle_m: float  # tallest return above the surface within the rotor-clearance radius
    edge_distance_m: float  # to the nearest drop of more than 1 m (inf when none is seen)
    reasons: tuple[str, ...]

    @property
    def clear(self) -> bool:
        return not self.reasons


def _edge_distance(
    world: np.ndarray,
    d: np.ndarray,
    up: np.ndarray,
    site_ne_m: tuple[float, float],
    surface: float,
    reach_m: float,
) -> float:
    """Distance to the nearest drop of more than 1 m, erring short.

    Seen from above, the surface itself hides the ground just past its edge, so the first "drop"
    return lies beyond the edge. In each of 16 directions where a drop is seen, the edge is taken at
    the farthest surface-level return in that direction (the surface is known to reach that far, no
    farther); the nearest such distance is the answer.
    """
    near = d <= reach_m
    if not near.any():
        return math.inf
    ang = np.arctan2(world[near, 1] - site_ne_m[1], world[near, 0] - site_ne_m[0])
    sector = ((ang + math.pi) / (2 * math.pi) * 16).astype(int) % 16
    dn, upn = d[near], up[near]
    drop = upn < surface - 1.0
    level = np.abs(upn - surface) < 0.3
    edge = math.inf
    for s in np.unique(sector[drop]):
        in_s = sector == s
        first_drop = float(dn[in_s & drop].min())
        roof = dn[in_s & level & (dn < first_drop)]
        edge = min(edge, float(roof.max()) if len(roof) else 0.0)
    return edge


def check_site(
    lidar_frd: np.ndarray | None,
    pos_ned_m: tuple[float, float, float],
    quat: tuple[float, float, float, float],
    site_ne_m: tuple[float, float],
    *,
    clearance_m: float = 2.0,
    max_obstacle_m: float = 0.3,
    max_roughness_m: float = 0.08,
    min_edge_m: float = 1.5,
) -> SiteCheck:
    """Slope/roughness, obstacles in the rotor disc and distance to an edge around ``site_ne_m``."""
    if lidar_frd is None or len(lidar_frd) == 0:
        return SiteCheck(0, math.nan, math.nan, math.nan, math.nan, ("no LiDAR returns",))
    world = _world_points(lidar_frd, pos_ned_m, quat)
    d = np.hypot(world[:, 0] - site_ne_m[0], world[:, 1] - site_ne_m[1])
    disc = d <= clearance_m
    if disc.sum() < 5:
        return SiteCheck(
            int(disc.sum()), math.nan, math.nan, math.nan, math.nan, ("too few returns on the site",)
        )
    up = -world[:, 2]
    core = up[d <= clearance_m * 0.5] if (d <= clearance_m * 0.5).sum() >= 3 else up[disc]
    surface = float(np.median(core))
    obstacle = float(up[disc].max() - surface)
    rough = float(np.std(up[disc][np.abs(up[disc] - surface) < max_obstacle_m]))
    edge = _edge_distance(world, d, up, site_ne_m, surface, clearance_m + 4.0)
    reasons = []
    if obstacle > max_obstacle_m:
        reasons.append(f"object {obstacle:.1f} m tall within {clearance_m:.0f} m")
    if rough > max_roughness_m:
        reasons.append(f"rough ({100 * rough:.0f} cm)")
    if edge < min_edge_m:
        reasons.append(f"{edge:.1f} m from an edge")
    return SiteCheck(int(disc.sum()), surface, rough, obstacle, edge, tuple(reasons))
