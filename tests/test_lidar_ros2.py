"""ROS 2 LiDAR clouds into the bridge: ``sensor_msgs/msg/PointCloud2`` decoded with numpy
(landfall_link.pointcloud2) in livox_ros_driver2's, ouster-ros's and a bare layout; recorded bags replayed
(rosbags) and a live topic followed (rclpy, here a stand-in: no ROS 2 is installed on the test machine)
into a ``LidarBridge``, read back through the sensor stream as the companion reads it.

The recorded samples are tests/data/ros2-lidar (tests/ros2_samples.py made them from synthetic scenes
whose body-frame points the tests compare with what the bridge serves)."""

from __future__ import annotations

import array
import asyncio
import logging
import math
import sys
import time
import types
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from landfall_link import lidar_bridge, lidar_ros2
from landfall_link.lidar_bridge import LidarBridge, LidarMount
from landfall_link.lidar_ros2 import (
    Ros2SourceError,
    _Pacer,
    bag_topic,
    read_bag,
    replay_bag,
    taken_monotonic_s,
)
from landfall_link.pointcloud2 import PointCloud2, PointCloud2Error, PointField, flu_to_frd, read_points
from landfall_link.sensorstream import SensorClient, SensorFrame, SensorStreamServerError
from tests import ros2_samples as samples
from tests.conftest import free_udp_port
from tests.test_lidar_bridge import FakeAutopilot, running_bridge

ROOT = Path(__file__).resolve().parent.parent
FLOAT32 = 7


def _cloud(points: np.ndarray, fields: tuple[tuple[str, int, int], ...], *, big: bool = False) -> PointCloud2:
    """A plain cloud of a structured array: (N,) is one row, (H, W) organized."""
    height, width = (1, points.size) if points.ndim == 1 else points.shape
    return PointCloud2(
        height=height, width=width, fields=tuple(PointField(n, o, d) for n, o, d in fields),
        point_step=points.dtype.itemsize, row_step=width * points.dtype.itemsize, data=points.tobytes(),
        is_bigendian=big,
    )  # fmt: skip


