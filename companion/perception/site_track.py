"""Keeping the chosen site in view: where the surface the reasoner chose lies in a newer camera frame.

The site is the world point the chosen pixel showed (inverse perspective mapping through the LiDAR).
That point was placed with the pose estimate of the frame it was chosen in: a heading error of one
degree moves a site 40 m away by 0.7 m, and an estimate that drifts moves it with it. The surface
itself stays in the camera's view on the way down, so each newer frame finds it again.

Both frames are resampled onto the same grid on the site's surface (a horizontal plane at the site's
height: Surface ID proposed it flat): ``ortho`` cells ``cell_m`` wide, rows north, columns east. On
that grid the two views differ by a shift only (scale and perspective are gone), which normalised
cross-correlation finds. The reference patch's centre is the site; where that patch sits in the newer
frame's grid is where the site is in the newer frame's estimate. A patch with too little texture, a
weak or ambiguous peak, or a site outside either view gives no answer (``TrackResult.found`` False,
``reason`` says which): the caller keeps its last target then.

Where the usual search finds nothing, a wide search (:func:`_reacquire`) looks for the newer view
about its centre, on the surface the LiDAR finds there, in the reference up to ``reacquire_m`` from
where the two estimates put it: the offset between the two estimates, whatever caused it (a GPS that
jumped). The usual search then looks for the site itself there; without it, nothing is found (a
city repeats its roofs, and a whole view can match another block as well).

Frames: NED world, FRD body, the camera of :mod:`companion.guidance.frames`. Images: (H, W, 3) uint8
RGB or (H, W) grey.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from companion.guidance.frames import PinholeCamera, quat_to_matrix

__all__ = ["SiteView", "TrackParams", "TrackResult", "centre_down", "track_site"]

NO_MATCH = "no good match"
AT_EDGE = "the best match is at the search's edge"
OUT_OF_VIEW = "the site is out of the camera's view"
NOT_IN_REFERENCE = "the site is not in the reference frame"
TOO_COARSE = "the reference is too coarse for a view this close"
REACQUIRE_PATCH_OF_VIEW = 0.7  # the wide search's patch, at most this much of the newer view's narrower half


@dataclass(frozen=True, slots=True)
class TrackParams:
    """How far around the site the tracker looks, and what counts as found.

    Attributes:
        patch_half_m: half the width of the reference patch on the surface (its texture: roof edges,
            fittings, markings), at least; ``patch_per_m`` of the reference frame's distance to the
            site when that is more (from far away fine texture blurs: a roof's outline is what shows).
        search_m: how far from the predicted position the site may have moved (the estimate's
            error), and ``search_per_m`` of each frame's distance to it more (an attitude estimate
            two degrees off: a frame taken while the vehicle rocks in a gust or brakes).
        max_cells: the patch's half width in grid cells at most (the cell grows beyond it).
        min_cell_m: the finest grid cell (a few centimetres: gravel grains, pixel noise and the
            sampling of texture that fine differ from frame to frame).
        min_texture: the reference patch's least grey-level standard deviation (0-255 scale).
        min_score: the least normalised cross-correlation at the peak.
        min_margin: how much higher the peak must be than the best match ``ambiguity_m`` from it
            (or at the search's edge when that is nearer): a uniform roof along an edge, or a road,
            matches everywhere along it.
        min_isotropy: and the least it falls off that far, against the most: along a road or a
            straight edge the score falls steeply across and hardly at all along (a large patch's
            peak is broad every way: its fall-off is small but alike all round).
        min_unique: how much higher the peak must be than the best match farther than
            ``ambiguity_m`` from it anywhere in the search (texture that repeats: gravel's blotches,
            tiles, a row of vents).
        ambiguity_m: see ``min_margin``.
        min_patch_half_m: a view that holds less than this much around the site is too close to track.
        min_patch_cells: nor one whose patch is fewer cells than this from its centre to its edge: a
            reference from far away has coarse cells, and a close view holds few of them (the frame a
            site was chosen in, 88 m above a gravel roof, looked for from 3.5 m: a patch of four 0.18 m
            cells from its centre to its edge, which matched half a metre off).
        blur_cells: both grids are smoothed this much (Gaussian sigma, cells) before matching: pixel
            noise and texture finer than a cell differ between views; what is coarser does not.
        flatten_m: and lose what varies more slowly than this (Gaussian sigma, metres on the
            surface; 0 keeps it): vignetting and light falling off across a frame differ between
            views.
        reacquire_m: how far from the prediction the wide search looks (0: no wide search), when
            the usual search finds nothing there (a GPS that jumps moves the whole estimate); its
            answer counts only where the usual search then finds the site itself.
        reacquire_cells: that wide search runs on a coarser grid, this many cells from its centre
            to its edge at most, then the usual search refines it.
        reacquire_patch_m: its patch's half width (the newer view around its centre: a roof's
            outline, not only its texture; a wide search has more places to mistake for the site),
            or ``patch_per_m`` of the reference's distance when that is more, but at most
            ``REACQUIRE_PATCH_OF_VIEW`` of the newer view's narrower half.
        reacquire_min_patch_m: no wide search when that leaves less than this (close to the surface).
        reacquire_min_score: the least score of the wide search's peak.
        reacquire_min_unique: its lead over the best match farther than its patch's half width.
            The wide search's answer is refined, and checked, by the usual search around it.
    """

    patch_half_m: float = 4.0
    patch_per_m: float = 0.08
    search_m: float = 1.5
    search_per_m: float = 0.035
    max_cells: int = 60
    min_cell_m: float = 0.06
    min_texture: float = 2.0
    min_score: float = 0.5
    min_margin: float = 0.02
    min_isotropy: float = 0.25
    min_unique: float = 0.05
    ambiguity_m: float = 1.5
    min_patch_half_m: float = 0.6
    min_patch_cells: int = 8
    blur_cells: float = 1.5
    flatten_m: float = 5.0
    reacquire_m: float = 30.0
    reacquire_cells: int = 150
    reacquire_patch_m: float = 6.0
    reacquire_min_patch_m: float = 3.0
    reacquire_min_score: float = 0.6
    reacquire_min_unique: float = 0.1


@dataclass(frozen=True, slots=True)
class SiteView:
    """A frame the site is looked for in (or was found in).

    Attributes:
        image: (H, W, 3) uint8 RGB or (H, W) grey.
        camera: its pinhole model.
        pos_ned_m: the vehicle's estimated position when it was taken.
        quat_wxyz: its estimated attitude then (body FRD -> NED).
        centre_down_m: the surface's height (NED down) about the view's centre, from the LiDAR
            (NaN when unknown: the site's surface is taken there).
    """

    image: np.ndarray
    camera: PinholeCamera
    pos_ned_m: tuple[float, float, float]
    quat_wxyz: tuple[float, float, float, float]
    centre_down_m: float = math.nan


@dataclass(frozen=True, slots=True)
class TrackResult:
    """Where the site is in the newer frame's estimate.

    Attributes:
        found: whether the site was found.
        site_ned_m: the site in the newer frame's estimate (the old one when not found).
        shift_m: (north, east) metres the site moved against where the estimate put it.
        score: normalised cross-correlation at the peak (NaN when no match was tried).
        margin: the peak's lead over the best match ``ambiguity_m`` from it (NaN likewise).
        cell_m: the grid's cell.
        reason: why it was not found ("" when found).
        reacquired: found by the wide search (:attr:`TrackParams.reacquire_m`), not where the
            estimate predicted it.
    """

    found: bool
    site_ned_m: tuple[float, float, float]
    shift_m: tuple[float, float]
    score: float
    margin: float
    cell_m: float
    reason: str = ""
    reacquired: bool = False


_THIN = np.ones((3, 3), np.uint8)
THIN_LINE_M = 0.04  # seams, joints and cracks: about this wide


def _grey(image: np.ndarray, close_thin: bool) -> np.ndarray:
    """Grey levels; with ``close_thin`` without thin dark lines (a grey-level closing over 3 x 3
    pixels): a seam, a joint or a crack narrower than a pixel comes and goes between views (where it
    falls on the sensor's grid), the surfaces between do not. Both frames of a match are read alike,
    by the coarser one's pixel."""
    grey = np.ascontiguousarray(image)
    if grey.ndim == 3:
        grey = cv2.cvtColor(grey, cv2.COLOR_RGB2GRAY)
    if grey.dtype != np.uint8:
        grey = np.clip(grey, 0, 255).astype(np.uint8)
    if close_thin:
        grey = cv2.morphologyEx(grey, cv2.MORPH_CLOSE, _THIN)
    return grey.astype(np.float32)


def _range_to(view: SiteView, point_ned: np.ndarray) -> tuple[float, tuple[float, float] | None]:
    """Camera depth of ``point_ned`` and its pixel (None when behind the camera)."""
    rot = quat_to_matrix(view.quat_wxyz)
    frd = rot.T @ (point_ned - np.asarray(view.pos_ned_m, dtype=np.float64))
    uv, in_front = view.camera.project_frd(frd[None, :])
    if not in_front[0]:
        return math.nan, None
    return float(frd[2]), (float(uv[0, 0]), float(uv[0, 1]))


def _ortho(
    grey: np.ndarray, view: SiteView, centre_ned: np.ndarray, half_cells: int, cell_m: float
) -> tuple[np.ndarray, np.ndarray]:
    """``grey`` resampled on a (2 * half_cells + 1)^2 grid of the plane through ``centre_ned``
    (rows north, columns east); and the mask of cells the camera saw."""
    offsets = np.arange(-half_cells, half_cells + 1, dtype=np.float64) * cell_m
    north = centre_ned[0] + offsets[:, None] * np.ones((1, offsets.size))
    east = centre_ned[1] + np.ones((offsets.size, 1)) * offsets[None, :]
    pts = np.stack([north.ravel(), east.ravel(), np.full(north.size, centre_ned[2])], axis=1)
    rot = quat_to_matrix(view.quat_wxyz)
    frd = (pts - np.asarray(view.pos_ned_m, dtype=np.float64)) @ rot
    uv, in_front = view.camera.project_frd(frd)
    # continuous pixel coordinates -> cv2's sample positions (pixel centres at integers)
    map_x = (uv[:, 0] - 0.5).reshape(north.shape).astype(np.float32)
    map_y = (uv[:, 1] - 0.5).reshape(north.shape).astype(np.float32)
    seen = (
        in_front.reshape(north.shape)
        & (map_x >= 0)
        & (map_x <= grey.shape[1] - 1)
        & (map_y >= 0)
        & (map_y <= grey.shape[0] - 1)
    )
    map_x[~seen] = -1.0
    map_y[~seen] = -1.0
    out = cv2.remap(grey, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    return out, seen


def _smoothed(grey: np.ndarray, gsd_m: float, cell_m: float) -> np.ndarray:
    """Blur an image whose pixels are finer than the grid's cells, so that resampling does not alias."""
    ratio = cell_m / max(gsd_m, 1e-6)
    if ratio <= 1.5:
        return grey
    sigma = 0.5 * ratio
    return cv2.GaussianBlur(grey, (0, 0), sigmaX=sigma, sigmaY=sigma)


def _band(grid: np.ndarray, p: TrackParams, cell_m: float) -> np.ndarray:
    """What both views share: texture between ``blur_cells`` and ``flatten_m`` (lighting that
    changes across the frame, the lens's vignetting and exposure are broader; pixel noise finer)."""
    out = grid
    if p.blur_cells > 0:
        out = cv2.GaussianBlur(out, (0, 0), sigmaX=p.blur_cells, sigmaY=p.blur_cells)
    if p.flatten_m > 0:
        broad = p.flatten_m / cell_m
        out = out - cv2.GaussianBlur(grid, (0, 0), sigmaX=broad, sigmaY=broad)
    return out


def _subcell(scores: np.ndarray, row: int, col: int) -> tuple[float, float]:
    """Parabolic refinement of an integer peak (rows, columns)."""

    def vertex(a: float, b: float, c: float) -> float:
        denom = a - 2 * b + c
        return 0.0 if denom >= 0 or not math.isfinite(denom) else 0.5 * (a - c) / denom

    dr = dc = 0.0
    if 0 < row < scores.shape[0] - 1:
        dr = vertex(float(scores[row - 1, col]), float(scores[row, col]), float(scores[row + 1, col]))
    if 0 < col < scores.shape[1] - 1:
        dc = vertex(float(scores[row, col - 1]), float(scores[row, col]), float(scores[row, col + 1]))
    return max(-0.5, min(0.5, dr)), max(-0.5, min(0.5, dc))


def track_site(
    reference: SiteView,
    site_ned_m: Sequence[float],
    current: SiteView,
    params: TrackParams | None = None,
    predicted_ne_m: Sequence[float] | None = None,
) -> TrackResult:
    """Find the site that ``reference`` showed at ``site_ned_m`` in ``current``: where the estimate
    predicts it, else around where a wide search puts it.

    Args:
        reference: the frame the site was chosen (or last found) in.
        site_ned_m: the site in ``reference``'s estimate: (north, east, down) metres; down is the
            surface's height, where both views are resampled.
        current: the newer frame.
        params: thresholds (:class:`TrackParams` defaults).
        predicted_ne_m: where the site is expected in ``current``'s estimate (north, east metres),
            when the estimate is known to move between the two frames (a GPS drifting steadily);
            ``site_ned_m`` itself when None. The usual search is centred there.

    Returns:
        A :class:`TrackResult`; ``site_ned_m`` there keeps ``site_ned_m``'s down coordinate.
    """
    p = params or TrackParams()
    site = np.asarray(site_ned_m, dtype=np.float64)
    if site.shape != (3,) or not np.isfinite(site).all():
        raise ValueError(f"site_ned_m must be three finite numbers, got {site_ned_m!r}")
    centre = site
    if predicted_ne_m is not None:
        centre = np.array([float(predicted_ne_m[0]), float(predicted_ne_m[1]), site[2]])
        if not np.isfinite(centre).all():
            raise ValueError(f"predicted_ne_m must be two finite numbers, got {predicted_ne_m!r}")
    first = _track(reference, site, current, p, centre)
    if first.found or p.reacquire_m <= 0 or first.reason == NOT_IN_REFERENCE:
        return first
    wide = _reacquire(reference, site, current, p)
    if wide is None:
        return first
    centre, coarse_cell = wide
    # the usual search around the wide one's answer: the site itself must match there, or nothing
    # (a city repeats its roofs: the whole view can match another block as well, twice running)
    fine = _track(reference, site, current, p, centre, search_m=p.search_m + 2.0 * coarse_cell)
    if not fine.found:
        return first
    return dataclasses.replace(fine, reacquired=True)


def _track(
    reference: SiteView,
    site: np.ndarray,
    current: SiteView,
    p: TrackParams,
    centre: np.ndarray,
    search_m: float | None = None,
) -> TrackResult:
    """The site looked for in ``current`` within a search around ``centre`` (the prediction: the
    site itself, or where a wide search put it); ``search_m`` overrides the search's reach."""
    keep = (float(site[0]), float(site[1]), float(site[2]))

    def lost(reason: str, cell_m: float = math.nan) -> TrackResult:
        return TrackResult(False, keep, (0.0, 0.0), math.nan, math.nan, cell_m, reason)

    depth_ref, px_ref = _range_to(reference, site)
    depth_cur, px_cur = _range_to(current, centre)
    if px_ref is None or not reference.camera.in_image(np.array([px_ref]))[0]:
        return lost(NOT_IN_REFERENCE)
    if px_cur is None or not current.camera.in_image(np.array([px_cur]))[0]:
        return lost(OUT_OF_VIEW)
    gsd_ref = depth_ref / reference.camera.fx
    gsd_cur = depth_cur / current.camera.fx
    # patch and search must fit the newer view: near the ground the camera sees little around the site
    margin_px = min(px_cur[0], current.camera.width - px_cur[0], px_cur[1], current.camera.height - px_cur[1])
    seen_m = 0.95 * margin_px * gsd_cur
    if search_m is None:
        # the prediction carries both frames' attitude errors, each times its distance to the site
        search_m = p.search_m + p.search_per_m * (depth_ref + depth_cur)
    search_m = min(search_m, 0.45 * seen_m)
    patch_half_m = min(max(p.patch_half_m, p.patch_per_m * depth_ref), seen_m - search_m)
    if patch_half_m < p.min_patch_half_m:
        return lost("too close to the surface to see around the site")
    cell_m = max(gsd_ref, gsd_cur, p.min_cell_m, patch_half_m / p.max_cells)
    if patch_half_m < p.min_patch_cells * cell_m:
        return lost(TOO_COARSE, cell_m)
    patch_cells = max(3, round(patch_half_m / cell_m))
    search_cells = max(1, round(search_m / cell_m))

    thin = max(gsd_ref, gsd_cur) > THIN_LINE_M
    ref_grey = _smoothed(_grey(reference.image, thin), gsd_ref, cell_m)
    cur_grey = _smoothed(_grey(current.image, thin), gsd_cur, cell_m)
    templ, templ_seen = _ortho(ref_grey, reference, site, patch_cells, cell_m)
    area, area_seen = _ortho(cur_grey, current, centre, patch_cells + search_cells, cell_m)
    if templ_seen.mean() < 0.9:
        return lost("the reference frame saw too little around the site", cell_m)
    if area_seen.mean() < 0.8:
        return lost("the camera sees too little around the site", cell_m)
    if float(templ[templ_seen].std()) < p.min_texture:
        return lost("too little texture around the site to follow it", cell_m)

    templ, area = _band(templ, p, cell_m), _band(area, p, cell_m)
    scores = cv2.matchTemplate(area, templ, cv2.TM_CCOEFF_NORMED)
    scores = np.nan_to_num(scores, nan=-1.0)
    _lo, best, _lo_at, (col, row) = cv2.minMaxLoc(scores)
    # the score must fall off every way from the peak: along a straight edge or a road it does not
    away = max(1, min(round(p.ambiguity_m / cell_m), search_cells))
    rows, cols = np.ogrid[: scores.shape[0], : scores.shape[1]]
    ring = np.maximum(np.abs(rows - row), np.abs(cols - col)) == away
    around = scores[ring] if ring.any() else np.array([-1.0])
    margin = float(best) - float(around.max())  # the least the score falls, whichever way
    steepest = float(best) - float(around.min())  # the most it falls

    def refused(reason: str) -> TrackResult:
        return TrackResult(False, keep, (0.0, 0.0), float(best), margin, cell_m, reason)

    if best < p.min_score:
        return refused(NO_MATCH)
    elsewhere = np.maximum(np.abs(rows - row), np.abs(cols - col)) > away
    second = float(scores[elsewhere].max()) if elsewhere.any() else -1.0
    if float(best) - second < p.min_unique:
        return refused("another place matches as well")
    if margin < p.min_margin or margin < p.min_isotropy * steepest:
        return refused("the match is ambiguous")
    if row in (0, scores.shape[0] - 1) or col in (0, scores.shape[1] - 1):
        return refused(AT_EDGE)
    dr, dc = _subcell(scores, row, col)
    shift_n = float(centre[0] - site[0]) + (row + dr - search_cells) * cell_m
    shift_e = float(centre[1] - site[1]) + (col + dc - search_cells) * cell_m
    found = (keep[0] + shift_n, keep[1] + shift_e, keep[2])
    return TrackResult(True, found, (shift_n, shift_e), float(best), margin, cell_m)


def _reacquire(
    reference: SiteView, site: np.ndarray, current: SiteView, p: TrackParams
) -> tuple[np.ndarray, float] | None:
    """The wide search. What the newer frame sees around its optical axis (on the site's surface) is
    looked for in the reference frame, up to ``p.reacquire_m`` from where the estimates put it, on a
    coarse grid: the offset between the two estimates, whatever moved them (a GPS that jumps moves
    everything alike), and so where the site is in the newer one. The patch comes from the newer
    frame because the reference was taken from higher up: it sees all the newer one does, and a patch
    as wide as the newer view stands out where a small one around the site would not.

    Returns the site's position in the newer frame's estimate and the grid's cell, or None when no
    place stands out."""
    # what lies at the view's centre, on its own surface (a street beside the roof is 20 m lower:
    # resampled at the roof's height it would not line up between two views)
    plane_d = current.centre_down_m if math.isfinite(current.centre_down_m) else float(site[2])
    depth_cur = _plane_depth(current, plane_d)
    if not math.isfinite(depth_cur):
        return None
    rot = quat_to_matrix(current.quat_wxyz)
    axis = rot @ np.array([0.0, 0.0, 1.0])
    centre_cur = np.asarray(current.pos_ned_m, dtype=np.float64) + depth_cur * axis
    centre_cur[2] = plane_d
    depth_ref, px_ref = _range_to(reference, centre_cur)
    if px_ref is None or not math.isfinite(depth_ref):
        return None
    gsd_ref = depth_ref / reference.camera.fx
    gsd_cur = depth_cur / current.camera.fx
    cam = current.camera
    view_half_m = 0.5 * min(cam.width, cam.height) * gsd_cur  # the newer view's narrower half
    patch_half_m = max(p.reacquire_patch_m, p.patch_per_m * depth_ref)
    patch_half_m = min(patch_half_m, REACQUIRE_PATCH_OF_VIEW * view_half_m)
    if patch_half_m < p.reacquire_min_patch_m:
        return None  # too close: too little in view to stand out
    reach_m = p.reacquire_m + patch_half_m
    cell_m = max(gsd_ref, gsd_cur, p.min_cell_m, reach_m / p.reacquire_cells)
    patch_cells = max(3, round(patch_half_m / cell_m))
    reach_cells = max(patch_cells + 1, round(reach_m / cell_m))
    ref_grey = _smoothed(_grey(reference.image, False), gsd_ref, cell_m)
    cur_grey = _smoothed(_grey(current.image, False), gsd_cur, cell_m)
    templ, templ_seen = _ortho(cur_grey, current, centre_cur, patch_cells, cell_m)
    if templ_seen.mean() < 0.98 or float(templ.std()) < p.min_texture:
        return None
    area, area_seen = _ortho(ref_grey, reference, centre_cur, reach_cells, cell_m)
    templ, area = _band(templ, p, cell_m), _band(area, p, cell_m)
    scores = np.nan_to_num(cv2.matchTemplate(area, templ, cv2.TM_CCOEFF_NORMED), nan=-1.0)
    # only places whose whole patch the reference saw
    seen = cv2.matchTemplate(area_seen.astype(np.float32), np.ones_like(templ), cv2.TM_CCORR)
    scores[seen < 0.98 * templ.size] = -1.0
    _lo, best, _lo_at, (col, row) = cv2.minMaxLoc(scores)
    if best < p.reacquire_min_score:
        return None
    rows, cols = np.ogrid[: scores.shape[0], : scores.shape[1]]
    elsewhere = np.maximum(np.abs(rows - row), np.abs(cols - col)) > patch_cells
    second = float(scores[elsewhere].max()) if elsewhere.any() else -1.0
    if float(best) - second < p.reacquire_min_unique:
        return None
    dr, dc = _subcell(scores, row, col)
    half = reach_cells - patch_cells  # the score map's centre: the estimates agree
    # the newer view's centre lies this far from where the reference's estimate has it
    offset = np.array([(row + dr - half) * cell_m, (col + dc - half) * cell_m, 0.0])
    return site - offset, cell_m


def centre_down(lidar_frd: np.ndarray | None, view: SiteView, cone_deg: float = 6.0) -> float:
    """The median height (NED down) of the LiDAR returns (body FRD metres in the first three
    columns) within ``cone_deg`` of the camera's axis (body down), placed with ``view``'s pose; NaN
    without any."""
    if lidar_frd is None:
        return math.nan
    pts = np.asarray(lidar_frd, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] < 3 or not len(pts):
        return math.nan
    pts = pts[:, :3]  # x, y, z (a sweep may carry more per return)
    pts = pts[np.isfinite(pts).all(axis=1)]
    off_axis = np.hypot(pts[:, 0], pts[:, 1])
    near = pts[(pts[:, 2] > 0) & (off_axis < math.tan(math.radians(cone_deg)) * pts[:, 2])]
    if not len(near):
        return math.nan
    rot = quat_to_matrix(view.quat_wxyz)
    down = near @ rot[2] + view.pos_ned_m[2]  # the NED down row of the rotation
    return float(np.median(down))


def _plane_depth(view: SiteView, down_m: float) -> float:
    """The camera's depth to a horizontal plane at ``down_m`` along its optical axis (NaN when it
    does not look down at it)."""
    rot = quat_to_matrix(view.quat_wxyz)
    axis = rot @ np.array([0.0, 0.0, 1.0])  # the optical axis (camera looks along body down)
    height = down_m - view.pos_ned_m[2]
    if axis[2] <= 0.1 or height <= 0:
        return math.nan
    return float(height / axis[2])
