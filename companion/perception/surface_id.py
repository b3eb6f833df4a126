"""Surface ID: the few flat surfaces worth asking the reasoner about, with their geometry.

depth map -> per-cell flatness (:mod:`companion.perception.flatness`) -> morphological close then open
(3 x 3: fill pinholes, drop slivers) -> connected components (4-connected) -> per component:

- ``area_m2``: the flat surface, its cells grown back by the half window the flatness test loses at
  the edges, each cell counted at its metric footprint ``(z / fx * cell_px)^2``; components under
  ``min_area_m2`` are dropped;
- ``edge_distance_m``: for each cell, the distance to the component's outline plus the half window,
  in metres at the component's median depth; the landing site is the cell farthest from any edge;
- the *landable* part: cells at least ``edge_margin_m`` from every edge (the rotor-clearance margin:
  the drone's centre may touch down there with its disc clear). Its bounding box is the candidate's
  box; a component with no landable cell is dropped;
- ``slope_deg`` and ``roughness_m``: medians over the component;
- ``height_above_m``: the component's median height above the lowest surface around it (the 10th
  percentile of the heights in a ring just past its edge, or the ground level the caller knows,
  whichever is lower);
- ``score`` = min(landable area, ``score_area_m2``) x fill x min(1, edge_distance_m / (2 x
  edge_margin_m)), where fill is the landable part's share of its box: compact sites with room to
  spare first. Area counts up to ``score_area_m2`` (beyond it a site is not safer, only bigger); fill
  keeps a sprawling street network, whose box is mostly buildings, behind a roof, whose box is the roof;
  metric surfaces less than ``roof_height_m`` above their surroundings score ``ground_level_factor``
  times less (streets, plazas and parking lots carry traffic and people even when they look empty);
- ``length_m``, ``width_m``: the smallest rectangle holding the surface on its own level (each cell's
  ray met with the level plane at the surface's median height; extended cells included); an elevated
  surface at least ``strip_min_length_m`` long and ``strip_min_aspect`` times as long as wide is a
  ``strip`` (a highway deck, a bridge, a ramp: a long band across the view, where a roof is a closed
  shape) and scores as street level does.

A box contained in another candidate's box is dropped when both surfaces lie at the same height
(within ``same_surface_m``: a fragment of the same surface, split off by clutter; a roof inside the
box of the streets around it stays); the best ``max_candidates`` by score are
kept and numbered 0.. in score order. Relative (monocular) depth has no metres: areas and margins are
then fractions of the image and the geometry fields are NaN. When nothing qualifies the image's four
quadrants and its centre are proposed instead (``fallback=True``, no geometry), so the reasoner can
still point a direction.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from companion.config_schema import DEFAULTS
from companion.guidance.frames import CAMERA_TO_BODY, PinholeCamera, quat_to_matrix
from companion.perception.depth import DepthError, DepthMap, DepthSource, grid_shape
from companion.perception.flatness import Flatness, flatness
from companion.perception.image_extend import ImageCells, extend_unmeasured

__all__ = ["Candidate", "SurfaceParams", "propose", "quadrant_fallback", "surface_id"]

LEVEL = (1.0, 0.0, 0.0, 0.0)
ROOF_HEIGHT_M = 3.0  # a surface this far above its surroundings is elevated (default of SurfaceParams)
_K3 = np.ones((3, 3), np.uint8)


@dataclass(frozen=True, slots=True)
class SurfaceParams:
    """Surface ID thresholds. A field named as a ``[perception]`` key is that key (its default is the
    schema's, :data:`~companion.config_schema.DEFAULTS`); no key sets the others."""

    cell_px: int = DEFAULTS.perception.cell_px
    window_cells: int = DEFAULTS.perception.window_cells
    max_slope_deg: float = DEFAULTS.perception.max_slope_deg
    max_roughness_m: float = DEFAULTS.perception.max_roughness_m
    min_area_m2: float = DEFAULTS.perception.min_area_m2
    edge_margin_m: float = DEFAULTS.perception.edge_margin_m
    max_candidates: int = DEFAULTS.perception.max_candidates
    max_relative_gradient: float = 0.004
    min_area_frac: float = 0.01  # relative depth: smallest component, fraction of the image
    relative_margin_frac: float = 0.02  # relative depth: edge margin, fraction of the image width
    score_area_m2: float = 400.0  # landable area beyond this adds nothing to the score
    same_surface_m: float = 1.0  # contained boxes this close in height are the same surface
    same_surface_rel: float = 0.02  # the same for relative depth (fraction of the depth range)
    # grow metric surfaces over unmeasured cells that look the same
    extend_with_image: bool = DEFAULTS.perception.extend_with_image
    roof_height_m: float = ROOF_HEIGHT_M  # a surface this far above its surroundings is elevated (a roof)
    ground_level_factor: float = 0.5  # score factor for surfaces at street level (traffic, people)
    strip_min_length_m: float = DEFAULTS.perception.strip_min_length_m  # an elevated surface this long ...
    # ... and this many times longer than wide is a deck, not a roof
    strip_min_aspect: float = DEFAULTS.perception.strip_min_aspect


@dataclass(frozen=True, slots=True)
class Candidate:
    """One proposed surface. Boxes are ``(x0, y0, x1, y1)`` pixels, half-open: ``x0 <= u < x1``."""

    index: int
    box_px: tuple[int, int, int, int]
    centre_px: tuple[float, float]  # the landing site's pixel (the point farthest from an edge)
    area_m2: float = math.nan
    roughness_m: float = math.nan
    height_above_m: float = math.nan
    edge_distance_m: float = math.nan
    site_ned_m: tuple[float, float, float] | None = None
    fallback: bool = False  # a quadrant or the centre: no geometry behind it
    slope_deg: float = math.nan
    landable_area_m2: float = math.nan
    score: float = 0.0
    measured_share: float = 1.0  # of the area, measured by depth (the rest extended from the image)
    length_m: float = math.nan  # the surface's extent on its own level: the long side of the smallest
    width_m: float = math.nan  # rectangle holding it, and the short side (metres; NaN without metric depth)
    strip: bool = False  # elevated, long and narrow: a highway deck, a bridge, a ramp (not a roof)

    @property
    def elevated(self) -> bool:
        """A roof: measured at least 3 m above its surroundings, and not a strip (a deck carries traffic)."""
        return math.isfinite(self.height_above_m) and self.height_above_m >= ROOF_HEIGHT_M and not self.strip

    def to_json(self) -> dict[str, Any]:
        def num(v: float, nd: int) -> float | None:
            return round(v, nd) if math.isfinite(v) else None

        return {
            "index": self.index,
            "box": list(self.box_px),
            "centre_px": [round(v, 1) for v in self.centre_px],
            "score": round(self.score, 2),
            "fallback": self.fallback,
            "geometry": {
                "area_m2": num(self.area_m2, 1),
                "landable_area_m2": num(self.landable_area_m2, 1),
                "slope_deg": num(self.slope_deg, 2),
                "roughness_m": num(self.roughness_m, 3),
                "height_above_m": num(self.height_above_m, 2),
                "edge_distance_m": num(self.edge_distance_m, 2),
                "measured_share": round(self.measured_share, 3),
                "length_m": num(self.length_m, 1),
                "width_m": num(self.width_m, 1),
                "strip": self.strip,
                "site_ned_m": None if self.site_ned_m is None else [round(v, 2) for v in self.site_ned_m],
            },
        }


def quadrant_fallback(camera: PinholeCamera) -> list[Candidate]:
    """The four image quadrants and the centre, for when no surface qualifies."""
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


def _ellipse(radius: int) -> np.ndarray:
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))


