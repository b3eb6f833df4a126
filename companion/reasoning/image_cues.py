"""What one RGB image shows, measured without learned weights: the onboard tier's eyes.

:func:`analyse` takes an RGB uint8 crop of any size and returns :class:`ImageCues`: the shares of it that
look like water, vegetation, asphalt or shadow, the compact objects standing out from the surface (and
whether they stand up: cast a shadow), the straight painted lines, the grain and edges, and from them a
``hazard`` (0 = nothing seen, larger = worse) with short phrases naming what was seen. With
``site=True`` it judges only the surface under the middle of a close-up (the landing site; see 7).

Method (numpy + OpenCV, deterministic):

1. **Working size.** The crop is shrunk (area averaging) to about ``work_area_px`` pixels, never
   enlarged, so a 40 x 30 px roof far away and a 960 x 540 px close-up cost about the same and their
   shares compare. A 3 x 3 median then removes what is finer than the working scale (gravel grain,
   sensor noise, rain streaks) for everything but the painted lines (6).
2. **The surface.** Each pixel's *background* is the colour of the surface it lies on, as if no object
   stood there: block medians (blocks of 1/10 of the smaller side), a 5 x 5 median over blocks (a
   window half the image wide), scaled back up. The *contrast unit* ``c`` is the robust spread
   (1.4826 x MAD) of the luminance about that background, floored at ``min_contrast``. Object and
   shadow thresholds are multiples of ``c``: a surface with a coarse but uniform texture (gravel,
   tiles, shingles) raises its own bar, and fog, which scales every contrast down, lowers it.
3. **Shadows.** A cast shadow is darker than its surface but keeps its chromaticity (only the direct
   sun is missing): pixels ``shadow_k`` c below their background within ``chroma_tol`` of its
   chromaticity, or (a shadow as wide as the background window, a building's) under
   ``wide_shadow_ratio`` of the image's lit surface with its chromaticity. Never a hazard by
   themselves, and the rims of large ones are no edges. Pixels under ``dark_object_ratio`` of their
   background are darker than any sunlit-to-shaded ratio under an open sky: dark objects.
4. **Objects.** Pixels ``object_k`` c brighter than their surface, of a clearly different
   chromaticity (paint, cars, people), or dark objects; grouped 8-connected, at least ``min_blob_px``,
   at most ``max_blob_share`` of the image (bigger: another surface); a bright one must also stand
   ``ring_k`` c above the lit pixels around it (the lit edge of a surface beside a wide shadow, bright
   only against a background that shadow darkened, does not). A component is *raised* when at
   least ``shadow_touch`` of its outline lies next to darker-than-surface pixels: its cast shadow, or
   its side seen obliquely. Raised blobs are HVAC units, vents, cars and people; flat ones are paint,
   stains, skylights. Thin straight components are left to the line finder; strips too wide for it
   (over ``blob_max_elongation`` times as long as wide) are lines too when they stand out all round
   (paint seen close up, a pipe), else the fringe of a surface beside a wide shadow. A compact shadow
   (under ``orphan_ratio`` of its surface, not a strip along the image's border) with no object beside
   it counts as a raised object too: its caster's top looks like the surface (a grey box on a pale
   roof, a person in grey).
5. **Surfaces by colour.** Water: blue over red by ``water_blue`` and not under green, in regions of at
   least ``region_min_share`` of the image that cast no shadow (a raised blue region is a solar panel
   row: a raised object). Vegetation: green over red and blue by ``green_margin``. Asphalt: dark,
   neutral, lit; a tar roof looks the same, so it weighs little, unless it also has asphalt's even fine
   grain (``road_grain``, 8): road texture.
6. **Lines**, on the working image before the median (which would erase a one-pixel lane marking):
   white top-hat (5 x 5), components long, thin and straight by their second moments. Paint is near
   white: a line's core must lie ``line_whiteness`` of the way from its surface to white, which
   semi-transparent rain streaks and chance rows of bright gravel grains do not reach. A line casting a
   shadow is a pipe or a rail (raised); one casting none is paint: lane markings, a road.
7. **Site mode** (a close-up for confirmation): only the middle of the image is looked at
   (``site_window_frame`` of each side of a camera frame, ``site_window_crop`` of a square close-up cut
   around the site, as the recovery loop sends; or what the caller asks), and within it the surface under
   the centre: the connected region of the centre's colour (within ``site_tol_k`` c or ``site_tol_min``,
   and ``site_chroma``) that no object or darker pixel crosses (a parapet and its shadow fence a roof in),
   plus its holes: the small parts of its complement, the objects standing on it (one the window's border
   cuts included). Objects and raised lines count when at least half of them lies on that region, paint
   lines when they touch it (a lane's markings bound it), and shares are of it; water counts within
   ``water_ring`` of the window's side around it (a pier is a site with water beside it). Streets beyond a
   roof's edge do not veto the roof: the LiDAR check judges the edge. The window has no metric scale (the
   request carries no range), so high up it takes in more than the rotor disc; the region keeps that
   honest.
8. **Grain and edges.** ``grain``: the fine texture's relative amplitude (robust spread of the working
   image less its 1-pixel Gaussian, over the surface's luminance); it is *uniform* when it varies
   little over a 4 x 4 grid of blocks. Edges at the working scale (Sobel of the smoothed luminance over
   ``edge_k`` c) spread evenly are texture too; gathered in places they count as clutter.

``hazard`` is a weighted sum (:class:`~companion.reasoning.cue_params.HazardWeights`), each term capped
at its weight, so that water or a road's markings alone outweigh the bonus an onboard ranker gives a
surface for standing above the street.

The thresholds named above are the fields of :class:`~companion.reasoning.cue_params.CueParams`
(``analyse(..., params=)``; the defaults were set on simbridge renders: clear, fog, rain). This module is
the pipeline, the order of the steps and the masks they pass on; the steps' parts live beside it: the
surface (2, 3, 5, 7, 8) in :mod:`companion.reasoning.cue_surface`, the objects and lines (4, 6) in
:mod:`companion.reasoning.cue_objects`, the result with its hazard and words in
:mod:`companion.reasoning.cue_verdict`.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from companion.reasoning.cue_objects import find_blobs, find_lines
from companion.reasoning.cue_params import CueParams, HazardWeights
from companion.reasoning.cue_surface import (
    K3,
    background,
    chroma_distance,
    drop_lines,
    edges,
    grain,
    large,
    near,
    region_share,
    site_region,
    water_regions,
    wide_shadow,
)
from companion.reasoning.cue_verdict import ImageCues, scored

__all__ = ["CueParams", "HazardWeights", "ImageCues", "analyse", "centre", "check_rgb"]

_DEFAULTS = CueParams()


def analyse(
    rgb: np.ndarray, *, site: bool = False, window: float | None = None, params: CueParams | None = None
) -> ImageCues:
    """Measure the cues of one RGB uint8 image of shape (height, width, 3), any size.

    Args:
        rgb: the crop (or, with ``site``, the close-up whose centre is the landing site).
        site: judge only the surface under the middle of the image (module docstring, 7).
        window: with ``site``, the share of each side looked at (0 < window <= 1); by default
            ``site_window_crop`` for a square-ish close-up, ``site_window_frame`` for a camera frame.
        params: the thresholds (default: ``CueParams()``).

    Raises:
        ValueError: not a non-empty (H, W, 3) uint8 numpy array, or a window outside (0, 1].
    """
    p = _DEFAULTS if params is None else params
    rgb = check_rgb(rgb)
    if window is not None and not 0.0 < window <= 1.0:
        raise ValueError(f"the site window is a share of each side in (0, 1], got {window}")
    if site:
        if window is None:
            wide = rgb.shape[1] >= p.square_aspect * rgb.shape[0]
            window = p.site_window_frame if wide else p.site_window_crop
        small = _working(centre(rgb, window), p.work_area_px)
    else:
        small = _working(rgb, p.work_area_px)
    h, w = small.shape[:2]
    img8 = cv2.medianBlur(small, 3) if min(h, w) >= 3 else small
    r, g, b = (plane.astype(np.float32) * np.float32(1.0 / 255.0) for plane in cv2.split(img8))
    lum = (r + g + b) * np.float32(1.0 / 3.0)
    bg = background(img8)
    br, bgg, bb = bg
    lbg = (br + bgg + bb) * np.float32(1.0 / 3.0)
    d = lum - lbg
    c = max(p.min_contrast, 1.4826 * float(np.median(np.abs(d[::2, ::2]))))  # every 4th pixel: enough
    cdist = chroma_distance((r, g, b), bg)
    sat = np.maximum(np.maximum(r, g), b) - np.minimum(np.minimum(r, g), b)

    dark_object = lum < p.dark_object_ratio * lbg
    darker = (d < -p.shadow_k * c) & ~dark_object
    shadow = darker & (cdist < p.chroma_tol)
    # A shadow as wide as the background window (a building's, across a roof) is the background
    # there: it is found against the image's lit surface instead, by the same rule.
    shadow |= wide_shadow((r, g, b), lum, lbg, dark_object, p)
    # Evidence of height next to an object: its cast shadow, or a side seen obliquely (darker than the
    # surface, of any chromaticity).
    near_dark = cv2.dilate(darker.view(np.uint8), K3).view(bool)
    # Blobs need a shadow patch beside them, not a thin dark line: a roof's joints and seams cross
    # rain streaks and gravel specks; a pipe's thin shadow still marks the pipe (lines use near_dark).
    near_patch = cv2.dilate(drop_lines(darker, p).view(np.uint8), K3).view(bool)
    coloured = (cdist > p.object_chroma) & (sat > p.object_min_sat)
    green = (g - r > p.green_margin) & (g - b > p.green_margin)
    water, panels = water_regions((b - r > p.water_blue) & (b >= g), near_patch, p)
    asphalt = (lum < p.asphalt_max_l) & (sat < p.asphalt_max_sat * (lum + 0.05)) & ~darker & ~dark_object

    objects = ((d > p.object_k * c) | coloured | dark_object) & ~green & ~water
    # Paint lines are no barrier: a lane's markings belong to the road the site would be on.
    focus = site_region(img8, bg, lum, c, drop_lines(objects, p) | darker, p) if site else None
    n = float(h * w) if focus is None else max(float(np.count_nonzero(focus)), 1.0)
    shade = darker & (lum < p.orphan_ratio * lbg)
    whiteness = d / np.maximum(1.0 - lbg, 0.05)  # how far toward white from the surface
    shade &= ~near(green)  # a tree's shadow has its tree beside it
    blobs = find_blobs(
        objects,
        near_patch,
        near_dark,
        coloured,
        dark_object,
        panels,
        shade,
        whiteness,
        lum,
        darker | shadow,
        c,
        focus,
        n,
        p,
    )
    raw = sum((plane.astype(np.float32) for plane in cv2.split(small)), np.zeros((h, w), np.float32))
    raw *= np.float32(1.0 / (3 * 255))  # luminance before the median: thin lines and the grain
    lines = find_lines(raw, lbg, near_dark, focus, p).plus(blobs.wide)
    edge_density, edge_cv = edges(lum, c, focus, near(large(shadow, p.max_blob_share)), p)
    grain_amplitude, uniform = grain(raw, lbg, p)
    if focus is None:
        water_share = float(np.count_nonzero(water)) / n
        shares = [float(np.count_nonzero(m)) / n for m in (shadow, asphalt)]
        vegetation_share = region_share(green, n, None, p)
    else:
        ring = max(1, round(p.water_ring * max(h, w)))
        around = cv2.dilate(focus.view(np.uint8), K3, iterations=ring).view(bool)
        water_share = min(1.0, float(np.count_nonzero(water & around)) / n)
        shares = [float(np.count_nonzero(m & focus)) / n for m in (shadow, asphalt)]
        vegetation_share = region_share(green, n, focus, p)
    measured = ImageCues(
        size_px=(int(rgb.shape[0]), int(rgb.shape[1])),
        work_px=(h, w),
        site_share=n / float(h * w),
        brightness=float(np.median(lum[::2, ::2])),
        contrast=c,
        grain=grain_amplitude,
        uniform_grain=uniform,
        edge_density=edge_density,
        edge_spread_cv=edge_cv,
        shadow_share=shares[0],
        water_share=water_share,
        vegetation_share=vegetation_share,
        asphalt_share=shares[1],
        raised_blobs=blobs.raised_blobs,
        raised_share=blobs.raised_share,
        coloured_blobs=blobs.coloured_blobs,
        shadow_blobs=blobs.shadow_blobs,
        flat_blobs=blobs.flat_blobs,
        flat_share=blobs.flat_share,
        dark_blobs=blobs.dark_blobs,
        lane_lines=lines.lane_lines,
        line_length=lines.line_length,
        raised_lines=lines.raised_lines,
        raised_line_length=lines.raised_line_length,
        other_surface_share=blobs.other_surface_share,
        hazard=0.0,
        terms=(),
        params=p,
    )
    return scored(measured)


def check_rgb(rgb: object) -> np.ndarray:
    """``rgb`` as a contiguous (H, W, 3) uint8 array; ValueError saying what it is instead."""
    if not isinstance(rgb, np.ndarray):
        raise ValueError(f"expected an RGB image as a numpy array, got {type(rgb).__name__}")
    if rgb.ndim != 3 or rgb.shape[2] != 3:
        raise ValueError(f"expected an RGB image of shape (height, width, 3), got shape {rgb.shape}")
    if rgb.dtype != np.uint8:
        raise ValueError(f"expected an RGB image of dtype uint8, got {rgb.dtype}")
    if rgb.shape[0] == 0 or rgb.shape[1] == 0:
        raise ValueError(f"expected a non-empty RGB image, got shape {rgb.shape}")
    return np.ascontiguousarray(rgb)


def centre(rgb: np.ndarray, frac: float) -> np.ndarray:
    """The middle ``frac`` of each side of an image (at least one pixel), contiguous."""
    h, w = rgb.shape[:2]
    ch, cw = max(1, round(h * frac)), max(1, round(w * frac))
    y0, x0 = (h - ch) // 2, (w - cw) // 2
    return np.ascontiguousarray(rgb[y0 : y0 + ch, x0 : x0 + cw])


def _working(rgb: np.ndarray, area_px: int) -> np.ndarray:
    """``rgb`` shrunk by area averaging to about ``area_px`` pixels; as it is when not larger."""
    h, w = rgb.shape[:2]
    s = math.sqrt(area_px / (h * w))
    if s >= 1.0:
        return rgb
    size = (max(1, round(w * s)), max(1, round(h * s)))
    return np.asarray(cv2.resize(rgb, size, interpolation=cv2.INTER_AREA))
