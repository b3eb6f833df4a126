"""Inverse perspective mapping: an image pixel -> the LiDAR return under it -> a world NED point.

The LiDAR returns (body FRD) are projected through the pinhole camera (:mod:`.frames`); those in front
of the camera and inside the image are indexed by their pixel coordinates. A pixel then maps to the
return whose projection lies nearest to it in the image (an exact search over every return: a frame is
asked a few pixels, which costs less than building a k-d tree, and the companion need not load SciPy's
spatial module, 37 MB of its memory), and that return's body point maps to
NED with the vehicle pose of the same capture. When the LiDAR has failed, the degraded mode
intersects the pixel's ray with a horizontal ground plane, e.g. at the height the rangefinder reads.

Exceptions (runtime conditions a caller handles; bad arguments raise
:class:`~.frames.GeometryInputError` instead)::

    IpmError
    ├── LidarUnavailable     no usable return: no cloud, empty, all NaN, or none inside the image
    ├── NoReturnNearPixel    the nearest return's projection is farther than max_px from the pixel
    └── RayDoesNotDescend    flat-plane fallback: the pixel ray never meets the ground plane
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from companion.guidance.frames import GeometryInputError, PinholeCamera, _finite, _vector, quat_to_matrix

__all__ = [
    "DEFAULT_MAX_PX",
    "IpmError",
    "IpmHit",
    "LidarPixelIndex",
    "LidarUnavailable",
    "NoReturnNearPixel",
    "RayDoesNotDescend",
    "ground_down_from_range",
    "pixel_to_ned",
    "pixel_to_ned_flat",
    "pixel_to_ned_surface",
]

DEFAULT_MAX_PX = 25.0
NEAREST_BLOCK = 2_000_000  # (pixel, return) pairs compared at once: 16 MB of squared distances
"""Default search radius in pixels. A 100 x 512 hemisphere seen by a 960 px, 90 deg camera leaves
returns up to ~8 px apart near the image centre; 25 px tolerates a few dropouts in a row."""
_MIN_DESCENT = 1e-3  # sine of the smallest depression angle for the flat-plane fallback (~0.06 deg)

Vec3Like = Sequence[float] | npt.ArrayLike


class IpmError(Exception):
    """Base class of the inverse-perspective-mapping conditions."""


class LidarUnavailable(IpmError):
    """No usable LiDAR return in the camera's view; use :func:`pixel_to_ned_flat` instead.

    Attributes:
        reason: what was wrong, in words.
        n_rows: rows in the given cloud (0 for no cloud).
    """

    def __init__(self, reason: str, n_rows: int = 0) -> None:
        super().__init__(f"LiDAR unavailable for IPM: {reason}")
        self.reason = reason
        self.n_rows = n_rows


class NoReturnNearPixel(IpmError):
    """No LiDAR return projects within ``max_px`` of the pixel.

    Attributes:
        u, v: the pixel asked about (continuous coordinates).
        nearest_px: the pixel distance to the nearest return's projection.
        max_px: the search radius in pixels.
    """

    def __init__(self, u: float, v: float, nearest_px: float, max_px: float) -> None:
        super().__init__(
            f"no LiDAR return within {max_px:g} px of pixel ({u:.1f}, {v:.1f}); "
            f"the nearest is {nearest_px:.1f} px away"
        )
        self.u = u
        self.v = v
        self.nearest_px = nearest_px
        self.max_px = max_px


class RayDoesNotDescend(IpmError):
    """The pixel's ray does not reach the ground plane below the vehicle.

    Attributes:
        u, v: the pixel (continuous coordinates).
        ray_ned: (3,) unit ray direction in NED.
        height_above_plane_m: vehicle height above the plane (negative when the plane is above it).
    """

    def __init__(self, u: float, v: float, ray_ned: np.ndarray, height_above_plane_m: float) -> None:
        if height_above_plane_m <= 0.0:
            why = f"the ground plane is {-height_above_plane_m:.2f} m above the vehicle, not below it"
        else:
            why = f"its ray points {math.degrees(math.asin(float(ray_ned[2]))):.2f} deg below the horizon"
        super().__init__(f"pixel ({u:.1f}, {v:.1f}) does not see the ground plane: {why}")
        self.u = u
        self.v = v
        self.ray_ned = ray_ned
        self.height_above_plane_m = height_above_plane_m


@dataclass(frozen=True, slots=True)
class IpmHit:
    """The LiDAR return nearest to a pixel in the image.

    Attributes:
        point_frd: the return in body FRD metres.
        pixel_distance: image distance in pixels from the pixel asked about to the return's projection.
        range_m: distance of the return from the body origin (the sensor), metres.
    """

    point_frd: tuple[float, float, float]
    pixel_distance: float
    range_m: float


class LidarPixelIndex:
    """LiDAR returns indexed by where they appear in the camera image (one capture).

    Args:
        lidar_frd: (N, 3+) array, columns body FRD x, y, z in metres (more columns, e.g. intensity, are
            ignored), or None when the LiDAR produced nothing. Rows with a NaN or infinite coordinate
            are dropped.
        camera: the pinhole camera of the same capture.

    Raises:
        LidarUnavailable: no cloud, an empty cloud (shape (0, 3+), or (0,) as ``[]`` gives), all rows
            non-finite, or no return inside the image.
        GeometryInputError: ``lidar_frd`` is not a 2-D numeric array with at least 3 columns.

    Attributes (read-only arrays):
        camera: the camera.
        points_frd: (M, 3) float64 returns inside the image, body FRD metres.
        uv: (M, 2) float64 their continuous pixel coordinates.
        n_rows: rows given; n_finite: rows with finite coordinates.
    """

    __slots__ = ("_tree", "camera", "n_finite", "n_rows", "points_frd", "uv")

    def __init__(self, lidar_frd: npt.ArrayLike | None, camera: PinholeCamera) -> None:
        if not isinstance(camera, PinholeCamera):
            raise GeometryInputError("camera", "a PinholeCamera", type(camera).__name__)
        if lidar_frd is None:
            raise LidarUnavailable("no point cloud (the LiDAR failed or was not asked for)")
        try:
            cloud = np.asarray(lidar_frd, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise GeometryInputError(
                "lidar_frd", "an (N, 3+) numeric array", type(lidar_frd).__name__
            ) from exc
        if cloud.shape == (0,):  # ``[]``: a sweep with no returns, however it was shaped
            raise LidarUnavailable("the point cloud is empty")
        if cloud.ndim != 2 or cloud.shape[1] < 3:
            raise GeometryInputError(
                "lidar_frd", "an (N, 3+) array of body FRD x, y, z (m)", f"shape {cloud.shape}"
            )
        n_rows = cloud.shape[0]
        if n_rows == 0:
            raise LidarUnavailable("the point cloud is empty")
        xyz = cloud[:, :3]
        # per column: np.isfinite(xyz).all(axis=1) reduces along the short axis and is 5x slower
        finite = np.isfinite(xyz[:, 0]) & np.isfinite(xyz[:, 1]) & np.isfinite(xyz[:, 2])
        n_finite = int(np.count_nonzero(finite))
        if n_finite == 0:
            raise LidarUnavailable(f"all {n_rows} returns have NaN or infinite coordinates", n_rows)
        uv, in_front = camera.project_frd(xyz)
        keep = np.flatnonzero(finite & in_front & camera.in_image(uv))
        if keep.size == 0:
            raise LidarUnavailable(
                f"none of the {n_finite} valid returns falls inside the {camera.width}x{camera.height} image",
                n_rows,
            )
        self.camera = camera
        self.n_rows = n_rows
        self.n_finite = n_finite
        self.points_frd: np.ndarray = xyz.take(keep, axis=0)
        self.uv: np.ndarray = uv.take(keep, axis=0)
        self.points_frd.flags.writeable = False
        self.uv.flags.writeable = False

    def __len__(self) -> int:
        """Number of returns inside the image."""
        return int(self.uv.shape[0])

    def __repr__(self) -> str:
        return (
            f"LidarPixelIndex({len(self)} returns in a {self.camera.width}x{self.camera.height} image, "
            f"from {self.n_rows} rows)"
        )

    def nearest(self, u: float, v: float, max_px: float = DEFAULT_MAX_PX) -> IpmHit:
        """The return whose projection is nearest to continuous pixel coordinates ``(u, v)``.

        Raises:
            NoReturnNearPixel: the nearest projection is farther than ``max_px`` pixels.
        """
        uf, vf = _finite("u", u), _finite("v", v)
        limit = _finite("max_px", max_px, 0.0)
        dist, idx = self._nearest(np.array([[uf, vf]]))
        distance = float(dist[0])
        if distance > limit:
            raise NoReturnNearPixel(uf, vf, distance, limit)
        return self._hit(int(idx[0]), distance)

    def nearest_many(self, uv: npt.ArrayLike, max_px: float = DEFAULT_MAX_PX) -> list[IpmHit | None]:
        """:meth:`nearest` for (K, 2) pixel coordinates at once; None where nothing is within ``max_px``."""
        pixels = np.asarray(uv, dtype=np.float64)
        if pixels.ndim != 2 or pixels.shape[1] != 2 or not np.isfinite(pixels).all():
            raise GeometryInputError(
                "uv", "a finite (K, 2) array of pixel coordinates", f"shape {pixels.shape}"
            )
        limit = _finite("max_px", max_px, 0.0)
        if pixels.shape[0] == 0:
            return []
        dist, idx = self._nearest(pixels)
        return [
            self._hit(int(i), float(d)) if d <= limit else None
            for d, i in zip(np.atleast_1d(dist).tolist(), np.atleast_1d(idx).tolist(), strict=True)
        ]

    def _nearest(self, pixels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The pixel distance to the nearest projection of each of (K, 2) ``pixels`` and its index (the
        first of equals), every return compared, in blocks of at most ``NEAREST_BLOCK`` pairs."""
        n = len(self.uv)
        step = max(1, NEAREST_BLOCK // n)
        dist = np.empty(len(pixels))
        idx = np.empty(len(pixels), np.intp)
        for s in range(0, len(pixels), step):
            block = pixels[s : s + step]
            du = self.uv[None, :, 0] - block[:, 0, None]
            dv = self.uv[None, :, 1] - block[:, 1, None]
            d2 = du * du + dv * dv
            best = d2.argmin(axis=1)
            idx[s : s + step] = best
            dist[s : s + step] = np.sqrt(d2[np.arange(len(block)), best])
        return dist, idx

    def _hit(self, i: int, distance: float) -> IpmHit:
        x, y, z = self.points_frd[i].tolist()
        return IpmHit(point_frd=(x, y, z), pixel_distance=distance, range_m=math.sqrt(x * x + y * y + z * z))


def pixel_to_ned(
    u: float,
    v: float,
    index: LidarPixelIndex,
    pos_ned_m: Vec3Like,
    quat_wxyz: Sequence[float] | npt.ArrayLike,
    max_px: float = DEFAULT_MAX_PX,
) -> np.ndarray:
    """World point seen at pixel ``(u, v)``: ``pos_ned_m + R(q) @ nearest_return_frd``.

    Args:
        u, v: continuous pixel coordinates (pixel ``(col, row)`` has its centre at ``col + 0.5, row + 0.5``).
        index: the LiDAR returns of the capture.
        pos_ned_m: vehicle position at capture, NED metres.
        quat_wxyz: vehicle attitude at capture, body FRD -> NED, ``(w, x, y, z)``.
        max_px: search radius in pixels.

    Returns:
        (3,) float64 NED metres.

    Raises:
        NoReturnNearPixel: no return projects within ``max_px`` of the pixel.
    """
    if not isinstance(index, LidarPixelIndex):
        raise GeometryInputError("index", "a LidarPixelIndex", type(index).__name__)
    pos = _vector("pos_ned_m", pos_ned_m, 3)
    rot = quat_to_matrix(quat_wxyz)
    hit = index.nearest(u, v, max_px)
    out: np.ndarray = pos + rot @ np.asarray(hit.point_frd)
    return out


def pixel_to_ned_surface(
    u: float,
    v: float,
    index: LidarPixelIndex,
    pos_ned_m: Vec3Like,
    quat_wxyz: Sequence[float] | npt.ArrayLike,
    max_px: float = DEFAULT_MAX_PX,
) -> np.ndarray:
    """World point seen at pixel ``(u, v)`` on a level surface: the pixel's own ray meets the
    horizontal plane through the nearest LiDAR return.

    :func:`pixel_to_ned` answers with the return itself, which lies up to ``max_px`` pixels from the
    pixel (the sweep is sparser than the image: at 90 m one return every metre or so); on the flat
    surfaces Surface ID proposes, the ray through the pixel meets the surface at the return's height
    where the pixel shows. A ray that does not descend to that plane gets the return itself.

    Returns:
        (3,) float64 NED metres.

    Raises:
        NoReturnNearPixel: no return projects within ``max_px`` of the pixel.
    """
    hit = pixel_to_ned(u, v, index, pos_ned_m, quat_wxyz, max_px)
    try:
        return pixel_to_ned_flat(u, v, index.camera, pos_ned_m, quat_wxyz, float(hit[2]))
    except RayDoesNotDescend:
        return hit


def pixel_to_ned_flat(
    u: float,
    v: float,
    camera: PinholeCamera,
    pos_ned_m: Vec3Like,
    quat_wxyz: Sequence[float] | npt.ArrayLike,
    ground_down_m: float,
) -> np.ndarray:
    """Degraded mode without LiDAR: the pixel's ray meets the horizontal plane NED down = ``ground_down_m``.

    Args:
        u, v: continuous pixel coordinates.
        camera: the pinhole camera of the capture.
        pos_ned_m: vehicle position at capture, NED metres.
        quat_wxyz: vehicle attitude at capture, body FRD -> NED, ``(w, x, y, z)``.
        ground_down_m: NED down coordinate of the ground plane, metres (greater than the vehicle's own
            down coordinate); see :func:`ground_down_from_range`.

    Returns:
        (3,) float64 NED metres, with ``out[2] == ground_down_m``.

    Raises:
        RayDoesNotDescend: the plane is not below the vehicle, or the ray points at or above the horizon.
    """
    if not isinstance(camera, PinholeCamera):
        raise GeometryInputError("camera", "a PinholeCamera", type(camera).__name__)
    pos = _vector("pos_ned_m", pos_ned_m, 3)
    ground = _finite("ground_down_m", ground_down_m)
    ray_ned: np.ndarray = quat_to_matrix(quat_wxyz) @ camera.pixel_ray_frd(u, v)
    height_m = ground - float(pos[2])
    if height_m <= 0.0 or float(ray_ned[2]) < _MIN_DESCENT:
        raise RayDoesNotDescend(float(u), float(v), ray_ned, height_m)
    out: np.ndarray = pos + ray_ned * (height_m / float(ray_ned[2]))
    out[2] = ground  # exact, whatever the rounding
    return out


def ground_down_from_range(
    pos_ned_m: Vec3Like, quat_wxyz: Sequence[float] | npt.ArrayLike, range_m: float
) -> float:
    """NED down coordinate of the surface a downward rangefinder (along body +z) reads ``range_m`` to.

    The rangefinder beam is tilted with the vehicle; the result is the down coordinate of the point it hit.
    """
    pos = _vector("pos_ned_m", pos_ned_m, 3)
    rng = _finite("range_m", range_m, 0.0)
    return float(pos[2]) + rng * float(quat_to_matrix(quat_wxyz)[2, 2])
