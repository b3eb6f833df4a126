"""Crops of the camera image for the reasoner: the candidate's exact box, the box padded by a share of
its size, and the full frame as context (DESIGN.md section 2, step 3).

A box padded by ``pad`` (0.2 = 20 %) keeps its centre and grows to ``(1 + pad)`` times its width and
height (``pad / 2`` of its size on each side), then is clamped to the image: near a border it grows
only inward. Boxes are ``(x0, y0, x1, y1)`` pixels, half-open.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ["PAD_LEVELS", "context_crops", "crop", "pad_box"]

PAD_LEVELS = (0.2, 0.3, 0.4, 0.5, 0.6)  # the study's context variants


def pad_box(box: Sequence[int], pad: float, width: int, height: int) -> tuple[int, int, int, int]:
    """``box`` grown by ``pad`` of its size (half on each side) and clamped to a width x height image."""
    if pad < 0:
        raise ValueError(f"padding must be >= 0, got {pad}")
    x0, y0, x1, y1 = (int(v) for v in box)
    if not (0 <= x0 < x1 <= width and 0 <= y0 < y1 <= height):
        raise ValueError(f"box {tuple(box)} is not a non-empty box inside a {width} x {height} image")
    dx, dy = (x1 - x0) * pad / 2, (y1 - y0) * pad / 2
    return (
        max(int(np.floor(x0 - dx)), 0),
        max(int(np.floor(y0 - dy)), 0),
        min(int(np.ceil(x1 + dx)), width),
        min(int(np.ceil(y1 + dy)), height),
    )


def crop(image: np.ndarray, box: Sequence[int], pad: float = 0.0) -> np.ndarray:
    """A copy of ``image`` inside ``box`` padded by ``pad``."""
    h, w = image.shape[:2]
    x0, y0, x1, y1 = pad_box(box, pad, w, h)
    return np.ascontiguousarray(image[y0:y1, x0:x1])


def context_crops(image: np.ndarray, box: Sequence[int]) -> dict[str, np.ndarray]:
    """Every context level for one box: ``exact``, ``pad20`` .. ``pad60`` and ``full`` (the frame)."""
    out = {"exact": crop(image, box)}
    for pad in PAD_LEVELS:
        out[f"pad{round(pad * 100)}"] = crop(image, box, pad)
    out["full"] = image
    return out
