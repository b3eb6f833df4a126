"""ROS 2 LiDAR sources for the bridge: a recorded bag replayed, or a live topic followed through rclpy.

Both push each ``sensor_msgs/msg/PointCloud2`` on one topic, decoded by
:mod:`landfall_link.pointcloud2` into the LiDAR frame's FRD axes, into a sink with ``LidarBridge``'s
``push(points, taken_monotonic_s)``:

- :func:`replay_bag` reads a ROS 2 bag (a folder with ``metadata.yaml``, or one ``.db3`` or ``.mcap``
  file) with the rosbags package (the ``lidar`` extra) and pushes its clouds in order, looped, at the
  pace of their header stamps (or of the bag's record times where the stamps go back or jump, or at a
  fixed rate), each dated when pushed, as the ``.npy`` replay does;
- :func:`follow_topic` subscribes to a live topic with rclpy, which comes with a ROS 2 installation
  (not from PyPI), and dates each cloud by its header stamp when that stamp is on this computer's clock
  (a driver stamping from ROS time, or a LiDAR synchronised by PTP), else by when it arrived.

rosbags and rclpy are imported only when a source runs; :func:`rosbags_missing` and
:func:`rclpy_missing` say, in one line, what to do when they are not there.
"""

from __future__ import annotations

import asyncio
import contextlib
import importlib
import logging
import math
import threading
import time
from collections.abc import Callable, Generator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from landfall_link.pointcloud2 import (
    DEFAULT_INTENSITY_SCALE,
    PointCloud2Error,
    header_stamp_s,
    sweep_from_cloud,
)

__all__ = [
    "POINTCLOUD2",
    "BagSweep",
    "Ros2SourceError",
    "SweepSink",
    "bag_topic",
    "follow_topic",
    "rclpy_missing",
    "read_bag",
    "replay_bag",
    "rosbags_missing",
    "say_when_silent",
    "taken_monotonic_s",
]

POINTCLOUD2 = "sensor_msgs/msg/PointCloud2"
LIDAR_EXTRA_HINT = "pip install 'landfall[lidar]'"
MAX_STAMP_GAP_S = 10.0  # a header stamp further than this from the previous one is on another clock
STAMP_TRUSTED_S = 1.0  # a live header stamp this old at most (and not ahead) is on this computer's clock
STAMP_AHEAD_S = 0.05  # ... allowing this much of a clock ahead of ours
NO_CLOUD_WARN_S = 5.0  # a live topic silent this long gets a warning saying what the ROS graph knows
BAD_CLOUD_LOG_EVERY = 100  # a live topic's undecodable clouds: the first, then one in this many

log = logging.getLogger("landfall_link.lidar_ros2")


class Ros2SourceError(ValueError):
    """A bag, a topic or a ROS 2 environment the bridge cannot use (says which and why)."""


class SweepSink(Protocol):
    """Where sweeps go: ``LidarBridge`` (or anything with its ``push``)."""

    def push(self, points: np.ndarray, taken_monotonic_s: float | None = None) -> None: ...


@dataclass(frozen=True, slots=True)
class BagSweep:
    """One cloud of a bag: ``points`` (N, 3 or 4) float32 in the LiDAR frame's FRD axes, its header
    stamp and the bag's record time (both seconds, on the clocks they were written on)."""

    points: np.ndarray
    stamp_s: float
    recorded_s: float
    frame_id: str


# ------------------------------------------------------------------------------------- dependencies
def _missing(modules: tuple[str, ...]) -> str | None:
    for name in modules:
        try:
            importlib.import_module(name)
        except ImportError as exc:  # not installed, or installed for another Python (rclpy's C parts)
            return str(exc) or name
    return None


def rosbags_missing() -> str | None:
    """One line saying how to install rosbags when it cannot be imported here; None when it can."""
    why = _missing(("rosbags.rosbag2", "rosbags.serde", "rosbags.typesys"))
    return None if why is None else f"reading a ROS 2 bag needs rosbags ({why}): {LIDAR_EXTRA_HINT}"


def rclpy_missing() -> str | None:
    """One line saying to source a ROS 2 environment when rclpy or sensor_msgs cannot be imported here;
    None when they can."""
    why = _missing(("rclpy", "rclpy.context", "rclpy.executors", "rclpy.qos", "sensor_msgs.msg"))
    if why is None:
        return None
    return (
        f"a live ROS 2 topic needs rclpy ({why}), which comes with ROS 2, not PyPI: source your ROS 2 "
        "environment first (e.g. source /opt/ros/jazzy/setup.bash) in a Python of the same version"
    )


