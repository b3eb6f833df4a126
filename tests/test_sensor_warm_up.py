"""simbridge renders at the launch pose before the link opens, also when the vehicle starts on the ground.

The first frames a companion asks for are taken there; the shadows of what a frame sees are computed
tile by tile on first sight, and a first frame 110 m up over scenario1 after a warm-up on the ground
took 213 ms against 57 ms after one at the launch pose (with real firmware, time its lock step spends
paused)."""

from __future__ import annotations

import numpy as np
import pytest

from simbridge.sim import SimBridge, SimConfig
from simbridge.world.live import LiveWorld

pytestmark = pytest.mark.slow


@pytest.mark.parametrize("start", ["ground", "air"])
def test_the_launch_pose_is_rendered_before_the_first_frame_is_asked(start: str) -> None:
    sim = SimBridge(SimConfig(scenario="scenario1", start=start, seed=3))
    world = sim.scenario.terrain
    assert isinstance(world, LiveWorld)
    sim._warm_up_sensors()
    done = int(world.shadow._done.sum())
    launch = sim._launch_pose_ned()
    assert launch[:2] == sim.scenario.launch_ne_m
    world.camera_frame(launch, sim.vehicle.state.quat, 0.0, "clear", np.random.default_rng(0))
    assert int(world.shadow._done.sum()) == done  # no shadow tile left to compute there
    if start == "ground":
        assert sim.vehicle.state.pos_ned_m[2] > launch[2] + 100.0  # still on the ground: nothing flew
