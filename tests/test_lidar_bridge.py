"""The reference LiDAR producer (landfall_link.lidar_bridge): a driver's sweeps served on the
sensor stream, turned into the body frame by the mounting and dated on the autopilot's boot clock, which
the bridge fits from the autopilot's own MAVLink. The autopilot here is the test, at the UDP boundary: it
stamps LOCAL_POSITION_NED on a boot clock that runs twice as fast as this computer's (a sped-up
simulator), so a dating that forgot the rate or the offset is off by seconds."""

from __future__ import annotations

import asyncio
import contextlib
import math
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink2

from landfall_link.lidar_bridge import LidarBridge, LidarMount, body_rotation, nadir_distance
from landfall_link.sensorstream import SensorClient, SensorStreamServerError
from tests.conftest import free_udp_port

ROOT = Path(__file__).resolve().parent.parent
RATE, OFFSET_S = 2.0, 100.0  # the autopilot's boot clock: 2 x monotonic + 100 s, from the test's start


class FakeAutopilot:
    """Sends LOCAL_POSITION_NED (and, when asked, a downward DISTANCE_SENSOR) at 20 Hz to ``port``, each
    stamped on the boot clock ``RATE * (t - t0) + OFFSET_S`` and sent after a random 0-20 ms delay."""

    def __init__(self, port: int, distance_cm: int | None = None) -> None:
        self.t0 = time.monotonic()
        self._port, self._distance = port, distance_cm
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def boot_s(self, monotonic_s: float) -> float:
        return RATE * (monotonic_s - self.t0) + OFFSET_S

    def _run(self) -> None:
        mav = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
        rng = np.random.default_rng(0)
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
            while not self._stop.is_set():
                stamp = round(1000 * self.boot_s(time.monotonic()))
                time.sleep(float(rng.uniform(0.0, 0.02)))  # the link's delay, after the stamp
                msgs = [mav.local_position_ned_encode(stamp, 1.0, 2.0, -30.0, 0, 0, 0)]
                if self._distance is not None:
                    msgs.append(mav.distance_sensor_encode(stamp, 20, 4000, self._distance, 0, 0, 25, 0))
                for m in msgs:
                    sock.sendto(m.pack(mav), ("127.0.0.1", self._port))
                time.sleep(0.05)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2)


@pytest.fixture
def autopilot_port() -> int:
    return free_udp_port()


@contextlib.contextmanager
def running_bridge(cmd: list[str], pilot: FakeAutopilot) -> Iterator[int]:
    """``landfall-lidar-bridge``'s command running against ``pilot``: the port it serves on (its first
    line says it); on leaving, it must stop on SIGTERM with status 0. ``pilot`` is closed either way."""
    with subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT) as proc:
        try:
            assert proc.stdout is not None
            line = proc.stdout.readline()
            assert line.startswith("lidar bridge: sensor stream on port "), line
            yield int(line.rsplit(" ", 1)[1])
            os.kill(proc.pid, signal.SIGTERM)
            assert proc.wait(timeout=10) == 0
        finally:
            pilot.close()
            if proc.poll() is None:
                proc.kill()


def _ground_sweep(depth_m: float, n: int = 400) -> np.ndarray:
    """A flat ground ``depth_m`` below a LiDAR looking straight down its +z axis, (N, 4) with intensity."""
    g = np.linspace(-10.0, 10.0, int(math.sqrt(n)))
    x, y = np.meshgrid(g, g)
    return np.column_stack([x.ravel(), y.ravel(), np.full(x.size, depth_m), np.full(x.size, 0.5)]).astype(
        np.float32
    )


def test_a_sweep_is_served_in_the_body_frame_and_dated_on_the_autopilots_clock(autopilot_port: int) -> None:
    mount = LidarMount(rpy_deg=(0.0, 0.0, 90.0), offset_frd_m=(0.2, 0.0, 0.1))

    async def run() -> None:
        pilot = FakeAutopilot(autopilot_port)
        try:
            bridge = LidarBridge(f"udpin:127.0.0.1:{autopilot_port}", "127.0.0.1:0", mount)
            async with bridge, SensorClient("127.0.0.1", bridge.port, timeout_s=5.0) as client:
                with pytest.raises(SensorStreamServerError, match="no LiDAR sweep yet"):
                    await client.frame(want=("lidar",))
                await asyncio.sleep(1.0)  # 20 stamps: the clock fit
                sweep = _ground_sweep(30.0)
                sweep[3] = np.nan  # a driver's miss
                taken = time.monotonic() - 0.1
                bridge.push(sweep, taken)
                frame = await client.frame(want=("lidar",))
                assert frame.image_rgb is None
                # dated on the autopilot's clock within the link's delay (0-20 ms, twice that on this clock; a
                # loaded test machine adds its own): a forgotten rate or offset is off by seconds
                assert frame.time_boot_ms / 1000.0 == pytest.approx(pilot.boot_s(taken), abs=0.2)
                assert frame.pos_ned_m == (1.0, 2.0, -30.0)
                pts = frame.lidar_frd
                assert pts is not None
                assert len(pts) == len(sweep) - 1
                want = np.delete(sweep, 3, axis=0)[:, :3] @ body_rotation(0, 0, 90).T + (0.2, 0.0, 0.1)
                assert np.allclose(pts[:, :3], want, atol=1e-4)
                assert np.allclose(pts[:, 3], 0.5)
                # yawed 90 degrees right: the LiDAR's +x (forward on the sensor) is the body's +y (right)
                assert np.allclose(body_rotation(0, 0, 90) @ (1, 0, 0), (0, 1, 0))
                assert frame.rangefinder_m == pytest.approx(
                    30.1, abs=1e-3
                )  # the sweep's own, no DISTANCE_SENSOR
        finally:
            pilot.close()

    asyncio.run(run())