def _xyz_cloud(xyz: np.ndarray) -> PointCloud2:
    pts = np.zeros(len(xyz), dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4")])
    pts["x"], pts["y"], pts["z"] = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    return _cloud(pts, (("x", 0, FLOAT32), ("y", 4, FLOAT32), ("z", 8, FLOAT32)))


# ------------------------------------------------------------------------------------------- decoding
@pytest.mark.parametrize("point_step", [26, 32])
def test_read_points_livox_layout_packed_or_padded(point_step: int) -> None:
    sweep = samples.livox_sweeps()[0].points
    names = list(sweep.dtype.names or ())
    layout = [sweep.dtype.fields[n] for n in names]  # type: ignore[index]
    dtype = {"names": names, "formats": [f[0] for f in layout], "offsets": [f[1] for f in layout]}
    padded: Any = np.zeros(sweep.size, dtype=np.dtype(dtype | {"itemsize": point_step}))  # type: ignore[call-overload]
    for name in names:
        padded[name] = sweep[name]
    got = read_points(_cloud(padded, samples.LIVOX_FIELDS))
    assert got.dtype == np.float32
    assert got.shape == (samples.LIVOX_POINTS, 4)
    assert np.array_equal(got[:, 0], sweep["x"])
    assert np.array_equal(got[:, 2], sweep["z"])
    assert np.allclose(got[:, 3], sweep["intensity"] / 255.0)
    assert set(np.round(got[:, 3] * 255.0).tolist()) == {40.0, 120.0}


def test_read_points_ouster_layout_leaves_out_the_beams_without_a_return() -> None:
    sweep = samples.ouster_sweeps()[0]
    cloud = _cloud(sweep.points, samples.OUSTER_FIELDS)
    assert (cloud.height, cloud.width, cloud.point_step) == (8, 48, 48)
    hits = np.isfinite(sweep.body_frd).all(axis=1)
    assert 0 < hits.sum() < hits.size  # the scene has beams with no return (x = y = z = 0)
    got = read_points(cloud, intensity_field="reflectivity")
    assert len(got) == hits.sum()
    flat = sweep.points.reshape(-1)[hits]  # row by row, as the cloud is
    assert np.array_equal(got[:, :3], np.column_stack([flat["x"], flat["y"], flat["z"]]))
    assert np.allclose(got[:, 3], flat["reflectivity"] / 255.0)
    photons = read_points(cloud)  # the intensity field: signal photons, far beyond 255 (the mount clips)
    assert photons[:, 3].max() > 1.0
    assert read_points(cloud, intensity_field=None).shape == (hits.sum(), 3)


def test_read_points_xyz_only_from_bytes_an_array_array_a_numpy_array_or_a_list() -> None:
    xyz = np.array([[1.0, 2.0, 3.0], [-4.5, 0.25, 10.0]], dtype=np.float32)
    cloud = _xyz_cloud(xyz)
    for data in (
        cloud.data,
        array.array("B", cloud.data),
        np.frombuffer(cloud.data, np.uint8),
        list(cloud.data),
    ):
        msg = types.SimpleNamespace(height=1, width=2, fields=list(cloud.fields), is_bigendian=False,
                                    point_step=12, row_step=24, data=data, is_dense=True)  # fmt: skip
        got = read_points(msg)
        assert got.shape == (2, 3)
        assert np.array_equal(got, xyz)


def test_read_points_big_endian_reads_the_same_points() -> None:
    sweep = samples.livox_sweeps()[1].points
    big = sweep.astype(sweep.dtype.newbyteorder(">"))
    assert big.tobytes() != sweep.tobytes()
    little = read_points(_cloud(sweep, samples.LIVOX_FIELDS))
    assert np.array_equal(read_points(_cloud(big, samples.LIVOX_FIELDS, big=True)), little)


def test_read_points_drops_nan_and_infinite_points_and_pads_rows() -> None:
    xyz = np.array([[1, 2, 3], [np.nan, 0, 1], [4, np.inf, 1], [0, 0, 0], [7, 8, 9]], dtype=np.float32)
    cloud = _xyz_cloud(xyz)
    assert np.array_equal(read_points(cloud), xyz[[0, 4]])
    # two rows of 5 points, each row padded to 64 bytes (row_step > width * point_step)
    rows = np.zeros((2, 64), dtype=np.uint8)
    rows[0, :60] = np.frombuffer(cloud.data, np.uint8)
    rows[1, :60] = np.frombuffer((xyz + 10).tobytes(), np.uint8)
    padded = PointCloud2(2, 5, cloud.fields, 12, 64, rows.tobytes())
    got = read_points(padded)
    assert len(got) == 2 + 3  # the second row: the nan and inf points stay out; [10, 10, 10] is a return
    assert np.array_equal(got[2], [11, 12, 13])


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"fields": (PointField("x", 0, FLOAT32), PointField("y", 4, FLOAT32))}, r"a cloud without z"),
        ({"fields": (PointField("x", 0, 9), PointField("y", 4, 7), PointField("z", 8, 7))}, r"datatype 9"),
        ({"fields": (PointField("x", 0, 7), PointField("y", 4, 7), PointField("z", 10, 7))}, r"does not fit"),
        ({"fields": (PointField("x", 0, 7, 3), PointField("y", 4, 7), PointField("z", 8, 7))}, r"count 3"),
        ({"data": bytes(20)}, r"data holds 20 bytes; expected height 1 x row_step 24 = 24"),
        ({"row_step": 12}, r"row_step 12 is shorter than width 2 x point_step 12 = 24"),
        ({"point_step": 0, "row_step": 0, "data": b""}, r"point_step is 0"),
        ({"width": -1}, r"width is a non-negative integer"),
    ],
)
def test_read_points_a_malformed_cloud_says_what_is_wrong(change: dict[str, Any], message: str) -> None:
    base = _xyz_cloud(np.ones((2, 3), dtype=np.float32))
    fields = {name: getattr(base, name) for name in PointCloud2.__dataclass_fields__}
    msg = types.SimpleNamespace(**(fields | change))
    with pytest.raises(PointCloud2Error, match=message):
        read_points(msg)


