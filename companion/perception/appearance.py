"""Surface candidates from the image alone, for a vehicle with a camera and no LiDAR (``--sensors none``).

Without depth, Surface ID has no geometry to find flat surfaces by. What the camera still tells is what
the surfaces look like: LandNet-S says per cell which classes are present (roof, edge, object, water,
road, ...). Cells where a roof surface is present and nothing else that matters (no edge, object,
person, vehicle, water, marking, vegetation, tree, road or bare ground) make the mask; it is eroded by a
cell (a margin from whatever borders it), its connected parts of at least ``min_cells`` cells become the
candidates, largest first, each centred on its most interior cell. They carry no geometry (NaN area,
height, edge distance; ``measured_share`` 0): the onboard ranking orders them by what their crops show
and by size, the IPM places the chosen pixel on flat ground at the rangefinder's distance, and each
descent step looks again from closer (docs/camera.md, "A camera alone").

The frame is read in ``tiles`` (columns, rows), each at about its own scale: LandNet-S reads an image
scaled to 128 px on its short side, and read in fewer, larger tiles (3 x 2 of a 960 x 540 frame) the
clear gravel roof of scenario1 came out as no roof at all and a highway as one; in 6 x 4 tiles (64 x 108
cells of 8 x 5 px) the clear roof is the largest candidate. 24 readings: 0.17 s here, two flights beside.
"""

from __future__ import annotations

from collections.abc import Callable

import cv2
import numpy as np

from companion.perception.surface_id import Candidate

__all__ = ["CLEAR_CLASS", "NOT_CLEAR_CLASSES", "appearance_candidates", "clear_cells"]

CLEAR_CLASS = "roof"
NOT_CLEAR_CLASSES = (
    "edge", "object", "person", "vehicle", "water", "marking", "low_vegetation", "tree", "road", "ground",
)  # fmt: skip
TILES = (6, 4)  # a tile of a 960 x 540 frame is read at about its own scale (what LandNet-S learnt)

Presence = Callable[[np.ndarray], np.ndarray]  # RGB crop -> (K, h, w) bool, LandNet.presence


def clear_cells(
    image: np.ndarray, presence: Presence, classes: tuple[str, ...], tiles: tuple[int, int] = TILES
) -> np.ndarray:
    """(rows, cols) bool over the image read in ``tiles``: a roof surface and nothing that matters."""
    if CLEAR_CLASS not in classes:
        raise ValueError(f"the judge has no {CLEAR_CLASS!r} class (classes: {', '.join(classes)})")
    roof = classes.index(CLEAR_CLASS)
    bad = [classes.index(c) for c in NOT_CLEAR_CLASSES if c in classes]
    h, w = image.shape[:2]
    cols, rows = tiles
    th, tw = h // rows, w // cols
    out_rows = []
    for r in range(rows):
        row = []
        for c in range(cols):
            pres = np.asarray(presence(image[r * th : (r + 1) * th, c * tw : (c + 1) * tw]))
            row.append(pres[roof] & ~pres[bad].any(axis=0))
        gh = min(p.shape[0] for p in row)
        out_rows.append(np.concatenate([p[:gh] for p in row], axis=1))
    gw = min(p.shape[1] for p in out_rows)
    return np.concatenate([p[:, :gw] for p in out_rows], axis=0)


def appearance_candidates(
    clear: np.ndarray, width_px: int, height_px: int, *, max_candidates: int = 5, min_cells: int = 3
) -> list[Candidate]:
    """Candidates from a clear-cell mask over a ``width_px`` x ``height_px`` image (see module)."""
    rows, cols = clear.shape
    mask = cv2.erode(clear.astype(np.uint8), np.ones((3, 3), np.uint8), borderType=cv2.BORDER_REPLICATE)
    count, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=4)
    sy, sx = height_px / rows, width_px / cols
    found: list[tuple[int, tuple[int, int, int, int], tuple[float, float]]] = []
    for k in range(1, count):
        x, y, w, h, area = (int(v) for v in stats[k])
        if area < min_cells:
            continue
        part = np.pad((labels == k).astype(np.uint8), 1)
        inner = cv2.distanceTransform(part, cv2.DIST_L2, 3)[1:-1, 1:-1]
        # the most interior cells (a long part has a ridge of them): the one nearest the part's middle
        rr, cc = np.nonzero(inner >= inner.max() - 0.5)
        pick = int(np.argmin((rr - rr.mean()) ** 2 + (cc - cc.mean()) ** 2))
        r, c = int(rr[pick]), int(cc[pick])
        # the part's box grown back by the eroded cell, in pixels
        box = (
            max(int((x - 1) * sx), 0),
            max(int((y - 1) * sy), 0),
            min(int((x + w + 1) * sx), width_px),
            min(int((y + h + 1) * sy), height_px),
        )
        found.append((area, box, ((c + 0.5) * sx, (r + 0.5) * sy)))
    found.sort(key=lambda t: -t[0])
    return [
        Candidate(i, box, centre, measured_share=0.0)
        for i, (_a, box, centre) in enumerate(found[:max_candidates])
    ]
