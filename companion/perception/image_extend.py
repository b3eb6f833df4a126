"""Extending a measured surface across cells the LiDAR never reached, using the camera image.

A LiDAR with a 100 m range, 115 m up, sees only the middle of a wide roof: the rest is unknown, not
uneven. The camera sees all of it. A measured flat surface is grown, cell by cell (4-connected), into
*unknown* cells only (never across a measured cell, so never past a parapet, a wall or a step the
LiDAR saw) whose colour matches the measured part (CIELAB, within 3 robust standard deviations of its
median, and at least ``min_colour_tol``) and which hold no image edge stronger than the measured part's
own texture (gradient magnitude above its 95th percentile x ``edge_factor``: a roof's edge, a
parapet's line, a kerb), and only where the sensor could not have seen the surface: where its plane,
carried on to the cell, lies beyond the LiDAR's range (``allowed``). A sidewalk beside a roof is
unknown because the ground there is out of range; the roof's plane there would be in range and
would have answered, so the roof does not continue there. The grown cells widen the candidate's
box for the reasoner; the landing site itself stays on measured cells, and the close-up check
before every descent measures the rest.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

__all__ = ["ImageCells", "extend_unmeasured"]


@dataclass(frozen=True, slots=True)
class ImageCells:
    """The camera image summarised on the depth grid: mean CIELAB colour and strongest edge per cell."""

    lab: np.ndarray  # (rows, cols, 3) float32
    edge: np.ndarray  # (rows, cols) float32, the largest grey-level gradient magnitude in the cell

    @classmethod
    def from_image(cls, image_rgb: np.ndarray, rows: int, cols: int, cell_px: int) -> ImageCells:
        h, w = rows * cell_px, cols * cell_px
        img = np.zeros((h, w, 3), np.uint8)
        ih, iw = min(h, image_rgb.shape[0]), min(w, image_rgb.shape[1])
        img[:ih, :iw] = image_rgb[:ih, :iw]
        small = cv2.resize(img, (cols, rows), interpolation=cv2.INTER_AREA)
        lab = cv2.cvtColor(small, cv2.COLOR_RGB2LAB).astype(np.float32)
        grey = cv2.cvtColor(img, cv2.COLOR_RGB2GRAY)
        gx = cv2.Sobel(grey, cv2.CV_32F, 1, 0, ksize=3)
        gy = cv2.Sobel(grey, cv2.CV_32F, 0, 1, ksize=3)
        mag = cv2.magnitude(gx, gy)
        # The largest value in each cell: a cell-sized dilation, sampled where its window is the cell.
        pooled = cv2.dilate(mag, np.ones((cell_px, cell_px), np.uint8))
        edge = np.ascontiguousarray(pooled[cell_px // 2 :: cell_px, cell_px // 2 :: cell_px][:rows, :cols])
        return cls(lab, edge)


def extend_unmeasured(
    surface: np.ndarray,
    known: np.ndarray,
    cells: ImageCells,
    *,
    allowed: np.ndarray | None = None,
    min_colour_tol: float = 6.0,
    edge_factor: float = 1.5,
) -> np.ndarray:
    """Unknown cells (``~known``) reachable from ``surface`` through cells that look like it."""
    if not surface.any() or known.all():
        return np.zeros_like(surface)
    seed = cells.lab[surface]
    med = np.median(seed, axis=0)
    spread = 1.4826 * np.median(np.abs(seed - med), axis=0)
    tol = np.maximum(3.0 * spread, min_colour_tol)
    edge_tol = float(np.percentile(cells.edge[surface], 95)) * edge_factor
    alike = np.all(np.abs(cells.lab - med) <= tol, axis=-1) & (cells.edge <= edge_tol) & ~known
    if allowed is not None:
        alike &= allowed
    if not alike.any():
        return np.zeros_like(surface)
    _count, labels = cv2.connectedComponents((alike | surface).astype(np.uint8), connectivity=4)
    touching = np.unique(labels[surface])
    reach = np.isin(labels, touching[touching > 0])
    out: np.ndarray = reach & alike
    return out