def test_flu_to_frd_a_known_point_lands_where_it_is() -> None:
    # a ROS cloud (x forward, y left, z up): a return 2 m ahead, 1 m to the left and 3 m below the sensor
    frd = flu_to_frd(np.array([[2.0, 1.0, -3.0, 0.5]], dtype=np.float32))
    assert frd.tolist() == [[2.0, -1.0, 3.0, 0.5]]  # FRD: 1 m left is y = -1, 3 m below is z = +3
    assert LidarMount().to_body(frd)[0].tolist() == [2.0, -1.0, 3.0, 0.5]  # ROS frame = the body's FLU
    # hung upside down (roll 180), x still forward: the sensor's z points down and its y (its left) to the
    # body's right, so a return 5 m below and 1 m right of the vehicle is (0, +1, +5) in the ROS cloud
    body = LidarMount(rpy_deg=(180.0, 0.0, 0.0)).to_body(flu_to_frd(np.array([[0.0, 1.0, 5.0]], np.float32)))
    assert np.allclose(body[0, :3], [0.0, 1.0, 5.0], atol=1e-6)


# ------------------------------------------------------------------------------------------------ bags
def test_the_committed_samples_decode_to_their_scenes() -> None:
    """Both storage formats (sqlite3 through the bag's folder, MCAP through its file), both layouts:
    what the bag gives, turned by the mount, is the scene's body-frame points."""
    cases = [
        (samples.LIVOX_BAG, samples.LIVOX_FRAME, samples.livox_sweeps(),
         LidarMount(samples.LIVOX_MOUNT_RPY_DEG, samples.LIVOX_OFFSET_FRD_M)),
        (samples.OUSTER_BAG / "ouster-os1.mcap", samples.OUSTER_FRAME, samples.ouster_sweeps(),
         LidarMount(samples.OUSTER_MOUNT_RPY_DEG, samples.OUSTER_OFFSET_FRD_M)),
    ]  # fmt: skip
    for path, frame, scene, mount in cases:
        got = list(read_bag(path))
        assert len(got) == len(scene)
        for k, (sweep, want) in enumerate(zip(got, scene, strict=True)):
            assert sweep.frame_id == frame
            assert sweep.stamp_s == pytest.approx(samples.STAMP0_S + k * samples.PERIOD_S, abs=1e-6)
            assert sweep.recorded_s - sweep.stamp_s == pytest.approx(0.004, abs=1e-6)
            body = mount.to_body(sweep.points)
            assert np.allclose(body[:, :3], want.body_frd[np.isfinite(want.body_frd).all(axis=1)], atol=1e-4)


def test_bag_topic_finds_the_clouds_and_names_them_when_asked_for_another(tmp_path: Path) -> None:
    assert bag_topic(samples.LIVOX_BAG) == ("/livox/lidar", 5)
    assert bag_topic(samples.OUSTER_BAG, "/ouster/points") == ("/ouster/points", 3)
    with pytest.raises(
        Ros2SourceError, match=r"no topic /points; its sensor_msgs/msg/PointCloud2 topics: /livox/lidar"
    ):
        bag_topic(samples.LIVOX_BAG, "/points")
    # livox_ros_driver2's own message (xfer_format 1) on the usual topic: said so, with the fix
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    custom = tmp_path / "custom"
    with Writer(custom, version=8) as writer:
        conn = writer.add_connection("/livox/lidar", "std_msgs/msg/String", typestore=store)
        writer.write(
            conn, 1, store.serialize_cdr(store.types["std_msgs/msg/String"](data="x"), "std_msgs/msg/String")
        )
    with pytest.raises(
        Ros2SourceError, match=r"no sensor_msgs/msg/PointCloud2 topic \(its topics: /livox/lidar\)"
    ):
        bag_topic(custom)
    with pytest.raises(Ros2SourceError, match=r"/livox/lidar is std_msgs/msg/String, not .*xfer_format 0"):
        bag_topic(custom, "/livox/lidar")
    with pytest.raises(FileNotFoundError):
        bag_topic(tmp_path / "absent")
    empty = tmp_path / "empty"
    with Writer(empty, version=8) as writer:
        writer.add_connection("/points", "sensor_msgs/msg/PointCloud2", typestore=store)
    with pytest.raises(Ros2SourceError, match="/points holds no message"):
        bag_topic(empty)
    with pytest.raises(Ros2SourceError, match="/points holds no cloud to replay"):  # not a busy loop
        asyncio.run(replay_bag(RecordingSink(), empty, "/points", asyncio.Event()))


