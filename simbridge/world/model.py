"""The 2.5-D world: per-cell top-surface height, semantic class, material and region id.

Rows run north, columns east: cell ``(i, j)`` covers north ``[n0 + i res, n0 + (i+1) res)`` and
east ``[e0 + j res, e0 + (j+1) res)`` in scenario NED metres; heights are metres *up* from the
scenario origin's ground level. Everything the simulator knows about the world (what the camera
and LiDAR see, what the vehicle lands on, how a landing is graded) is read from these arrays.

Painting primitives take scenario coordinates (north, east, metres) and shapes rotated by
``yaw_rad`` (0 = the shape's length along north, positive turns toward east).
"""

from __future__ import annotations

import enum
import hashlib
import itertools
import math
from dataclasses import dataclass

import numpy as np


class SurfaceClass(enum.IntEnum):
    """Semantic class of a cell's top surface (ground truth)."""

    UNKNOWN = 0
    GROUND = 1  # bare or open ground
    ROOF_FLAT = 2
    ROOF_CLUTTER = 3  # HVAC units, vents, pipes, domes, antennas, solar panels, rubble
    PARAPET = 4
    ROOF_PITCHED = 5
    ROAD = 6
    HIGHWAY = 7  # elevated highway deck and ramps
    GUARD_RAIL = 8
    SIDEWALK = 9
    CROSSWALK = 10
    PARKING_LOT = 11
    PARKING_ROOF = 12  # top deck of a parking structure
    GRASS = 13  # park, lawn
    TREE = 14
    WATER = 15
    PIER = 16
    VEHICLE = 17
    PEDESTRIAN = 18
    RAIL = 19  # a railway's track: ballast, sleepers and rails
    MACHINERY = 20  # containers, stacked material, trucks' trailers and machines parked in a yard
    CROP = 21  # a field of standing crops (wheat, maize, rows of vegetables): never a landing site


class Material(enum.IntEnum):
    """Surface material: drives the camera's procedural texture."""

    NONE = 0
    GRAVEL = 1
    CONCRETE = 2
    TAR = 3
    MEMBRANE = 4
    TILES = 5
    ASPHALT = 6
    LANE_MARKING = 7
    PAVING = 8
    ZEBRA = 9
    GRASS = 10
    FOLIAGE = 11
    WATER = 12
    WOOD = 13
    METAL = 14
    SOLAR = 15
    RUBBLE = 16
    BRICK = 17
    SOIL = 18
    CAR_PAINT = 19
    CLOTH = 20
    PAINT_TEXT = 21  # painted letters on a roof ("LAND HERE")
    CORRUGATED = 22  # corrugated sheet (metal or fibre cement): ridges 7-18 cm apart, sheet joints
    SLATE = 23  # slate or flat concrete tiles: small dark overlapping rows
    SHINGLE = 24  # asphalt shingles: staggered tabs
    SEAM_METAL = 25  # standing-seam metal: raised seams 0.4-0.6 m apart
    GLASS = 26  # skylights, roof windows, greenhouse panes
    POOL = 27  # swimming-pool water (light cyan over tiles)
    SAND = 28  # beach and dune sand, sand pits
    CROP = 29  # standing crops: rows of plants over soil


ROOF_MATERIALS = (Material.GRAVEL, Material.CONCRETE, Material.TAR, Material.MEMBRANE, Material.TILES)

# What the landing grader calls each class (DESIGN.md section 9's surface classes).
GRADE_SURFACE: dict[SurfaceClass, str] = {
    SurfaceClass.UNKNOWN: "no_landing",
    SurfaceClass.GROUND: "ground",
    SurfaceClass.ROOF_FLAT: "rooftop_clear",
    SurfaceClass.ROOF_CLUTTER: "rooftop_obstructed",
    SurfaceClass.PARAPET: "rooftop_obstructed",
    SurfaceClass.ROOF_PITCHED: "rooftop_obstructed",
    SurfaceClass.ROAD: "road",
    SurfaceClass.HIGHWAY: "highway",
    SurfaceClass.GUARD_RAIL: "highway",
    SurfaceClass.SIDEWALK: "sidewalk",
    SurfaceClass.CROSSWALK: "road",
    SurfaceClass.PARKING_LOT: "parking",
    SurfaceClass.PARKING_ROOF: "parking",
    SurfaceClass.GRASS: "park",
    SurfaceClass.TREE: "park",
    SurfaceClass.WATER: "water",
    SurfaceClass.PIER: "pier",
    SurfaceClass.VEHICLE: "road",
    SurfaceClass.PEDESTRIAN: "sidewalk",
    SurfaceClass.RAIL: "rail",
    SurfaceClass.MACHINERY: "machinery",
    SurfaceClass.CROP: "crops",
}