# ---------------------------------------------------------------------------------------------- bags
def _connections(reader: Any, path: Path, topic: str | None) -> list[Any]:
    """The reader's connections of the PointCloud2 topic ``topic`` (the bag's only one when None)."""
    clouds = sorted({c.topic for c in reader.connections if c.msgtype == POINTCLOUD2})
    if topic is None:
        if not clouds:
            topics = ", ".join(sorted({c.topic for c in reader.connections})) or "none"
            raise Ros2SourceError(f"{path}: no {POINTCLOUD2} topic (its topics: {topics})")
        if len(clouds) > 1:
            raise Ros2SourceError(
                f"{path}: {len(clouds)} {POINTCLOUD2} topics ({', '.join(clouds)}); name one with --topic"
            )
        topic = clouds[0]
    chosen = [c for c in reader.connections if c.topic == topic]
    if not chosen:
        raise Ros2SourceError(
            f"{path}: no topic {topic}; its {POINTCLOUD2} topics: {', '.join(clouds) or 'none'}"
        )
    others = sorted({c.msgtype for c in chosen if c.msgtype != POINTCLOUD2})
    if others:
        raise Ros2SourceError(
            f"{path}: {topic} is {', '.join(others)}, not {POINTCLOUD2} (livox_ros_driver2: publish with "
            "xfer_format 0)"
        )
    return chosen


def bag_topic(path: Path, topic: str | None = None) -> tuple[str, int]:
    """The PointCloud2 topic a replay of ``path`` reads (``topic``, or the bag's only one) and its
    message count; :class:`Ros2SourceError` when there is none such, or it holds no message."""
    from rosbags.rosbag2 import Reader, ReaderError

    try:
        with Reader(path) as reader:
            chosen = _connections(reader, path, topic)
            count = sum(int(c.msgcount) for c in chosen)
    except ReaderError as exc:
        raise Ros2SourceError(f"{path}: not a ROS 2 bag rosbags can read: {exc}") from exc
    if count == 0:
        raise Ros2SourceError(f"{path}: {chosen[0].topic} holds no message")
    return str(chosen[0].topic), count


def read_bag(
    path: Path,
    topic: str | None = None,
    *,
    intensity_field: str | None = "intensity",
    intensity_scale: float = DEFAULT_INTENSITY_SCALE,
) -> Generator[BagSweep, None, None]:
    """The clouds of ``topic`` in ``path``, in record order, decoded (blocking: file I/O)."""
    from rosbags.rosbag2 import Reader, ReaderError
    from rosbags.serde import SerdeError
    from rosbags.typesys import Stores, get_typestore

    typestore = get_typestore(Stores.ROS2_HUMBLE)  # PointCloud2 is the same in every ROS 2 distribution
    try:
        with Reader(path) as reader:
            for connection, recorded_ns, raw in reader.messages(
                connections=_connections(reader, path, topic)
            ):
                where = f"{path}: {connection.topic} at {recorded_ns} ns"
                try:
                    msg: Any = typestore.deserialize_cdr(raw, connection.msgtype)
                    points = sweep_from_cloud(
                        msg, intensity_field=intensity_field, intensity_scale=intensity_scale
                    )
                except (SerdeError, PointCloud2Error) as exc:
                    raise Ros2SourceError(f"{where}: {exc}") from exc
                yield BagSweep(points, header_stamp_s(msg), recorded_ns * 1e-9, str(msg.header.frame_id))
    except ReaderError as exc:
        raise Ros2SourceError(f"{path}: not a ROS 2 bag rosbags can read: {exc}") from exc


class _Pacer:
    """When each sweep of a replay is due on ``time.monotonic()``: the first now, each next one after the
    gap between their header stamps (the bag's record times where the stamps go back or jump more than
    ``MAX_STAMP_GAP_S``), or ``1 / rate_hz`` after the previous one when a rate is given."""

    def __init__(self, rate_hz: float | None) -> None:
        self._rate = rate_hz
        self._due: float | None = None
        self._last: tuple[float, float] = (0.0, 0.0)

    def due(self, stamp_s: float, recorded_s: float, now_s: float) -> float:
        if self._due is None:
            self._due = now_s
        elif self._rate is not None:
            self._due += 1.0 / self._rate
        else:
            gap = stamp_s - self._last[0]
            if not 0.0 <= gap <= MAX_STAMP_GAP_S:
                gap = min(max(recorded_s - self._last[1], 0.0), MAX_STAMP_GAP_S)
            self._due += gap
        self._last = (stamp_s, recorded_s)
        return self._due


