"""People near a site: what the onboard net sees of people within a margin of the site, in a camera frame.

The confirmation judges the site's own window; a person a few metres beyond it is not in that window,
and a regulator's margin (no one within 10 m of the touchdown) reaches further. :func:`people_near`
reads the frame around the site's pixel out to ``margin_m`` in square tiles, each at about the scale
the net learnt people at (``TILE_M`` metres per tile at the finest, that is 3 cm a pixel over the
net's 128-pixel views; a tile seen coarser than that is read as it is, from ``MIN_TILE_PX`` pixels),
and counts the cells where the net says a person is present whose centres lie within ``margin_m`` of
the site. The frame's scale at the site (pixels per metre) comes from the caller, who knows the pose.

The net decides what a person is: the packaged nets learnt people from simbridge's renders (pedestrians
1.7 m tall seen from 3-25 cm a pixel) and do not see everyone: from 15-25 m above suburban lawns
LandNet-S found about half of the people in view (docs/reasoning.md). A watch that sees no one is no
proof that no one is there; one that sees someone is a reason to wait.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from companion.reasoning.landnet import LandNet

__all__ = ["MIN_TILE_PX", "TILE_M", "PeopleSeen", "people_near"]

TILE_M = 3.84  # a tile's side on the ground at the finest: 128 px at 3 cm a pixel
MIN_TILE_PX = 96  # a tile is never read from fewer pixels than this (coarser frames: as they are)
READ_PX = 128  # the side a fine tile is reduced to before the net reads it
SENSITIVITY = 0.5  # a person cell at this share of the net's own threshold: a watch would rather hold
PERSON = "person"


@dataclass(frozen=True, slots=True)
class PeopleSeen:
    """What :func:`people_near` found: person cells within the margin, the nearest one's distance from
    the site (metres; None when none), the share of the margin's disc the frame showed, and where in
    the image each person cell is (pixel centres u, v: where to step aside from)."""

    cells: int
    nearest_m: float | None
    seen_share: float
    cells_px: tuple[tuple[float, float], ...] = ()

    def phrase(self, margin_m: float) -> str:
        if not self.cells:
            return f"no one seen within {margin_m:.0f} m ({100 * self.seen_share:.0f} % of that in view)"
        return f"a person {self.nearest_m:.0f} m from the site (within {margin_m:.0f} m)"


def people_near(
    net: LandNet, image: np.ndarray, site_px: tuple[float, float], px_per_m: float, margin_m: float
) -> PeopleSeen:
    """Person cells the net finds within ``margin_m`` of the site at pixel ``site_px`` (u, v) of
    ``image`` (RGB), whose scale at the site is ``px_per_m`` (module docstring).

    Raises:
        ValueError: a scale or margin that is not a positive finite number, or a class list without
            ``"person"``.
    """
    if not (math.isfinite(px_per_m) and px_per_m > 0 and math.isfinite(margin_m) and margin_m > 0):
        raise ValueError(f"px_per_m and margin_m must be positive, got {px_per_m} and {margin_m}")
    if PERSON not in net.classes:
        raise ValueError(f"the net has no {PERSON!r} class (classes: {', '.join(net.classes)})")
    k = net.classes.index(PERSON)
    threshold = SENSITIVITY * float(net.cell_thresholds[k])
    h, w = image.shape[:2]
    u, v = site_px
    reach = margin_m * px_per_m
    x0, x1 = max(0, int(u - reach)), min(w, math.ceil(u + reach))
    y0, y1 = max(0, int(v - reach)), min(h, math.ceil(v + reach))
    if x1 - x0 < 8 or y1 - y0 < 8:
        return PeopleSeen(0, None, 0.0)
    tile = max(MIN_TILE_PX, round(TILE_M * px_per_m))
    nearest = math.inf
    cells = 0
    where: list[tuple[float, float]] = []
    for ty in _starts(y0, y1, tile):
        for tx in _starts(x0, x1, tile):
            part = image[ty : min(ty + tile, y1), tx : min(tx + tile, x1)]
            th, tw = part.shape[:2]
            if th > READ_PX or tw > READ_PX:
                scale = READ_PX / max(th, tw)
                part = cv2.resize(
                    part, (max(8, round(tw * scale)), max(8, round(th * scale))), interpolation=cv2.INTER_AREA
                )
            present = net.probabilities(np.ascontiguousarray(part))[k] >= threshold
            rows, cols = np.nonzero(present)
            if not len(rows):
                continue
            cu = tx + (cols + 0.5) * tw / present.shape[1]
            cv = ty + (rows + 0.5) * th / present.shape[0]
            d = np.hypot(cu - u, cv - v) / px_per_m
            inside = d <= margin_m
            cells += int(inside.sum())
            if inside.any():
                nearest = min(nearest, float(d[inside].min()))
                where.extend(zip(cu[inside].tolist(), cv[inside].tolist(), strict=True))
    return PeopleSeen(cells, None if cells == 0 else nearest, _seen_share(u, v, reach, w, h), tuple(where))


def _starts(a: int, b: int, tile: int) -> list[int]:
    """Tile origins covering [a, b): every ``tile`` pixels, the last one ending at ``b`` (overlapping
    its neighbour rather than reading a sliver)."""
    if b - a <= tile:
        return [a]
    out = list(range(a, b - tile, tile))
    out.append(b - tile)
    return out


def _seen_share(u: float, v: float, reach: float, w: int, h: int) -> float:
    """The share of the disc of radius ``reach`` around (u, v) inside a ``w`` x ``h`` image."""
    ys, xs = np.mgrid[-1:1:41j, -1:1:41j]
    inside = xs**2 + ys**2 <= 1.0
    px, py = u + xs[inside] * reach, v + ys[inside] * reach
    return float(np.mean((px >= 0) & (px < w) & (py >= 0) & (py < h)))
