"""Extending a measured surface across cells the LiDAR never reached, using the camera image.

A LiDAR with a 100 m range, 115 m up, sees only the middle of a wide roof: the rest is unknown, not
uneven. The camera sees all of it. A measured flat surface is grown, cell by cell (4-connected), into
*unknown* cells only (never across a measured cell, so never past a parapet, a wall or a step the
LiDAR saw) whose colour matches the measured part (CIELAB, within 3 robust standard deviations of its
median, and at least ``min_colour_tol``) and which hold no image edge stronger than the surface's own
texture (gradient magnitude above the 95th percentile of its flat interior x ``edge_factor``: a
roof's edge, a parapet's line, a kerb). Growth starts only from the surface's cells without such an
edge, so a parapet's line on the surface's rim is a wall too; the cell that holds the stopping edge
is taken (the surface reaches up to it), nothing beyond.

The caller also says where the surface could be at all (``allowed``: a function that keeps those of
the candidate cells it is given): where the sensor could not
have seen it (surface_id.py: its plane, carried on, lies beyond the LiDAR's range, straight out from
where the LiDAR saw it at that range). The grown cells widen the candidate's box for the reasoner;
the landing site itself stays on measured cells, and the close-up check before every descent
measures the rest.
"""

from __future__ import annotations

from collections.abc import Callable
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


def warm_up() -> None:
    """Run :meth:`ImageCells.from_image` once on a tiny image: OpenCV builds its CIELAB tables on the
    first conversion (about 0.1 s on this project's machine), which the first alarm's Surface ID would
    otherwise pay."""
    ImageCells.from_image(np.zeros((16, 16, 3), np.uint8), 2, 2, 8)


def extend_unmeasured(
    surface: np.ndarray,
    known: np.ndarray,
    cells: ImageCells,
    *,
    allowed: Callable[[np.ndarray], np.ndarray] | None = None,
    sample: np.ndarray | None = None,
    min_colour_tol: float = 6.0,
    edge_factor: float = 1.5,
) -> np.ndarray:
    """Unknown cells (``~known``) reachable from ``surface`` through cells that look like it.

    ``sample``: the cells whose texture stands for the surface's (default: all of it); its flat
    interior, say, without the cells at its rim that hold a parapet's line or shadow."""
    if not surface.any() or known.all():
        return np.zeros_like(surface)
    like = surface if sample is None or not sample.any() else sample
    seed = cells.lab[surface]
    med = np.median(seed, axis=0)
    spread = 1.4826 * np.median(np.abs(seed - med), axis=0)
    tol = np.maximum(3.0 * spread, min_colour_tol)
    edge_tol = float(np.percentile(cells.edge[like], 95)) * edge_factor
    lab = cells.lab
    coloured = ~known
    for ch in range(3):  # (numpy's all() over a last axis of 3 is several times slower)
        coloured &= np.abs(lab[..., ch] - med[ch]) <= tol[ch]
    if allowed is not None:
        coloured = allowed(coloured)
    quiet = cells.edge <= edge_tol
    alike = coloured & quiet
    # Growth starts only from the surface's quiet cells: one holding a parapet's line is a wall
    # between the surface and what lies beyond, even when the depth saw no step there.
    source = surface & quiet
    if not alike.any() or not source.any():
        return np.zeros_like(surface)
    count, labels = cv2.connectedComponents((alike | source).astype(np.uint8), connectivity=4)
    touching = np.zeros(count, bool)
    touching[labels[source]] = True
    touching[0] = False
    reach = touching[labels] & alike
    # The rim: a cell of the surface's colour holding the edge that stops the growth holds the
    # surface up to that edge. It is taken, and nothing beyond it.
    rim = cv2.dilate(reach.astype(np.uint8), _CROSS).astype(bool) & coloured & ~reach
    out: np.ndarray = reach | rim
    return out


_CROSS = cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))