def _nonempty_box(box: tuple[int, int, int, int], camera: PinholeCamera) -> tuple[int, int, int, int]:
    """``box`` at least one pixel wide and tall inside the image. A landable part that is a single
    cell exactly at the margin has no reach past its centre: its box would have no width (a city
    flight's recovery once died cropping one), so it keeps the pixel at that centre."""
    x0, y0, x1, y1 = box
    if x1 <= x0:
        x0 = min(max(x0, 0), camera.width - 1)
        x1 = x0 + 1
    if y1 <= y0:
        y0 = min(max(y0, 0), camera.height - 1)
        y1 = y0 + 1
    return x0, y0, x1, y1


def _edge_distance_cells(mask: np.ndarray) -> np.ndarray:
    """Per cell of ``mask``, the distance (cells) to the nearest cell outside it. A mask with no cell
    outside it (one surface filling the whole view) is measured to the view's border instead: the
    distance transform alone would answer FLT_MAX everywhere."""
    m = mask.astype(np.uint8)
    if m.all():
        padded = cv2.distanceTransform(np.pad(m, 1), cv2.DIST_L2, 5)
        return np.asarray(padded[1:-1, 1:-1])
    return np.asarray(cv2.distanceTransform(m, cv2.DIST_L2, 5))


def _contained(inner: tuple[int, int, int, int], outer: tuple[int, int, int, int]) -> bool:
    return inner[0] >= outer[0] and inner[1] >= outer[1] and inner[2] <= outer[2] and inner[3] <= outer[3]