# Classes a vehicle must never land on, whatever the geometry says.
FORBIDDEN_CLASSES = frozenset(
    {
        SurfaceClass.ROAD, SurfaceClass.HIGHWAY, SurfaceClass.GUARD_RAIL, SurfaceClass.SIDEWALK,
        SurfaceClass.CROSSWALK, SurfaceClass.WATER, SurfaceClass.PIER, SurfaceClass.TREE,
        SurfaceClass.VEHICLE, SurfaceClass.PEDESTRIAN, SurfaceClass.UNKNOWN, SurfaceClass.RAIL,
        SurfaceClass.MACHINERY, SurfaceClass.CROP,
    }
)  # fmt: skip
# Classes that count as an obstacle inside the rotor-clearance disc.
OBSTACLE_CLASSES = frozenset(
    {
        SurfaceClass.ROOF_CLUTTER, SurfaceClass.PARAPET, SurfaceClass.TREE, SurfaceClass.VEHICLE,
        SurfaceClass.PEDESTRIAN, SurfaceClass.GUARD_RAIL, SurfaceClass.MACHINERY,
    }
)  # fmt: skip


class WorldError(ValueError):
    """A world that cannot be built as described."""


@dataclass
class WorldGrid:
    """The rasters. Build with :meth:`empty`, paint, then hand to the sensors."""

    n0: float
    e0: float
    res: float
    height: np.ndarray  # float32 (rows, cols), metres up
    cls: np.ndarray  # uint8 SurfaceClass
    mat: np.ndarray  # uint8 Material
    region: np.ndarray  # int32 id of the building/object a cell belongs to (0: none)

    @staticmethod
    def empty(
        north_m: tuple[float, float],
        east_m: tuple[float, float],
        res: float = 0.2,
        ground_cls: SurfaceClass = SurfaceClass.GROUND,
        ground_mat: Material = Material.SOIL,
    ) -> WorldGrid:
        """Flat ground over ``north_m = (min, max)`` by ``east_m = (min, max)``."""
        if not 0.01 <= res <= 1.0:
            raise WorldError(f"grid resolution must be in [0.01, 1] m, got {res}")
        rows = round((north_m[1] - north_m[0]) / res)
        cols = round((east_m[1] - east_m[0]) / res)
        if rows <= 0 or cols <= 0:
            raise WorldError(f"empty world extent: north {north_m}, east {east_m}")
        return WorldGrid(
            n0=north_m[0],
            e0=east_m[0],
            res=res,
            height=np.zeros((rows, cols), np.float32),
            cls=np.full((rows, cols), int(ground_cls), np.uint8),
            mat=np.full((rows, cols), int(ground_mat), np.uint8),
            region=np.zeros((rows, cols), np.int32),
        )

    # ------------------------------------------------------------------ geometry
    @property
    def shape(self) -> tuple[int, int]:
        return (int(self.height.shape[0]), int(self.height.shape[1]))

    @property
    def extent_m(self) -> tuple[float, float, float, float]:
        """(north_min, north_max, east_min, east_max)."""
        rows, cols = self.shape
        return (self.n0, self.n0 + rows * self.res, self.e0, self.e0 + cols * self.res)

    def index(self, north_m: float, east_m: float) -> tuple[int, int] | None:
        i = math.floor((north_m - self.n0) / self.res)
        j = math.floor((east_m - self.e0) / self.res)
        rows, cols = self.shape
        if 0 <= i < rows and 0 <= j < cols:
            return i, j
        return None

    def height_at(self, north_m: float, east_m: float) -> float:
        """Top-surface height at a point; 0 (open ground) outside the grid."""
        ij = self.index(north_m, east_m)
        return 0.0 if ij is None else float(self.height[ij])

    def class_at(self, north_m: float, east_m: float) -> SurfaceClass:
        ij = self.index(north_m, east_m)
        return SurfaceClass.GROUND if ij is None else SurfaceClass(int(self.cls[ij]))

    def cell_centres(self, i0: int, i1: int, j0: int, j1: int) -> tuple[np.ndarray, np.ndarray]:
        """North and east of the centres of cells ``[i0, i1) x [j0, j1)`` as 2-D arrays."""
        n = self.n0 + (np.arange(i0, i1) + 0.5) * self.res
        e = self.e0 + (np.arange(j0, j1) + 0.5) * self.res
        return np.meshgrid(n, e, indexing="ij")

    def window(
        self, n_min: float, n_max: float, e_min: float, e_max: float
    ) -> tuple[int, int, int, int] | None:
        """Cell index window (i0, i1, j0, j1) covering a north/east box, clipped; None if empty."""
        return self._window(n_min, n_max, e_min, e_max)

    def _window(
        self, n_min: float, n_max: float, e_min: float, e_max: float
    ) -> tuple[int, int, int, int] | None:
        rows, cols = self.shape
        i0 = max(math.floor((n_min - self.n0) / self.res), 0)
        i1 = min(math.ceil((n_max - self.n0) / self.res), rows)
        j0 = max(math.floor((e_min - self.e0) / self.res), 0)
        j1 = min(math.ceil((e_max - self.e0) / self.res), cols)
        if i0 >= i1 or j0 >= j1:
            return None
        return i0, i1, j0, j1

    # ------------------------------------------------------------------ painting
    def rect_mask(
        self, centre_ne: tuple[float, float], length_m: float, width_m: float, yaw_rad: float = 0.0
    ) -> tuple[tuple[int, int, int, int], np.ndarray, np.ndarray, np.ndarray] | None:
        """Cells whose centres fall in a rotated rectangle.

        Returns ``(window, mask, u, v)``: the grid window (i0, i1, j0, j1), the boolean mask over
        it, and each cell's coordinates along the rectangle's length (u) and width (v) axes.
        ``simbridge.world.stamping`` repeats this window and test cell by cell for the moving actors:
        change both together.
        """
        cn, ce = centre_ne
        c, s = math.cos(yaw_rad), math.sin(yaw_rad)
        # the tight axis-aligned box of the rotated rectangle (a long strip must not scan a square)
        half_n = abs(c) * length_m / 2 + abs(s) * width_m / 2
        half_e = abs(s) * length_m / 2 + abs(c) * width_m / 2
        win = self._window(cn - half_n, cn + half_n, ce - half_e, ce + half_e)
        if win is None:
            return None
        n, e = self.cell_centres(*win)
        u = (n - cn) * c + (e - ce) * s
        v = -(n - cn) * s + (e - ce) * c
        mask = (np.abs(u) <= length_m / 2) & (np.abs(v) <= width_m / 2)
        return win, mask, u, v

    def paint(
        self,
        window: tuple[int, int, int, int],
        mask: np.ndarray,
        heights: np.ndarray | float | None,
        cls: SurfaceClass | None,
        mat: Material | None,
        region: int | None = None,
        mode: str = "set",
    ) -> None:
        """Write into the cells under ``mask``.

        ``mode``: ``set`` (height = value), ``add`` (height += value: clutter on a roof),
        ``max`` (height = max(height, value): trees, domes; class, material and region change only
        where the new surface ends up on top).
        """
        i0, i1, j0, j1 = window
        if mode not in ("set", "add", "max"):
            raise WorldError(f"unknown paint mode {mode!r}")
        if heights is not None:
            h = self.height[i0:i1, j0:j1]
            val = np.broadcast_to(np.asarray(heights, np.float32), mask.shape)
            if mode == "max":
                mask = mask & (val >= h)  # only where the new surface is on top: relabel those alone
            if not mask.any():
                return
            if mode == "add":
                h[mask] += val[mask]
            else:
                h[mask] = val[mask]
        elif not mask.any():
            return
        if cls is not None:
            self.cls[i0:i1, j0:j1][mask] = int(cls)
        if mat is not None:
            self.mat[i0:i1, j0:j1][mask] = int(mat)
        if region is not None:
            self.region[i0:i1, j0:j1][mask] = region

    def fill_rect(
        self,
        centre_ne: tuple[float, float],
        length_m: float,
        width_m: float,
        yaw_rad: float = 0.0,
        *,
        height_m: float | None = None,
        cls: SurfaceClass | None = None,
        mat: Material | None = None,
        region: int | None = None,
        mode: str = "set",
    ) -> np.ndarray | None:
        """Paint a rotated rectangle; returns the mask's window-sized boolean array or None."""
        got = self.rect_mask(centre_ne, length_m, width_m, yaw_rad)
        if got is None:
            return None
        win, mask, _, _ = got
        self.paint(win, mask, height_m, cls, mat, region, mode)
        return mask

    def fill_disc(
        self,
        centre_ne: tuple[float, float],
        radius_m: float,
        *,
        height_m: float | None = None,
        dome: bool = False,
        cls: SurfaceClass | None = None,
        mat: Material | None = None,
        region: int | None = None,
        mode: str = "set",
    ) -> None:
        """Paint a disc; with ``dome`` the height rises as a spherical cap to ``height_m``."""
        cn, ce = centre_ne
        win = self._window(cn - radius_m, cn + radius_m, ce - radius_m, ce + radius_m)
        if win is None:
            return
        n, e = self.cell_centres(*win)
        d2 = (n - cn) ** 2 + (e - ce) ** 2
        mask = d2 <= radius_m**2
        heights: np.ndarray | float | None = height_m
        if dome and height_m is not None:
            heights = height_m * np.sqrt(np.clip(1.0 - d2 / radius_m**2, 0.0, 1.0))
        self.paint(win, mask, heights, cls, mat, region, mode)

    def fill_pitched(
        self,
        centre_ne: tuple[float, float],
        length_m: float,
        width_m: float,
        yaw_rad: float,
        eave_m: float,
        ridge_m: float,
        *,
        region: int | None = None,
        mat: Material = Material.TILES,
        mode: str = "set",
    ) -> None:
        """A gable roof: eaves at ``eave_m``, ridge along the length at ``ridge_m`` (absolute).

        ``mode`` "max" joins it to a roof already painted (the wings of an L-shaped house meet in valleys).
        """
        got = self.rect_mask(centre_ne, length_m, width_m, yaw_rad)
        if got is None:
            return
        win, mask, _, v = got
        heights = eave_m + (ridge_m - eave_m) * (1.0 - np.abs(v) / (width_m / 2))
        self.paint(win, mask, heights.astype(np.float32), SurfaceClass.ROOF_PITCHED, mat, region, mode)

    def fill_polyline(
        self,
        points_ne: list[tuple[float, float]],
        width_m: float,
        *,
        height_m: float | None = None,
        cls: SurfaceClass | None = None,
        mat: Material | None = None,
        region: int | None = None,
        mode: str = "set",
    ) -> None:
        """A strip ``width_m`` wide along straight segments (roads, rails, pipes)."""
        for (n1, e1), (n2, e2) in itertools.pairwise(points_ne):
            length = math.hypot(n2 - n1, e2 - e1)
            if length == 0:
                continue
            yaw = math.atan2(e2 - e1, n2 - n1)
            self.fill_rect(
                ((n1 + n2) / 2, (e1 + e2) / 2), length + width_m * 0.01, width_m, yaw,
                height_m=height_m, cls=cls, mat=mat, region=region, mode=mode,
            )  # fmt: skip

    def fill_ramp(
        self,
        start_ne: tuple[float, float],
        end_ne: tuple[float, float],
        width_m: float,
        start_height_m: float,
        end_height_m: float,
        *,
        cls: SurfaceClass = SurfaceClass.HIGHWAY,
        mat: Material = Material.ASPHALT,
        region: int | None = None,
    ) -> None:
        """A straight deck whose height varies linearly from start to end (highway ramps)."""
        (n1, e1), (n2, e2) = start_ne, end_ne
        length = math.hypot(n2 - n1, e2 - e1)
        if length == 0:
            raise WorldError("ramp start and end coincide")
        yaw = math.atan2(e2 - e1, n2 - n1)
        got = self.rect_mask(((n1 + n2) / 2, (e1 + e2) / 2), length, width_m, yaw)
        if got is None:
            return
        win, mask, u, _ = got
        frac = np.clip(u / length + 0.5, 0.0, 1.0)
        heights = (start_height_m + frac * (end_height_m - start_height_m)).astype(np.float32)
        self.paint(win, mask, heights, cls, mat, region, "max")

    # ------------------------------------------------------------------ queries
    def digest(self) -> str:
        """A short stable fingerprint of the world: 16 hex digits of BLAKE2b over the grid's placement
        (origin, resolution, shape) and the bytes of its height and class rasters. Two grids with the
        same digest are the same world for the sensors' geometry and for grading (materials, which only
        tint the camera's textures, are left out). Take it before actors are stamped: it fingerprints
        whatever the arrays hold now. About 0.2 s for a 1.2 km city at 0.2 m (6000 x 6000 cells).
        """
        h = hashlib.blake2b(digest_size=8)
        rows, cols = self.shape
        h.update(f"{self.n0!r},{self.e0!r},{self.res!r},{rows},{cols};".encode())
        for a, dtype in ((self.height, "<f4"), (self.cls, np.uint8)):  # little-endian: one digest everywhere
            h.update(np.ascontiguousarray(a, dtype=dtype).data)  # no copy: the array's own buffer
        return h.hexdigest()

    def memory_bytes(self) -> int:
        return int(self.height.nbytes + self.cls.nbytes + self.mat.nbytes + self.region.nbytes)
