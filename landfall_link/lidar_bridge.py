"""A reference producer for the sensor stream: a real LiDAR's sweeps served to the companion, each dated
on the autopilot's boot clock (docs/sensor-stream.md, "Feeding the companion from a real LiDAR").

A LiDAR driver knows its points and when it took them on *this* computer's clock; the companion places
every sweep with the autopilot's own pose at the sweep's ``time_boot_ms``. The bridge listens to the
autopilot's MAVLink (a mavlink-router endpoint of its own), fits the boot clock from the
``time_boot_ms`` stamps as they arrive (:class:`~landfall_link.boot_clock.BootClock`), turns the points
from the LiDAR's axes into the body's (its mounting) and serves the newest sweep to any client::

    mount = LidarMount(rpy_deg=(0, 0, 0), offset_frd_m=(0.1, 0, 0.05))
    async with LidarBridge("udpin:127.0.0.1:14551", "127.0.0.1:5601", mount) as bridge:
        async for points, taken_monotonic_s in driver.sweeps():  # (N, 3) or (N, 4) in the LiDAR's axes
            bridge.push(points, taken_monotonic_s)

Its frames carry the LiDAR and the rangefinder only (no image: the companion's camera is a video stream,
docs/camera.md); the rangefinder is the autopilot's downward DISTANCE_SENSOR when fresh, else the
sweep's nearest returns around the nadir. ``python -m landfall_link.lidar_bridge --replay DIR`` serves
recorded sweeps (``.npy`` files) the same way, to try a set-up without the sensor; ``--ros2-bag BAG`` and
``--ros2-topic TOPIC`` feed it a ROS 2 driver's ``sensor_msgs/msg/PointCloud2`` clouds, recorded or live
(:mod:`landfall_link.lidar_ros2`).
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import logging
import math
import signal
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from landfall_link import lidar_ros2
from landfall_link.boot_clock import BootClock
from landfall_link.mavlink import URL_FORMS, open_link
from landfall_link.pointcloud2 import DEFAULT_INTENSITY_SCALE
from landfall_link.sensorstream import SensorFrame, SensorStreamServer, parse_endpoint

__all__ = ["LidarBridge", "LidarBridgeError", "LidarMount", "body_rotation", "build_parser", "main"]

MAV_COMP_ID_PERIPHERAL = 158
MAV_TYPE_ONBOARD_CONTROLLER = 18
MAV_AUTOPILOT_INVALID = 8
MAV_SENSOR_ROTATION_PITCH_270 = 25  # DISTANCE_SENSOR orientation: looking down
NADIR_CONE_DEG = 5.0  # returns this close to straight down give the sweep's own ground distance
RANGEFINDER_FRESH_S = 1.0

log = logging.getLogger("landfall_link.lidar_bridge")


class LidarBridgeError(ValueError):
    """A sweep or a mounting the bridge cannot use (says which and why)."""


def body_rotation(roll_deg: float, pitch_deg: float, yaw_deg: float) -> np.ndarray:
    """The rotation (3, 3) of a sensor's axes turned by roll, pitch and yaw (ZYX, aerospace order) from
    the body's FRD axes: ``body = R @ sensor``."""
    r, p, y = (math.radians(v) for v in (roll_deg, pitch_deg, yaw_deg))
    rx = np.array([[1, 0, 0], [0, math.cos(r), -math.sin(r)], [0, math.sin(r), math.cos(r)]])
    ry = np.array([[math.cos(p), 0, math.sin(p)], [0, 1, 0], [-math.sin(p), 0, math.cos(p)]])
    rz = np.array([[math.cos(y), -math.sin(y), 0], [math.sin(y), math.cos(y), 0], [0, 0, 1]])
    out: np.ndarray = rz @ ry @ rx
    return out


@dataclass(frozen=True, slots=True)
class LidarMount:
    """Where the LiDAR sits: its axes turned by ``rpy_deg`` from the body's FRD axes, its origin at
    ``offset_frd_m`` from the vehicle's reference point (the autopilot's position)."""

    rpy_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)
    offset_frd_m: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        for name in ("rpy_deg", "offset_frd_m"):
            values = getattr(self, name)
            if len(values) != 3 or not all(isinstance(v, int | float) and math.isfinite(v) for v in values):
                raise LidarBridgeError(f"LiDAR mount {name}: three finite numbers, got {values!r}")

    def to_body(self, points: np.ndarray) -> np.ndarray:
        """(N, 3 or 4) points in the LiDAR's axes -> (N, 4) float32 body FRD + intensity (1 when the
        sweep has none)."""
        pts = np.asarray(points)
        if pts.ndim != 2 or pts.shape[1] not in (3, 4) or not np.issubdtype(pts.dtype, np.floating):
            raise LidarBridgeError(f"a sweep is an (N, 3) or (N, 4) float array, got {pts.dtype} {pts.shape}")
        pts = pts[np.isfinite(pts).all(axis=1)]  # a driver's NaN rows are misses
        out = np.ones((len(pts), 4), dtype=np.float32)
        rot = body_rotation(*self.rpy_deg)
        out[:, :3] = pts[:, :3].astype(np.float64) @ rot.T + np.asarray(self.offset_frd_m)
        if pts.shape[1] == 4:
            out[:, 3] = np.clip(pts[:, 3], 0.0, 1.0)
        return out