def test_the_pace_follows_header_stamps_else_record_times_else_the_rate() -> None:
    pacer = _Pacer(None)
    assert pacer.due(100.0, 5.0, now_s=50.0) == 50.0
    assert pacer.due(100.1, 5.3, now_s=50.0) == pytest.approx(50.1)  # header stamps, not the record time
    assert pacer.due(0.0, 5.5, now_s=50.0) == pytest.approx(50.3)  # a stamp gone back: the record time
    assert pacer.due(0.1, 5.6, now_s=99.0) == pytest.approx(50.4)  # late: due at once, the pace kept
    fixed = _Pacer(4.0)
    assert [fixed.due(s, s, now_s=10.0) for s in (0.0, 7.0, 7.1)] == [10.0, 10.25, 10.5]


async def _first_frame(client: SensorClient) -> SensorFrame:
    """The first frame the bridge serves (it refuses until the clock fit has its first stamps)."""
    for _ in range(100):
        try:
            return await client.frame(want=("lidar",))
        except SensorStreamServerError:
            await asyncio.sleep(0.1)
    raise AssertionError("no frame from the bridge in 10 s")


class LoopWatch:
    """Hands sweeps on to the bridge and notes when ``n`` have gone by."""

    def __init__(self, bridge: LidarBridge, n: int) -> None:
        self._bridge, self._n = bridge, n
        self.looped = asyncio.Event()

    def push(self, points: np.ndarray, taken_monotonic_s: float | None = None) -> None:
        self._bridge.push(points, taken_monotonic_s)
        if self._bridge.sweeps_pushed >= self._n:
            self.looped.set()


def test_a_recorded_livox_bag_reaches_the_companion_in_the_body_frame() -> None:
    """The bag source feeding a running bridge, read through the sensor stream: an upside-down Mid-360's
    clouds arrive as the scene's body-frame points, the roof ahead and to the right, the ground 15 m
    below (the sweep's own nadir distance: no DISTANCE_SENSOR here)."""
    port = free_udp_port()
    mount = LidarMount(samples.LIVOX_MOUNT_RPY_DEG, samples.LIVOX_OFFSET_FRD_M)
    scene = [s.body_frd for s in samples.livox_sweeps()]

    async def run() -> int:
        pilot = FakeAutopilot(port)
        stop = asyncio.Event()
        try:
            bridge = LidarBridge(f"udpin:127.0.0.1:{port}", "127.0.0.1:0", mount)
            async with bridge, SensorClient("127.0.0.1", bridge.port, timeout_s=5.0) as client:
                watch = LoopWatch(bridge, samples.LIVOX_SWEEPS + 1)
                source = asyncio.create_task(replay_bag(watch, samples.LIVOX_BAG, "/livox/lidar", stop))
                frame = await _first_frame(client)
                assert frame.pos_ned_m == (1.0, 2.0, -30.0)
                pts = frame.lidar_frd
                assert pts is not None
                assert pts.shape == (samples.LIVOX_POINTS, 4)
                assert sum(np.allclose(pts[:, :3], want, atol=1e-4) for want in scene) == 1
                assert frame.rangefinder_m == pytest.approx(samples.GROUND_Z_M, abs=1e-3)
                roof = np.isclose(pts[:, 2], samples.ROOF_Z_M, atol=1e-3)
                assert roof.sum() > 5
                assert np.isclose(pts[~roof, 2], samples.GROUND_Z_M, atol=1e-3).all()
                ahead, right = pts[roof, 0] >= 3.0 - 1e-4, pts[roof, 1] >= 2.0 - 1e-4
                assert ahead.all()
                assert right.all()
                assert np.allclose(pts[roof, 3], 120.0 / 255.0)
                assert np.allclose(pts[~roof, 3], 40.0 / 255.0)
                await asyncio.wait_for(watch.looped.wait(), 10.0)  # the bag's end, then its first sweep again
                stop.set()
                return await asyncio.wait_for(source, 5.0)
        finally:
            pilot.close()

    assert asyncio.run(run()) >= samples.LIVOX_SWEEPS + 1