def _component(
    comp: np.ndarray,
    offset: tuple[int, int],
    fl: Flatness,
    depth: DepthMap,
    camera: PinholeCamera,
    p: SurfaceParams,
    pos_ned_m: tuple[float, float, float] | None,
    ground_up_m: float | None,
    extra: np.ndarray | None = None,
    quat_wxyz: tuple[float, float, float, float] = LEVEL,
) -> tuple[Candidate, float] | None:
    """Geometry, box and level (median height, or relative depth) of one component.

    ``comp`` is the component's mask in a padded window of the grid at ``offset``; ``extra`` the
    unmeasured cells the image extends it over (same window), if any.
    """
    r0, c0 = offset
    rows, cols = comp.shape
    sl = (slice(r0, r0 + rows), slice(c0, c0 + cols))
    valid = depth.valid[sl]
    hw = fl.half_window
    grown = (
        cv2.dilate(comp.astype(np.uint8), np.ones((2 * hw + 1, 2 * hw + 1), np.uint8)).astype(bool) & valid
    )
    extended = extra is not None and bool(extra.any())
    if extended:
        assert extra is not None
        # The surface's extent is known (measured, grown back to its edges, plus the image's share):
        # edge distances are measured from that outline itself.
        body = comp | extra
        dist = _edge_distance_cells(grown | extra)
        edge_cells = np.where(body, dist - 0.5, 0.0)
    else:
        body = comp
        dist = _edge_distance_cells(comp)
        edge_cells = np.where(comp, dist + hw - 0.5, 0.0)
    s = depth.cell_px
    measured_share = 1.0
    if depth.metric:
        cell_m = fl.cell_m[sl]
        scale = float(np.median(cell_m[comp]))
        # Unmeasured cells count at the surface's own scale (they lie at its depth if they are it).
        foot = np.where(np.isfinite(cell_m), cell_m, scale) ** 2
        area = float(np.sum(foot[grown])) + (float(np.sum(foot[extra])) if extended else 0.0)
        if area < p.min_area_m2:
            return None
        if extended:
            measured_share = float(np.sum(foot[grown])) / area
        edge_m = edge_cells * scale
        land = body & (edge_m >= p.edge_margin_m)
        if not land.any():
            return None
        landable = float(np.sum(foot[land]))
        margin, unit = p.edge_margin_m, scale  # metres per cell
    else:
        area_frac = float(grown.sum()) * s * s / (camera.width * camera.height)
        if area_frac < p.min_area_frac:
            return None
        margin_cells = p.relative_margin_frac * camera.width / s
        land = comp & (edge_cells >= margin_cells)
        if not land.any():
            return None
        edge_m = edge_cells / margin_cells  # in margins, for the score only
        landable, margin, area = float(land.sum()) * s * s, 1.0, math.nan
        unit = 1.0 / margin_cells  # margins per cell
    # The landing site: the measured cell farthest from an edge.
    bi, bj = np.unravel_index(int(np.argmax(np.where(comp, edge_m, -1.0))), edge_m.shape)
    best_edge = float(edge_m[bi, bj])
    lr, lc = np.nonzero(land)
    # Sub-cell box: the edge distance falls by one cell per cell outward, so the margin is crossed
    # ``(edge - margin) / scale`` cells (at most one) past a landable cell's centre.
    reach = np.clip((edge_m[lr, lc] - margin) / unit, 0.0, 1.0)
    box = _nonempty_box(
        (
            round(max((c0 + lc + 0.5 - reach).min() * s, 0)),
            round(max((r0 + lr + 0.5 - reach).min() * s, 0)),
            round(min((c0 + lc + 0.5 + reach).max() * s, camera.width)),
            round(min((r0 + lr + 0.5 + reach).max() * s, camera.height)),
        ),
        camera,
    )
    centre = (float((c0 + bj + 0.5) * s), float((r0 + bi + 0.5) * s))
    fill = float(land.sum()) / float((lr.max() - lr.min() + 1) * (lc.max() - lc.min() + 1))
    room = min(landable, p.score_area_m2) if depth.metric else landable
    score = room * fill * (min(1.0, best_edge / (2.0 * margin)) if margin > 0 else 1.0)
    if not depth.metric:
        return Candidate(0, box, centre, score=score), float(np.median(depth.depth[sl][comp]))
    ned = fl.ned_m[sl]
    up = -ned[..., 2]
    ring = cv2.dilate(comp.astype(np.uint8), _ellipse(hw + 3)).astype(bool)
    ring &= ~cv2.dilate(comp.astype(np.uint8), _ellipse(hw + 1)).astype(bool) & valid
    low = float(np.percentile(up[ring], 10)) if ring.sum() >= 5 else math.nan
    if ground_up_m is not None:
        low = ground_up_m if math.isnan(low) else min(low, ground_up_m)
    site = None
    if pos_ned_m is not None:
        site = (
            float(pos_ned_m[0] + ned[bi, bj, 0]),
            float(pos_ned_m[1] + ned[bi, bj, 1]),
            float(pos_ned_m[2] + ned[bi, bj, 2]),
        )
    level = float(np.median(up[comp]))
    length, width = _extent_m(body, (r0, c0), s, camera, quat_wxyz, -level)
    elevated = level - low >= p.roof_height_m  # NaN (nothing around it measured) counts as street level
    strip = bool(elevated and length >= p.strip_min_length_m and length >= p.strip_min_aspect * width)
    if not elevated or strip:
        score *= p.ground_level_factor
    cand = Candidate(
        0,
        box,
        centre,
        area_m2=area,
        roughness_m=float(np.median(fl.roughness_m[sl][comp])),
        height_above_m=level - low,
        edge_distance_m=best_edge,
        site_ned_m=site,
        slope_deg=float(np.median(fl.slope_deg[sl][comp])),
        landable_area_m2=landable,
        score=score,
        measured_share=measured_share,
        length_m=length,
        width_m=width,
        strip=strip,
    )
    return cand, level