def nadir_distance(points_frd: np.ndarray, cone_deg: float = NADIR_CONE_DEG) -> float | None:
    """The ground distance straight down from a sweep (body FRD): the median of the returns within
    ``cone_deg`` of the body's +z axis, along +z; None when none is there."""
    xyz = points_frd[:, :3].astype(np.float64)
    r = np.linalg.norm(xyz, axis=1)
    down = (xyz[:, 2] > 0) & (xyz[:, 2] >= r * math.cos(math.radians(cone_deg)))
    return float(np.median(xyz[down, 2])) if down.any() else None


class LidarBridge:
    """Serves the newest sweep pushed to it on the sensor stream at ``endpoint`` (``HOST:PORT``), dated on
    the boot clock of the autopilot heard on ``mavlink_url`` (UDP, TCP or serial: ``URL_FORMS``)."""

    def __init__(
        self,
        mavlink_url: str,
        endpoint: str,
        mount: LidarMount | None = None,
        *,
        vehicle_system_id: int = 1,
        max_sweep_age_s: float = 1.0,
    ) -> None:
        self.mount = mount or LidarMount()
        self.clock = BootClock()
        self._host, self._port = parse_endpoint(endpoint)
        self._vehicle = vehicle_system_id
        self._max_age_s = max_sweep_age_s
        self._link = open_link(mavlink_url, 1, MAV_COMP_ID_PERIPHERAL, self._on_message, logger=log)
        self._server: SensorStreamServer | None = None
        self._sweep: tuple[np.ndarray, float] | None = None  # body FRD points, taken (monotonic s)
        self._pos = (0.0, 0.0, 0.0)
        self._quat = (1.0, 0.0, 0.0, 0.0)
        self._range: tuple[float, float] | None = None  # DISTANCE_SENSOR metres, received (monotonic s)
        self.sweeps_pushed = 0
        self._beat: asyncio.Task[None] | None = None

    async def _heartbeats(self) -> None:
        """A peripheral's HEARTBEAT once a second: a ``udpout`` peer or a router learns where we are."""
        mav = self._link.mav
        while True:
            self._link.send(mav.heartbeat_encode(MAV_TYPE_ONBOARD_CONTROLLER, MAV_AUTOPILOT_INVALID, 0, 0, 0))
            await asyncio.sleep(1.0)

    async def __aenter__(self) -> LidarBridge:
        await self._link.__aenter__()
        self._beat = asyncio.create_task(self._heartbeats(), name="lidar-bridge-heartbeat")
        info = {"producer": "landfall_link.lidar_bridge", "lidar": {"mount_rpy_deg": list(self.mount.rpy_deg),
                "offset_frd_m": list(self.mount.offset_frd_m)}, "camera": None}  # fmt: skip
        self._server = SensorStreamServer(self._host, self._port, self._capture, info)
        await self._server.__aenter__()
        return self

    async def __aexit__(self, *exc: object) -> None:
        if self._beat is not None:
            self._beat.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._beat
        if self._server is not None:
            await self._server.__aexit__(None, None, None)
        await self._link.__aexit__(None, None, None)

    @property
    def port(self) -> int:
        """The sensor-stream port served (the one chosen when ``endpoint`` asked for port 0)."""
        assert self._server is not None, "the bridge is not running"
        return int(self._server.port)

    def push(self, points: np.ndarray, taken_monotonic_s: float | None = None) -> None:
        """A new sweep: (N, 3) or (N, 4) points in the LiDAR's axes (metres; intensity in 0..1), taken at
        ``taken_monotonic_s`` on this computer's ``time.monotonic()`` clock (now when not given)."""
        taken = time.monotonic() if taken_monotonic_s is None else float(taken_monotonic_s)
        self._sweep = (self.mount.to_body(points), taken)
        self.sweeps_pushed += 1
        if self.sweeps_pushed == 1:
            log.info("first LiDAR sweep: %d points", len(self._sweep[0]))

    def _on_message(self, msg: Any, _addr: Any) -> None:
        if msg.get_srcSystem() != self._vehicle or msg.get_srcComponent() != 1:
            return
        kind = msg.get_type()
        now = time.monotonic()
        if kind == "LOCAL_POSITION_NED":
            known = self.clock.rate is not None
            self.clock.add(now, msg.time_boot_ms / 1000.0)
            self._pos = (float(msg.x), float(msg.y), float(msg.z))
            if not known and self.clock.rate is not None:
                log.info("the autopilot's boot clock is known (rate %.4f)", self.clock.rate)
        elif kind == "ATTITUDE_QUATERNION":
            self._quat = (float(msg.q1), float(msg.q2), float(msg.q3), float(msg.q4))
        elif (
            kind == "DISTANCE_SENSOR"
            and msg.orientation == MAV_SENSOR_ROTATION_PITCH_270
            and msg.min_distance <= msg.current_distance <= msg.max_distance
        ):
            self._range = (msg.current_distance / 100.0, now)

    async def _capture(self, want: set[str]) -> SensorFrame:
        if self._sweep is None:
            raise LidarBridgeError("no LiDAR sweep yet")
        points, taken = self._sweep
        age = time.monotonic() - taken
        if age > self._max_age_s:
            raise LidarBridgeError(f"the newest LiDAR sweep is {age:.1f} s old (the driver stopped?)")
        boot = self.clock.boot_at(taken)
        if boot is None:
            raise LidarBridgeError("the autopilot's clock is not known yet (no LOCAL_POSITION_NED heard)")
        fresh = self._range is not None and time.monotonic() - self._range[1] < RANGEFINDER_FRESH_S
        distance = self._range[0] if fresh and self._range is not None else nadir_distance(points)
        if distance is None:
            raise LidarBridgeError("no distance to the ground: no downward DISTANCE_SENSOR, no return below")
        return SensorFrame(
            t_s=boot, time_boot_ms=max(0, round(boot * 1000)), pos_ned_m=self._pos, quat_wxyz=self._quat,
            rangefinder_m=distance, fx=1.0, fy=1.0, cx=0.5, cy=0.5, width=1, height=1, weather="clear",
            image_rgb=None, depth_m=None, lidar_frd=points if "lidar" in want else None,
        )  # fmt: skip