def test_the_autopilots_rangefinder_wins_and_a_stale_sweep_is_refused(autopilot_port: int) -> None:
    async def run() -> None:
        pilot = FakeAutopilot(autopilot_port, distance_cm=2750)
        try:
            bridge = LidarBridge(f"udpin:127.0.0.1:{autopilot_port}", "127.0.0.1:0", max_sweep_age_s=0.5)
            async with bridge, SensorClient("127.0.0.1", bridge.port, timeout_s=5.0) as client:
                await asyncio.sleep(1.0)
                bridge.push(_ground_sweep(30.0)[:, :3])  # no intensity column: 1 for every point
                frame = await client.frame(want=("lidar",))
                assert frame.rangefinder_m == pytest.approx(27.5)  # DISTANCE_SENSOR, downward
                assert frame.lidar_frd is not None
                assert np.allclose(frame.lidar_frd[:, 3], 1.0)
                await asyncio.sleep(0.7)
                with pytest.raises(SensorStreamServerError, match=r"LiDAR sweep is 0\.[0-9] s old"):
                    await client.frame(want=("lidar",))
                with pytest.raises(ValueError, match=r"\(N, 3\) or \(N, 4\) float array"):
                    bridge.push(np.zeros((10, 2), dtype=np.float32))
        finally:
            pilot.close()

    asyncio.run(run())


def test_without_the_autopilot_no_frame_is_dated() -> None:
    async def run() -> None:
        bridge = LidarBridge(f"udpin:127.0.0.1:{free_udp_port()}", "127.0.0.1:0")
        async with bridge, SensorClient("127.0.0.1", bridge.port, timeout_s=5.0) as client:
            bridge.push(_ground_sweep(30.0))
            with pytest.raises(SensorStreamServerError, match="autopilot's clock is not known yet"):
                await client.frame(want=("lidar",))

    asyncio.run(run())
    assert nadir_distance(_ground_sweep(12.0)) == pytest.approx(12.0)
    assert nadir_distance(np.array([[5.0, 0.0, -1.0, 1.0]], dtype=np.float32)) is None  # nothing below


def test_the_replay_command_serves_recorded_sweeps_and_stops_on_sigterm(
    tmp_path: Path, autopilot_port: int
) -> None:
    for k in range(3):
        np.save(tmp_path / f"sweep{k:03d}.npy", _ground_sweep(20.0 + k))
    link = f"udpin:127.0.0.1:{autopilot_port}"
    cmd = [sys.executable, "-m", "landfall_link.lidar_bridge", "--mavlink", link, "--sensors", "127.0.0.1:0",
           "--replay", str(tmp_path), "--rate", "20"]  # fmt: skip
    with running_bridge(cmd, FakeAutopilot(autopilot_port)) as port:

        async def ask() -> float:
            async with SensorClient("127.0.0.1", port, timeout_s=5.0) as client:
                for _ in range(50):
                    try:
                        frame = await client.frame(want=("lidar",))
                    except SensorStreamServerError:
                        await asyncio.sleep(0.1)  # the clock fit needs its first stamps
                        continue
                    assert frame.lidar_frd is not None
                    return frame.rangefinder_m
            raise AssertionError("no frame from the replaying bridge")

        distance = asyncio.run(ask())
        assert min(abs(distance - d) for d in (20.0, 21.0, 22.0)) < 1e-3, distance
    bad = subprocess.run([*cmd[:-4], "--replay", str(tmp_path / "absent")], capture_output=True, text=True,
                         cwd=ROOT, timeout=60)  # fmt: skip
    assert bad.returncode == 2
    assert "no .npy sweeps to replay" in bad.stderr
