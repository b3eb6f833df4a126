"""The objects of the image cues (steps 4 and 6 of :mod:`companion.reasoning.image_cues`): compact
blobs standing out of the surface, raised or flat (:func:`find_blobs`), the compact shadows of objects
that blend in, and thin straight lines, painted or raised (:func:`find_lines`). Each takes the masks
the surface steps made (:mod:`companion.reasoning.cue_surface`) and returns counts, shares and lengths.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np

from companion.reasoning.cue_params import CueParams
from companion.reasoning.cue_surface import (
    K3,
    component_shape,
    in_focus,
    is_line,
    labels,
    touching,
    touching_focus,
)

__all__ = ["Blobs", "Lines", "find_blobs", "find_lines"]

_LINE_KERNEL = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5))


@dataclass(frozen=True, slots=True)
class Lines:
    """Straight lines: painted ones (casting no shadow) and raised ones (pipes, rails); lengths in
    working-image diagonals."""

    lane_lines: int = 0
    line_length: float = 0.0
    raised_lines: int = 0
    raised_line_length: float = 0.0

    def plus(self, other: Lines) -> Lines:
        """Both sets of lines together."""
        return Lines(
            self.lane_lines + other.lane_lines,
            self.line_length + other.line_length,
            self.raised_lines + other.raised_lines,
            self.raised_line_length + other.raised_line_length,
        )


@dataclass(frozen=True, slots=True)
class Blobs:
    """Compact objects (counts, and shares of the image or of the site: :class:`ImageCues
    <companion.reasoning.cue_verdict.ImageCues>` says what each is)."""

    raised_blobs: int
    raised_share: float
    coloured_blobs: int
    shadow_blobs: int
    flat_blobs: int
    flat_share: float
    dark_blobs: int
    other_surface_share: float
    wide: Lines = field(default_factory=Lines)  # strips too wide for the line finder that are lines


def find_blobs(
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
    p: CueParams,
) -> Blobs:
    """Compact objects: raised (next to darker pixels) or flat; coloured; darker than any shadow; and
    compact shadows with no object beside them (an object whose top matches its surface)."""
    raised_blobs, raised_share = 0, 0.0
    if panels.any():  # raised blue regions: rows of solar panels
        pcount, plab = labels(panels)
        keep = in_focus(plab, pcount, focus)
        keep[0] = False
        raised_blobs = int(keep.sum())
        raised_share = float(np.count_nonzero(keep[plab])) / n
    # Close one-pixel gaps first: a parapet or a pipe broken up by rain streaks or noise is one line,
    # not a row of specks.
    objects = cv2.morphologyEx(objects.view(np.uint8), cv2.MORPH_CLOSE, K3).view(bool)
    count, lab = labels(objects)
    area, length, width = component_shape(lab, count, objects.shape)
    raised = touching(objects, lab, count, near_dark, p)
    col = np.bincount(lab, coloured.ravel(), count) >= 0.5 * area
    drk = np.bincount(lab, dark.ravel(), count) >= 0.5 * area
    big = (area > p.max_blob_share * objects.size) & in_focus(lab, count, focus)
    # Thin lines are left to find_lines, which sees them before the median filter.
    # Long strips wider than a line are the fringes of surfaces (a lit band beside a wide shadow, a
    # parapet seen close up), not objects standing on one.
    strip = length > p.blob_max_elongation * width
    blob = (area >= p.min_blob_px) & ~big & ~strip & ~is_line(length, width, p) & in_focus(lab, count, focus)
    blob &= col | drk | _brighter_than_ring(lab, count, objects, lum, darker, max(p.ring_min, p.ring_k * c))
    blob[0] = big[0] = False
    orphans, orphan_area = _orphan_shadows(shade, (blob & raised)[lab].reshape(objects.shape), focus, p)
    raised_blobs += orphans + int((blob & raised).sum())
    raised_share += orphan_area / n
    raised_share += float(area[blob & raised].sum()) / n
    # Paint, stains and skylights lie flat, whatever their colour; a faint patch (a rain streak's
    # fragment, semi-transparent) is not one.
    white = np.bincount(lab, whiteness.ravel(), count) / np.maximum(area, 1.0)
    flat = blob & ~raised & ~drk & ((white >= p.flat_whiteness) | col)
    # Strips wider than the line finder's reach that stand out all round: paint seen close up (a lane
    # marking 10 px wide) when near-white and flat, a pipe or parapet when raised.
    # Their whiteness is taken against the lit pixels around them, and a thin shadow beside them (a
    # pipe's) is enough to make them raised.
    ring_white = _ring_whiteness(lab, count, objects, lum, darker)
    wide = strip & ~big & (area >= p.min_blob_px) & (ring_white >= p.line_whiteness)
    wide[0] = False
    lifted = touching(objects, lab, count, near_line, p)
    diag = math.hypot(*objects.shape)
    paint = wide & ~lifted & touching_focus(lab, count, focus)
    pipes = wide & lifted & in_focus(lab, count, focus)
    return Blobs(
        raised_blobs=raised_blobs,
        raised_share=raised_share,
        coloured_blobs=int((blob & col & raised).sum()),
        shadow_blobs=orphans,
        flat_blobs=int(flat.sum()),
        flat_share=float(area[flat].sum()) / n,
        dark_blobs=int((blob & drk & ~raised).sum()),
        other_surface_share=min(1.0, float(area[big].sum()) / n),
        wide=Lines(
            lane_lines=int(paint.sum()),
            line_length=float(length[paint].sum()) / diag,
            raised_lines=int(pipes.sum()),
            raised_line_length=float(length[pipes].sum()) / diag,
        ),
    )


def _ring(
    lab: np.ndarray, count: int, objects: np.ndarray, lum: np.ndarray, darker: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per component: mean luminance inside, mean luminance of the lit pixels just around it (2 px),
    and how many such pixels there are."""
    labels = lab.reshape(objects.shape).astype(np.uint16)
    around = cv2.dilate(labels, K3, iterations=2).ravel()
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