# ------------------------------------------------------------------------------------------------ CLI
def _replay_files(folder: Path) -> list[Path]:
    files = sorted(folder.glob("*.npy"))
    if not files:
        raise LidarBridgeError(f"{folder}: no .npy sweeps to replay")
    return files


async def _replay(bridge: LidarBridge, files: list[Path], rate_hz: float, stop: asyncio.Event) -> None:
    k = 0
    while not stop.is_set():
        bridge.push(np.load(files[k % len(files)]))
        k += 1
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(stop.wait(), 1.0 / rate_hz)


async def _serve(args: argparse.Namespace) -> None:
    mount = LidarMount(tuple(args.mount_rpy_deg), tuple(args.offset_frd_m))
    if args.replay is not None:
        files = _replay_files(args.replay)
        what = f"replaying {len(files)} files at {args.rate:g} Hz"
    elif args.ros2_bag is not None:
        topic, count = await asyncio.to_thread(lidar_ros2.bag_topic, args.ros2_bag, args.topic)
        pace = "their header stamps" if args.rate is None else f"{args.rate:g} Hz"
        what = f"replaying {count} clouds of {topic} from {args.ros2_bag} at {pace}"
    else:
        what = f"following the ROS 2 topic {args.ros2_topic}"
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    bridge = LidarBridge(args.mavlink, args.sensors, mount, vehicle_system_id=args.vehicle_system_id)
    async with bridge:
        log.info("serving LiDAR sweeps on %s (port %d), %s", args.sensors, bridge.port, what)
        print(f"lidar bridge: sensor stream on port {bridge.port}", flush=True)
        if args.replay is not None:
            await _replay(bridge, files, args.rate, stop)
        elif args.ros2_bag is not None:
            await lidar_ros2.replay_bag(bridge, args.ros2_bag, topic, stop, rate_hz=args.rate,
                                        intensity_field=args.intensity_field,
                                        intensity_scale=args.intensity_scale)  # fmt: skip
        else:
            await lidar_ros2.follow_topic(bridge, args.ros2_topic, stop, intensity_field=args.intensity_field,
                                          intensity_scale=args.intensity_scale)  # fmt: skip


