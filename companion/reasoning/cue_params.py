"""The image cues' tuning: every threshold :func:`companion.reasoning.image_cues.analyse` measures with
(:class:`CueParams`) and how the measured cues weigh as a hazard (:class:`HazardWeights`).

The defaults were set on simbridge renders (clear, fog, rain); each is explained where it is defined, and
the steps they belong to are numbered in :mod:`companion.reasoning.image_cues`' docstring. Luminance and
chromaticity are fractions (0..1), sizes are pixels of the working image, shares are fractions of the image
(or of the site in site mode), and ``c`` is the contrast unit of step 2.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields

__all__ = ["CueParams", "HazardWeights"]


@dataclass(frozen=True, slots=True)
class HazardWeights:
    """The most each hazard term adds, and how much of a cue gives its full weight.

    Water or a road's markings alone (2.5 to 3) outweigh the elevation bonus the onboard ranker gives a
    surface above the street. The term names of :attr:`ImageCues.terms
    <companion.reasoning.cue_verdict.ImageCues.terms>` are the names of the weights here.
    """

    water: float = 3.0
    vegetation: float = 2.0  # trees and lawns: canopies, hidden ground
    markings: float = 2.5  # painted lines casting no shadow: a road, which stays risky even when empty
    raised: float = 2.5  # objects casting a shadow: HVAC units, vents, cars, people, panels
    coloured: float = 1.5  # raised objects of a saturated colour (cars, people), on top of "raised"
    lines_raised: float = 1.5  # pipes, rails
    dark_blobs: float = 1.0  # objects darker than any shadow
    flat_blobs: float = 0.6  # patches casting no shadow (paint, stains, skylights)
    asphalt: float = 0.5  # dark neutral surface: a road, or a tar roof
    road_texture: float = 1.0  # ... with asphalt's fine even grain (tar's is finer and patchy)
    edges: float = 1.0  # edges gathered in places (not a texture)
    # Where each term reaches its full weight:
    water_full: float = 0.25  # share
    vegetation_full: float = 0.3  # share
    markings_full: float = 1.0  # total line length, in working-image diagonals
    road_markings: float = 0.4  # this much line length makes the raised objects on it "vehicle-like" in words
    raised_full: float = 0.04  # share covered by raised objects ...
    raised_count_full: int = 4  # ... or this many of them
    coloured_full: int = 3  # count
    lines_raised_full: float = 0.6  # total length, in diagonals
    dark_full: int = 3  # count
    flat_blobs_full: float = 0.05  # share
    edges_full: float = 0.15  # clustered edge density
    min_term: float = 0.05  # smaller terms are dropped (and not named)

    def __post_init__(self) -> None:
        _check_positive(self)


@dataclass(frozen=True, slots=True)
class CueParams:
    """The thresholds of the image cues' measurements (module docstring: units)."""

    # 1. working size
    work_area_px: int = 128 * 128  # ~16 k pixels (about 3 ms a crop on one core)
    # 2. the surface
    min_contrast: float = 0.006  # floor on the contrast unit c: 1.5 steps of 8-bit luminance
    # 3. shadows
    shadow_k: float = 3.0  # shadow: this many contrast units darker than the surface ...
    chroma_tol: float = 0.035  # ... with the surface's chromaticity (r, g, b summing to 1) within this
    wide_shadow_ratio: float = 0.6  # a shadow wider than the background window: under this share of the
    #                                 lit surface
    dark_object_ratio: float = 0.2  # darker than this share of the surface: an object, not a shadow
    #                                 (sunlit to shaded ratios under an open sky lie near 0.3 to 0.6)
    # 4. objects
    object_k: float = 4.0  # objects: this many contrast units brighter than their surface ...
    object_chroma: float = 0.06  # ... or this far from its chromaticity ...
    object_min_sat: float = 0.08  # ... where saturated enough (max - min of r, g, b) for chromaticity to
    #                               mean something
    ring_k: float = 2.0  # a bright object is this many contrast units brighter than the lit pixels
    #                      around it ...
    ring_min: float = 0.015  # ... and at least this (2 sensor-noise sigmas): HVAC tops stand 0.1 above
    #                          gravel
    min_blob_px: int = 3  # smaller specks are noise at the working scale
    max_blob_share: float = 0.2  # a component larger than this share of the image is another surface
    blob_max_elongation: float = 6.0  # an object is at most this many times as long as wide (a car: 2.4,
    #                                   an HVAC unit: 1 to 2, a person's shadow: 3); longer strips are
    #                                   surface fringes
    shadow_touch: float = 0.12  # raised: this share of a component's outline lies next to darker pixels
    #                             (for blobs: next to a darker patch; thin dark lines, a roof's joints,
    #                             do not count)
    orphan_ratio: float = 0.7  # a compact shadow with no object beside it is this dark (a sunlit-to-
    #                            shaded ratio; fog, which lifts every shadow toward its surface, hides
    #                            them)
    orphan_min_px: int = 12  # ... at least this big ...
    orphan_min_width_px: float = 3.0  # ... this wide (where joints or grout lines cross is a smaller
    #                                   dark dot) ...
    orphan_max_elongation: float = 4.0  # ... and compact: a person's shadow at 45 deg of sun is ~3 times
    #                                     as long as wide; a wall's shadow along a building is a long strip
    flat_whiteness: float = 0.2  # a flat patch (no shadow, not coloured) goes this share of the way to
    #                              white
    # 6. lines
    line_min_len_px: float = 6.0  # a line: at least this long ...
    line_max_width_px: float = 3.5  # ... at most this wide ...
    line_elongation: float = 3.5  # ... length over width at least this
    line_min_excess: float = 0.05  # line pixels: this much brighter than the 5 x 5 opening
    line_whiteness: float = 0.2  # a painted line's core goes this share of the way from its surface to
    #                              white (simbridge renders: paint 0.3 to 0.95 when lit, 0.24 in a
    #                              building's shadow; rain streaks, semi-transparent, and chance rows of
    #                              bright gravel grains mostly under 0.15, at most 0.22: a few short
    #                              false lines in rain, weighed by length)
    # 5. surfaces by colour
    water_blue: float = 0.06  # water: blue exceeds red by this (fog at 110 m leaves ~0.09 of a
    #                           harbour's 0.25)
    region_min_share: float = 0.04  # a blue or green region under this share of the image is an object
    green_margin: float = 0.03  # vegetation: green exceeds red and blue by this
    asphalt_max_l: float = 0.42  # asphalt: darker than this ...
    asphalt_max_sat: float = 0.1  # ... and this neutral: (max - min of r, g, b) under this share of its
    #                               luminance (asphalt ~0.03, tar ~0.05, gravel ~0.15 even in shade,
    #                               where it is dark too)
    # 8. grain and edges
    edge_k: float = 3.0  # an edge: a luminance gradient of this many contrast units per working pixel
    edge_cv_texture: float = 0.45  # edges spread over 4 x 4 blocks with a coefficient of variation under
    #                                this: texture
    grain_min: float = 0.03  # a visible grain: fine texture of at least 3 % of the surface's luminance ...
    grain_cv: float = 0.5  # ... spread evenly (coefficient of variation over 4 x 4 blocks under this)
    road_grain: float = 0.03  # asphalt's even grain on a mostly asphalt-like image: road texture
    #                           (simbridge: asphalt 0.032 to 0.068 from 8 to 90 m up, tar roofs 0.015 to
    #                           0.03 and patchy)
    # 7. site mode
    site_window_frame: float = 0.3  # a whole camera frame (wider than square_aspect): the middle 30 % of
    #                                 each side (0.6 x the height above the site in metres with a 90 deg
    #                                 camera: 53 m at 88 m up, 12 m at 20 m)
    site_window_crop: float = 0.67  # a square close-up cut around the site (the recovery loop's +-6 m):
    #                                 the middle two thirds (+-4 m: the 2 m rotor disc and as much again)
    square_aspect: float = 1.3  # width over height below this: a crop around the site, not a camera frame
    site_tol_k: float = 3.0  # site surface: luminance within this many contrast units of the centre's ...
    site_tol_min: float = 0.05  # ... or of this, whichever is larger ...
    site_chroma: float = 0.03  # ... and chromaticity within this
    water_ring: float = 0.08  # water this close to the site (share of the window's side) counts
    # the hazard
    weights: HazardWeights = field(default_factory=HazardWeights)

    def __post_init__(self) -> None:
        _check_positive(self)
        for name in ("site_window_frame", "site_window_crop"):
            if (share := getattr(self, name)) > 1.0:
                raise ValueError(f"CueParams.{name} is a share of each side in (0, 1], got {share}")


def _check_positive(params: CueParams | HazardWeights) -> None:
    """Every number of ``params`` finite and above 0; ValueError naming the first that is not."""
    for f in fields(params):
        value = getattr(params, f.name)
        if isinstance(value, int | float) and not (math.isfinite(value) and value > 0):
            raise ValueError(f"{type(params).__name__}.{f.name} must be a finite number above 0, got {value}")
