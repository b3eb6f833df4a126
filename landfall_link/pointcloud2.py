"""ROS 2 ``sensor_msgs/msg/PointCloud2`` decoded into the sweeps
:class:`~landfall_link.lidar_bridge.LidarBridge` takes, with numpy alone (no ROS installation).

Every maintained LiDAR family's ROS 2 driver publishes this message (livox_ros_driver2 for the Mid-360,
HAP and Avia, ouster-ros, velodyne, Hesai, RoboSense); only the point layout differs, and the message
describes it: ``fields`` (each a name, a byte offset in the point, a ``datatype`` code and a ``count``),
``point_step`` bytes a point, ``row_step`` bytes a row, ``height`` rows of ``width`` points,
``is_bigendian``. :func:`read_points` builds a numpy structured dtype from the fields it needs (x, y, z
and an intensity) and reads them straight out of ``data``, so any layout with float or integer x, y, z
decodes: livox_ros_driver2's packed 26-byte points (x, y, z, intensity float32; tag, line uint8;
timestamp float64), ouster-ros's 48-byte aligned points (x, y, z, padding, intensity float32, t uint32,
reflectivity, ring, ambient uint16, range uint32), a bare x, y, z cloud.

A cloud is accepted as a message object, as rclpy or rosbags give it, or as the plain
:class:`PointCloud2` below: anything with those attributes. ``data`` may be bytes, an ``array.array``
(rclpy), a uint8 numpy array (rosbags) or a list of ints.

Frames. A ROS cloud is in its ``header.frame_id``'s axes, which ROS's convention (REP 103) makes x
forward, y left, z up (FLU). :class:`~landfall_link.lidar_bridge.LidarMount` turns a sweep from the
LiDAR's axes into the body's FRD (x forward, y right, z down) by the roll, pitch and yaw of the LiDAR's
FRD axes from the body's; :func:`flu_to_frd` gives the cloud's points in those axes (y and z negated: a
half turn about x), so that a LiDAR whose ROS frame is the body's forward-left-up needs the mount
(0, 0, 0), and one hung upside down under the airframe, x still forward, (180, 0, 0).
:func:`sweep_from_cloud` is the two in one: what a driver hands to ``LidarBridge.push``.

Points that are not returns are left out: a NaN or infinite coordinate (a driver's miss in a cloud
that is not ``is_dense``) and a point at exactly the origin (ouster-ros's organized clouds keep every
beam and give a beam without a return x = y = z = 0).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

__all__ = [
    "POINT_FIELD_DATATYPES",
    "PointCloud2",
    "PointCloud2Error",
    "PointField",
    "flu_to_frd",
    "header_stamp_s",
    "read_points",
    "sweep_from_cloud",
]

# sensor_msgs/msg/PointField's datatype constants (INT8 = 1 ... FLOAT64 = 8), as numpy types; restated
# here because the decoder must run where no ROS message package is installed.
POINT_FIELD_DATATYPES: dict[int, str] = dict(enumerate(("i1", "u1", "i2", "u2", "i4", "u4", "f4", "f8"), 1))
DEFAULT_INTENSITY_SCALE = 255.0  # Livox, Velodyne, Hesai and RoboSense publish intensity in 0..255


class PointCloud2Error(ValueError):
    """A cloud that cannot be decoded: says what was wrong and what was expected."""


class PointFieldLike(Protocol):
    """One field of a point, as ``sensor_msgs/msg/PointField`` gives it."""

    @property
    def name(self) -> str: ...
    @property
    def offset(self) -> int: ...
    @property
    def datatype(self) -> int: ...
    @property
    def count(self) -> int: ...


class PointCloud2Like(Protocol):
    """What the decoder reads of a ``sensor_msgs/msg/PointCloud2`` (rclpy's, rosbags' or ours)."""

    @property
    def height(self) -> int: ...
    @property
    def width(self) -> int: ...
    @property
    def fields(self) -> Sequence[PointFieldLike]: ...
    @property
    def is_bigendian(self) -> bool: ...
    @property
    def point_step(self) -> int: ...
    @property
    def row_step(self) -> int: ...
    @property
    def data(self) -> Any: ...  # bytes, array.array, a uint8 ndarray or a list of ints


@dataclass(frozen=True, slots=True)
class PointField:
    """A point's field: ``datatype`` is a ``POINT_FIELD_DATATYPES`` code, ``offset`` in bytes."""

    name: str
    offset: int
    datatype: int
    count: int = 1


@dataclass(frozen=True, slots=True)
class PointCloud2:
    """A cloud given as plain fields (the message's, without its header)."""

    height: int
    width: int
    fields: tuple[PointField, ...]
    point_step: int
    row_step: int
    data: bytes = field(repr=False)
    is_bigendian: bool = False
    is_dense: bool = True


def header_stamp_s(msg: Any) -> float:
    """The message's ``header.stamp`` in seconds (ROS time: ``sec`` + ``nanosec`` / 1e9)."""
    stamp = msg.header.stamp
    return float(stamp.sec) + float(stamp.nanosec) * 1e-9


def _as_bytes(data: Any) -> np.ndarray:
    if isinstance(data, np.ndarray):
        return np.ascontiguousarray(data).reshape(-1).view(np.uint8)
    try:
        return np.frombuffer(data, dtype=np.uint8)  # bytes, bytearray, memoryview, array.array
    except TypeError:
        return np.asarray(data, dtype=np.uint8).reshape(-1)  # a list of ints