def _extent_m(
    body: np.ndarray,
    offset: tuple[int, int],
    cell_px: int,
    camera: PinholeCamera,
    quat_wxyz: tuple[float, float, float, float],
    below_m: float,
) -> tuple[float, float]:
    """Length and width (metres) of the smallest rectangle holding a surface's cells, each cell's
    centre ray met with the level plane ``below_m`` under the camera: the measured cells and those
    the image extended alike. ``(nan, nan)`` when the plane is not below the camera."""
    if not below_m > 0.0:
        return math.nan, math.nan
    rr, cc = np.nonzero(body)
    x = ((cc + offset[1] + 0.5) * cell_px - camera.cx) / camera.fx
    y = ((rr + offset[0] + 0.5) * cell_px - camera.cy) / camera.fy
    m = quat_to_matrix(quat_wxyz) @ CAMERA_TO_BODY  # camera -> level NED
    rays = m @ np.stack([x, y, np.ones_like(x)])
    down = rays[2] > 1e-6
    if down.sum() < 3:
        return math.nan, math.nan
    ne = (rays[:2, down] * (below_m / rays[2, down])).T.astype(np.float32)
    (_cx, _cy), (a, b), _angle = cv2.minAreaRect(ne)
    cell_m = cell_px * below_m / camera.fx  # the rectangle runs through the outer cells' centres
    return max(a, b) + cell_m, min(a, b) + cell_m


