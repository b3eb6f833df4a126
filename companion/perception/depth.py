"""Depth sources behind one interface: LiDAR (metric), a saved array (evaluation), monocular (relative).

Every source turns what the drone has into a :class:`DepthMap` on the camera's image grid, coarsened by
``cell_px`` pixels per cell (Surface ID works on cells, not pixels: 960 x 540 at 4 px is 240 x 135).

- :class:`LidarDepth` (the default when a LiDAR is present): returns in body FRD are rotated into the
  camera frame (``CAMERA_TO_BODY``), projected with the pinhole model and z-buffered into cells (the
  nearest return wins). The sparse cells are densified by a morphological closing of the sampled
  mask (which fills the gaps between scan rings but never grows the outline of what was seen: past a
  roof's edge, where the ground lies out of range, stays unknown) and nearest-sample filling inside it.
  A horizontal surface under a nadir camera has a constant z-depth, so nearest filling is exact there
  and close to it for the few degrees a hovering vehicle tilts.
- :class:`ArrayDepth`: a depth image from a file (``simbridge render --depth-out``), metric or not,
  sampled at each cell's centre pixel.
- :class:`companion.perception.mono_depth.DepthAnythingV2`: relative depth from the image alone
  (:func:`companion.perception.sources.make_source` builds the configured one)
  (optional ``depth`` extra; torch).

Depth is the camera z coordinate (along the optical axis), not the range along the ray; NaN marks
cells with no measurement. Bad input raises :class:`DepthError` naming what was wrong.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

import cv2
import numpy as np
import numpy.typing as npt

from companion.config_schema import DEFAULTS
from companion.guidance.frames import PinholeCamera

__all__ = [
    "ArrayDepth",
    "DepthError",
    "DepthMap",
    "DepthSource",
    "FirstAvailable",
    "LidarDepth",
    "load_depth_file",
]


class DepthError(ValueError):
    """Depth input that cannot be used (wrong shape, no finite values, no LiDAR returns, no model)."""


@dataclass(frozen=True, slots=True)
class DepthMap:
    """Depth on the image's cell grid.

    Attributes:
        depth: (rows, cols) float32; camera z in metres when ``metric``, else relative depth in [0, 1]
            (0 nearest, 1 farthest in this frame); NaN where unknown.
        metric: whether ``depth`` is in metres.
        cell_px: image pixels per cell side; cell ``(r, c)`` covers pixels
            ``[c * cell_px, (c + 1) * cell_px) x [r * cell_px, (r + 1) * cell_px)``.
        source: ``"lidar"``, ``"file"`` or the monocular model's name.
        measured: (rows, cols) bool, cells holding a measurement (the rest were filled), or None.
        max_range_m: the sensor's range, when a cell can be unknown because its surface lies beyond it.
        ring_spacing_rad: for a scanning sensor, the angle between its scan rings (its last ring on
            a surface may fall that far short of the range); None for a dense one.
    """

    depth: np.ndarray
    metric: bool
    cell_px: int
    source: str
    measured: np.ndarray | None = field(default=None, repr=False)
    max_range_m: float | None = None
    ring_spacing_rad: float | None = None

    @property
    def shape(self) -> tuple[int, int]:
        rows, cols = self.depth.shape
        return int(rows), int(cols)

    @property
    def valid(self) -> np.ndarray:
        out: np.ndarray = np.isfinite(self.depth)
        return out


class DepthSource(Protocol):
    """Anything that makes a :class:`DepthMap` for one frame."""

    @property
    def name(self) -> str: ...

    def depth_map(
        self, camera: PinholeCamera, *, image: np.ndarray | None = None, lidar_frd: np.ndarray | None = None
    ) -> DepthMap: ...


def grid_shape(camera: PinholeCamera, cell_px: int) -> tuple[int, int]:
    if not isinstance(cell_px, int) or cell_px < 1:
        raise DepthError(f"cell_px must be an integer >= 1, got {cell_px!r}")
    return math.ceil(camera.height / cell_px), math.ceil(camera.width / cell_px)


def lidar_points(lidar_frd: npt.ArrayLike | None) -> np.ndarray:
    """LiDAR rows as a finite (N, 3) float64 array of body FRD metres; DepthError when none are usable."""
    if lidar_frd is None:
        raise DepthError("no LiDAR sweep in this frame")
    arr = np.asarray(lidar_frd)
    if arr.ndim != 2 or arr.shape[1] < 3:
        raise DepthError(
            f"LiDAR points must be an (N, 3) or (N, 4) array of body FRD metres, got {arr.shape}"
        )
    if not np.issubdtype(arr.dtype, np.number):
        raise DepthError(f"LiDAR points must be numbers, got dtype {arr.dtype}")
    pts = arr[:, :3].astype(np.float64)
    pts = pts[np.isfinite(pts).all(axis=1)]
    if len(pts) == 0:
        raise DepthError(f"the LiDAR sweep has no finite returns ({arr.shape[0]} rows)")
    return pts


def _close_kernel(gap_cells: int) -> np.ndarray:
    size = 2 * gap_cells + 1
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (size, size))


def densify(sparse: np.ndarray, gap_cells: int) -> np.ndarray:
    """Fill NaN cells lying between samples (closing of the sampled mask) with the nearest sample."""
    sampled = np.isfinite(sparse)
    if not sampled.any():
        return sparse
    inside = cv2.morphologyEx(sampled.astype(np.uint8), cv2.MORPH_CLOSE, _close_kernel(gap_cells)).astype(
        bool
    )
    # Nearest sampled cell for every cell: the distance transform's labels over the unsampled cells.
    _, labels = cv2.distanceTransformWithLabels(
        (~sampled).astype(np.uint8), cv2.DIST_L2, 3, labelType=cv2.DIST_LABEL_PIXEL
    )
    values = np.zeros(int(labels.max()) + 1, np.float32)
    values[labels[sampled]] = sparse[sampled]
    dense: np.ndarray = values[labels]
    dense[~inside] = np.nan
    return dense


@dataclass(frozen=True, slots=True)
class LidarDepth:
    """Metric depth from a LiDAR sweep projected into the image and densified.

    Args:
        cell_px: image pixels per depth cell.
        gap_cells: largest gap between samples, in cells, that is filled (the scan-ring spacing in the
            image; 1.5 m rings seen from 90 m are 8 px apart).
        range_m: the LiDAR's maximum range (a surface farther away returns nothing).
    """

    cell_px: int = DEFAULTS.perception.cell_px
    gap_cells: int = 3
    range_m: float = DEFAULTS.perception.lidar_range_m
    name: str = "lidar"

    def depth_map(
        self, camera: PinholeCamera, *, image: np.ndarray | None = None, lidar_frd: np.ndarray | None = None
    ) -> DepthMap:
        rows, cols = grid_shape(camera, self.cell_px)
        pts = lidar_points(lidar_frd)
        uv, front = camera.project_frd(pts)
        inside = front & camera.in_image(uv)
        if not inside.any():
            raise DepthError(f"none of the {len(pts)} LiDAR returns falls inside the camera image")
        c = np.floor(uv[inside, 0] / self.cell_px).astype(np.int64)
        r = np.floor(uv[inside, 1] / self.cell_px).astype(np.int64)
        z = pts[inside, 2].astype(np.float32)  # camera z is body z (CAMERA_TO_BODY)
        # z-buffer: write far to near so the nearest return in a cell is the one left.
        order = np.argsort(-z, kind="stable")
        sparse = np.full((rows, cols), np.nan, np.float32)
        sparse[r[order], c[order]] = z[order]
        measured = np.isfinite(sparse)
        dense = densify(sparse, self.gap_cells)
        return DepthMap(dense, True, self.cell_px, self.name, measured, self.range_m, ring_spacing_rad(pts))


def ring_spacing_rad(points_frd: np.ndarray) -> float | None:
    """The angle between a scanning LiDAR's rings, from its returns: the median gap between the
    distinct elevations they come back at (range noise moves a return along its ray, never off its
    ring). None with fewer than four rings seen or for returns at no repeated elevations."""
    if len(points_frd) < 8:
        return None
    el = np.sort(np.arctan2(points_frd[:, 2], np.hypot(points_frd[:, 0], points_frd[:, 1])))
    gaps = np.diff(el)
    rings = gaps[gaps > _RING_GAP_MIN_RAD]
    if len(rings) < 3 or len(rings) > len(el) // 4:  # not rings: returns at scattered elevations
        return None
    return float(np.median(rings))


_RING_GAP_MIN_RAD = math.radians(0.05)


def to_cells(depth_px: np.ndarray, camera: PinholeCamera, cell_px: int) -> np.ndarray:
    """A full-resolution depth image -> cells: each cell takes its centre pixel's depth.

    Point samples, like LiDAR returns: averaging a block would hide the roughness the flatness test
    measures, and its minimum would bias it.
    """
    rows, cols = grid_shape(camera, cell_px)
    half = cell_px // 2
    r = np.minimum(np.arange(rows) * cell_px + half, depth_px.shape[0] - 1)
    c = np.minimum(np.arange(cols) * cell_px + half, depth_px.shape[1] - 1)
    return np.ascontiguousarray(depth_px[np.ix_(r, c)], dtype=np.float32)


def check_depth_image(depth: npt.ArrayLike, camera: PinholeCamera, what: str) -> np.ndarray:
    arr = np.asarray(depth)
    if arr.ndim == 3 and arr.shape[2] == 1:
        arr = arr[:, :, 0]
    if arr.shape != (camera.height, camera.width):
        raise DepthError(
            f"{what} must be {camera.height} x {camera.width} (rows x columns, as the camera image), "
            f"got {arr.shape}"
        )
    if not np.issubdtype(arr.dtype, np.number):
        raise DepthError(f"{what} must hold numbers, got dtype {arr.dtype}")
    out = arr.astype(np.float32)
    out[~np.isfinite(out)] = np.nan
    if not np.isfinite(out).any():
        raise DepthError(f"{what} has no finite values")
    return out


@dataclass(frozen=True, slots=True)
class ArrayDepth:
    """A depth image given as an array (a file in evaluation). Metric depth must be positive metres."""

    depth_px: np.ndarray
    metric: bool = True
    cell_px: int = DEFAULTS.perception.cell_px
    name: str = "file"

    def depth_map(
        self, camera: PinholeCamera, *, image: np.ndarray | None = None, lidar_frd: np.ndarray | None = None
    ) -> DepthMap:
        px = check_depth_image(self.depth_px, camera, "the depth image")
        if self.metric:
            px[px <= 0] = np.nan
            if not np.isfinite(px).any():
                raise DepthError("the metric depth image has no positive values")
        else:
            px = normalise_relative(px)
        cells = to_cells(px, camera, self.cell_px)
        return DepthMap(cells, self.metric, self.cell_px, self.name, np.isfinite(cells))


def normalise_relative(depth: np.ndarray) -> np.ndarray:
    """Relative depth scaled to [0, 1] by its 1st and 99th percentiles (robust to a few outliers)."""
    finite = depth[np.isfinite(depth)]
    lo, hi = np.percentile(finite, [1, 99])
    span = float(hi - lo) if hi > lo else 1.0
    out: np.ndarray = np.clip((depth - lo) / span, 0.0, 1.0).astype(np.float32)
    return out


@dataclass(frozen=True, slots=True)
class FirstAvailable:
    """The first source that has depth for this frame (e.g. the LiDAR, then the image alone)."""

    sources: tuple[DepthSource, ...]
    name: str = "auto"

    def depth_map(
        self, camera: PinholeCamera, *, image: np.ndarray | None = None, lidar_frd: np.ndarray | None = None
    ) -> DepthMap:
        problems = []
        for src in self.sources:
            try:
                return src.depth_map(camera, image=image, lidar_frd=lidar_frd)
            except DepthError as exc:
                problems.append(f"{src.name}: {exc}")
        raise DepthError("; ".join(problems) or "no depth source configured")


def load_depth_file(path: Path) -> np.ndarray:
    """A depth image saved with numpy (``.npy``); DepthError for anything else."""
    try:
        arr = np.load(path, allow_pickle=False)
    except (OSError, ValueError) as exc:
        raise DepthError(f"{path}: not a readable .npy array ({exc})") from exc
    if not isinstance(arr, np.ndarray):
        raise DepthError(f"{path}: expected one array, got {type(arr).__name__}")
    return arr