def _int(cloud: Any, name: str) -> int:
    value = getattr(cloud, name, None)
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 0:
        raise PointCloud2Error(f"a PointCloud2's {name} is a non-negative integer, got {value!r}")
    return int(value)


def _field_dtype(f: PointFieldLike, point_step: int, byteorder: str) -> np.dtype[Any]:
    code = POINT_FIELD_DATATYPES.get(int(f.datatype))
    if code is None:
        raise PointCloud2Error(
            f"field {f.name!r} has datatype {f.datatype}; expected one of sensor_msgs/PointField's 1..8 "
            "(INT8 ... FLOAT64)"
        )
    if int(f.count) != 1:
        raise PointCloud2Error(f"field {f.name!r} has count {f.count}; a coordinate or intensity has count 1")
    dt = np.dtype(byteorder + code)
    if not 0 <= int(f.offset) <= point_step - dt.itemsize:
        raise PointCloud2Error(
            f"field {f.name!r} ({dt.itemsize} bytes at offset {f.offset}) does not fit in a point of "
            f"point_step {point_step} bytes"
        )
    return dt


def read_points(
    cloud: PointCloud2Like,
    *,
    intensity_field: str | None = "intensity",
    intensity_scale: float = DEFAULT_INTENSITY_SCALE,
) -> np.ndarray:
    """The cloud's returns as an (N, 3) float32 array of x, y, z (metres, in the cloud's own FLU axes),
    or (N, 4) with intensity / ``intensity_scale`` when the cloud has the field ``intensity_field``.

    Rows are in the cloud's order (row by row), less the points that are not returns (non-finite or at
    the origin). A non-finite intensity reads 0.

    Raises:
        PointCloud2Error: no x, y or z field; a field of a datatype or count the decoder cannot read, or
            outside the point; sizes that disagree (``row_step`` shorter than ``width * point_step``,
            ``data`` not ``height * row_step`` bytes).
    """
    if not (np.isfinite(intensity_scale) and intensity_scale > 0):
        raise PointCloud2Error(f"intensity_scale must be a finite number > 0, got {intensity_scale!r}")
    height, width = _int(cloud, "height"), _int(cloud, "width")
    point_step, row_step = _int(cloud, "point_step"), _int(cloud, "row_step")
    fields = {str(f.name): f for f in reversed(list(cloud.fields))}  # the first of a repeated name wins
    missing = [axis for axis in ("x", "y", "z") if axis not in fields]
    if missing:
        raise PointCloud2Error(
            f"a cloud without {', '.join(missing)}: its fields are {sorted(fields) or 'none'}; expected "
            "x, y and z"
        )
    if point_step == 0:
        raise PointCloud2Error("a PointCloud2's point_step is 0 bytes; expected the size of one point")
    if row_step < width * point_step:
        raise PointCloud2Error(
            f"row_step {row_step} is shorter than width {width} x point_step {point_step} = "
            f"{width * point_step}"
        )
    raw = _as_bytes(cloud.data)
    if raw.size != height * row_step:
        raise PointCloud2Error(
            f"data holds {raw.size} bytes; expected height {height} x row_step {row_step} = "
            f"{height * row_step}"
        )
    byteorder = ">" if bool(cloud.is_bigendian) else "<"
    names = ["x", "y", "z"]
    if intensity_field is not None and intensity_field in fields and intensity_field not in names:
        names.append(intensity_field)
    dtype = np.dtype(
        {
            "names": names,
            "formats": [_field_dtype(fields[n], point_step, byteorder) for n in names],
            "offsets": [int(fields[n].offset) for n in names],
            "itemsize": point_step,
        }
    )
    if height * width == 0:
        return np.zeros((0, len(names)), dtype=np.float32)
    grid = np.ndarray((height, width), dtype=dtype, buffer=raw, strides=(row_step, point_step))
    out = np.empty((height * width, len(names)), dtype=np.float32)
    for k, name in enumerate(names):
        out[:, k] = grid[name].reshape(-1)
    xyz = out[:, :3]
    keep = np.isfinite(xyz).all(axis=1) & (xyz != 0.0).any(axis=1)
    kept: np.ndarray = out[keep]
    if len(names) == 4:
        kept[:, 3] = np.nan_to_num(kept[:, 3] / np.float32(intensity_scale), nan=0.0, posinf=0.0, neginf=0.0)
    return kept


def flu_to_frd(points: np.ndarray) -> np.ndarray:
    """(N, 3 or 4) points in a ROS frame's FLU axes -> the same points in that frame's FRD axes (y and z
    negated, a half turn about x; any intensity column kept), a new array."""
    pts = np.array(points, dtype=np.float32, copy=True)
    if pts.ndim != 2 or pts.shape[1] < 3:
        raise PointCloud2Error(f"points are an (N, 3) or (N, 4) array, got shape {pts.shape}")
    pts[:, 1:3] *= -1.0
    return pts


def sweep_from_cloud(
    cloud: PointCloud2Like,
    *,
    intensity_field: str | None = "intensity",
    intensity_scale: float = DEFAULT_INTENSITY_SCALE,
) -> np.ndarray:
    """The cloud as a sweep for ``LidarBridge.push``: :func:`read_points` turned into the LiDAR frame's
    FRD axes (:func:`flu_to_frd`), (N, 3) or (N, 4) float32, intensity in 0..1 once the mount clips it."""
    sweep: np.ndarray = flu_to_frd(
        read_points(cloud, intensity_field=intensity_field, intensity_scale=intensity_scale)
    )
    return sweep
