"""The classes LandNet-S sees, and how simbridge's per-pixel truth maps onto them.

A pixel's class comes from what the camera ray hit (``Frame.hit_class``, ``hit_material``,
``hit_kind``): the top of a roof is ``roof`` (paint and letters on it included; slope is geometry's
business), anything standing on a roof is ``object`` (its top and its sides), a parapet, a rail or a
building's wall is ``edge``, painted lane markings and zebras are ``marking`` whatever they are painted
on. Sky is ``IGNORE``.
"""

from __future__ import annotations

import numpy as np

from simbridge.world.camera import LABEL_SKY
from simbridge.world.model import Material as M
from simbridge.world.model import SurfaceClass as C
from simbridge.world.raycast import HIT_TOP

__all__ = ["CLASSES", "CLASSES_WITH_CROP", "CROP", "HAZARD_CLASSES", "IGNORE", "label_map", "site_clear"]

CLASSES = (
    "roof",  # 0 the top of a roof: flat or pitched, any material, paint included
    "object",  # 1 something on a roof: HVAC, vents, pipes, domes, antennas, panels, rubble, chimneys
    "edge",  # 2 parapets, guard rails, walls
    "person",  # 3
    "vehicle",  # 4
    "water",  # 5
    "low_vegetation",  # 6 grass, lawns
    "tree",  # 7
    "road",  # 8 roads, highways, crosswalks and parking (asphalt where traffic runs)
    "marking",  # 9 painted lane lines and zebras
    "ground",  # 10 sidewalks, plazas, piers, bare ground
)
IGNORE = 255
# The classes of a model that also tells standing crops from grass (LandNet-E's second cell head,
# landfall_train.cells_head): ``crop`` after the eleven, so the others keep their indices.
CLASSES_WITH_CROP = (*CLASSES, "crop")
CROP = len(CLASSES)  # 11
# Classes whose presence on a site makes it no clear place to land.
HAZARD_CLASSES = (1, 3, 4, 5, 9)
CLEAR_ROOF_SHARE = 0.85  # site_clear: at least this share of the (non-sky) patch is roof surface ...

_TOP = np.full(256, 10, np.uint8)  # class of a top hit, by SurfaceClass
for _c, _k in {
    C.ROOF_FLAT: 0,
    C.ROOF_PITCHED: 0,
    C.ROOF_CLUTTER: 1,
    C.PARAPET: 2,
    C.GUARD_RAIL: 2,
    C.PEDESTRIAN: 3,
    C.VEHICLE: 4,
    C.WATER: 5,
    C.GRASS: 6,
    C.TREE: 7,
    C.ROAD: 8,
    C.HIGHWAY: 8,
    C.CROSSWALK: 8,
    C.PARKING_LOT: 8,
    C.PARKING_ROOF: 8,
    C.RAIL: 8,
    C.MACHINERY: 1,
    C.CROP: 6,
}.items():
    _TOP[int(_c)] = _k
_WALL = np.full(256, 2, np.uint8)  # class of a wall hit: a wall, unless it is the side of an object
# (a pitched roof is stepped on the grid: the risers of its steps are roof too)
for _c, _k in {
    C.ROOF_CLUTTER: 1,
    C.PEDESTRIAN: 3,
    C.VEHICLE: 4,
    C.TREE: 7,
    C.ROOF_PITCHED: 0,
    C.MACHINERY: 1,
}.items():
    _WALL[int(_c)] = _k
_MARKING = np.zeros(256, bool)
_MARKING[[int(M.LANE_MARKING), int(M.ZEBRA)]] = True


def label_map(
    hit_class: np.ndarray, hit_material: np.ndarray, hit_kind: np.ndarray, crops: bool = False
) -> np.ndarray:
    """(H, W) uint8 class index per pixel (``CLASSES``; ``IGNORE`` for sky) from a labelled render;
    ``crops``: standing crops are ``CROP`` (``CLASSES_WITH_CROP``) instead of ``low_vegetation``."""
    top = hit_kind == HIT_TOP
    out = np.where(top, _TOP[hit_class], _WALL[hit_class]).astype(np.uint8)
    if crops:
        out[top & (hit_class == int(C.CROP))] = CROP
    out[top & _MARKING[hit_material]] = 9
    out[hit_kind == LABEL_SKY] = IGNORE
    return np.asarray(out, np.uint8)


def site_clear(labels: np.ndarray, roof_share: float = CLEAR_ROOF_SHARE) -> bool:
    """A patch is a clear landing site: at least ``roof_share`` of what is not sky is roof surface,
    and not one pixel shows an object, a person, a vehicle, water or a painted marking."""
    seen = labels != IGNORE
    n = int(seen.sum())
    if n == 0:
        return False
    if np.isin(labels, HAZARD_CLASSES).any():
        return False
    return float((labels == 0).sum()) >= roof_share * n