def build_parser() -> argparse.ArgumentParser:
    """The command line of ``landfall-lidar-bridge``."""
    p = argparse.ArgumentParser(
        prog="landfall-lidar-bridge",
        description="Serve LiDAR sweeps to the companion on the sensor stream, dated on the autopilot's "
        "clock (docs/sensor-stream.md): recorded .npy sweeps, a recorded ROS 2 bag, or a live ROS 2 "
        "PointCloud2 topic; any other driver uses LidarBridge.",
    )
    p.add_argument(
        "--mavlink",
        required=True,
        help="the autopilot's MAVLink, e.g. udpin:127.0.0.1:14551 or serial:/dev/ttyAMA0:921600; "
        f"forms: {URL_FORMS}",
    )
    p.add_argument(
        "--sensors",
        default="127.0.0.1:5601",
        help="HOST:PORT served, the companion's --sensors (default %(default)s, the companion's too)",
    )
    source = p.add_mutually_exclusive_group(required=True)
    source.add_argument("--replay", type=Path, metavar="DIR", help="folder of .npy sweeps, (N, 3|4) float32")
    source.add_argument(
        "--ros2-bag",
        type=Path,
        metavar="BAG",
        help="a recorded ROS 2 bag (its folder, or a .db3 or .mcap file) of sensor_msgs/msg/PointCloud2, "
        f"replayed in a loop (needs rosbags: {lidar_ros2.LIDAR_EXTRA_HINT})",
    )
    source.add_argument(
        "--ros2-topic",
        metavar="TOPIC",
        help="a live sensor_msgs/msg/PointCloud2 topic, e.g. /livox/lidar (needs rclpy: a sourced ROS 2)",
    )
    p.add_argument("--topic", help="--ros2-bag's PointCloud2 topic (default: the bag's only one)")
    p.add_argument(
        "--rate",
        type=float,
        help="sweeps a second (default: 10 for --replay; --ros2-bag keeps its header stamps' pace)",
    )
    p.add_argument(
        "--intensity-field",
        default="intensity",
        help="the PointCloud2 field read as intensity (default intensity; ouster-ros: reflectivity)",
    )
    p.add_argument(
        "--intensity-scale",
        type=float,
        default=DEFAULT_INTENSITY_SCALE,
        help="the intensity field's full scale, read as 1 (default 255)",
    )
    p.add_argument(
        "--mount-rpy-deg",
        type=float,
        nargs=3,
        default=(0.0, 0.0, 0.0),
        metavar=("R", "P", "Y"),
        help="the LiDAR's axes turned from the body's FRD, degrees (a ROS 2 cloud's FLU frame is taken to "
        "FRD first: upside down, x forward, is 180 0 0)",
    )
    p.add_argument(
        "--offset-frd-m",
        type=float,
        nargs=3,
        default=(0.0, 0.0, 0.0),
        metavar=("X", "Y", "Z"),
        help="the LiDAR's origin from the autopilot's reference point, body FRD metres",
    )
    p.add_argument(
        "--vehicle-system-id", type=int, default=1, help="the autopilot's MAVLink system id (default 1)"
    )
    return p


def main(argv: Sequence[str] | None = None) -> int:
    p = build_parser()
    args = p.parse_args(argv)
    if args.topic is not None and args.ros2_bag is None:
        p.error("--topic names a topic of --ros2-bag (a live topic is --ros2-topic TOPIC)")
    if args.rate is not None and args.ros2_topic is not None:
        p.error("--rate paces a replay; a live --ros2-topic comes at the LiDAR's own rate")
    if args.rate is None and args.replay is not None:
        args.rate = 10.0
    if args.rate is not None and not (math.isfinite(args.rate) and args.rate > 0):
        p.error(f"--rate must be > 0, got {args.rate}")
    if not (math.isfinite(args.intensity_scale) and args.intensity_scale > 0):
        p.error(f"--intensity-scale must be > 0, got {args.intensity_scale}")
    missing = None
    if args.ros2_bag is not None:
        missing = lidar_ros2.rosbags_missing()
    elif args.ros2_topic is not None:
        missing = lidar_ros2.rclpy_missing()
    if missing is not None:
        print(f"lidar bridge: {missing}", file=sys.stderr)
        return 2
    logging.basicConfig(level=logging.INFO, stream=sys.stderr, format="%(levelname)s %(name)s: %(message)s")
    try:
        asyncio.run(_serve(args))
    except (LidarBridgeError, ValueError, OSError) as exc:
        print(f"lidar bridge: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
