"""Frames, attitude and the camera model: the conventions, stated once.

World frame: NED, metres (north, east, down) from the scenario origin. Body frame: FRD (forward,
right, down), origin at the vehicle's reference point; the camera and the LiDAR sit at that origin
(no lever arms).

Attitude: a unit quaternion ``(w, x, y, z)``, scalar first, rotating body FRD vectors into NED:
``v_ned = quat_to_matrix(q) @ v_frd`` (as MAVLink ``ATTITUDE_QUATERNION`` and PX4 ``q``).

Camera frame (OpenCV): x right, y down, z along the optical axis. The camera looks straight down the
body +z axis with the image top toward the vehicle's nose::

    x_cam -> +y_body (right),  y_cam -> -x_body (image down = aft),  z_cam -> +z_body (down)

``CAMERA_TO_BODY`` holds this rotation, columns = camera axes in body FRD, so
``v_frd = CAMERA_TO_BODY @ v_cam`` (identical to ``simbridge.world.camera.CAMERA_TO_BODY``).

Pixels: continuous image coordinates ``(u, v)``, u to the right, v down, origin at the top-left
corner of the image. Pixel ``(col, row)`` covers ``[col, col + 1) x [row, row + 1)``, so its centre is
``(col + 0.5, row + 0.5)``. The default principal point is the image centre ``(W / 2, H / 2)`` and
``fx = fy = (W / 2) / tan(hfov / 2)``.

Bad arguments raise :class:`GeometryInputError` (a ``ValueError``) saying what was expected.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from numbers import Integral, Real

import numpy as np
import numpy.typing as npt

__all__ = [
    "CAMERA_TO_BODY",
    "GeometryInputError",
    "PinholeCamera",
    "compass_point",
    "frd_to_ned",
    "quat_to_matrix",
]

CAMERA_TO_BODY: np.ndarray = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
"""(3, 3) rotation camera -> body FRD; columns are the camera x, y, z axes in body FRD."""
CAMERA_TO_BODY.flags.writeable = False

_MIN_DEPTH_M = 1e-3  # a point must be this far in front of the camera to project
_QUAT_NORM_TOLERANCE = 1e-3  # float32 telemetry is unit to ~1e-7; a larger error is a bug upstream


class GeometryInputError(ValueError):
    """An argument with the wrong type, shape or value.

    Attributes:
        field_name: the argument (or argument element) at fault.
        expected: what was expected, in words.
        actual: what was given, in words.
    """

    def __init__(self, field_name: str, expected: str, actual: str) -> None:
        super().__init__(f"{field_name}: expected {expected}, got {actual}")
        self.field_name = field_name
        self.expected = expected
        self.actual = actual


def _finite(name: str, value: object, minimum: float | None = None, exclusive: bool = False) -> float:
    bound = "" if minimum is None else f" {'>' if exclusive else '>='} {minimum}"
    if isinstance(value, bool) or not isinstance(value, Real):
        raise GeometryInputError(name, f"a finite number{bound}", f"{type(value).__name__} {value!r}")
    out = float(value)
    low = minimum is not None and (out <= minimum if exclusive else out < minimum)
    if not math.isfinite(out) or low:
        raise GeometryInputError(name, f"a finite number{bound}", repr(out))
    return out


def _integer(name: str, value: object, minimum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, Integral) or int(value) < minimum:
        raise GeometryInputError(name, f"an integer >= {minimum}", f"{type(value).__name__} {value!r}")
    return int(value)


def _vector(name: str, value: object, n: int) -> np.ndarray:
    """``value`` as a finite float64 (n,) array."""
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise GeometryInputError(name, f"{n} finite numbers", f"{type(value).__name__} {value!r}") from exc
    if arr.shape != (n,):
        raise GeometryInputError(name, f"{n} finite numbers", f"shape {arr.shape}")
    if not np.isfinite(arr).all():
        raise GeometryInputError(name, f"{n} finite numbers", repr(arr.tolist()))
    return arr


def quat_to_matrix(quat_wxyz: Sequence[float] | npt.ArrayLike) -> np.ndarray:
    """Rotation matrix of a unit quaternion.

    Args:
        quat_wxyz: ``(w, x, y, z)``, scalar first, body FRD -> NED. Renormalised when its norm is within
            1e-3 of 1; anything further from unit length is rejected as a bug upstream.

    Returns:
        (3, 3) float64 ``R`` with ``v_ned = R @ v_frd``.
    """
    q = _vector("quat_wxyz", quat_wxyz, 4)
    norm = float(np.linalg.norm(q))
    if abs(norm - 1.0) > _QUAT_NORM_TOLERANCE:
        raise GeometryInputError("quat_wxyz", "a unit quaternion (w, x, y, z)", f"norm {norm:.6g}")
    w, x, y, z = (q / norm).tolist()
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def frd_to_ned(
    point_frd: npt.ArrayLike,
    pos_ned_m: Sequence[float] | npt.ArrayLike,
    quat_wxyz: Sequence[float] | npt.ArrayLike,
) -> np.ndarray:
    """A body FRD point (metres from the body origin) -> NED metres: ``pos_ned_m + R(q) @ point_frd``.

    Returns:
        (3,) float64 NED position.
    """
    p = _vector("point_frd", point_frd, 3)
    pos = _vector("pos_ned_m", pos_ned_m, 3)
    out: np.ndarray = pos + quat_to_matrix(quat_wxyz) @ p
    return out


@dataclass(frozen=True, slots=True)
class PinholeCamera:
    """An undistorted pinhole camera looking down body +z (see the module docstring for the frames).

    Attributes:
        width, height: image size in pixels.
        fx, fy: focal lengths in pixels.
        cx, cy: principal point in continuous pixel coordinates (the image centre is ``(W/2, H/2)``).
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float

    def __post_init__(self) -> None:
        for name in ("width", "height"):
            object.__setattr__(self, name, _integer(name, getattr(self, name), 1))
        for name in ("fx", "fy"):
            object.__setattr__(self, name, _finite(name, getattr(self, name), 0.0, exclusive=True))
        for name in ("cx", "cy"):
            object.__setattr__(self, name, _finite(name, getattr(self, name)))

    @classmethod
    def from_hfov(cls, width: int, height: int, hfov_deg: float) -> PinholeCamera:
        """Square pixels, principal point at the image centre, ``fx = fy = (W / 2) / tan(hfov / 2)``."""
        hfov = _finite("hfov_deg", hfov_deg, 0.0, exclusive=True)
        if hfov >= 180.0:
            raise GeometryInputError("hfov_deg", "a finite number in (0, 180)", repr(hfov))
        w, h = _integer("width", width, 1), _integer("height", height, 1)
        focal = (w / 2) / math.tan(math.radians(hfov) / 2)
        return cls(w, h, focal, focal, w / 2, h / 2)

    def project_frd(self, points_frd: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Project body FRD points into the image.

        Args:
            points_frd: (N, 3) points in body FRD metres.

        Returns:
            ``(uv, in_front)``: (N, 2) float64 continuous pixel coordinates, NaN rows where the point is
            not in front of the camera (depth <= 1 mm or not finite); (N,) bool ``in_front``. Points in
            front may still fall outside the image (a NaN or infinite x or y gives a non-finite
            coordinate); see :meth:`in_image`.
        """
        pts = np.asarray(points_frd, dtype=np.float64)
        if pts.ndim != 2 or pts.shape[1] != 3:
            raise GeometryInputError("points_frd", "an (N, 3) array of body FRD points", f"shape {pts.shape}")
        # CAMERA_TO_BODY is a signed permutation: x_cam = y_body, y_cam = -x_body, z_cam = z_body.
        # Column arithmetic, not a (N, 3) @ (3, 3) matmul, which goes through BLAS and is slow on one core.
        x, y, z = pts[:, 0], pts[:, 1], pts[:, 2]
        in_front = (z > _MIN_DEPTH_M) & (z < np.inf)  # False for NaN
        uv = np.empty((pts.shape[0], 2))
        with np.errstate(all="ignore"):  # 1 / z of points behind, huge coordinates: masked to NaN
            inv_z = np.where(in_front, 1.0 / z, np.nan)
            np.multiply(y, inv_z, out=uv[:, 0])
            np.multiply(x, inv_z, out=uv[:, 1])
        uv[:, 0] *= self.fx
        uv[:, 0] += self.cx
        uv[:, 1] *= -self.fy
        uv[:, 1] += self.cy
        return uv, in_front

    def in_image(self, uv: npt.ArrayLike) -> np.ndarray:
        """(N,) bool: which (N, 2) pixel coordinates lie inside ``[0, W) x [0, H)`` (False for NaN)."""
        arr = np.asarray(uv, dtype=np.float64)
        if arr.ndim != 2 or arr.shape[1] != 2:
            raise GeometryInputError("uv", "an (N, 2) array of pixel coordinates", f"shape {arr.shape}")
        u, v = arr[:, 0], arr[:, 1]
        inside: np.ndarray = (u >= 0.0) & (u < self.width) & (v >= 0.0) & (v < self.height)
        return inside

    def pixel_rays_frd(self, uv: npt.ArrayLike) -> np.ndarray:
        """Unit (N, 3) directions in body FRD of the rays through (N, 2) pixel coordinates, as
        :meth:`pixel_ray_frd` gives them one at a time."""
        arr = np.asarray(uv, dtype=np.float64)
        if arr.ndim != 2 or arr.shape[1] != 2 or not np.isfinite(arr).all():
            raise GeometryInputError(
                "uv", "an (N, 2) array of finite pixel coordinates", f"shape {arr.shape}"
            )
        cam = np.column_stack(
            [(arr[:, 0] - self.cx) / self.fx, (arr[:, 1] - self.cy) / self.fy, np.ones(len(arr))]
        )
        rays: np.ndarray = cam @ CAMERA_TO_BODY.T
        unit: np.ndarray = rays / np.linalg.norm(rays, axis=1, keepdims=True)
        return unit

    def pixel_ray_frd(self, u: float, v: float) -> np.ndarray:
        """Unit (3,) direction in body FRD of the ray through continuous pixel coordinates ``(u, v)``.

        Any finite ``(u, v)`` is accepted, also outside the image.
        """
        ray_cam = np.array(
            [(_finite("u", u) - self.cx) / self.fx, (_finite("v", v) - self.cy) / self.fy, 1.0]
        )
        ray: np.ndarray = CAMERA_TO_BODY @ ray_cam
        return ray / float(np.linalg.norm(ray))


def compass_point(bearing_deg: float) -> str:
    """The nearest of the eight compass points (``"N"``, ``"NE"`` ... ``"NW"``) to a bearing in degrees
    from north toward east, as the recovery names directions to people."""
    names = ["N", "NE", "E", "SE", "S", "SW", "W", "NW"]
    return names[round((bearing_deg % 360) / 45) % 8]