_SEED_LEVEL_M = 0.3  # measured cells this close to a flat surface's level are that surface


def _range_reached(depth: DepthMap, camera: PinholeCamera, below_m: float) -> float | None:
    """How far along a level plane ``below_m`` under the sensor its returns surely reach, when the
    plane goes on past its range: the range, less one ring spacing (the last ring on the plane may
    fall that short of it; a quarter more for the tilt of a hovering vehicle) and less one cell (the
    depth grid's step). A surface measured out to here may continue unseen; one that ends short of
    it ends. None when the plane lies beyond the range everywhere."""
    r = depth.max_range_m
    if r is None or below_m <= 0.0 or below_m >= r:
        return None
    cos = below_m / r
    sin = math.sqrt(1.0 - cos * cos)
    ring = 1.25 * r * (sin / cos) * (depth.ring_spacing_rad or 0.0)
    cell = depth.cell_px * below_m / camera.fx * sin
    return r - ring - cell


_AZIMUTH_BINS = 720  # half a degree: finer than a 0.2 m cell seen 50 m out


class _PlaneRays:
    """Per cell centre ray, on a level plane one metre below the camera: its range there (inf where
    it never meets the plane) and, when first asked for, its azimuth about the camera's nadir as a
    bin of ``_AZIMUTH_BINS``."""

    def __init__(
        self, depth: DepthMap, camera: PinholeCamera, quat_wxyz: tuple[float, float, float, float]
    ) -> None:
        rows, cols = depth.shape
        s = depth.cell_px
        x = ((np.arange(cols, dtype=np.float32) + 0.5) * s - camera.cx) / camera.fx
        y = ((np.arange(rows, dtype=np.float32) + 0.5) * s - camera.cy) / camera.fy
        m = (quat_to_matrix(quat_wxyz) @ CAMERA_TO_BODY).astype(np.float32)  # camera -> level NED
        n, e, d = (m[i, 0] * x[None, :] + m[i, 1] * y[:, None] + m[i, 2] for i in range(3))
        with np.errstate(divide="ignore", invalid="ignore"):
            self.range_per_m: np.ndarray = np.where(d > 1e-6, np.sqrt(n * n + e * e + d * d) / d, np.inf)
        self._ne = (n, e)
        self._azimuth_bin: np.ndarray | None = None

    @property
    def azimuth_bin(self) -> np.ndarray:
        if self._azimuth_bin is None:
            turn = (np.arctan2(self._ne[1], self._ne[0]) + math.pi) * (_AZIMUTH_BINS / (2 * math.pi))
            self._azimuth_bin = np.minimum(turn.astype(np.int32), _AZIMUTH_BINS - 1)
        return self._azimuth_bin

    def seen_to_the_range(self, seed: np.ndarray, below_m: float, reach_m: float) -> np.ndarray:
        """Which azimuth bins hold a cell of ``seed`` at least ``reach_m`` from the sensor on the
        level plane ``below_m`` under it (and the bins either side: the cells' own width).

        A vertical plane through the sensor holds one azimuth of every ring: along it, a level
        surface that goes on past the range was measured up to the range, and one that ended
        short of it left unknown cells the sensor would have answered from. So a surface continues
        only straight out from where it was seen at the range, never sideways round a corner."""
        far = seed & (self.range_per_m * below_m >= reach_m)
        bins = np.zeros(_AZIMUTH_BINS, bool)
        bins[self.azimuth_bin[far]] = True
        out: np.ndarray = bins | np.roll(bins, 1) | np.roll(bins, -1)
        return out


