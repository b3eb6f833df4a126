"""Crops of the camera image for the reasoner: the candidate's exact box, the box padded by a share of
its size, and the full frame as context (DESIGN.md section 2, step 3).

A box padded by ``pad`` (0.2 = 20 %) keeps its centre and grows to ``(1 + pad)`` times its width and
height (``pad / 2`` of its size on each side), then is clamped to the image: near a border it grows
only inward. Boxes are ``(x0, y0, x1, y1)`` pixels, half-open.

A box, padding or site pixel that cannot be cut from the image raises :class:`CropError` (a
``ValueError``): a box that is empty or reaches outside the image, a negative or non-finite padding, a
site pixel outside the image.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

__all__ = [
    "MIN_SITE_HALF_PX",
    "PAD_LEVELS",
    "CropError",
    "context_crops",
    "crop",
    "pad_box",
    "pad_of",
    "rank_crops",
    "site_box",
]

PAD_LEVELS = (0.2, 0.3, 0.4, 0.5, 0.6)  # the study's context variants
MIN_SITE_HALF_PX = 48  # a confirm close-up is at least 96 px wide where the frame allows


class CropError(ValueError):
    """A box, padding or site pixel that cannot be cut from a ``width`` x ``height`` image."""


def pad_box(box: Sequence[int], pad: float, width: int, height: int) -> tuple[int, int, int, int]:
    """``box`` grown by ``pad`` of its size (half on each side) and clamped to a width x height image.

    Raises:
        CropError: ``pad`` negative or not finite; ``box`` not four integers of a non-empty box inside
            the image.
    """
    if not (math.isfinite(pad) and pad >= 0):  # NaN and inf would only fail later, in int()
        raise CropError(f"padding must be a finite share >= 0, got {pad}")
    try:
        x0, y0, x1, y1 = (int(v) for v in box)
    except (TypeError, ValueError, OverflowError) as exc:
        raise CropError(f"box {box!r} is not four integer pixel coordinates (x0, y0, x1, y1)") from exc
    if not (0 <= x0 < x1 <= width and 0 <= y0 < y1 <= height):
        raise CropError(f"box {tuple(box)} is not a non-empty box inside a {width} x {height} image")
    # Past the image's own size a padding changes nothing; capped there, a huge one stays finite.
    dx, dy = min((x1 - x0) * pad / 2, width), min((y1 - y0) * pad / 2, height)
    return (
        max(int(np.floor(x0 - dx)), 0),
        max(int(np.floor(y0 - dy)), 0),
        min(int(np.ceil(x1 + dx)), width),
        min(int(np.ceil(y1 + dy)), height),
    )


def site_box(u: float, v: float, half_px: float, width: int, height: int) -> tuple[int, int, int, int]:
    """The square box of half-side ``half_px`` centred on pixel (u, v) of a width x height image (the
    close-up the confirm stage judges). Near a border it shrinks on every side rather than being cut on
    one, so (u, v) stays in its middle; it never shrinks below ``MIN_SITE_HALF_PX``, where it is clamped
    instead.

    Raises:
        CropError: (u, v) outside the image, or ``half_px`` NaN.
    """
    if not (0 <= u < width and 0 <= v < height):
        raise CropError(f"site pixel ({u:.0f}, {v:.0f}) is outside the {width} x {height} image")
    if math.isnan(half_px):
        raise CropError("the close-up's half-side must be a number of pixels, got NaN")
    cu, cv = int(u), int(v)
    room = min(cu, cv, width - cu, height - cv)
    # min before int: an infinite half-side (a site right under the camera) is all the room there is
    half = int(max(min(half_px, room), MIN_SITE_HALF_PX))
    return max(cu - half, 0), max(cv - half, 0), min(cu + half, width), min(cv + half, height)


def crop(image: np.ndarray, box: Sequence[int], pad: float = 0.0) -> np.ndarray:
    """A copy of ``image`` inside ``box`` padded by ``pad``."""
    h, w = image.shape[:2]
    x0, y0, x1, y1 = pad_box(box, pad, w, h)
    return np.ascontiguousarray(image[y0:y1, x0:x1])


def pad_of(context: str) -> float:
    """The padding share of a context variant: ``crop`` and ``full`` 0, ``padNN`` NN %.

    Raises:
        ValueError: an unknown variant.
    """
    if context in ("crop", "full"):
        return 0.0
    if context.startswith("pad") and context[3:].isdigit() and 0 < int(context[3:]) <= 100:
        return int(context[3:]) / 100
    raise ValueError(f"unknown context variant {context!r}: crop, pad20 .. pad60, or full")


def rank_crops(
    image: np.ndarray, boxes: Sequence[Sequence[int]], context: str
) -> tuple[tuple[np.ndarray, ...], tuple[tuple[int, int, int, int], ...]]:
    """What the reasoner is shown for one context variant: per box, its crop (padded as the variant
    says) and the box itself in that crop's pixels (its *core*: the whole crop when unpadded)."""
    h, w = image.shape[:2]
    pad = pad_of(context)
    crops, cores = [], []
    for box in boxes:
        x0, y0, x1, y1 = pad_box(box, pad, w, h)
        crops.append(np.ascontiguousarray(image[y0:y1, x0:x1]))
        bx0, by0, bx1, by1 = (int(v) for v in box)
        cores.append((bx0 - x0, by0 - y0, bx1 - x0, by1 - y0))
    return tuple(crops), tuple(cores)


def context_crops(image: np.ndarray, box: Sequence[int]) -> dict[str, np.ndarray]:
    """Every context level for one box: ``exact``, ``pad20`` .. ``pad60`` and ``full`` (the frame)."""
    out = {"exact": crop(image, box)}
    for pad in PAD_LEVELS:
        out[f"pad{round(pad * 100)}"] = crop(image, box, pad)
    out["full"] = image
    return out
