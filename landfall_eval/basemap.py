"""A top-view picture of a scenario's ground truth: one colour per surface class, shaded by height.

The picture is north up, east right. Pixel ``(row, col)`` covers north
``[n_max - (row + 1) px_m, n_max - row px_m)`` and east ``[e_min + col px_m, e_min + (col + 1) px_m)``
in scenario NED metres. A pixel stands for a square block of grid cells and takes the class most of
them have (the mode), so thin features (lane markings, parapets, guard rails) give way to what they
border when the map is coarser than the grid. Overhead wires (power lines' conductors) are drawn over
it as thin dark lines, whatever the scale. Moving actors (traffic, pedestrians) are left out: the map
shows the static world.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from simbridge.world.model import SurfaceClass, WorldGrid
from simbridge.world.world import Wire

# One colour per class (RGB, 0-255): roofs light, clutter dark, roads dark grey, water blue, parks green.
CLASS_RGB: dict[SurfaceClass, tuple[int, int, int]] = {
    SurfaceClass.UNKNOWN: (200, 200, 200),
    SurfaceClass.GROUND: (214, 202, 172),
    SurfaceClass.ROOF_FLAT: (232, 229, 220),
    SurfaceClass.ROOF_CLUTTER: (84, 74, 72),
    SurfaceClass.PARAPET: (160, 154, 146),
    SurfaceClass.ROOF_PITCHED: (190, 118, 92),
    SurfaceClass.ROAD: (96, 98, 104),
    SurfaceClass.HIGHWAY: (60, 62, 76),
    SurfaceClass.GUARD_RAIL: (176, 176, 186),
    SurfaceClass.SIDEWALK: (180, 178, 170),
    SurfaceClass.CROSSWALK: (150, 150, 156),
    SurfaceClass.PARKING_LOT: (122, 128, 148),
    SurfaceClass.PARKING_ROOF: (146, 152, 176),
    SurfaceClass.GRASS: (150, 192, 118),
    SurfaceClass.TREE: (60, 112, 58),
    SurfaceClass.WATER: (86, 142, 204),
    SurfaceClass.PIER: (150, 110, 70),
    SurfaceClass.VEHICLE: (112, 64, 140),
    SurfaceClass.PEDESTRIAN: (240, 140, 0),
    SurfaceClass.RAIL: (110, 84, 70),
    SurfaceClass.MACHINERY: (200, 90, 60),
    SurfaceClass.CROP: (196, 186, 84),
}

CLASS_LABEL: dict[SurfaceClass, str] = {
    SurfaceClass.UNKNOWN: "unknown",
    SurfaceClass.GROUND: "ground",
    SurfaceClass.ROOF_FLAT: "flat roof",
    SurfaceClass.ROOF_CLUTTER: "roof clutter",
    SurfaceClass.PARAPET: "parapet",
    SurfaceClass.ROOF_PITCHED: "pitched roof",
    SurfaceClass.ROAD: "road",
    SurfaceClass.HIGHWAY: "highway",
    SurfaceClass.GUARD_RAIL: "guard rail",
    SurfaceClass.SIDEWALK: "sidewalk",
    SurfaceClass.CROSSWALK: "crosswalk",
    SurfaceClass.PARKING_LOT: "parking lot",
    SurfaceClass.PARKING_ROOF: "parking deck",
    SurfaceClass.GRASS: "park",
    SurfaceClass.TREE: "trees",
    SurfaceClass.WATER: "water",
    SurfaceClass.PIER: "pier",
    SurfaceClass.VEHICLE: "parked vehicle",
    SurfaceClass.PEDESTRIAN: "pedestrian",
    SurfaceClass.RAIL: "railway",
    SurfaceClass.MACHINERY: "machinery",
    SurfaceClass.CROP: "crops",
}

_N_CLASSES = 32  # > every SurfaceClass value; bincount bins per block
_BAND_CELLS = 4_000_000  # grid cells per band when taking block modes (bounds the memory used)
_FLAT_HALF_M = 100.0  # half side of the map of the flat scenario when no bounds are given
_LIGHT_AZ_DEG, _LIGHT_EL_DEG = 315.0, 45.0
_WIRE_RGB = (30, 30, 34)  # hillshade light from the north-west


class BaseMapError(ValueError):
    """A base map that cannot be drawn as asked (bad bounds, bounds outside the world, bad size)."""


@dataclass(frozen=True, slots=True)
class BaseMap:
    """A top-view RGB picture of a world with its class raster.

    Attributes:
        rgb: (rows, cols, 3) uint8, row 0 the northern edge, column 0 the western edge.
        cls: (rows, cols) uint8 SurfaceClass of each pixel (the mode of the cells it covers).
        extent_ne_m: (north_min, north_max, east_min, east_max) scenario metres the picture covers.
        px_m: metres per pixel (the same north and east).
        world_digest: the fingerprint of the whole static world drawn from
            (:meth:`simbridge.world.model.WorldGrid.digest`, as in simbridge's episode log), or None
            when unknown (a bare grid, the flat scenario).
    """

    rgb: np.ndarray
    cls: np.ndarray
    extent_ne_m: tuple[float, float, float, float]
    px_m: float
    world_digest: str | None = None

    def __post_init__(self) -> None:
        rows, cols = self.cls.shape
        if self.rgb.shape != (rows, cols, 3) or self.rgb.dtype != np.uint8:
            raise BaseMapError(
                f"BaseMap.rgb must be uint8 of shape {(rows, cols, 3)}, got {self.rgb.dtype} {self.rgb.shape}"
            )

    @property
    def imshow_extent(self) -> tuple[float, float, float, float]:
        """(left, right, bottom, top) = (east_min, east_max, north_min, north_max) for ``imshow``."""
        n_min, n_max, e_min, e_max = self.extent_ne_m
        return (e_min, e_max, n_min, n_max)

    def pixel(self, north_m: float, east_m: float) -> tuple[int, int] | None:
        """(row, col) of the pixel covering a scenario point; None outside the picture."""
        _, n_max, e_min, _ = self.extent_ne_m
        row = math.floor((n_max - north_m) / self.px_m)
        col = math.floor((east_m - e_min) / self.px_m)
        rows, cols = self.cls.shape
        if 0 <= row < rows and 0 <= col < cols:
            return row, col
        return None

    def classes(self) -> list[SurfaceClass]:
        """The classes in the picture, most pixels first."""
        counts = np.bincount(self.cls.ravel(), minlength=_N_CLASSES)
        order = np.argsort(-counts, kind="stable")
        return [SurfaceClass(int(c)) for c in order if counts[c] > 0]


def basemap(
    scenario: str,
    seed: int,
    bounds_ne_m: tuple[float, float, float, float] | None = None,
    max_px: int = 1600,
    place: str = "downtown",
    world_cache: Path | None = None,
) -> BaseMap:
    """Draw a scenario's world from simbridge's ground truth.

    Args:
        scenario: a simbridge scenario name (``scenario1``, ``city``, a ``.toml`` path, ...).
        seed: the world seed: for ``city`` the city seed (simbridge ``--city-seed``), for a scenario
            file the seed of its furniture (rubble, park trees, parked cars: simbridge ``--seed``).
        bounds_ne_m: (north_min, north_max, east_min, east_max) metres to draw, clipped to the world;
            None draws the whole world. The picture snaps outward to whole blocks of cells, so it may
            reach past the bounds by less than one pixel (never past the world's edge by more).
        max_px: the longest side of the picture in pixels; the grid is reduced by a whole stride.
        place: for ``city``, the kind of place (simbridge ``--place``).
        world_cache: where built places are kept (simbridge ``--world-cache``); None: built here.

    Raises:
        BaseMapError: bad bounds or ``max_px``, or bounds that miss the world.
        ValueError: an unknown scenario (from :func:`simbridge.scenarios.load_scenario`).
    """
    if max_px < 16:
        raise BaseMapError(f"max_px must be at least 16, got {max_px}")
    if bounds_ne_m is not None:
        n_min, n_max, e_min, e_max = (float(b) for b in bounds_ne_m)
        if (
            not all(math.isfinite(b) for b in (n_min, n_max, e_min, e_max))
            or n_min >= n_max
            or e_min >= e_max
        ):
            raise BaseMapError(
                f"bounds_ne_m must be finite (north_min, north_max, east_min, east_max) with min < max, "
                f"got {bounds_ne_m}"
            )
    from simbridge.scenarios import load_scenario
    from simbridge.world.live import LiveWorld

    if scenario == "city":  # the city of this seed; the episode seed only moves actors, left out below
        terrain = load_scenario(scenario, 0, city_seed=seed, place=place, world_cache=world_cache).terrain
    else:
        terrain = load_scenario(scenario, seed).terrain
    if not isinstance(terrain, LiveWorld):  # the flat scenario: open ground everywhere
        h = _FLAT_HALF_M
        n_min, n_max, e_min, e_max = bounds_ne_m if bounds_ne_m is not None else (-h, h, -h, h)
        res = min(max(max(n_max - n_min, e_max - e_min) / max_px, 0.01), 1.0)
        grid = WorldGrid.empty((n_min, n_max), (e_min, e_max), res)
    else:
        terrain.actors.unstamp(terrain.grid)  # the static world: no traffic or pedestrians
        drawn = grid_basemap(terrain.grid, bounds_ne_m, max_px, terrain.world.wires)
        return replace(drawn, world_digest=terrain.world_digest)
    return grid_basemap(grid, bounds_ne_m, max_px)


def grid_basemap(
    grid: WorldGrid,
    bounds_ne_m: tuple[float, float, float, float] | None = None,
    max_px: int = 1600,
    wires: tuple[Wire, ...] = (),
) -> BaseMap:
    """Draw a grid (see :func:`basemap` for the arguments), and ``wires`` over it as thin dark lines."""
    if bounds_ne_m is None:
        win: tuple[int, int, int, int] | None = (0, grid.shape[0], 0, grid.shape[1])
    else:
        win = grid.window(*bounds_ne_m)
    if win is None:
        raise BaseMapError(f"bounds_ne_m {bounds_ne_m} miss the world, which spans {grid.extent_m}")
    i0, i1, j0, j1 = win
    stride = max(1, math.ceil(max(i1 - i0, j1 - j0) / max_px))
    # grow the window to whole blocks, inside the grid where it can, else pad with the edge cells
    rows_b, cols_b = math.ceil((i1 - i0) / stride), math.ceil((j1 - j0) / stride)
    i0 = max(0, min(i0, grid.shape[0] - rows_b * stride))
    j0 = max(0, min(j0, grid.shape[1] - cols_b * stride))
    i1, j1 = i0 + rows_b * stride, j0 + cols_b * stride
    cls = _padded(grid.cls, i0, i1, j0, j1)
    height = _padded(grid.height, i0, i1, j0, j1)
    block_cls = _block_mode(cls, stride)
    block_h = height.reshape(rows_b, stride, cols_b, stride).mean(axis=(1, 3), dtype=np.float64)
    px_m = grid.res * stride
    rgb = _shade(_palette()[block_cls], block_h, px_m)
    extent = (
        grid.n0 + i0 * grid.res,
        grid.n0 + i1 * grid.res,
        grid.e0 + j0 * grid.res,
        grid.e0 + j1 * grid.res,
    )
    # grid rows run north; picture rows run south from the top
    picture = np.ascontiguousarray(rgb[::-1])
    if wires:
        import cv2  # drawing lines only: the map itself needs none of OpenCV
    for wire in wires:
        pts = np.asarray(wire.points_neh, np.float64)[:, :2]
        xy = np.stack([(pts[:, 1] - extent[2]) / px_m, (extent[1] - pts[:, 0]) / px_m], axis=1)
        cv2.polylines(picture, [np.round(xy * 16).astype(np.int32)], False, _WIRE_RGB, 1, cv2.LINE_AA, 4)
    return BaseMap(
        rgb=picture,
        cls=np.ascontiguousarray(block_cls[::-1]),
        extent_ne_m=extent,
        px_m=px_m,
    )


def _padded(a: np.ndarray, i0: int, i1: int, j0: int, j1: int) -> np.ndarray:
    """``a[i0:i1, j0:j1]``, padded with its edge cells where the window runs past the array."""
    rows, cols = a.shape
    part = a[i0 : min(i1, rows), j0 : min(j1, cols)]
    pad = ((0, i1 - i0 - part.shape[0]), (0, j1 - j0 - part.shape[1]))
    return np.pad(part, pad, mode="edge") if pad[0][1] or pad[1][1] else part


def _block_mode(cls: np.ndarray, stride: int) -> np.ndarray:
    """The most common class in each ``stride`` x ``stride`` block of a (rows, cols) uint8 raster."""
    if stride == 1:
        return cls.astype(np.uint8, copy=True)
    rows, cols = cls.shape[0] // stride, cls.shape[1] // stride
    out = np.empty((rows, cols), np.uint8)
    band = max(1, _BAND_CELLS // (cls.shape[1] * stride))  # block rows per band
    for r0 in range(0, rows, band):
        nb = min(band, rows - r0)
        part = cls[r0 * stride : (r0 + nb) * stride]
        blocks = (
            part.reshape(nb, stride, cols, stride).transpose(0, 2, 1, 3).reshape(nb * cols, stride * stride)
        )
        keys = np.arange(nb * cols, dtype=np.int64)[:, None] * _N_CLASSES + blocks
        counts = np.bincount(keys.ravel(), minlength=nb * cols * _N_CLASSES).reshape(nb * cols, _N_CLASSES)
        out[r0 : r0 + nb] = counts.argmax(axis=1).reshape(nb, cols)
    return out


def _palette() -> np.ndarray:
    lut = np.zeros((256, 3), np.float32)
    lut[:] = CLASS_RGB[SurfaceClass.UNKNOWN]
    for c, rgb in CLASS_RGB.items():
        lut[int(c)] = rgb
    return lut


def _shade(rgb: np.ndarray, height: np.ndarray, px_m: float) -> np.ndarray:
    """Hillshade (light from the north-west) and a little brightening with height, so buildings read.

    ``rgb`` (rows, cols, 3) float and ``height`` (rows, cols) metres up, both with rows running north.
    """
    d_north, d_east = np.gradient(height, px_m)
    normal = np.stack([-d_east, -d_north, np.ones_like(height)], axis=-1)  # east, north, up
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    az, el = math.radians(_LIGHT_AZ_DEG), math.radians(_LIGHT_EL_DEG)
    light = np.array([math.cos(el) * math.sin(az), math.cos(el) * math.cos(az), math.sin(el)])
    lit = np.clip(normal @ light, 0.0, 1.0) / math.sin(el)  # 1 on flat ground
    gain = 1.0 + 0.45 * (np.clip(lit, 0.3, 1.4) - 1.0) + 0.08 * np.clip(height / 60.0, -0.1, 1.0)
    out: np.ndarray = np.clip(rgb * gain[..., None], 0, 255).astype(np.uint8)
    return out


def main(argv: list[str] | None = None) -> int:
    """``python -m landfall_eval.basemap --place KIND --city-seed S --out MAP.png``: the whole map of a
    procedural place (docs/simbridge.md's maps of the kinds of place are drawn with it)."""
    import argparse

    import cv2

    from simbridge.args import non_negative_seed
    from simbridge.world.places import DEFAULT_PLACE, PLACES

    ap = argparse.ArgumentParser(prog="python -m landfall_eval.basemap", description=main.__doc__)
    ap.add_argument("--place", choices=PLACES, default=DEFAULT_PLACE)
    ap.add_argument("--city-seed", type=non_negative_seed, default=0, metavar="S")
    ap.add_argument("--max-px", type=int, default=900, help="the picture's longest side (default 900)")
    ap.add_argument("--out", required=True, help="the picture (.png or .jpg)")
    args = ap.parse_args(argv)
    bm = basemap("city", args.city_seed, max_px=args.max_px, place=args.place)
    if not cv2.imwrite(args.out, cv2.cvtColor(bm.rgb, cv2.COLOR_RGB2BGR)):
        ap.error(f"cannot write {args.out}")
    print(f"{args.out}: {args.place} {args.city_seed}, {bm.px_m:.2f} m a pixel, world {bm.world_digest}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