def surface_id(
    depth: DepthMap,
    camera: PinholeCamera,
    *,
    quat_wxyz: tuple[float, float, float, float] = LEVEL,
    pos_ned_m: tuple[float, float, float] | None = None,
    ground_up_m: float | None = None,
    params: SurfaceParams | None = None,
    image: np.ndarray | None = None,
) -> list[Candidate]:
    """Candidates best-first (at most ``params.max_candidates``), or the quadrant fallback.

    Args:
        depth: from any depth source, on ``camera``'s grid.
        quat_wxyz: vehicle attitude (body FRD -> NED), for the level frame; level when unknown.
        pos_ned_m: vehicle position, to give each candidate its site in NED.
        ground_up_m: ground level relative to the camera (metres, negative below it; in flight
            ``pos_ned_m[2]`` when home is at ground level), a floor for ``height_above_m``.
        image: the camera image (RGB, camera-sized), to extend metric surfaces over unmeasured cells
            (:mod:`companion.perception.image_extend`); ignored when ``params.extend_with_image`` is off.
    """
    p = params or SurfaceParams()
    if depth.shape != grid_shape(camera, depth.cell_px):
        raise DepthError(f"depth map {depth.shape} does not match the camera at {depth.cell_px} px per cell")
    fl = flatness(
        depth,
        camera,
        quat_wxyz,
        window=p.window_cells,
        max_slope_deg=p.max_slope_deg,
        max_roughness_m=p.max_roughness_m,
        max_relative_gradient=p.max_relative_gradient,
    )
    mask = cv2.morphologyEx(fl.flat.astype(np.uint8), cv2.MORPH_CLOSE, _K3)
    # The closing fills pinholes; on the grid's rim, where no flatness window fits, it would grow
    # cells that were never fitted (erosion counts outside the grid as set): only fitted cells there.
    hw = fl.half_window
    rim = np.ones(mask.shape, bool)
    rim[hw : mask.shape[0] - hw, hw : mask.shape[1] - hw] = False
    mask[rim & ~fl.flat] = 0
    mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, _K3)
    count, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=4)
    rows, cols = depth.shape
    pad = fl.half_window + 5
    found: list[tuple[Candidate, float]] = []
    cells: ImageCells | None = None
    use_image = depth.metric and image is not None and p.extend_with_image and not depth.valid.all()
    plane = _PlaneRays(depth, camera, quat_wxyz) if use_image else None

    def unseen_beyond(seed: np.ndarray, below_m: float, reach_m: float) -> Callable[[np.ndarray], np.ndarray]:
        """Which of some cells the seed's level plane, ``below_m`` under the camera, reaches beyond
        the sensor's range (``reach_m``), straight out from a part of the seed measured there."""
        assert plane is not None
        bins = plane.seen_to_the_range(seed, below_m, reach_m)

        def keep(cand: np.ndarray) -> np.ndarray:
            out: np.ndarray = cand & (plane.range_per_m * below_m >= reach_m) & bins[plane.azimuth_bin]
            return out

        return keep

    k_grow = np.ones((2 * fl.half_window + 1, 2 * fl.half_window + 1), np.uint8)
    for c in range(1, count):
        x, y, w, h = (int(v) for v in stats[c, :4])
        r0, c0 = max(y - pad, 0), max(x - pad, 0)
        r1, c1 = min(y + h + pad, rows), min(x + w + pad, cols)
        comp = labels[r0:r1, c0:c1] == c
        extra = None
        if plane is not None:  # use_image
            # The measured cells around the flat part at its level (the flatness window stops short
            # of where the measurement ends), but not its parapet or kerb: a wall stays a wall.
            down = fl.ned_m[r0:r1, c0:c1, 2]
            below_m = float(np.median(down[comp]))
            with np.errstate(invalid="ignore"):
                level = np.abs(down - below_m) <= _SEED_LEVEL_M
            grown = cv2.dilate(comp.astype(np.uint8), k_grow).astype(bool) & depth.valid[r0:r1, c0:c1] & level
            edge_of_known = cv2.dilate(grown.astype(np.uint8), _K3).astype(bool) & ~depth.valid[r0:r1, c0:c1]
            # Growth starts next to the measured surface, beyond the range or not at all.
            reach_m = None if depth.max_range_m is None else _range_reached(depth, camera, below_m)
            if reach_m is not None:
                edge_of_known &= plane.range_per_m[r0:r1, c0:c1] * below_m >= reach_m
            elif depth.max_range_m is not None:
                edge_of_known[:] = False  # the plane lies beyond the range everywhere: nothing seen
            if edge_of_known.any():
                if cells is None:
                    assert image is not None
                    cells = ImageCells.from_image(np.asarray(image), rows, cols, depth.cell_px)
                full = np.zeros(depth.shape, bool)
                full[r0:r1, c0:c1] = grown
                flat = np.zeros(depth.shape, bool)
                flat[r0:r1, c0:c1] = comp
                allowed = None if reach_m is None else unseen_beyond(full, below_m, reach_m)
                ext = extend_unmeasured(full, depth.valid, cells, allowed=allowed, sample=flat)
                if ext.any():
                    er, ec = np.nonzero(ext)
                    r0, c0 = min(r0, int(er.min()) - pad), min(c0, int(ec.min()) - pad)
                    r1, c1 = max(r1, int(er.max()) + 1 + pad), max(c1, int(ec.max()) + 1 + pad)
                    r0, c0, r1, c1 = max(r0, 0), max(c0, 0), min(r1, rows), min(c1, cols)
                    comp = labels[r0:r1, c0:c1] == c
                    extra = ext[r0:r1, c0:c1]
        cand = _component(comp, (r0, c0), fl, depth, camera, p, pos_ned_m, ground_up_m, extra, quat_wxyz)
        if cand is not None:
            found.append(cand)
    found.sort(key=lambda cl: -cl[0].score)
    same = p.same_surface_m if depth.metric else p.same_surface_rel
    kept = [
        cd
        for i, (cd, level) in enumerate(found)
        if not any(
            _contained(cd.box_px, other.box_px)
            and abs(level - other_level) <= same
            and (cd.box_px != other.box_px or j < i)
            for j, (other, other_level) in enumerate(found)
            if j != i
        )
    ]
    if not kept:
        return quadrant_fallback(camera)
    return [dataclasses.replace(cd, index=k) for k, cd in enumerate(kept[: p.max_candidates])]


def propose(
    source: DepthSource,
    camera: PinholeCamera,
    *,
    image: np.ndarray | None = None,
    lidar_frd: np.ndarray | None = None,
    quat_wxyz: tuple[float, float, float, float] = LEVEL,
    pos_ned_m: tuple[float, float, float] | None = None,
    ground_up_m: float | None = None,
    params: SurfaceParams | None = None,
) -> tuple[list[Candidate], DepthMap]:
    """Depth from ``source`` then :func:`surface_id`; DepthError when the source has nothing to give."""
    depth = source.depth_map(camera, image=image, lidar_frd=lidar_frd)
    cands = surface_id(
        depth,
        camera,
        quat_wxyz=quat_wxyz,
        pos_ned_m=pos_ned_m,
        ground_up_m=ground_up_m,
        params=params,
        image=image,
    )
    return cands, depth
