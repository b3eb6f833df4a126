"""What one RGB image shows, measured without learned weights: the onboard tier's eyes.

:func:`analyse` takes an RGB uint8 crop of any size and returns :class:`ImageCues`: the shares of it that
look like water, vegetation, asphalt or shadow, the compact objects standing out from the surface (and
whether they stand up: cast a shadow), the straight painted lines, the grain and edges, and from them a
``hazard`` (0 = nothing seen, larger = worse) with short phrases naming what was seen. With
``site=True`` it judges only the surface under the middle of a close-up (the landing site; see 7).

Method (numpy + OpenCV, deterministic):

1. **Working size.** The crop is shrunk (area averaging) to about ``WORK_AREA_PX`` pixels, never
   enlarged, so a 40 x 30 px roof far away and a 960 x 540 px close-up cost about the same and their
   shares compare. A 3 x 3 median then removes what is finer than the working scale (gravel grain,
   sensor noise, rain streaks) for everything but the painted lines (6).
2. **The surface.** Each pixel's *background* is the colour of the surface it lies on, as if no object
   stood there: block medians (blocks of 1/10 of the smaller side), a 5 x 5 median over blocks (a
   window half the image wide), scaled back up. The *contrast unit* ``c`` is the robust spread
   (1.4826 x MAD) of the luminance about that background, floored at ``MIN_CONTRAST``. Object and
   shadow thresholds are multiples of ``c``: a surface with a coarse but uniform texture (gravel,
   tiles, shingles) raises its own bar, and fog, which scales every contrast down, lowers it.
3. **Shadows.** A cast shadow is darker than its surface but keeps its chromaticity (only the direct
   sun is missing): pixels ``SHADOW_K`` c below their background within ``CHROMA_TOL`` of its
   chromaticity, or (a shadow as wide as the background window, a building's) under
   ``WIDE_SHADOW_RATIO`` of the image's lit surface with its chromaticity. Never a hazard by
   themselves, and the rims of large ones are no edges. Pixels under ``DARK_OBJECT_RATIO`` of their
   background are darker than any sunlit-to-shaded ratio under an open sky: dark objects.
4. **Objects.** Pixels ``OBJECT_K`` c brighter than their surface, of a clearly different
   chromaticity (paint, cars, people), or dark objects; grouped 8-connected, at least ``MIN_BLOB_PX``,
   at most ``MAX_BLOB_SHARE`` of the image (bigger: another surface); a bright one must also stand
   ``RING_K`` c above the lit pixels around it (the lit edge of a surface beside a wide shadow, bright
   only against a background that shadow darkened, does not). A component is *raised* when at
   least ``SHADOW_TOUCH`` of its outline lies next to darker-than-surface pixels: its cast shadow, or
   its side seen obliquely. Raised blobs are HVAC units, vents, cars and people; flat ones are paint,
   stains, skylights. Thin straight components are left to the line finder; strips too wide for it
   (over ``BLOB_MAX_ELONGATION`` times as long as wide) are lines too when they stand out all round
   (paint seen close up, a pipe), else the fringe of a surface beside a wide shadow. A compact shadow
   (under ``ORPHAN_RATIO`` of its surface, not a strip along the image's border) with no object beside
   it counts as a raised object too: its caster's top looks like the surface (a grey box on a pale
   roof, a person in grey).
5. **Surfaces by colour.** Water: blue over red by ``WATER_BLUE`` and not under green, in regions of at
   least ``REGION_MIN_SHARE`` of the image that cast no shadow (a raised blue region is a solar panel
   row: a raised object). Vegetation: green over red and blue by ``GREEN_MARGIN``. Asphalt: dark,
   neutral, lit; a tar roof looks the same, so it weighs little, unless it also has asphalt's even fine
   grain (``ROAD_GRAIN``, 8): road texture.
6. **Lines**, on the working image before the median (which would erase a one-pixel lane marking):
   white top-hat (5 x 5), components long, thin and straight by their second moments. Paint is near
   white: a line's core must lie ``LINE_WHITENESS`` of the way from its surface to white, which
   semi-transparent rain streaks and chance rows of bright gravel grains do not reach. A line casting a
   shadow is a pipe or a rail (raised); one casting none is paint: lane markings, a road.
7. **Site mode** (a close-up for confirmation): only the middle of the image is looked at
   (``SITE_WINDOW_FRAME`` of each side of a camera frame, ``SITE_WINDOW_CROP`` of a square close-up cut
   around the site, as the recovery loop sends; or what the caller asks), and within it the surface under
   the centre: the connected region of the centre's colour (within ``SITE_TOL_K`` c or ``SITE_TOL_MIN``,
   and ``SITE_CHROMA``) that no object or darker pixel crosses (a parapet and its shadow fence a roof in),
   plus its holes: the small parts of its complement, the objects standing on it (one the window's border
   cuts included). Objects and raised lines count when at least half of them lies on that region, paint
   lines when they touch it (a lane's markings bound it), and shares are of it; water counts within
   ``WATER_RING`` of the window's side around it (a pier is a site with water beside it). Streets beyond a
   roof's edge do not veto the roof: the LiDAR check judges the edge. The window has no metric scale (the
   request carries no range), so high up it takes in more than the rotor disc; the region keeps that
   honest.
8. **Grain and edges.** ``grain``: the fine texture's relative amplitude (robust spread of the working
   image less its 1-pixel Gaussian, over the surface's luminance); it is *uniform* when it varies
   little over a 4 x 4 grid of blocks. Edges at the working scale (Sobel of the smoothed luminance over
   ``EDGE_K`` c) spread evenly are texture too; gathered in places they count as clutter.

``hazard`` is a weighted sum (``WEIGHTS``), each term capped at its weight, so that water or a road's
markings alone outweigh the bonus an onboard ranker gives a surface for standing above the street.
Thresholds were set on simbridge renders (clear, fog, rain) and are explained where they are defined.

Kept whole (about 900 lines): one pipeline whose numbered steps above each rely on the previous
steps' masks; split, the steps would read apart from the masks they pass on.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

__all__ = ["WEIGHTS", "ImageCues", "analyse"]

WORK_AREA_PX = 128 * 128  # working size: ~16 k pixels (about 3 ms a crop on one core)
MIN_CONTRAST = 0.006  # floor on the contrast unit c: 1.5 steps of 8-bit luminance
SHADOW_K = 3.0  # shadow: this many contrast units darker than the surface ...
CHROMA_TOL = 0.035  # ... with the surface's chromaticity (r, g, b summing to 1) within this
WIDE_SHADOW_RATIO = 0.6  # a shadow wider than the background window: under this share of the lit surface
DARK_OBJECT_RATIO = 0.2  # darker than this share of the surface: an object, not a shadow (sunlit to
#                          shaded ratios under an open sky lie near 0.3 to 0.6)
OBJECT_K = 4.0  # objects: this many contrast units brighter than their surface ...
OBJECT_CHROMA = 0.06  # ... or this far from its chromaticity ...
OBJECT_MIN_SAT = 0.08  # ... where saturated enough (max - min of r, g, b) for chromaticity to mean something
RING_K = 2.0  # a bright object is this many contrast units brighter than the lit pixels around it ...
RING_MIN = 0.015  # ... and at least this (2 sensor-noise sigmas): HVAC tops stand 0.1 above gravel
MIN_BLOB_PX = 3  # smaller specks are noise at the working scale
MAX_BLOB_SHARE = 0.2  # a component larger than this share of the image is another surface
BLOB_MAX_ELONGATION = 6.0  # an object is at most this many times as long as wide (a car: 2.4, an HVAC
#                            unit: 1 to 2, a person's shadow: 3); longer strips are surface fringes
SHADOW_TOUCH = 0.12  # raised: this share of a component's outline lies next to darker pixels (for
#                      blobs: next to a darker patch; thin dark lines, a roof's joints, do not count)
ORPHAN_RATIO = 0.7  # a compact shadow with no object beside it is this dark (a sunlit-to-shaded ratio;
#                     fog, which lifts every shadow toward its surface, hides them)
ORPHAN_MIN_PX = 12  # ... at least this big ...
ORPHAN_MIN_WIDTH_PX = 3.0  # ... this wide (where joints or grout lines cross is a smaller dark dot) ...
ORPHAN_MAX_ELONGATION = 4.0  # ... and compact: a person's shadow at 45 deg of sun is ~3 times as long as
#                              wide; a wall's shadow along a building is a long strip
FLAT_WHITENESS = 0.2  # a flat patch (no shadow, not coloured) goes this share of the way to white
LINE_MIN_LEN_PX = 6.0  # a line: at least this long ...
LINE_MAX_WIDTH_PX = 3.5  # ... at most this wide ...
LINE_ELONGATION = 3.5  # ... length over width at least this
LINE_MIN_EXCESS = 0.05  # line pixels: this much brighter than the 5 x 5 opening
LINE_WHITENESS = 0.2  # a painted line's core goes this share of the way from its surface to white
#                       (simbridge renders: paint 0.3 to 0.95 when lit, 0.24 in a building's shadow;
#                       rain streaks, semi-transparent, and chance rows of bright gravel grains mostly
#                       under 0.15, at most 0.22: a few short false lines in rain, weighed by length)
WATER_BLUE = 0.06  # water: blue exceeds red by this (fog at 110 m leaves ~0.09 of a harbour's 0.25)
REGION_MIN_SHARE = 0.04  # a blue or green region under this share of the image is an object
GREEN_MARGIN = 0.03  # vegetation: green exceeds red and blue by this
ASPHALT_MAX_L = 0.42  # asphalt: darker than this ...
ASPHALT_MAX_SAT = 0.1  # ... and this neutral: (max - min of r, g, b) under this share of its luminance
#                        (asphalt ~0.03, tar ~0.05, gravel ~0.15 even in shade, where it is dark too)
EDGE_K = 3.0  # an edge: a luminance gradient of this many contrast units per working pixel
EDGE_CV_TEXTURE = 0.45  # edges spread over 4 x 4 blocks with a coefficient of variation under this: texture
GRAIN_MIN = 0.03  # a visible grain: fine texture of at least 3 % of the surface's luminance ...
GRAIN_CV = 0.5  # ... spread evenly (coefficient of variation over 4 x 4 blocks under this)
ROAD_GRAIN = 0.03  # asphalt's even grain on a mostly asphalt-like image: road texture (simbridge: asphalt
#                    0.032 to 0.068 from 8 to 90 m up, tar roofs 0.015 to 0.03 and patchy)
SITE_WINDOW_FRAME = 0.3  # site mode, a whole camera frame (wider than SQUARE_ASPECT): the middle 30 % of
#                          each side (0.6 x the height above the site in metres with a 90 deg camera:
#                          53 m at 88 m up, 12 m at 20 m)
SITE_WINDOW_CROP = 0.67  # site mode, a square close-up cut around the site (the recovery loop's +-6 m):
#                          the middle two thirds (+-4 m: the 2 m rotor disc and as much again)
SQUARE_ASPECT = 1.3  # width over height below this: a crop around the site, not a camera frame
SITE_TOL_K = 3.0  # site surface: luminance within this many contrast units of the centre's ...
SITE_TOL_MIN = 0.05  # ... or of this, whichever is larger ...
SITE_CHROMA = 0.03  # ... and chromaticity within this
WATER_RING = 0.08  # site mode: water this close to the site (share of the window's side) counts

# Hazard weights: the most each cue adds. Water or a road's markings alone (2.5 to 3) outweigh the
# elevation bonus the onboard ranker gives a surface above the street.
WEIGHTS: dict[str, float] = {
    "water": 3.0,
    "vegetation": 2.0,  # trees and lawns: canopies, hidden ground
    "markings": 2.5,  # painted lines casting no shadow: a road, which stays risky even when empty
    "raised": 2.5,  # objects casting a shadow: HVAC units, vents, cars, people, panels
    "coloured": 1.5,  # raised objects of a saturated colour (cars, people), on top of "raised"
    "lines_raised": 1.5,  # pipes, rails
    "dark_blobs": 1.0,  # objects darker than any shadow
    "flat_blobs": 0.6,  # patches casting no shadow (paint, stains, skylights)
    "asphalt": 0.5,  # dark neutral surface: a road, or a tar roof
    "road_texture": 1.0,  # ... with asphalt's fine even grain (tar's is finer and patchy)
    "edges": 1.0,  # edges gathered in places (not a texture)
}
# Where each term reaches its full weight (shares are of the image, or of the site in site mode):
WATER_FULL = 0.25  # share
VEGETATION_FULL = 0.3  # share
MARKINGS_FULL = 1.0  # total line length, in working-image diagonals
ROAD_MARKINGS = 0.4  # this much line length makes the raised objects on it "vehicle-like" in words
RAISED_FULL = 0.04  # share covered by raised objects ...
RAISED_COUNT_FULL = 4  # ... or this many of them
COLOURED_FULL = 3  # count
LINES_RAISED_FULL = 0.6  # total length, in diagonals
DARK_FULL = 3  # count
FLAT_BLOBS_FULL = 0.05  # share
EDGES_FULL = 0.15  # clustered edge density
MIN_TERM = 0.05  # smaller terms are dropped (and not named)

_K3 = np.ones((3, 3), np.uint8)
_LINE_KERNEL = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5))


@dataclass(frozen=True, slots=True)
class ImageCues:
    """Measured cues of one image. Shares are fractions (0..1) of the image, or of the site."""

    size_px: tuple[int, int]  # (height, width) of the image as given
    work_px: tuple[int, int]  # (height, width) it was analysed at (the window, in site mode)
    site_share: float  # share of the analysed window judged (1.0 unless site mode)
    brightness: float  # median luminance, 0..1
    contrast: float  # the contrast unit c (luminance, 0..1)
    grain: float  # relative amplitude of the fine texture
    uniform_grain: bool  # the grain is visible and spread evenly: gravel, tiles, shingles
    edge_density: float  # share of pixels on an edge at the working scale
    edge_spread_cv: float  # its coefficient of variation over 4 x 4 blocks
    shadow_share: float
    water_share: float
    vegetation_share: float
    asphalt_share: float
    raised_blobs: int  # compact objects next to a shadow (or their own side wall)
    raised_share: float
    coloured_blobs: int  # raised objects of a saturated colour unlike the surface (cars, people)
    shadow_blobs: int  # compact shadows with no object beside them: something stands there unseen
    flat_blobs: int  # compact patches casting no shadow (paint, stains)
    flat_share: float
    dark_blobs: int  # compact objects darker than any shadow, casting none
    lane_lines: int  # straight thin near-white lines casting no shadow (paint)
    line_length: float  # their total length, in working-image diagonals
    raised_lines: int  # straight thin lines casting a shadow (pipes, rails)
    raised_line_length: float
    other_surface_share: float  # components too large to be objects: another surface in view
    hazard: float
    terms: tuple[tuple[str, float], ...]  # the hazard's non-zero terms, largest first

    @property
    def road(self) -> bool:
        """Clear lane markings seen (``ROAD_MARKINGS``): a road, a highway or a car park."""
        return self.line_length >= ROAD_MARKINGS

    def term(self, name: str) -> float:
        return dict(self.terms).get(name, 0.0)

    def observations(self) -> tuple[str, ...]:
        """Short phrases naming what was seen, hazards first (largest first), then what is not one."""
        out = [self.phrase(name) for name, _v in self.terms]
        if self.term("raised") == 0.0 and self.term("lines_raised") == 0.0:
            out.append("no clutter")
        if self.uniform_grain and self.term("road_texture") == 0.0:
            out.append(f"uniform {self._material()} texture (not a hazard)")
        if self.shadow_share >= 0.02:
            out.append(f"shadow {100 * self.shadow_share:.0f} % (not a hazard)")
        if self.contrast <= MIN_CONTRAST and self.brightness > 0.55:
            out.append("low contrast (haze?)")
        return tuple(out)

    def phrase(self, name: str) -> str:
        """The observation naming one hazard term (``WEIGHTS``' keys)."""
        if name == "water":
            return f"water ({100 * self.water_share:.0f} %)"
        if name == "vegetation":
            return f"vegetation ({100 * self.vegetation_share:.0f} %)"
        if name == "markings":
            lines = "1 painted line" if self.lane_lines == 1 else f"{self.lane_lines} painted lines"
            return f"lane markings ({lines}: a road stays risky even when empty)"
        if name == "raised":
            # A few objects on a road are vehicles; many of them (clutter's share) are clutter, whatever
            # pipes running across them look like.
            what = (
                "vehicle-like objects" if self.road and self.raised_share < RAISED_FULL else "HVAC-like blobs"
            )
            seen = self.raised_blobs - self.shadow_blobs
            if self.shadow_blobs == 0:
                return f"{what} with shadows ({seen})"
            unseen = f"compact shadows of unseen objects ({self.shadow_blobs})"
            return unseen if seen == 0 else f"{what} with shadows ({seen}) and {unseen}"
        if name == "coloured":
            return f"coloured objects with shadows ({self.coloured_blobs}: vehicles or people?)"
        if name == "lines_raised":
            return f"pipes or rails casting shadows ({self.raised_lines})"
        if name == "flat_blobs":
            return f"flat patches without shadows ({self.flat_blobs}: paint or stains)"
        if name == "dark_blobs":
            return f"dark objects ({self.dark_blobs})"
        if name == "asphalt":
            return f"dark asphalt-like surface ({100 * self.asphalt_share:.0f} %)"
        if name == "road_texture":
            return "road texture (an even fine grain on the asphalt)"
        return f"busy edges ({100 * self.edge_density:.0f} %)"

    def _material(self) -> str:
        return "gravel or tile" if self.brightness > 0.35 else "dark"

    def to_json(self) -> dict[str, Any]:
        return {
            "size_px": list(self.size_px),
            "work_px": list(self.work_px),
            "site_share": round(self.site_share, 4),
            "brightness": round(self.brightness, 3),
            "contrast": round(self.contrast, 4),
            "grain": round(self.grain, 4),
            "uniform_grain": self.uniform_grain,
            "edge_density": round(self.edge_density, 4),
            "edge_spread_cv": round(self.edge_spread_cv, 3),
            "shares": {
                "shadow": round(self.shadow_share, 4),
                "water": round(self.water_share, 4),
                "vegetation": round(self.vegetation_share, 4),
                "asphalt": round(self.asphalt_share, 4),
                "raised": round(self.raised_share, 4),
                "flat": round(self.flat_share, 4),
                "other_surface": round(self.other_surface_share, 4),
            },
            "counts": {
                "raised_blobs": self.raised_blobs,
                "coloured_blobs": self.coloured_blobs,
                "shadow_blobs": self.shadow_blobs,
                "flat_blobs": self.flat_blobs,
                "dark_blobs": self.dark_blobs,
                "lane_lines": self.lane_lines,
                "raised_lines": self.raised_lines,
            },
            "line_length": round(self.line_length, 3),
            "raised_line_length": round(self.raised_line_length, 3),
            "hazard": round(self.hazard, 3),
            "terms": {k: round(v, 3) for k, v in self.terms},
            "observations": list(self.observations()),
        }


# ------------------------------------------------------------------------------------------ analysis
def analyse(rgb: np.ndarray, *, site: bool = False, window: float | None = None) -> ImageCues:
    """Measure the cues of one RGB uint8 image of shape (height, width, 3), any size.

    Args:
        rgb: the crop (or, with ``site``, the close-up whose centre is the landing site).
        site: judge only the surface under the middle of the image (module docstring, 7).
        window: with ``site``, the share of each side looked at (0 < window <= 1); by default
            ``SITE_WINDOW_CROP`` for a square-ish close-up, ``SITE_WINDOW_FRAME`` for a camera frame.

    Raises:
        ValueError: not a non-empty (H, W, 3) uint8 numpy array, or a window outside (0, 1].
    """
    rgb = check_rgb(rgb)
    if window is not None and not 0.0 < window <= 1.0:
        raise ValueError(f"the site window is a share of each side in (0, 1], got {window}")
    if site:
        if window is None:
            wide = rgb.shape[1] >= SQUARE_ASPECT * rgb.shape[0]
            window = SITE_WINDOW_FRAME if wide else SITE_WINDOW_CROP
        small = _working(centre(rgb, window))
    else:
        small = _working(rgb)
    h, w = small.shape[:2]
    img8 = cv2.medianBlur(small, 3) if min(h, w) >= 3 else small
    r, g, b = (p.astype(np.float32) * np.float32(1.0 / 255.0) for p in cv2.split(img8))
    lum = (r + g + b) * np.float32(1.0 / 3.0)
    bg = _background(img8)
    br, bgg, bb = bg
    lbg = (br + bgg + bb) * np.float32(1.0 / 3.0)
    d = lum - lbg
    c = max(MIN_CONTRAST, 1.4826 * float(np.median(np.abs(d[::2, ::2]))))  # every 4th pixel: enough
    cdist = _chroma_distance((r, g, b), bg)
    sat = np.maximum(np.maximum(r, g), b) - np.minimum(np.minimum(r, g), b)

    dark_object = lum < DARK_OBJECT_RATIO * lbg
    darker = (d < -SHADOW_K * c) & ~dark_object
    shadow = darker & (cdist < CHROMA_TOL)
    # A shadow as wide as the background window (a building's, across a roof) is the background
    # there: it is found against the image's lit surface instead, by the same rule.
    shadow |= _wide_shadow((r, g, b), lum, lbg, dark_object)
    # Evidence of height next to an object: its cast shadow, or a side seen obliquely (darker than the
    # surface, of any chromaticity).
    near_dark = cv2.dilate(darker.view(np.uint8), _K3).view(bool)
    # Blobs need a shadow patch beside them, not a thin dark line: a roof's joints and seams cross
    # rain streaks and gravel specks; a pipe's thin shadow still marks the pipe (lines use near_dark).
    near_patch = cv2.dilate(_drop_lines(darker).view(np.uint8), _K3).view(bool)
    coloured = (cdist > OBJECT_CHROMA) & (sat > OBJECT_MIN_SAT)
    green = (g - r > GREEN_MARGIN) & (g - b > GREEN_MARGIN)
    water, panels = _water((b - r > WATER_BLUE) & (b >= g), near_patch)
    asphalt = (lum < ASPHALT_MAX_L) & (sat < ASPHALT_MAX_SAT * (lum + 0.05)) & ~darker & ~dark_object

    objects = ((d > OBJECT_K * c) | coloured | dark_object) & ~green & ~water
    # Paint lines are no barrier: a lane's markings belong to the road the site would be on.
    focus = _site_region(img8, bg, lum, c, _drop_lines(objects) | darker) if site else None
    n = float(h * w) if focus is None else max(float(np.count_nonzero(focus)), 1.0)
    shade = darker & (lum < ORPHAN_RATIO * lbg)
    whiteness = d / np.maximum(1.0 - lbg, 0.05)  # how far toward white from the surface
    shade &= ~_near(green)  # a tree's shadow has its tree beside it
    blobs = _blobs(
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
    )
    raw = sum((p.astype(np.float32) for p in cv2.split(small)), np.zeros((h, w), np.float32))
    raw *= np.float32(1.0 / (3 * 255))  # luminance before the median: thin lines and the grain
    lines = _lines(raw, lbg, near_dark, focus)
    lines["lane_lines"] += blobs.pop("wide_lines")
    lines["line_length"] += blobs.pop("wide_line_length")
    lines["raised_lines"] += blobs.pop("wide_raised_lines")
    lines["raised_line_length"] += blobs.pop("wide_raised_length")
    edge_density, edge_cv = _edges(lum, c, focus, _near(_large(shadow, MAX_BLOB_SHARE)))
    grain, uniform = _grain(raw, lbg)
    if focus is None:
        water_share = float(np.count_nonzero(water)) / n
        shares = [float(np.count_nonzero(m)) / n for m in (shadow, asphalt)]
        vegetation_share = _region_share(green, n)
    else:
        ring = max(1, round(WATER_RING * max(h, w)))
        near = cv2.dilate(focus.view(np.uint8), _K3, iterations=ring).view(bool)
        water_share = min(1.0, float(np.count_nonzero(water & near)) / n)
        shares = [float(np.count_nonzero(m & focus)) / n for m in (shadow, asphalt)]
        vegetation_share = _region_share(green, n, focus)
    cues: dict[str, Any] = dict(
        size_px=(int(rgb.shape[0]), int(rgb.shape[1])),
        work_px=(h, w),
        site_share=n / float(h * w),
        brightness=float(np.median(lum[::2, ::2])),
        contrast=c,
        grain=grain,
        uniform_grain=uniform,
        edge_density=edge_density,
        edge_spread_cv=edge_cv,
        shadow_share=shares[0],
        water_share=water_share,
        vegetation_share=vegetation_share,
        asphalt_share=shares[1],
        **blobs,
        **lines,
    )
    terms = _hazard_terms(cues)
    return ImageCues(**cues, hazard=float(sum(v for _k, v in terms)), terms=terms)


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


def _working(rgb: np.ndarray) -> np.ndarray:
    h, w = rgb.shape[:2]
    s = math.sqrt(WORK_AREA_PX / (h * w))
    if s >= 1.0:
        return rgb
    size = (max(1, round(w * s)), max(1, round(h * s)))
    return np.asarray(cv2.resize(rgb, size, interpolation=cv2.INTER_AREA))


def _background(img8: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-pixel colour (r, g, b planes, float32 0..1) of the surface under it: block medians, then a
    5 x 5 median over blocks, scaled back up (the whole image's median when it is small). Medians, not
    means, so a large object or its shadow does not tint the surface around it."""
    h, w = img8.shape[:2]
    side = min(h, w)
    if side < 16:
        med = np.median(img8.reshape(-1, 3), axis=0) / 255.0
        return tuple(np.full((h, w), v, np.float32) for v in med)  # type: ignore[return-value]
    block = max(2, side // 10)
    # Blocks of 4 px or more are sampled at every other pixel: the median of a quarter is as good.
    sub, bs = (img8[::2, ::2], block // 2) if block >= 4 else (img8, block)
    hb, wb = sub.shape[0] // bs, sub.shape[1] // bs
    cells = sub[: hb * bs, : wb * bs].reshape(hb, bs, wb, bs, 3).transpose(0, 2, 4, 1, 3)
    cells = cells.reshape(hb, wb, 3, bs * bs)
    mid = bs * bs // 2
    coarse = np.ascontiguousarray(np.partition(cells, mid, axis=3)[..., mid])
    coarse = cv2.medianBlur(coarse, 5)
    up = cv2.resize(coarse, (w, h), interpolation=cv2.INTER_LINEAR)
    r, g, b = (p.astype(np.float32) * np.float32(1.0 / 255.0) for p in cv2.split(up))
    return r, g, b


def _chroma_distance(
    a: tuple[np.ndarray, np.ndarray, np.ndarray], b: tuple[np.ndarray, np.ndarray, np.ndarray]
) -> np.ndarray:
    """Largest difference of chromaticity (r, g, b over their sum), damped toward grey where dark."""
    damp = np.float32(0.03)
    sa = np.float32(1.0) / (a[0] + a[1] + a[2] + 3 * damp)
    sb = np.float32(1.0) / (b[0] + b[1] + b[2] + 3 * damp)
    out: np.ndarray = np.abs((a[0] + damp) * sa - (b[0] + damp) * sb)
    for k in (1, 2):
        np.maximum(out, np.abs((a[k] + damp) * sa - (b[k] + damp) * sb), out=out)
    return out


def _wide_shadow(
    rgb: tuple[np.ndarray, np.ndarray, np.ndarray], lum: np.ndarray, lbg: np.ndarray, dark: np.ndarray
) -> np.ndarray:
    """Pixels under ``WIDE_SHADOW_RATIO`` of the image's lit surface (the brightest tenth of its
    background) with that surface's chromaticity."""
    lit = lbg >= np.percentile(lbg[::2, ::2], 90)
    colour = tuple(np.full((1, 1), p[lit].mean(), np.float32) for p in rgb)  # a homogeneous tenth: mean
    level = float(sum(float(v[0, 0]) for v in colour)) / 3.0
    out: np.ndarray = (lum < WIDE_SHADOW_RATIO * level) & ~dark
    out &= _chroma_distance(rgb, colour) < CHROMA_TOL  # type: ignore[arg-type]
    return out


def _site_region(
    img8: np.ndarray,
    bg: tuple[np.ndarray, np.ndarray, np.ndarray],
    lum: np.ndarray,
    c: float,
    barrier: np.ndarray,
) -> np.ndarray:
    """The surface under the centre: connected pixels of its colour, not crossing ``barrier`` (objects
    and darker pixels, gaps closed: a parapet and its shadow fence a roof in), its holes (the objects
    standing on it) filled."""
    h, w = lum.shape
    planes = tuple(p.astype(np.float32) * np.float32(1.0 / 255.0) for p in cv2.split(img8))
    cy, cx, k = h // 2, w // 2, max(1, min(h, w) // 16)
    # The site's colour is the background's at the centre: an object standing right under the vehicle
    # (a person) must not be taken for the site itself.
    centre = tuple(np.full((1, 1), p[cy, cx], np.float32) for p in bg)
    lc = float(sum(float(v[0, 0]) for v in centre)) / 3.0
    similar = np.abs(lum - lc) <= max(SITE_TOL_MIN, SITE_TOL_K * c)
    similar &= _chroma_distance(planes, centre) <= SITE_CHROMA  # type: ignore[arg-type]
    similar &= ~cv2.morphologyEx(barrier.view(np.uint8), cv2.MORPH_CLOSE, _K3).view(bool)
    count, lab = cv2.connectedComponents(similar.view(np.uint8), connectivity=4)
    core = lab[cy - k : cy + k + 1, cx - k : cx + k + 1]
    core = core[core > 0]
    if core.size == 0:  # the centre is all object or barrier: judge the whole window
        return np.ones((h, w), bool)
    region = lab == np.bincount(core).argmax()
    # Holes: the objects standing on the site, small parts of its complement. An object the window's
    # border cuts is still one (it meets the border over about its width); a strip along the border
    # (the roof's edge, just in view) is not.
    count, out_lab, stats, _ = cv2.connectedComponentsWithStats((~region).view(np.uint8), connectivity=8)
    area = stats[:, cv2.CC_STAT_AREA].astype(np.float64)
    rim = np.concatenate([out_lab[0], out_lab[-1], out_lab[1:-1, 0], out_lab[1:-1, -1]])
    contact = np.bincount(rim, minlength=count)
    hole = (area <= MAX_BLOB_SHARE * h * w) & (contact <= 2.0 * np.sqrt(area))
    hole[0] = True  # label 0: the region itself
    out: np.ndarray = hole[out_lab]
    return out


def _near(mask: np.ndarray, px: int = 2) -> np.ndarray:
    """``mask`` widened by ``px`` pixels."""
    out: np.ndarray = cv2.dilate(mask.view(np.uint8), _K3, iterations=px).view(bool)
    return out


def _large(mask: np.ndarray, min_share: float) -> np.ndarray:
    """The components of ``mask`` of at least ``min_share`` of the image."""
    if not mask.any():
        return mask
    count, lab = _labels(mask)
    keep = np.bincount(lab, minlength=count) >= min_share * mask.size
    keep[0] = False
    out: np.ndarray = keep[lab].reshape(mask.shape)
    return out


def _labels(mask: np.ndarray) -> tuple[int, np.ndarray]:
    count, labels = cv2.connectedComponents(mask.view(np.uint8), connectivity=8)
    return int(count), labels.ravel()


_GRID: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = {}


def _shape(lab: np.ndarray, count: int, shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per component (index 0 = background): area, length and width in pixels from second moments.

    A uniform bar of length L has variance L^2 / 12 along it (+1/12 for a pixel's own extent)."""
    grid = _GRID.get(shape)
    if grid is None:
        ys, xs = np.indices(shape, dtype=np.float64)
        grid = _GRID.setdefault(shape, (xs.ravel(), ys.ravel()))
    on = np.flatnonzero(lab)  # only the components' own pixels
    sub, xs, ys = lab[on], grid[0][on], grid[1][on]
    area = np.bincount(sub, minlength=count).astype(np.float64)
    safe = np.maximum(area, 1.0)
    mx = np.bincount(sub, xs, count) / safe
    my = np.bincount(sub, ys, count) / safe
    cxx = np.bincount(sub, xs * xs, count) / safe - mx * mx
    cyy = np.bincount(sub, ys * ys, count) / safe - my * my
    cxy = np.bincount(sub, xs * ys, count) / safe - mx * my
    half = (cxx + cyy) / 2
    root = np.sqrt(np.maximum(half**2 - (cxx * cyy - cxy**2), 0.0))
    length = np.sqrt(12.0 * (half + root) + 1.0)
    width = np.sqrt(12.0 * np.maximum(half - root, 0.0) + 1.0)
    return area, length, width


def _touching(mask: np.ndarray, lab: np.ndarray, count: int, near: np.ndarray) -> np.ndarray:
    """Per component: does ``SHADOW_TOUCH`` of its outline (inside the image) lie on ``near``?"""
    # cv2.erode treats outside the image as set, so the image's border is no outline.
    outline = np.flatnonzero(mask & ~cv2.erode(mask.view(np.uint8), _K3).view(bool))
    total = np.bincount(lab[outline], minlength=count)
    touch = np.bincount(lab[outline], near.ravel()[outline], count)
    out: np.ndarray = (touch >= SHADOW_TOUCH * total) & (touch > 0)
    return out


def _in_focus(lab: np.ndarray, count: int, focus: np.ndarray | None) -> np.ndarray:
    """Per component: does at least half of it lie on the focus region (all do without one)?"""
    if focus is None:
        return np.ones(count, bool)
    out: np.ndarray = np.bincount(lab, focus.ravel(), count) >= 0.5 * np.bincount(lab, minlength=count)
    return out


def _drop_lines(mask: np.ndarray) -> np.ndarray:
    """``mask`` without its thin straight components."""
    if not mask.any():
        return mask
    count, lab = _labels(mask)
    _area, length, width = _shape(lab, count, mask.shape)
    keep = ~_is_line(length, width)
    keep[0] = False
    out: np.ndarray = keep[lab].reshape(mask.shape)
    return out


def _touching_focus(lab: np.ndarray, count: int, focus: np.ndarray | None) -> np.ndarray:
    """Per component: does it touch the focus region, widened by 2 px (all do without one)?"""
    if focus is None:
        return np.ones(count, bool)
    out: np.ndarray = np.bincount(lab, _near(focus).ravel(), count) > 0
    return out


def _is_line(length: np.ndarray, width: np.ndarray) -> np.ndarray:
    out: np.ndarray = (
        (length >= LINE_MIN_LEN_PX) & (width <= LINE_MAX_WIDTH_PX) & (length >= LINE_ELONGATION * width)
    )
    return out


def _water(blue: np.ndarray, near_dark: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Water (large blue regions casting no shadow) and raised blue panels (casting one), as masks."""
    empty = np.zeros(blue.shape, bool)
    if not blue.any():
        return empty, empty
    count, lab = _labels(blue)
    area = np.bincount(lab, minlength=count)
    large = area >= REGION_MIN_SHARE * blue.size
    large[0] = False
    if not large.any():
        return empty, empty
    raised = _touching(blue, lab, count, near_dark)
    water = (large & ~raised)[lab].reshape(blue.shape)
    panels = (large & raised)[lab].reshape(blue.shape)
    return water, panels


def _region_share(mask: np.ndarray, n: float, focus: np.ndarray | None = None) -> float:
    """Share (of ``n`` pixels) in regions of ``mask`` of at least ``REGION_MIN_SHARE`` of the image."""
    if not mask.any():
        return 0.0
    count, lab = _labels(mask)
    large = np.bincount(lab, minlength=count) >= REGION_MIN_SHARE * mask.size
    large[0] = False
    keep = large[lab]
    if focus is not None:
        keep &= focus.ravel()
    return min(1.0, float(np.count_nonzero(keep)) / n)


def _blobs(
    objects: np.ndarray,
    near_dark: np.ndarray,
    near_line: np.ndarray,
    coloured: np.ndarray,
    dark: np.ndarray,
    panels: np.ndarray,
    shade: np.ndarray,
    whiteness: np.ndarray,
    lum: np.ndarray,
    darker: np.ndarray,
    c: float,
    focus: np.ndarray | None,
    n: float,
) -> dict[str, Any]:
    """Compact objects: raised (next to darker pixels) or flat; coloured; darker than any shadow; and
    compact shadows with no object beside them (an object whose top matches its surface)."""
    out: dict[str, Any] = {
        "raised_blobs": 0, "raised_share": 0.0, "coloured_blobs": 0, "shadow_blobs": 0, "flat_blobs": 0,
        "flat_share": 0.0, "dark_blobs": 0, "other_surface_share": 0.0, "wide_lines": 0,
        "wide_line_length": 0.0, "wide_raised_lines": 0, "wide_raised_length": 0.0,
    }  # fmt: skip
    if panels.any():  # raised blue regions: rows of solar panels
        pcount, plab = _labels(panels)
        keep = _in_focus(plab, pcount, focus)
        keep[0] = False
        out["raised_blobs"] = int(keep.sum())
        out["raised_share"] = float(np.count_nonzero(keep[plab])) / n
    # Close one-pixel gaps first: a parapet or a pipe broken up by rain streaks or noise is one line,
    # not a row of specks.
    objects = cv2.morphologyEx(objects.view(np.uint8), cv2.MORPH_CLOSE, _K3).view(bool)
    count, lab = _labels(objects)
    area, length, width = _shape(lab, count, objects.shape)
    raised = _touching(objects, lab, count, near_dark)
    col = np.bincount(lab, coloured.ravel(), count) >= 0.5 * area
    drk = np.bincount(lab, dark.ravel(), count) >= 0.5 * area
    big = (area > MAX_BLOB_SHARE * objects.size) & _in_focus(lab, count, focus)
    # Thin lines are left to _lines, which sees them before the median filter.
    # Long strips wider than a line are the fringes of surfaces (a lit band beside a wide shadow, a
    # parapet seen close up), not objects standing on one.
    strip = length > BLOB_MAX_ELONGATION * width
    blob = (area >= MIN_BLOB_PX) & ~big & ~strip & ~_is_line(length, width) & _in_focus(lab, count, focus)
    blob &= col | drk | _brighter_than_ring(lab, count, objects, lum, darker, max(RING_MIN, RING_K * c))
    blob[0] = big[0] = False
    orphans, orphan_area = _orphan_shadows(shade, (blob & raised)[lab].reshape(objects.shape), focus)
    out["shadow_blobs"] = orphans
    out["raised_blobs"] += orphans
    out["raised_share"] += orphan_area / n
    out["raised_blobs"] += int((blob & raised).sum())
    out["raised_share"] += float(area[blob & raised].sum()) / n
    out["coloured_blobs"] = int((blob & col & raised).sum())
    # Paint, stains and skylights lie flat, whatever their colour; a faint patch (a rain streak's
    # fragment, semi-transparent) is not one.
    white = np.bincount(lab, whiteness.ravel(), count) / np.maximum(area, 1.0)
    flat = blob & ~raised & ~drk & ((white >= FLAT_WHITENESS) | col)
    out["flat_blobs"] = int(flat.sum())
    out["flat_share"] = float(area[flat].sum()) / n
    out["dark_blobs"] = int((blob & drk & ~raised).sum())
    out["other_surface_share"] = min(1.0, float(area[big].sum()) / n)
    # Strips wider than the line finder's reach that stand out all round: paint seen close up (a lane
    # marking 10 px wide) when near-white and flat, a pipe or parapet when raised.
    # Their whiteness is taken against the lit pixels around them, and a thin shadow beside them (a
    # pipe's) is enough to make them raised.
    ring_white = _ring_whiteness(lab, count, objects, lum, darker)
    wide = strip & ~big & (area >= MIN_BLOB_PX) & (ring_white >= LINE_WHITENESS)
    wide[0] = False
    lifted = _touching(objects, lab, count, near_line)
    diag = math.hypot(*objects.shape)
    paint = wide & ~lifted & _touching_focus(lab, count, focus)
    pipes = wide & lifted & _in_focus(lab, count, focus)
    out["wide_lines"] = int(paint.sum())
    out["wide_line_length"] = float(length[paint].sum()) / diag
    out["wide_raised_lines"] = int(pipes.sum())
    out["wide_raised_length"] = float(length[pipes].sum()) / diag
    return out


def _ring(
    lab: np.ndarray, count: int, objects: np.ndarray, lum: np.ndarray, darker: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per component: mean luminance inside, mean luminance of the lit pixels just around it (2 px),
    and how many such pixels there are."""
    labels = lab.reshape(objects.shape).astype(np.uint16)
    around = cv2.dilate(labels, _K3, iterations=2).ravel()
    ring = (around > 0) & ~objects.ravel() & ~darker.ravel()
    flat = lum.ravel()
    inside = np.bincount(lab, flat, count) / np.maximum(np.bincount(lab, minlength=count), 1)
    ring_n = np.bincount(around[ring], minlength=count)
    ring_mean = np.bincount(around[ring], flat[ring], count) / np.maximum(ring_n, 1)
    return inside, ring_mean, ring_n


def _brighter_than_ring(
    lab: np.ndarray, count: int, objects: np.ndarray, lum: np.ndarray, darker: np.ndarray, excess: float
) -> np.ndarray:
    """Per component: brighter by ``excess`` than the lit pixels just around it (2 px)? An object stands
    out on every side; the lit fringe of a surface beside a wide shadow, found bright only against a
    background the shadow darkened, does not."""
    inside, ring_mean, ring_n = _ring(lab, count, objects, lum, darker)
    out: np.ndarray = (ring_n == 0) | (inside - ring_mean >= excess)
    return out


def _ring_whiteness(
    lab: np.ndarray, count: int, objects: np.ndarray, lum: np.ndarray, darker: np.ndarray
) -> np.ndarray:
    """Per component: how far toward white from the lit pixels around it (0 with none around)."""
    inside, ring_mean, ring_n = _ring(lab, count, objects, lum, darker)
    out: np.ndarray = np.where(ring_n > 0, (inside - ring_mean) / np.maximum(1.0 - ring_mean, 0.05), 0.0)
    return out


def _orphan_shadows(shade: np.ndarray, objects: np.ndarray, focus: np.ndarray | None) -> tuple[int, float]:
    """Compact shadows with no raised object (``objects``) beside them: count and pixels.

    A cast shadow needs a caster; when the caster's top looks like the surface (a grey box on a pale
    roof, a person in grey seen from above) its shadow is the only sign of it. Shadows along the image's
    border (a building or tree outside the view) and thin dark lines (joints, seams) are not counted."""
    if not shade.any():
        return 0, 0.0
    shade = cv2.morphologyEx(shade.view(np.uint8), cv2.MORPH_CLOSE, _K3).view(bool)
    count, lab = _labels(shade)
    area, length, width = _shape(lab, count, shade.shape)
    grid = lab.reshape(shade.shape)
    sides = [np.bincount(side, minlength=count) for side in (grid[0], grid[-1], grid[:, 0], grid[:, -1])]
    # Cut by one side of the image over about its width at most: not a strip along the border, nor
    # one across the view (a wall's or a building's shadow).
    inside = (sum(sides) <= 2.0 * np.sqrt(area)) & (sum((v > 0).astype(int) for v in sides) <= 1)
    beside = cv2.dilate(objects.view(np.uint8), _K3, iterations=2).view(bool).ravel()
    alone = np.bincount(lab, beside, count) == 0
    keep = (area >= ORPHAN_MIN_PX) & (area <= MAX_BLOB_SHARE * shade.size) & (width >= ORPHAN_MIN_WIDTH_PX)
    keep &= length <= ORPHAN_MAX_ELONGATION * width
    keep &= inside & alone & _in_focus(lab, count, focus)
    keep[0] = False
    return int(keep.sum()), float(area[keep].sum())


def _lines(
    lum: np.ndarray, lbg: np.ndarray, near_dark: np.ndarray, focus: np.ndarray | None
) -> dict[str, Any]:
    """Straight thin bright lines, on the working image before the median filter (module docstring, 6)."""
    out: dict[str, Any] = {"lane_lines": 0, "line_length": 0.0, "raised_lines": 0, "raised_line_length": 0.0}
    h, w = lum.shape
    if min(h, w) < 8:
        return out
    top = cv2.morphologyEx(lum, cv2.MORPH_TOPHAT, _LINE_KERNEL)
    mask = top > LINE_MIN_EXCESS
    if not mask.any():
        return out
    count, lab = _labels(mask)
    area, length, width = _shape(lab, count, mask.shape)
    line = _is_line(length, width)
    line[0] = False
    if not line.any():
        return out
    # Whiteness: how far toward white from the surface, averaged over the brighter half of the line's
    # pixels (its core: a one-pixel line's mask also takes in some of its anti-aliased rim).
    on = np.flatnonzero(mask)
    sub = lab[on]
    # The surface under a line: the background, or the opening where that is brighter (beside a wide
    # shadow the background is darkened, and the lit edge would look like paint against it).
    under = np.maximum(lbg.ravel()[on], (lum - top).ravel()[on])
    wv = (lum.ravel()[on] - under) / np.maximum(1.0 - under, 0.05)
    mean = np.bincount(sub, wv, count) / np.maximum(area, 1.0)
    core = wv >= mean[sub]
    white = np.bincount(sub, wv * core, count) / np.maximum(np.bincount(sub, core, count), 1.0)
    line &= white >= LINE_WHITENESS
    raised = _touching(mask, lab, count, near_dark)
    # Paint bounding the site (a lane's markings) counts; a raised line must lie on it (not a parapet).
    line &= np.where(raised, _in_focus(lab, count, focus), _touching_focus(lab, count, focus))
    diag = math.hypot(h, w)
    out["lane_lines"] = int((line & ~raised).sum())
    out["line_length"] = float(length[line & ~raised].sum()) / diag
    out["raised_lines"] = int((line & raised).sum())
    out["raised_line_length"] = float(length[line & raised].sum()) / diag
    return out


def _edges(lum: np.ndarray, c: float, focus: np.ndarray | None, shadow: np.ndarray) -> tuple[float, float]:
    """Edge density at the working scale, and its coefficient of variation over 4 x 4 blocks. Edges on
    ``shadow`` (the rims of large cast shadows: a building's, a tower's) are no clutter and do not count."""
    h, w = lum.shape
    if min(h, w) < 8:
        return 0.0, 0.0
    sm = cv2.GaussianBlur(lum, (0, 0), 1.0)
    gx = cv2.Sobel(sm, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(sm, cv2.CV_32F, 0, 1, ksize=3)
    # Sobel's 3 x 3 kernel weighs a unit step per pixel 8 times over.
    edges = ((gx * gx + gy * gy) > np.float32((8.0 * EDGE_K * c) ** 2)) & ~shadow
    if focus is not None:
        edges &= focus
    area = h * w if focus is None else max(int(np.count_nonzero(focus)), 1)
    density = float(np.count_nonzero(edges)) / area
    if density == 0.0:
        return 0.0, 0.0
    blocks = cv2.resize(edges.view(np.uint8).astype(np.float32), (4, 4), interpolation=cv2.INTER_AREA)
    return density, float(blocks.std() / max(float(blocks.mean()), 1e-6))


def _grain(lum: np.ndarray, lbg: np.ndarray) -> tuple[float, bool]:
    """Relative amplitude of the fine texture, and whether it is spread evenly over 4 x 4 blocks."""
    h, w = lum.shape
    if min(h, w) < 8:
        return 0.0, False
    fine = np.abs(lum - cv2.GaussianBlur(lum, (0, 0), 1.0))
    level = max(float(np.median(lbg[::2, ::2])), 0.05)
    grain = 1.4826 * float(np.median(fine[::2, ::2])) / level
    blocks = cv2.resize(fine, (4, 4), interpolation=cv2.INTER_AREA)
    cv = float(blocks.std() / max(float(blocks.mean()), 1e-6))
    return grain, grain >= GRAIN_MIN and cv < GRAIN_CV


def _hazard_terms(cues: dict[str, Any]) -> tuple[tuple[str, float], ...]:
    wt = WEIGHTS
    road_grain = cues["asphalt_share"] >= 0.5 and cues["grain"] >= ROAD_GRAIN
    raised = max(cues["raised_share"] / RAISED_FULL, cues["raised_blobs"] / RAISED_COUNT_FULL)
    clustered = 0.0 if cues["edge_spread_cv"] < EDGE_CV_TEXTURE else cues["edge_density"]
    values = {
        "water": wt["water"] * min(1.0, cues["water_share"] / WATER_FULL),
        "vegetation": wt["vegetation"] * min(1.0, cues["vegetation_share"] / VEGETATION_FULL),
        "markings": wt["markings"] * min(1.0, cues["line_length"] / MARKINGS_FULL),
        "raised": wt["raised"] * min(1.0, raised),
        "coloured": wt["coloured"] * min(1.0, cues["coloured_blobs"] / COLOURED_FULL),
        "lines_raised": wt["lines_raised"] * min(1.0, cues["raised_line_length"] / LINES_RAISED_FULL),
        "dark_blobs": wt["dark_blobs"] * min(1.0, cues["dark_blobs"] / DARK_FULL),
        "flat_blobs": wt["flat_blobs"] * min(1.0, cues["flat_share"] / FLAT_BLOBS_FULL),
        "asphalt": wt["asphalt"] * min(1.0, cues["asphalt_share"]),
        "road_texture": wt["road_texture"] * cues["asphalt_share"] * (cues["uniform_grain"] and road_grain),
        "edges": wt["edges"] * min(1.0, clustered / EDGES_FULL),
    }
    kept = [(k, float(v)) for k, v in values.items() if v >= MIN_TERM]
    return tuple(sorted(kept, key=lambda kv: -kv[1]))
