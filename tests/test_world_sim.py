"""simbridge with a world, as real processes: sensor frames over TCP, the rangefinder over a roof,
and touchdowns graded from ground truth in the episode log."""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from landfall_link.sensorstream import SensorClient
from tests.conftest import SimProcess, free_udp_port
from tests.mavclient import MAV_RESULT_ACCEPTED, MavClient

pytestmark = pytest.mark.slow


async def test_sensor_frames_served_from_scenario1(
    start_sim: Callable[..., SimProcess], client_for: Callable[..., MavClient]
) -> None:
    port = free_udp_port()  # a free TCP port is as good as the UDP one here
    sim = start_sim("--scenario", "scenario1", "--sensors", f"127.0.0.1:{port}", "--speed", "1")
    c = client_for(sim.port)
    c.wait_heartbeat(timeout_s=60)
    async with SensorClient("127.0.0.1", port, timeout_s=30.0) as client:
        info = await client.hello()
        assert info.info["scenario"] == "scenario1"
        assert info.version == 1
        frame = await client.frame(want=("image", "depth", "lidar"), image_encoding="png")
    assert frame.image_rgb is not None
    assert frame.image_rgb.shape == (540, 960, 3)
    assert frame.depth_m is not None
    assert frame.lidar_frd is not None
    assert frame.lidar_frd.shape[1] == 4
    assert frame.pos_ned_m[2] == pytest.approx(-110.0, abs=0.5)  # launch 110 m above the origin
    # the origin is on the street: the rangefinder and the centre pixel both see about 110 m
    assert frame.rangefinder_m == pytest.approx(110.0, abs=1.0)
    assert float(np.nanmedian(frame.depth_m[260:280, 470:490])) == pytest.approx(110.0, abs=2.0)
    assert len(np.unique(frame.image_rgb.reshape(-1, 3), axis=0)) > 1000  # a textured city, not a flat fill
    # the episode log keeps the true pose each frame was rendered from, by the autopilot's clock
    (logged,) = [e for e in sim.events("frame") if e["time_boot_ms"] == frame.time_boot_ms]
    assert logged["t_s"] == pytest.approx(frame.t_s, abs=1e-4)
    assert logged["pos_ned_m"] == pytest.approx(list(frame.pos_ned_m), abs=1e-4)
    assert logged["quat_wxyz"] == pytest.approx(list(frame.quat_wxyz), abs=1e-6)
    assert logged["parts"] == ["depth", "image", "lidar"]


def _land_at(c: MavClient, north: float, east: float) -> None:
    assert c.set_mode_ap("GUIDED") == MAV_RESULT_ACCEPTED
    c.send_position(north, east, -40.0)
    c.wait_position(north, east, -40.0, tol_m=0.4, timeout_s=60)
    assert c.set_mode_ap("LAND") == MAV_RESULT_ACCEPTED
    c.wait_disarmed(timeout_s=90)


def test_touchdown_on_the_clear_roof_is_graded_safe(
    start_sim: Callable[..., SimProcess], client_for: Callable[..., MavClient]
) -> None:
    sim = start_sim("--scenario", "scenario1", "--autopilot", "ardupilot", "--speed", "8")
    c = client_for(sim.port)
    c.wait_heartbeat(timeout_s=60)
    _land_at(c, 0.0, -27.0)  # centre of the clear gravel roof, 22 m up
    td = sim.events("touchdown")[0]
    assert td["surface"] == "rooftop_clear"
    assert td["safe"] is True
    assert td["reasons"] == []
    assert float(td["pos_ned_m"][2]) == pytest.approx(-(22.0 + 0.15), abs=0.1)  # type: ignore[index]


def test_touchdown_on_the_street_is_graded_unsafe(
    start_sim: Callable[..., SimProcess], client_for: Callable[..., MavClient]
) -> None:
    sim = start_sim("--scenario", "scenario1", "--autopilot", "ardupilot", "--speed", "8")
    c = client_for(sim.port)
    c.wait_heartbeat(timeout_s=60)
    ds = c.recv("DISTANCE_SENSOR")
    assert ds.current_distance == pytest.approx(11000, abs=60)
    _land_at(c, 40.0, 0.0)  # north along the street between the roofs
    td = sim.events("touchdown")[0]
    assert td["safe"] is False
    assert td["surface"] in ("road", "sidewalk")
    assert any("landed on" in r for r in td["reasons"])  # type: ignore[union-attr]


def test_render_cli_writes_image_depth_and_lidar(tmp_path: Path) -> None:
    out = tmp_path / "f.png"
    cmd = [
        sys.executable, "-m", "simbridge", "render", "--scenario", "scenario2", "--weather", "fog",
        "--pose", "0,0,115,0", "--out", str(out), "--depth-out", str(tmp_path / "d.npy"),
        "--lidar-out", str(tmp_path / "l.npy"),
    ]  # fmt: skip
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    summary = json.loads(res.stdout)
    assert out.exists()
    assert np.load(tmp_path / "d.npy").shape == (540, 960)
    lidar = np.load(tmp_path / "l.npy")
    assert lidar.ndim == 2
    assert lidar.shape[1] == 4
    assert summary["lidar_points"] == lidar.shape[0]
    bad = subprocess.run([*cmd[:5], "--pose", "1,2,3"], capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2
    assert "--pose" in bad.stderr


@pytest.mark.parametrize(("autopilot", "param"), [("ardupilot", "FENCE_RADIUS"), ("px4", "GF_MAX_HOR_DIST")])
def test_fence_map_sets_the_emulated_autopilots_circle_to_the_maps_nearest_edge(
    start_sim: Callable[..., SimProcess], client_for: Callable[..., MavClient], autopilot: str, param: str
) -> None:
    """``--fence map`` at scenario1's origin: the circle reaches the map's nearest edge, the parameter
    a companion reads says so (ArduPilot's enabled), and the episode log records it."""
    from simbridge.scenarios import load_scenario

    world = load_scenario("scenario1", 0).terrain
    n0, n1, e0, e1 = world.grid.extent_m  # type: ignore[attr-defined]
    edge = min(-n0, n1, -e0, e1)  # the launch is at the origin
    sim = start_sim("--scenario", "scenario1", "--autopilot", autopilot, "--fence", "map")
    c = client_for(sim.port)
    c.wait_heartbeat(timeout_s=60)
    assert c.param_read(param).param_value == pytest.approx(edge)
    if autopilot == "ardupilot":
        assert c.param_read("FENCE_ENABLE").param_value == 1
        assert c.param_read("FENCE_TYPE").param_value == 7
    (fence,) = sim.events("fence")
    assert fence["radius_m"] == pytest.approx(edge, abs=0.1)
    assert fence["param"] == param


def test_fence_map_is_for_the_emulation_only() -> None:
    from simbridge.sim import SimConfig

    with pytest.raises(ValueError, match="--fence map sets the emulated autopilot's fence"):
        SimConfig(autopilot="ardupilot-sitl", fence="map")
    with pytest.raises(ValueError, match="--fence must be off or map"):
        SimConfig(fence="on")