async def replay_bag(
    sink: SweepSink,
    path: Path,
    topic: str | None,
    stop: asyncio.Event,
    *,
    rate_hz: float | None = None,
    loop: bool = True,
    intensity_field: str | None = "intensity",
    intensity_scale: float = DEFAULT_INTENSITY_SCALE,
) -> int:
    """Pushes the bag's clouds of ``topic`` into ``sink`` until ``stop`` is set (the bag looped), or to the
    bag's end when ``loop`` is False; the number pushed. The bag is read on a thread of its own."""
    if rate_hz is not None and not (math.isfinite(rate_hz) and rate_hz > 0):
        raise Ros2SourceError(f"rate_hz must be a finite number > 0, got {rate_hz!r}")
    running = asyncio.get_running_loop()
    pushed = 0
    with ThreadPoolExecutor(1, thread_name_prefix="landfall-ros2-bag") as pool:  # one reader, one thread
        while not stop.is_set():
            sweeps = read_bag(path, topic, intensity_field=intensity_field, intensity_scale=intensity_scale)
            pacer = _Pacer(rate_hz)
            before = pushed
            try:
                while not stop.is_set():
                    sweep = await running.run_in_executor(pool, next, sweeps, None)
                    if sweep is None:
                        break
                    wait_s = pacer.due(sweep.stamp_s, sweep.recorded_s, time.monotonic()) - time.monotonic()
                    if wait_s > 0:
                        with contextlib.suppress(TimeoutError):
                            await asyncio.wait_for(stop.wait(), wait_s)
                    if stop.is_set():
                        break
                    sink.push(sweep.points)
                    pushed += 1
            finally:
                await running.run_in_executor(pool, sweeps.close)  # closes the bag on the reader's thread
            if pushed == before and not stop.is_set():
                raise Ros2SourceError(f"{path}: {topic or 'its PointCloud2 topic'} holds no cloud to replay")
            if not loop:
                break
    return pushed


# --------------------------------------------------------------------------------------- live topics
def taken_monotonic_s(stamp_s: float, wall_now_s: float, monotonic_now_s: float) -> float | None:
    """When a cloud stamped ``stamp_s`` (seconds on the publisher's clock) was taken on this computer's
    ``time.monotonic()``, given both clocks now; None when the stamp is not on this computer's wall
    clock (more than ``STAMP_TRUSTED_S`` old, or ahead of it: a LiDAR's own clock since power-up)."""
    age = wall_now_s - stamp_s
    if not -STAMP_AHEAD_S <= age <= STAMP_TRUSTED_S:
        return None
    return monotonic_now_s - max(age, 0.0)


class _Dating:
    """Dates live clouds (:func:`taken_monotonic_s`), on arrival when the stamps are not on our clock,
    and says once which it does."""

    def __init__(self) -> None:
        self._said: bool | None = None

    def taken(self, stamp_s: float) -> float:
        now = time.monotonic()
        taken = taken_monotonic_s(stamp_s, time.time(), now)
        trusted = taken is not None
        if self._said is not trusted:
            if trusted:
                log.info("dating LiDAR clouds by their header stamps (on this computer's clock)")
            else:
                log.warning(
                    "the clouds' header stamps are %.3f s from this computer's clock: dating them on arrival "
                    "instead (stamp them from ROS time, or synchronise the LiDAR by PTP)",
                    time.time() - stamp_s,
                )
            self._said = trusted
        return now if taken is None else taken