def test_the_bridge_command_replays_an_mcap_bag_and_stops_on_sigterm() -> None:
    """``landfall-lidar-bridge --ros2-bag FILE.mcap`` as its own process: an upright Ouster, its cloud in
    os_lidar (x toward the connector, which faces aft: mount yaw 180), reflectivity as intensity; the
    wall is served 30 m ahead, never behind, and the autopilot's rangefinder gives the distance."""
    port = free_udp_port()
    bag = samples.OUSTER_BAG / "ouster-os1.mcap"
    cmd = [sys.executable, "-m", "landfall_link.lidar_bridge", "--mavlink", f"udpin:127.0.0.1:{port}",
           "--sensors", "127.0.0.1:0", "--ros2-bag", str(bag), "--topic", "/ouster/points",
           "--intensity-field", "reflectivity", "--mount-rpy-deg", "0", "0", "180",
           "--offset-frd-m", "0", "0", "-0.1"]  # fmt: skip
    with running_bridge(cmd, FakeAutopilot(port, distance_cm=2000)) as served:

        async def ask() -> SensorFrame:
            async with SensorClient("127.0.0.1", served, timeout_s=5.0) as client:
                return await _first_frame(client)

        frame = asyncio.run(ask())
    assert frame.rangefinder_m == pytest.approx(20.0)  # DISTANCE_SENSOR, downward
    pts = frame.lidar_frd
    assert pts is not None
    wall = np.isclose(pts[:, 0], samples.WALL_X_M, atol=1e-3)
    assert wall.sum() > 10
    assert not np.isclose(pts[:, 0], -samples.WALL_X_M, atol=1e-3).any()
    assert np.allclose(pts[wall, 3], 200.0 / 255.0)
    assert np.isclose(pts[~wall, 2], samples.OUSTER_GROUND_Z_M, atol=1e-3).all()


