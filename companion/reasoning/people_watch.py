"""People near a site: what the onboard net sees of people within a margin of the site, in a camera frame.

The confirmation judges the site's own window; a person a few metres beyond it is not in that window,
and a regulator's margin (no one within 10 m of the touchdown) reaches further. :func:`people_near`
reads the frame around the site's pixel out to ``margin_m`` in square tiles, each at about the scale
the net learnt people at (``TILE_M`` metres per tile at the finest, that is 3 cm a pixel over the
net's 128-pixel views; a tile seen coarser than that is read as it is, from ``MIN_TILE_PX`` pixels),
and counts the cells where the net says a person is present whose centres lie within ``margin_m`` of
the site. The frame's scale at the site (pixels per metre) comes from the caller, who knows the pose.

The LiDAR then has its say (:func:`lidar_check`): a person stands, and a cell whose ground the LiDAR
swept and found nothing standing on is a texture the net took for a person. On simbridge's hillside
meadows LandNet-E found 15-60 such cells in every look from 15 to 50 m up, with no one within 250 m
(2026-12-03), and the vehicle held and gave up site after site. A cell the LiDAR did not see stays a
person: the LiDAR only ever takes a person away where it measured the ground bare.

The net decides what a person is: the packaged nets learnt people from simbridge's renders (pedestrians
1.7 m tall seen from 3-25 cm a pixel) and do not see everyone: from 15-25 m above suburban lawns
LandNet-S found about half of the people in view (docs/reasoning.md). A watch that sees no one is no
proof that no one is there; one that sees someone is a reason to wait.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from companion.guidance.frames import PinholeCamera
from companion.guidance.ipm import IpmError, LidarPixelIndex
from companion.perception.site_check import world_points
from companion.reasoning.landnet import LandNet

__all__ = ["MIN_TILE_PX", "TILE_M", "PeopleSeen", "lidar_check", "people_in_frame", "people_near"]

TILE_M = 3.84  # a tile's side on the ground at the finest: 128 px at 3 cm a pixel
MIN_TILE_PX = 96  # a tile is never read from fewer pixels than this (coarser frames: as they are)
READ_PX = 128  # the side a fine tile is reduced to before the net reads it
SENSITIVITY = 0.5  # a person cell at this share of the net's own threshold: a watch would rather hold
PERSON = "person"
PERSON_MIN_HEIGHT_M = 0.8  # a return this far above the ground around a cell: something stands there
LIDAR_NEAR_M = 0.75  # returns whose image position lies within this (on the ground) of a cell are its own
LIDAR_GROUND_M = 3.0  # the ground around a cell: a plane through the returns within this
LIDAR_MIN_RETURNS = 4  # fewer of its own returns: the LiDAR did not see the cell, the camera's word stands


@dataclass(frozen=True, slots=True)
class PeopleSeen:
    """What :func:`people_near` found: person cells within the margin, the nearest one's distance from
    the site (metres; None when none), the share of the margin's disc the frame showed, and where in
    the image each person cell is (pixel centres u, v: where to step aside from)."""

    cells: int
    nearest_m: float | None
    seen_share: float
    cells_px: tuple[tuple[float, float], ...] = ()
    refuted: int = 0  # cells the net saw and the LiDAR found bare ground under (:func:`lidar_check`)

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


def lidar_check(
    seen: PeopleSeen,
    returns_px: np.ndarray,
    returns_up_m: np.ndarray,
    returns_ne_m: np.ndarray,
    site_px: tuple[float, float],
    px_per_m: float,
) -> PeopleSeen:
    """``seen`` less the person cells the LiDAR refutes (module docstring): a cell with at least
    ``LIDAR_MIN_RETURNS`` returns within ``LIDAR_NEAR_M`` of it in the image (at the site's scale
    ``px_per_m``), none of them ``PERSON_MIN_HEIGHT_M`` above the plane fitted through the returns
    within ``LIDAR_GROUND_M`` (a slope is ground, not a person). ``returns_px`` (M, 2) are the returns'
    image positions, ``returns_up_m`` their heights (metres up) and ``returns_ne_m`` (M, 2) their
    north and east. The nearest person is measured again among the cells kept (image distance from
    ``site_px``); ``refuted`` counts those taken away."""
    if not seen.cells_px or len(returns_px) < LIDAR_MIN_RETURNS:
        return seen
    from scipy.spatial import cKDTree

    tree = cKDTree(np.asarray(returns_px, dtype=np.float64))
    up = np.asarray(returns_up_m, dtype=np.float64)
    ne = np.asarray(returns_ne_m, dtype=np.float64)
    kept: list[tuple[float, float]] = []
    for u, v in seen.cells_px:
        own = tree.query_ball_point((u, v), LIDAR_NEAR_M * px_per_m)
        if len(own) < LIDAR_MIN_RETURNS or _stands(
            own, tree.query_ball_point((u, v), LIDAR_GROUND_M * px_per_m), up, ne
        ):
            kept.append((u, v))
    if len(kept) == len(seen.cells_px):
        return seen
    su, sv = site_px
    dist = [math.hypot(u - su, v - sv) / px_per_m for u, v in kept]
    return PeopleSeen(
        len(kept), min(dist) if dist else None, seen.seen_share, tuple(kept), len(seen.cells_px) - len(kept)
    )


def _stands(own: list[int], around: list[int], up: np.ndarray, ne: np.ndarray) -> bool:
    """Whether one of the returns ``own`` stands ``PERSON_MIN_HEIGHT_M`` above the ground plane fitted
    (least squares, then again without what stood out) through the returns ``around``."""
    idx = np.asarray(around)
    a = np.column_stack([ne[idx], np.ones(len(idx))])
    keep = np.ones(len(idx), bool)
    for _ in range(2):  # a person's own returns pull the plane up: fitted again without them
        if keep.sum() < 3:
            return True  # too little ground to judge by: the camera's word stands
        coef = np.linalg.lstsq(a[keep], up[idx][keep], rcond=None)[0]
        keep = up[idx] - a @ coef < 0.5 * PERSON_MIN_HEIGHT_M
    mine = np.asarray(own)
    height = up[mine] - np.column_stack([ne[mine], np.ones(len(mine))]) @ coef
    return bool(height.max() >= PERSON_MIN_HEIGHT_M)


def people_in_frame(
    net: LandNet,
    frame: Any,
    camera: PinholeCamera,
    site_px: tuple[float, float],
    px_per_m: float,
    margin_m: float,
) -> PeopleSeen:
    """:func:`people_near` in a sensor frame's image, less what the LiDAR's sweep of the same frame
    refutes (:func:`lidar_check`); the image's word alone without a sweep."""
    seen = people_near(net, frame.image_rgb, site_px, px_per_m, margin_m)
    if not seen.cells or frame.lidar_frd is None:
        return seen
    try:
        index = LidarPixelIndex(frame.lidar_frd, camera)
    except IpmError:
        return seen
    ned = world_points(index.points_frd, frame.pos_ned_m, frame.quat_wxyz)
    return lidar_check(seen, index.uv, -ned[:, 2], ned[:, :2], site_px, px_per_m)
