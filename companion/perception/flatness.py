"""Flatness of every depth cell: slope and roughness in physical units, or a relative gradient test.

Metric depth: each cell is back-projected through the pinhole model to a 3-D point, rotated into a
level frame (north, east, down relative to the camera, using the vehicle attitude), and a plane
``down = a * north + b * east + c`` is least-squares fitted to the *measured* cells (LiDAR returns, not
the filled ones: filling would smear a parapet's height into the roof beside it) in the ``window`` x
``window`` cells around it. Slope is the plane's angle from horizontal, ``atan(hypot(a, b))``;
roughness is the RMS residual of the points about the plane. The fit uses running sums (box
filters) of the point moments, so every window costs the same whatever its size. A cell is flat
when its window lies wholly inside the depth map's known area, holds at least 6 measured cells, has
a slope of at most ``max_slope_deg`` and a roughness of at most ``max_roughness_m``. Because the
whole window must be flat, flat cells lie at least half a window inside the edge of their surface:
Surface ID adds that half-window back when it measures the distance to an edge.

Relative depth (a monocular network): no metric units exist, so a cell is flat when the depth
gradient everywhere in its window is at most ``max_relative_gradient`` of the frame's depth range per
cell. A horizontal surface under a nadir camera has a constant depth, whatever the unknown scale.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from companion.guidance.frames import CAMERA_TO_BODY, PinholeCamera, quat_to_matrix
from companion.perception.depth import DepthMap

__all__ = ["Flatness", "flatness"]

_MIN_FIT_POINTS = 6  # measured cells a window needs for a plane fit


@dataclass(frozen=True, slots=True)
class Flatness:
    """Per-cell flatness on the depth map's grid.

    Attributes:
        flat: bool, the cell's whole window passes the test.
        slope_deg, roughness_m: float32, NaN where not fitted (relative depth: all NaN).
        ned_m: (rows, cols, 3) float64 level-frame position of each cell's point relative to the
            camera (north, east, down); NaN where unknown. Relative depth: NaN.
        cell_m: float32, metres per cell side at the cell's depth (NaN for relative depth).
        half_window: cells between a window's centre and its side.
    """

    flat: np.ndarray
    slope_deg: np.ndarray
    roughness_m: np.ndarray
    ned_m: np.ndarray
    cell_m: np.ndarray
    half_window: int


def _box(a: np.ndarray, k: int) -> np.ndarray:
    return cv2.boxFilter(a, cv2.CV_64F, (k, k), normalize=False, borderType=cv2.BORDER_CONSTANT)


def cell_points(depth: DepthMap, camera: PinholeCamera, quat_wxyz: tuple[float, ...]) -> np.ndarray:
    """(rows, cols, 3) level-frame (north, east, down) metres of every cell centre's point."""
    rows, cols = depth.shape
    s = depth.cell_px
    u = (np.arange(cols) + 0.5) * s
    v = (np.arange(rows) + 0.5) * s
    z = depth.depth.astype(np.float64)
    x = ((u[None, :] - camera.cx) / camera.fx) * z
    y = ((v[:, None] - camera.cy) / camera.fy) * z
    m = quat_to_matrix(quat_wxyz) @ CAMERA_TO_BODY  # camera -> level NED
    return np.stack([m[i, 0] * x + m[i, 1] * y + m[i, 2] * z for i in range(3)], axis=-1)


def flatness(
    depth: DepthMap,
    camera: PinholeCamera,
    quat_wxyz: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0),
    *,
    window: int = 5,
    max_slope_deg: float = 8.0,
    max_roughness_m: float = 0.06,
    max_relative_gradient: float = 0.004,
) -> Flatness:
    if window < 3 or window % 2 == 0:
        raise ValueError(f"the flatness window must be an odd number of cells >= 3, got {window}")
    if depth.metric:
        return _metric(depth, camera, quat_wxyz, window, max_slope_deg, max_roughness_m)
    return _relative(depth, window, max_relative_gradient)


def _metric(
    depth: DepthMap,
    camera: PinholeCamera,
    quat_wxyz: tuple[float, float, float, float],
    k: int,
    max_slope_deg: float,
    max_roughness_m: float,
) -> Flatness:
    valid = depth.valid
    fit = valid if depth.measured is None else depth.measured & valid
    ned = cell_points(depth, camera, quat_wxyz)
    # Centre the coordinates on the frame's mean point: the moments stay small and exact in float64.
    # A map without a measured cell (a depth image finite only between cell centres) fits nothing.
    mean = ned[fit].mean(axis=0) if fit.any() else np.zeros(3)
    n, e, d = (np.where(fit, ned[..., i] - mean[i], 0.0) for i in range(3))
    full = _box(valid.astype(np.float64), k) >= k * k - 0.5
    count = _box(fit.astype(np.float64), k)
    full &= count >= _MIN_FIT_POINTS
    inv = 1.0 / np.maximum(count, 1.0)
    mn, me, md = _box(n, k) * inv, _box(e, k) * inv, _box(d, k) * inv
    cnn = _box(n * n, k) * inv - mn * mn
    cee = _box(e * e, k) * inv - me * me
    cne = _box(n * e, k) * inv - mn * me
    cnd = _box(n * d, k) * inv - mn * md
    ced = _box(e * d, k) * inv - me * md
    cdd = _box(d * d, k) * inv - md * md
    det = cnn * cee - cne * cne
    ok = full & (det > 1e-9 * np.maximum(cnn + cee, 1e-12) ** 2)
    safe = np.where(ok, det, 1.0)
    a = (cnd * cee - ced * cne) / safe
    b = (ced * cnn - cnd * cne) / safe
    slope = np.degrees(np.arctan(np.hypot(a, b)))
    rough = np.sqrt(np.maximum(cdd - (a * cnd + b * ced), 0.0))
    slope = np.where(ok, slope, np.nan).astype(np.float32)
    rough = np.where(ok, rough, np.nan).astype(np.float32)
    with np.errstate(invalid="ignore"):
        flat = ok & (slope <= max_slope_deg) & (rough <= max_roughness_m)
    cell_m = (depth.depth / camera.fx * depth.cell_px).astype(np.float32)
    ned[~valid] = np.nan
    return Flatness(flat, slope, rough, ned, cell_m, k // 2)


def _relative(depth: DepthMap, k: int, max_gradient: float) -> Flatness:
    valid = depth.valid
    rel = np.where(valid, depth.depth, 0.0).astype(np.float32)
    gx = cv2.Sobel(rel, cv2.CV_32F, 1, 0, ksize=3) / 8.0
    gy = cv2.Sobel(rel, cv2.CV_32F, 0, 1, ksize=3) / 8.0
    grad = np.hypot(gx, gy)
    # Sobel at a cell reads its 8 neighbours: an unknown neighbour makes the cell unknown too.
    unknown = cv2.dilate((~valid).astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
    grad[unknown] = np.inf
    worst = cv2.dilate(grad, np.ones((k, k), np.uint8), borderType=cv2.BORDER_CONSTANT, borderValue=np.inf)
    flat = worst <= max_gradient
    nan = np.full(depth.shape, np.nan, np.float32)
    return Flatness(flat, nan, nan.copy(), np.full((*depth.shape, 3), np.nan), nan.copy(), k // 2)