async def follow_topic(
    sink: SweepSink,
    topic: str,
    stop: asyncio.Event,
    *,
    intensity_field: str | None = "intensity",
    intensity_scale: float = DEFAULT_INTENSITY_SCALE,
    node_name: str = "landfall_lidar_bridge",
) -> None:
    """Pushes every cloud published on ``topic`` into ``sink`` until ``stop`` is set, through rclpy
    (sensor-data QoS: best effort, the newest few). rclpy's executor runs on a thread of its own; each
    cloud is decoded there and pushed on this event loop. A cloud that cannot be decoded is logged and
    skipped (the bridge then refuses frames once its last sweep is too old); a topic silent for
    ``NO_CLOUD_WARN_S`` is logged with what the ROS graph knows of it (:func:`say_when_silent`).

    Raises:
        Ros2SourceError: rclpy's executor stopped by itself.
    """
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import PointCloud2 as RosPointCloud2

    running = asyncio.get_running_loop()
    dating = _Dating()
    heard = bad = 0

    def on_cloud(msg: Any) -> None:  # on rclpy's thread
        nonlocal heard, bad
        heard += 1
        try:
            points = sweep_from_cloud(msg, intensity_field=intensity_field, intensity_scale=intensity_scale)
        except PointCloud2Error as exc:
            if bad % BAD_CLOUD_LOG_EVERY == 0:
                log.warning("%s: a cloud skipped (%d so far): %s", topic, bad + 1, exc)
            bad += 1
            return
        running.call_soon_threadsafe(sink.push, points, dating.taken(header_stamp_s(msg)))

    context = Context()
    _init_rclpy(rclpy, context)
    try:
        node = rclpy.create_node(node_name, context=context)
        executor = SingleThreadedExecutor(context=context)
        try:
            node.create_subscription(RosPointCloud2, topic, on_cloud, qos_profile_sensor_data)
            executor.add_node(node)
            log.info("subscribed to %s (%s) as node %s", topic, POINTCLOUD2, node_name)
            silence = asyncio.create_task(
                say_when_silent(node, topic, lambda: heard, stop), name="ros2-silence"
            )
            try:
                await _spin_until(executor, context, stop)
            finally:
                silence.cancel()
                with contextlib.suppress(asyncio.CancelledError):
                    await silence
        finally:
            executor.shutdown()
            node.destroy_node()
    finally:
        with contextlib.suppress(Exception):  # already shut down (a ROS signal handler got there first)
            rclpy.shutdown(context=context)


async def say_when_silent(
    node: Any, topic: str, heard: Callable[[], int], stop: asyncio.Event, after_s: float = NO_CLOUD_WARN_S
) -> None:
    """Logs a warning, with what the ROS graph knows of ``topic``, when no message has come after
    ``after_s`` (a driver publishing another type, as livox_ros_driver2's ``xfer_format`` 1 does, is
    silent to a PointCloud2 subscriber); nothing when one has, or ``stop`` is set first."""
    try:
        await asyncio.wait_for(stop.wait(), after_s)
        return
    except TimeoutError:
        pass
    if heard():
        return
    types = {str(name): [str(t) for t in kinds] for name, kinds in node.get_topic_names_and_types()}.get(
        topic
    )
    if types is None:
        why = "no node publishes it (ros2 topic list -t shows what is published)"
    elif POINTCLOUD2 not in types:
        why = f"it carries {', '.join(types)}, not {POINTCLOUD2} (livox_ros_driver2: xfer_format 0)"
    else:
        why = "it is a PointCloud2 topic: is its publisher on this ROS_DOMAIN_ID and network?"
    log.warning("no cloud on %s after %g s: %s", topic, after_s, why)


def _init_rclpy(rclpy: Any, context: Any) -> None:
    """rclpy initialised in ``context`` without its own SIGINT handler (the bridge's loop stops on
    SIGINT and SIGTERM); distributions before Humble have no such option and install theirs."""
    try:
        from rclpy.signals import SignalHandlerOptions
    except ImportError:
        rclpy.init(context=context)
        return
    rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)


async def _spin_until(executor: Any, context: Any, stop: asyncio.Event) -> None:
    done = threading.Event()

    def spin() -> None:
        while not done.is_set() and context.ok():
            executor.spin_once(timeout_sec=0.1)

    spinning = asyncio.ensure_future(asyncio.to_thread(spin))
    stopping = asyncio.ensure_future(stop.wait())
    try:
        await asyncio.wait({spinning, stopping}, return_when=asyncio.FIRST_COMPLETED)
    finally:
        done.set()
        stopping.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await stopping
        await asyncio.shield(spinning)  # the thread ends within one spin_once timeout
    if not stop.is_set():
        spinning.result()  # an exception from the executor comes out here
        raise Ros2SourceError("rclpy's executor stopped (the ROS 2 context was shut down)")