# ---------------------------------------------------------------------------------- the command line
def test_the_command_says_in_one_line_what_a_source_is_missing(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    base = ["--mavlink", f"udpin:127.0.0.1:{free_udp_port()}", "--sensors", "127.0.0.1:0"]
    assert lidar_bridge.main([*base, "--ros2-bag", str(samples.LIVOX_BAG), "--topic", "/points"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0
    assert "no topic /points; its sensor_msgs/msg/PointCloud2 topics: /livox/lidar" in err
    for name in ("rclpy", "rclpy.context", "sensor_msgs", "sensor_msgs.msg"):
        monkeypatch.setitem(sys.modules, name, None)  # importing it now raises ImportError
    assert lidar_bridge.main([*base, "--ros2-topic", "/livox/lidar"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0
    assert "comes with ROS 2, not PyPI: source your ROS 2 environment" in err
    for name in ("rosbags", "rosbags.rosbag2", "rosbags.serde", "rosbags.typesys"):
        monkeypatch.setitem(sys.modules, name, None)
    assert lidar_bridge.main([*base, "--ros2-bag", str(samples.LIVOX_BAG)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0
    assert err.endswith("pip install 'landfall[lidar]'")
    for wrong in (["--ros2-topic", "/x", "--rate", "5"], ["--replay", "sweeps", "--topic", "/x"], []):
        with pytest.raises(SystemExit) as exited:
            lidar_bridge.main([*base, *wrong])
        assert exited.value.code == 2


# --------------------------------------------------------------------------------------- live topics
def test_taken_monotonic_s_trusts_only_stamps_on_this_computers_clock() -> None:
    assert taken_monotonic_s(999.8, wall_now_s=1000.0, monotonic_now_s=50.0) == pytest.approx(49.8)
    assert taken_monotonic_s(1000.02, wall_now_s=1000.0, monotonic_now_s=50.0) == 50.0  # a hair ahead
    assert taken_monotonic_s(990.0, wall_now_s=1000.0, monotonic_now_s=50.0) is None  # another clock
    assert taken_monotonic_s(1001.0, wall_now_s=1000.0, monotonic_now_s=50.0) is None


class FakeRclpy:
    """Just what follow_topic uses of rclpy and sensor_msgs, recording the calls: ``publish`` hands a
    message to the subscription on the executor's thread, as rclpy's executor would."""

    def __init__(self) -> None:
        import queue

        self.inbox: queue.Queue[Any] = queue.Queue()
        self.calls: list[str] = []
        self.callback: Any = None
        self.graph: list[tuple[str, list[str]]] = []
        fake = self

        class Context:
            def ok(self) -> bool:
                return "shutdown" not in fake.calls

        class Node:
            def create_subscription(self, msg_type: Any, topic: str, callback: Any, qos: Any) -> None:
                fake.calls.append(f"subscribe {topic} {msg_type.__name__} {qos}")
                fake.callback = callback

            def destroy_node(self) -> None:
                fake.calls.append("destroy_node")

            def get_topic_names_and_types(self) -> list[tuple[str, list[str]]]:
                return fake.graph

        class SingleThreadedExecutor:
            def __init__(self, context: Any) -> None:
                assert isinstance(context, Context)

            def add_node(self, node: Any) -> None:
                fake.calls.append("add_node")

            def spin_once(self, timeout_sec: float) -> None:
                try:
                    msg = fake.inbox.get(timeout=timeout_sec)
                except queue.Empty:
                    return
                fake.callback(msg)

            def shutdown(self) -> None:
                fake.calls.append("executor shutdown")

        def init(context: Any, signal_handler_options: Any = None) -> None:
            fake.calls.append(f"init {signal_handler_options}")

        def shutdown(context: Any) -> None:
            fake.calls.append("shutdown")

        self.modules = {
            "rclpy": types.SimpleNamespace(
                init=init, shutdown=shutdown, create_node=lambda name, context: Node()
            ),
            "rclpy.context": types.SimpleNamespace(Context=Context),
            "rclpy.executors": types.SimpleNamespace(SingleThreadedExecutor=SingleThreadedExecutor),
            "rclpy.qos": types.SimpleNamespace(qos_profile_sensor_data="sensor-data-qos"),
            "rclpy.signals": types.SimpleNamespace(
                SignalHandlerOptions=types.SimpleNamespace(NO="no-handlers")
            ),
            "sensor_msgs": types.SimpleNamespace(),
            "sensor_msgs.msg": types.SimpleNamespace(PointCloud2=type("PointCloud2", (), {})),
        }

    def publish(self, xyz: np.ndarray, stamp_s: float) -> None:
        cloud = _xyz_cloud(xyz)
        sec = math.floor(stamp_s)
        stamp = types.SimpleNamespace(sec=sec, nanosec=round((stamp_s - sec) * 1e9))
        self.inbox.put(types.SimpleNamespace(
            header=types.SimpleNamespace(stamp=stamp, frame_id="livox_frame"),
            height=1, width=len(xyz), fields=list(cloud.fields), is_bigendian=False, point_step=12,
            row_step=cloud.row_step, data=array.array("B", cloud.data), is_dense=True,
        ))  # fmt: skip


class RecordingSink:
    def __init__(self) -> None:
        self.pushed: asyncio.Queue[tuple[np.ndarray, float | None]] = asyncio.Queue()

    def push(self, points: np.ndarray, taken_monotonic_s: float | None = None) -> None:
        self.pushed.put_nowait((points, taken_monotonic_s))


def test_follow_topic_dates_clouds_by_stamp_or_arrival_and_skips_bad_ones(
    monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    ros = FakeRclpy()
    for name, module in ros.modules.items():
        monkeypatch.setitem(sys.modules, name, module)
    assert lidar_ros2.rclpy_missing() is None

    async def run() -> None:
        sink, stop = RecordingSink(), asyncio.Event()
        task = asyncio.create_task(lidar_ros2.follow_topic(sink, "/livox/lidar", stop))
        # a cloud stamped 0.1 s ago on this computer's clock: dated by its stamp, in the LiDAR's FRD axes
        taken = time.monotonic() - 0.1
        ros.publish(np.array([[2.0, 1.0, -3.0]], dtype=np.float32), time.time() - 0.1)
        points, at = await asyncio.wait_for(sink.pushed.get(), 5.0)
        assert points.tolist() == [[2.0, -1.0, 3.0]]
        assert at == pytest.approx(taken, abs=0.02)
        # a cloud without z is skipped; one stamped on the LiDAR's own clock is dated on arrival
        bad = _xyz_cloud(np.ones((1, 3), dtype=np.float32))
        ros.inbox.put(types.SimpleNamespace(**{n: getattr(bad, n) for n in ("height", "width", "is_bigendian",
                      "point_step", "row_step", "data")}, fields=list(bad.fields[:2])))  # fmt: skip
        before = time.monotonic()
        ros.publish(np.array([[5.0, 0.0, 0.0]], dtype=np.float32), 12345.0)
        points, at = await asyncio.wait_for(sink.pushed.get(), 5.0)
        assert points.tolist() == [[5.0, 0.0, 0.0]]
        assert at is not None
        assert before <= at <= time.monotonic()
        stop.set()
        await asyncio.wait_for(task, 5.0)

    with caplog.at_level(logging.INFO, logger="landfall_link.lidar_ros2"):
        asyncio.run(run())
    assert ros.calls == ["init no-handlers", "subscribe /livox/lidar PointCloud2 sensor-data-qos", "add_node",
                         "executor shutdown", "destroy_node", "shutdown"]  # fmt: skip
    text = caplog.text
    assert "a cloud skipped (1 so far): a cloud without z" in text
    assert "dating LiDAR clouds by their header stamps" in text
    assert "dating them on arrival" in text


def test_follow_topic_says_when_rclpys_executor_stops_by_itself(monkeypatch: pytest.MonkeyPatch) -> None:
    ros = FakeRclpy()
    for name, module in ros.modules.items():
        monkeypatch.setitem(sys.modules, name, module)
    ros.calls.append("shutdown")  # the context is no longer ok: the spin thread ends at once

    async def run() -> None:
        await lidar_ros2.follow_topic(RecordingSink(), "/points", asyncio.Event())

    with pytest.raises(Ros2SourceError, match="rclpy's executor stopped"):
        asyncio.run(asyncio.wait_for(run(), 5.0))


@pytest.mark.parametrize(
    ("graph", "heard", "says"),
    [
        ([("/livox/lidar", ["livox_ros_driver2/msg/CustomMsg"])], 0,
         "it carries livox_ros_driver2/msg/CustomMsg, not sensor_msgs/msg/PointCloud2 (livox_ros_driver2: "
         "xfer_format 0)"),
        ([("/other", ["sensor_msgs/msg/PointCloud2"])], 0, "no node publishes it"),
        ([("/livox/lidar", ["sensor_msgs/msg/PointCloud2"])], 0, "is its publisher on this ROS_DOMAIN_ID"),
        ([("/livox/lidar", ["livox_ros_driver2/msg/CustomMsg"])], 1, None),
    ],
)  # fmt: skip
def test_a_silent_topic_gets_a_warning_saying_what_the_ros_graph_knows(
    graph: list[tuple[str, list[str]]], heard: int, says: str | None, caplog: pytest.LogCaptureFixture
) -> None:
    ros = FakeRclpy()
    ros.graph = graph
    node = ros.modules["rclpy"].create_node("n", context=None)

    async def run() -> None:
        await lidar_ros2.say_when_silent(node, "/livox/lidar", lambda: heard, asyncio.Event(), after_s=0.01)
        stop = asyncio.Event()
        stop.set()  # stopped before the time: nothing said
        await lidar_ros2.say_when_silent(node, "/livox/lidar", lambda: 0, stop, after_s=0.01)

    with caplog.at_level(logging.WARNING, logger="landfall_link.lidar_ros2"):
        asyncio.run(run())
    warnings = [r.getMessage() for r in caplog.records]
    if says is None:
        assert warnings == []
    else:
        assert len(warnings) == 1
        assert warnings[0].startswith("no cloud on /livox/lidar after 0.01 s: ")
        assert says in warnings[0]