def _orphan_shadows(
    shade: np.ndarray, objects: np.ndarray, focus: np.ndarray | None, p: CueParams
) -> tuple[int, float]:
    """Compact shadows with no raised object (``objects``) beside them: count and pixels.

    A cast shadow needs a caster; when the caster's top looks like the surface (a grey box on a pale
    roof, a person in grey seen from above) its shadow is the only sign of it. Shadows along the image's
    border (a building or tree outside the view) and thin dark lines (joints, seams) are not counted."""
    if not shade.any():
        return 0, 0.0
    shade = cv2.morphologyEx(shade.view(np.uint8), cv2.MORPH_CLOSE, K3).view(bool)
    count, lab = labels(shade)
    area, length, width = component_shape(lab, count, shade.shape)
    grid = lab.reshape(shade.shape)
    sides = [np.bincount(side, minlength=count) for side in (grid[0], grid[-1], grid[:, 0], grid[:, -1])]
    # Cut by one side of the image over about its width at most: not a strip along the border, nor
    # one across the view (a wall's or a building's shadow).
    inside = (sum(sides) <= 2.0 * np.sqrt(area)) & (sum((v > 0).astype(int) for v in sides) <= 1)
    beside = cv2.dilate(objects.view(np.uint8), K3, iterations=2).view(bool).ravel()
    alone = np.bincount(lab, beside, count) == 0
    keep = (
        (area >= p.orphan_min_px) & (area <= p.max_blob_share * shade.size) & (width >= p.orphan_min_width_px)
    )
    keep &= length <= p.orphan_max_elongation * width
    keep &= inside & alone & in_focus(lab, count, focus)
    keep[0] = False
    return int(keep.sum()), float(area[keep].sum())


def find_lines(
    lum: np.ndarray, lbg: np.ndarray, near_dark: np.ndarray, focus: np.ndarray | None, p: CueParams
) -> Lines:
    """Straight thin bright lines, on the working image before the median filter (module docstring, 6)."""
    none = Lines()
    h, w = lum.shape
    if min(h, w) < 8:
        return none
    top = cv2.morphologyEx(lum, cv2.MORPH_TOPHAT, _LINE_KERNEL)
    mask = top > p.line_min_excess
    if not mask.any():
        return none
    count, lab = labels(mask)
    area, length, width = component_shape(lab, count, mask.shape)
    line = is_line(length, width, p)
    line[0] = False
    if not line.any():
        return none
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
    line &= white >= p.line_whiteness
    raised = touching(mask, lab, count, near_dark, p)
    # Paint bounding the site (a lane's markings) counts; a raised line must lie on it (not a parapet).
    line &= np.where(raised, in_focus(lab, count, focus), touching_focus(lab, count, focus))
    diag = math.hypot(h, w)
    return Lines(
        lane_lines=int((line & ~raised).sum()),
        line_length=float(length[line & ~raised].sum()) / diag,
        raised_lines=int((line & raised).sum()),
        raised_line_length=float(length[line & raised].sum()) / diag,
    )
