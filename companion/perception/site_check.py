"""The geometric veto: slope, roughness, obstacles in the rotor-clearance disc and the distance to an
edge around a landing site, from a close-up LiDAR sweep.

Rough also means a surface with the ground seen through it: standing crops (a canopy of leaves in rows,
the soil between them 0.2-1 m lower) or a step down inside the disc. Their top alone can look smooth, so
the share of the disc's returns that lie ``SUNKEN_BAND_M`` below the surface is a test of its own
(``MAX_SUNKEN_SHARE``): a rotor disc over a crop field has about a third of them there, a lawn or a
roof none.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from companion.guidance.frames import quat_to_matrix


def world_points(
    lidar_frd: np.ndarray, pos_ned_m: tuple[float, float, float], quat: tuple[float, ...]
) -> np.ndarray:
    pts = np.asarray(lidar_frd, dtype=np.float64)[:, :3]
    pts = pts[np.isfinite(pts).all(axis=1)]
    return np.asarray(pts @ quat_to_matrix(quat).T + np.asarray(pos_ned_m))


MIN_SITE_RETURNS = 5  # LiDAR returns within the rotor-clearance disc needed to judge a site
# returns this far below the surface (metres; a drop of more than 1 m is an edge) are the ground seen
# through a canopy or the foot of a step: more than this share of the disc's returns there is rough
SUNKEN_BAND_M = (0.2, 1.0)
MAX_SUNKEN_SHARE = 0.1
MIN_PLANE_RETURNS = 10  # surface returns in the disc needed to fit its plane (fewer: taken as level)
MIN_PLANE_SPREAD_M = 1.0  # and their spread north and east, so that the tilt is measured, not guessed
NEAR_M = 6.0  # around the site as far as the confirmation's close-up shows (recovery closeup_half_m) ...
MIN_NEAR_RETURNS = 50  # ... the tallest return there is measured from this many returns
# Water returns little of a near-infrared LiDAR's pulse (absorbed, or mirrored away off the beam):
# about 2 % reflectivity at 905 nm against 5-10 % for black tar or EPDM, 10-20 % for asphalt and more
# for everything else. Intensity on the sensor stream is 0..1, calibrated reflectivity as far as the
# sensor gives it. A disc whose surface returns have a median under this is water, whatever a camera
# sees through fog ...
WATER_MAX_INTENSITY = 0.04
# ... when the sweep reports intensity at all: a LiDAR (or a bridge) that measures none sends zeros;
# read from beams within 30 deg of straight down (their cosine from this): at a grazing angle black tar
# returns as little as water does
WATER_BEAM_COS = math.cos(math.radians(30.0))


@dataclass(frozen=True, slots=True)
class SiteCheck:
    """Geometry of a landing site from a close-up LiDAR sweep (the geometric veto)."""

    points: int
    surface_up_m: float
    roughness_m: float
    obstacle_m: float  # tallest return above the surface within the rotor-clearance radius
    edge_distance_m: float  # to the nearest drop of more than 1 m (inf when none is seen)
    reasons: tuple[str, ...]
    sunken_share: float = math.nan  # share of the disc's returns SUNKEN_BAND_M below the surface
    slope_deg: float = math.nan  # of the plane fitted to the surface's returns in the disc
    # tallest return above the surface's plane within NEAR_M of the site: a tree's crown, a wall, a
    # vehicle near it (NaN: fewer than MIN_NEAR_RETURNS there)
    tallest_near_m: float = math.nan
    # median intensity (0..1) of the disc's surface returns (NaN: the sweep reports no intensity)
    surface_intensity: float = math.nan

    @property
    def clear(self) -> bool:
        return not self.reasons

    @property
    def measured(self) -> bool:
        """The sweep put enough returns on the site to judge it (an empty or partial sweep may not)."""
        return self.points >= MIN_SITE_RETURNS


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
    max_slope_deg: float = 8.0,
    max_water_intensity: float = WATER_MAX_INTENSITY,
) -> SiteCheck:
    """Slope/roughness, obstacles in the rotor disc and distance to an edge around ``site_ne_m``.

    Heights are measured from the plane fitted to the surface's returns in the disc
    (:func:`_surface_plane`), so a gentle slope is neither rough nor an obstacle; it is refused over
    ``max_slope_deg`` (Surface ID's limit: ``perception.max_slope_deg``). A surface whose returns in
    the disc are as dark as water (median intensity under ``max_water_intensity``; 0: not judged) is
    refused as water: in fog a camera may not see a harbour's water, a LiDAR still does.

    Never raises for a sweep: no sweep, an empty one or one that is not an (N, 3+) array of body FRD
    metres is a check that measured nothing (``measured`` False), rows with a NaN are dropped.
    """
    if lidar_frd is None or len(lidar_frd) == 0:
        return SiteCheck(0, math.nan, math.nan, math.nan, math.nan, ("no LiDAR returns",))
    shape = np.shape(lidar_frd)
    if len(shape) != 2 or shape[1] < 3:
        return SiteCheck(
            0, math.nan, math.nan, math.nan, math.nan, (f"LiDAR sweep of shape {shape}, not (N, 3+)",)
        )
    rows = np.asarray(lidar_frd, dtype=np.float64)
    rows = rows[np.isfinite(rows[:, :3]).all(axis=1)]
    world = world_points(rows, pos_ned_m, quat)
    dn, de = world[:, 0] - site_ne_m[0], world[:, 1] - site_ne_m[1]
    d = np.hypot(dn, de)
    disc = d <= clearance_m
    if disc.sum() < MIN_SITE_RETURNS:
        return SiteCheck(
            int(disc.sum()), math.nan, math.nan, math.nan, math.nan, ("too few returns on the site",)
        )
    up = -world[:, 2]
    core = up[d <= clearance_m * 0.5] if (d <= clearance_m * 0.5).sum() >= 3 else up[disc]
    level = _surface_plane(dn, de, up, disc, float(np.median(core)), max_obstacle_m)
    # heights above the surface's plane: a lawn on a 7 degree slope is level in them, not 12 cm rough
    rel = up - (level[0] * dn + level[1] * de + level[2])
    surface = level[2]
    slope = math.degrees(math.atan(math.hypot(level[0], level[1])))
    obstacle = float(rel[disc].max())
    on_surface = rel[disc][np.abs(rel[disc]) < max_obstacle_m]
    # No return near the median level (the disc holds two levels, a step or a ramp): nothing there
    # is a surface, so its roughness is the spread of the whole disc, not the std of nothing (NaN).
    rough = float(np.std(on_surface if len(on_surface) else up[disc]))
    below = -rel[disc]
    sunken = float(np.mean((below > SUNKEN_BAND_M[0]) & (below <= SUNKEN_BAND_M[1])))
    edge = _edge_distance(world, d, rel, site_ne_m, 0.0, clearance_m + 4.0)
    near = d <= NEAR_M
    tallest = float(rel[near].max()) if near.sum() >= MIN_NEAR_RETURNS else math.nan
    beam = world - np.asarray(pos_ned_m)  # steep beams only: a grazing one returns little from anything
    steep = beam[:, 2] >= WATER_BEAM_COS * np.linalg.norm(beam, axis=1)
    intensity = rows[:, 3] if rows.shape[1] >= 4 else None
    dark = _surface_intensity(intensity, disc & (np.abs(rel) < max_obstacle_m) & steep)
    reasons = []
    if dark < max_water_intensity:
        reasons.append(f"returns as dark as water (median intensity {dark:.2f})")
    if obstacle > max_obstacle_m:
        reasons.append(f"object {obstacle:.1f} m tall within {clearance_m:.0f} m")
    if rough > max_roughness_m:
        reasons.append(f"rough ({100 * rough:.0f} cm)")
    elif sunken > MAX_SUNKEN_SHARE:
        low, high = SUNKEN_BAND_M
        reasons.append(
            f"rough ({100 * sunken:.0f} % of returns {low:g}-{high:g} m below the surface: "
            "the ground seen through a crop, or a step)"
        )
    if edge < min_edge_m:
        reasons.append(f"{edge:.1f} m from an edge")
    if slope > max_slope_deg:
        reasons.append(f"sloped {slope:.0f} deg")
    return SiteCheck(
        int(disc.sum()), surface, rough, obstacle, edge, tuple(reasons), sunken, slope, tallest, dark
    )


def _surface_intensity(intensity: np.ndarray | None, on_surface: np.ndarray) -> float:
    """Median of the sweep's ``intensity`` (one per finite return; None: no column) over the returns
    ``on_surface``; NaN when the sweep reports none (every return's is zero) or has fewer than
    ``MIN_SITE_RETURNS`` such returns."""
    if intensity is None:
        return math.nan
    if not np.nanmax(intensity, initial=0.0) > 0.0:
        return math.nan
    seen = intensity[on_surface & np.isfinite(intensity)]
    return float(np.median(seen)) if len(seen) >= MIN_SITE_RETURNS else math.nan


def _surface_plane(
    dn: np.ndarray, de: np.ndarray, up: np.ndarray, disc: np.ndarray, level: float, band_m: float
) -> tuple[float, float, float]:
    """The plane ``up = a * dn + b * de + c`` (north and east from the site) through the surface's
    returns in the rotor disc: those within ``band_m`` of ``level`` (the median height at the site),
    then, fitted once, those within ``band_m`` of that plane (the far side of a slope steeper than the
    band). Objects on it, a step's other level and the ground seen through a crop lie outside the band
    and do not tilt it. Level at ``level`` when too few returns, or too little spread, to fit one."""
    sel = disc & (np.abs(up - level) < band_m)
    plane = (0.0, 0.0, level)
    for _ in range(2):
        if sel.sum() < MIN_PLANE_RETURNS or min(np.ptp(dn[sel]), np.ptp(de[sel])) < MIN_PLANE_SPREAD_M:
            return plane
        a = np.column_stack([dn[sel], de[sel], np.ones(int(sel.sum()))])
        coef = np.linalg.lstsq(a, up[sel], rcond=None)[0]
        plane = (float(coef[0]), float(coef[1]), float(coef[2]))
        sel = disc & (np.abs(up - (plane[0] * dn + plane[1] * de + plane[2])) < band_m)
    return plane
