"""The recorded ROS 2 LiDAR samples of tests/data/ros2-lidar, and the synthetic scenes they were made from.

Two bags, each a drone hovering still over a deterministic scene, in the point layouts the drivers
publish (``sensor_msgs/msg/PointCloud2``):

- ``livox-mid360`` (sqlite3, ``/livox/lidar``, frame ``livox_frame``): livox_ros_driver2's packed
  26-byte points, 5 sweeps of 400 at 10 Hz, from a Mid-360 hung upside down under the airframe (mount
  180, 0, 0) looking at flat ground 15 m below the vehicle's reference point and a roof 3 m tall
  ahead and to the right;
- ``ouster-os1`` (MCAP, ``/ouster/points``, frame ``os_lidar``): ouster-ros's 48-byte points in an
  organized cloud of 8 rows x 48 columns, 3 sweeps, from an upright OS1 whose connector faces aft (its
  os_lidar +x points at the connector: mount 0, 0, 180) seeing ground 20 m below and a wall 30 m
  ahead; beams without a return are x = y = z = 0, as ouster-ros gives them.

The points are made in the body's FRD axes and taken back into the sensor's ROS (FLU) axes through the
mount, so a test can compare what the bridge serves with the scene. Run this file to write the bags again
(``python -m tests.ros2_samples``; rosbags, the ``lidar`` extra); it refuses to overwrite them.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from landfall_link.lidar_bridge import body_rotation

DATA = Path(__file__).resolve().parent / "data" / "ros2-lidar"
LIVOX_BAG = DATA / "livox-mid360"
OUSTER_BAG = DATA / "ouster-os1"
STAMP0_S = 1_767_225_600  # 2026-01-01T00:00:00Z, the first sweep's header stamp
PERIOD_S = 0.1
RECORD_DELAY_NS = 4_000_000  # the bag's record time, after the stamp

# Livox Mid-360, upside down
LIVOX_TOPIC, LIVOX_FRAME = "/livox/lidar", "livox_frame"
LIVOX_MOUNT_RPY_DEG = (180.0, 0.0, 0.0)
LIVOX_OFFSET_FRD_M = (0.10, 0.0, 0.08)
LIVOX_SWEEPS, LIVOX_POINTS = 5, 400
GROUND_Z_M = 15.0  # body FRD: the ground this far below the reference point
ROOF_Z_M = 12.0
ROOF_X_M, ROOF_Y_M = (3.0, 8.0), (2.0, 6.0)  # ahead and to the right
LIVOX_INTENSITY = {"ground": 40.0, "roof": 120.0}  # of 255

# Ouster OS1, upright, connector aft, its cloud in os_lidar
OUSTER_TOPIC, OUSTER_FRAME = "/ouster/points", "os_lidar"
OUSTER_MOUNT_RPY_DEG = (0.0, 0.0, 180.0)
OUSTER_OFFSET_FRD_M = (0.0, 0.0, -0.10)
OUSTER_SWEEPS, OUSTER_ROWS, OUSTER_COLUMNS = 3, 8, 48
OUSTER_GROUND_Z_M = 20.0
WALL_X_M, WALL_HALF_WIDTH_M = 30.0, 15.0
OUSTER_RANGE_M = 100.0
OUSTER_REFLECTIVITY = {"ground": 60, "wall": 200}

# sensor_msgs/msg/PointField datatypes
UINT8, UINT16, UINT32, FLOAT32, FLOAT64 = 2, 4, 6, 7, 8
LIVOX_FIELDS = (("x", 0, FLOAT32), ("y", 4, FLOAT32), ("z", 8, FLOAT32), ("intensity", 12, FLOAT32),
                ("tag", 16, UINT8), ("line", 17, UINT8), ("timestamp", 18, FLOAT64))  # fmt: skip
LIVOX_DTYPE = np.dtype({"names": [f[0] for f in LIVOX_FIELDS], "offsets": [f[1] for f in LIVOX_FIELDS],
                        "formats": ["<f4"] * 4 + ["u1", "u1", "<f8"], "itemsize": 26})  # fmt: skip
OUSTER_FIELDS = (("x", 0, FLOAT32), ("y", 4, FLOAT32), ("z", 8, FLOAT32), ("intensity", 16, FLOAT32),
                 ("t", 20, UINT32), ("reflectivity", 24, UINT16), ("ring", 26, UINT16),
                 ("ambient", 28, UINT16), ("range", 32, UINT32))  # fmt: skip
OUSTER_DTYPE = np.dtype({"names": [f[0] for f in OUSTER_FIELDS], "offsets": [f[1] for f in OUSTER_FIELDS],
                         "formats": ["<f4", "<f4", "<f4", "<f4", "<u4", "<u2", "<u2", "<u2", "<u4"],
                         "itemsize": 48})  # fmt: skip


@dataclass(frozen=True, slots=True)
class SampleSweep:
    """One sweep of a sample: the structured points as the driver lays them out (sensor FLU), the body
    FRD x, y, z of each (NaN where a beam has no return) and the header stamp in nanoseconds."""

    points: np.ndarray
    body_frd: np.ndarray
    stamp_ns: int


def to_sensor_flu(
    body_frd: np.ndarray, rpy_deg: tuple[float, float, float], offset: tuple[float, ...]
) -> np.ndarray:
    """Body FRD points (N, 3) -> the sensor's ROS FLU axes, by a mount (the inverse of the bridge's)."""
    frd: np.ndarray = (body_frd - np.asarray(offset)) @ body_rotation(*rpy_deg)  # R^T (p - o), row by row
    flu: np.ndarray = frd * np.array([1.0, -1.0, -1.0])
    return flu


def livox_sweeps() -> list[SampleSweep]:
    """The Mid-360's sweeps: random directions within 50 degrees of straight down (a new pattern each
    sweep, as its non-repetitive scan), each to the roof top or the ground."""
    rng = np.random.default_rng(360)
    origin = np.asarray(LIVOX_OFFSET_FRD_M)
    out = []
    for k in range(LIVOX_SWEEPS):
        cone = np.radians(50.0) * np.sqrt(rng.uniform(0.0, 1.0, LIVOX_POINTS))
        azimuth = rng.uniform(0.0, 2.0 * math.pi, LIVOX_POINTS)
        d = np.column_stack([np.sin(cone) * np.cos(azimuth), np.sin(cone) * np.sin(azimuth), np.cos(cone)])
        hit_roof = origin + d * ((ROOF_Z_M - origin[2]) / d[:, 2])[:, None]
        on_roof = (hit_roof[:, 0] >= ROOF_X_M[0]) & (hit_roof[:, 0] <= ROOF_X_M[1])
        on_roof &= (hit_roof[:, 1] >= ROOF_Y_M[0]) & (hit_roof[:, 1] <= ROOF_Y_M[1])
        body = np.where(
            on_roof[:, None], hit_roof, origin + d * ((GROUND_Z_M - origin[2]) / d[:, 2])[:, None]
        )
        flu = to_sensor_flu(body, LIVOX_MOUNT_RPY_DEG, LIVOX_OFFSET_FRD_M)
        stamp_ns = round((STAMP0_S + k * PERIOD_S) * 1e9)
        pts = np.zeros(LIVOX_POINTS, dtype=LIVOX_DTYPE)
        pts["x"], pts["y"], pts["z"] = flu[:, 0], flu[:, 1], flu[:, 2]
        pts["intensity"] = np.where(on_roof, LIVOX_INTENSITY["roof"], LIVOX_INTENSITY["ground"])
        pts["line"] = np.arange(LIVOX_POINTS) % 4
        pts["timestamp"] = stamp_ns + np.arange(LIVOX_POINTS) * 250_000.0  # 0.1 s over the sweep, in ns
        out.append(SampleSweep(pts, body, stamp_ns))
    return out


def ouster_sweeps() -> list[SampleSweep]:
    """The OS1's sweeps: 8 beams from 22.5 to 5 degrees below its horizon, 48 columns round; each beam to
    the wall ahead, the ground, or no return beyond its range."""
    sensor_origin = np.asarray(OUSTER_OFFSET_FRD_M)
    down = np.radians(np.linspace(22.5, 5.0, OUSTER_ROWS))  # below the horizon, top row last
    heading = np.radians(np.arange(OUSTER_COLUMNS) * 360.0 / OUSTER_COLUMNS)  # body azimuth, 0 = ahead
    dd, hh = np.meshgrid(down, heading, indexing="ij")
    d = np.stack([np.cos(dd) * np.cos(hh), np.cos(dd) * np.sin(hh), np.sin(dd)], axis=-1)  # body FRD
    t_ground = (OUSTER_GROUND_Z_M - sensor_origin[2]) / d[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        t_wall = np.where(d[..., 0] > 0, (WALL_X_M - sensor_origin[0]) / d[..., 0], np.inf)
        wall_hit = sensor_origin + d * t_wall[..., None]
    on_wall = (t_wall < t_ground) & (np.abs(wall_hit[..., 1]) <= WALL_HALF_WIDTH_M)
    t = np.where(on_wall, t_wall, t_ground)
    hit = t <= OUSTER_RANGE_M
    body = np.where(hit[..., None], sensor_origin + d * t[..., None], np.nan)
    flu = to_sensor_flu(np.nan_to_num(body.reshape(-1, 3)), OUSTER_MOUNT_RPY_DEG, OUSTER_OFFSET_FRD_M)
    flu[~hit.reshape(-1)] = 0.0  # ouster-ros: a beam without a return is the origin
    out = []
    for k in range(OUSTER_SWEEPS):
        pts = np.zeros((OUSTER_ROWS, OUSTER_COLUMNS), dtype=OUSTER_DTYPE)
        pts["x"], pts["y"], pts["z"] = (flu[:, i].reshape(OUSTER_ROWS, OUSTER_COLUMNS) for i in range(3))
        refl = np.where(on_wall, OUSTER_REFLECTIVITY["wall"], OUSTER_REFLECTIVITY["ground"])
        pts["reflectivity"] = np.where(hit, refl, 0)
        pts["intensity"] = np.where(hit, 8.0 * refl + k, 0.0)  # signal photons, beyond 255
        pts["t"] = (np.arange(OUSTER_COLUMNS) * (100_000_000 // OUSTER_COLUMNS))[None, :]
        pts["ring"] = np.arange(OUSTER_ROWS)[:, None]
        pts["ambient"] = 30
        pts["range"] = np.where(hit, np.round(t * 1000.0), 0).astype(np.uint32)
        out.append(SampleSweep(pts, body.reshape(-1, 3), round((STAMP0_S + k * PERIOD_S) * 1e9)))
    return out


def _write(path: Path, topic: str, frame: str, fields: tuple[tuple[str, int, int], ...],
           sweeps: list[SampleSweep], mcap: bool) -> None:  # fmt: skip
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    t = store.types
    msgtype = "sensor_msgs/msg/PointCloud2"
    plugin = StoragePlugin.MCAP if mcap else StoragePlugin.SQLITE3
    with Writer(path, version=8, storage_plugin=plugin) as writer:
        conn = writer.add_connection(topic, msgtype, typestore=store)
        for sweep in sweeps:
            pts = sweep.points
            height, width = (1, pts.size) if pts.ndim == 1 else pts.shape
            msg = t[msgtype](
                header=t["std_msgs/msg/Header"](
                    stamp=t["builtin_interfaces/msg/Time"](
                        sec=sweep.stamp_ns // 10**9, nanosec=sweep.stamp_ns % 10**9
                    ),
                    frame_id=frame,
                ),
                height=height,
                width=width,
                fields=[
                    t["sensor_msgs/msg/PointField"](name=n, offset=o, datatype=d, count=1)
                    for n, o, d in fields
                ],
                is_bigendian=False,
                point_step=pts.dtype.itemsize,
                row_step=width * pts.dtype.itemsize,
                data=np.frombuffer(pts.tobytes(), dtype=np.uint8),
                is_dense=True,
            )
            writer.write(conn, sweep.stamp_ns + RECORD_DELAY_NS, store.serialize_cdr(msg, msgtype))


def main() -> int:
    for path in (LIVOX_BAG, OUSTER_BAG):
        if path.exists():
            print(f"{path} exists: remove it first to write it again", file=sys.stderr)
            return 1
    DATA.mkdir(parents=True, exist_ok=True)
    _write(LIVOX_BAG, LIVOX_TOPIC, LIVOX_FRAME, LIVOX_FIELDS, livox_sweeps(), mcap=False)
    _write(OUSTER_BAG, OUSTER_TOPIC, OUSTER_FRAME, OUSTER_FIELDS, ouster_sweeps(), mcap=True)
    for path in sorted(DATA.rglob("*")):
        if path.is_file():
            print(f"{path.relative_to(DATA.parent.parent.parent)}: {path.stat().st_size} bytes")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
