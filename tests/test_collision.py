"""A flight into a building's wall is a graded collision, not the simulator's end: the ground under the
vehicle rising above it in one step stops JSBSim (whose ground reaction inside a wall blew up and
ended simbridge on a MAVLink pack error), leaves the wreck at the wall's foot, and the episode ends on
the wreck's touchdown, graded unsafe with the surface ``collision``."""

from __future__ import annotations

import itertools
import json
import math
from dataclasses import dataclass
from pathlib import Path

from pymavlink.dialects.v20 import common as mavlink2

from landfall_eval.grading import failure_class, surface_class
from simbridge.control import Setpoint
from simbridge.geo import GeoOrigin, Quat
from simbridge.physics import GEAR_HEIGHT_M
from simbridge.sim import SimBridge, SimConfig
from simbridge.terrain import FlatTerrain, TouchdownGrade
from simbridge.vehicle import Vehicle

WALL_N_M = 20.0  # a building from 20 m north on, 30 m tall


@dataclass(frozen=True)
class Wall:
    """Flat ground with a building north of ``WALL_N_M`` (a test's world)."""

    top_m: float = 30.0

    def height_m(self, north_m: float, east_m: float) -> float:
        return self.top_m if north_m >= WALL_N_M else 0.0

    def grade_touchdown(self, north_m: float, east_m: float, t_s: float) -> TouchdownGrade:
        return TouchdownGrade("ground", True, ())

    def rangefinder_m(self, pos_ned_m: tuple[float, float, float], quat: Quat, max_m: float = 200.0) -> float:
        return FlatTerrain(self.height_m(pos_ned_m[0], pos_ned_m[1])).rangefinder_m(pos_ned_m, quat, max_m)


def test_flying_level_into_a_wall_leaves_a_wreck_at_its_foot_and_the_physics_finite() -> None:
    v = Vehicle(GeoOrigin(), Wall())
    v.reset((0.0, 0.0, -10.0), 0.0)
    for _ in range(round(2.0 / v.DT_S)):  # spun up, holding 10 m over the street
        v.step(Setpoint.hold((0.0, 0.0, -10.0)))
    assert v.physics.collision is None
    states = [v.step(Setpoint.hold((40.0, 0.0, -10.0))) for _ in range(round(15.0 / v.DT_S))]
    c = v.physics.collision
    assert c is not None, "flew through the wall"
    assert c.pos_ned_m[0] >= WALL_N_M > c.pos_ned_m[0] - 0.2  # struck at the wall, not beyond it
    assert c.struck_up_m == 30.0
    assert c.ground_before_m == 0.0
    assert c.speed_m_s > 1.0
    assert "structure 30 m tall" in c.said()
    assert "10.0 m above the ground" in c.said()
    s = states[-1]
    assert s.on_ground
    assert s.thrust_n == 0.0
    assert s.vel_ned_m_s == (0.0, 0.0, 0.0)
    assert s.pos_ned_m[0] < WALL_N_M  # outside the building, at its foot
    assert s.pos_ned_m[2] == -GEAR_HEIGHT_M
    assert s.height_agl_m == GEAR_HEIGHT_M
    assert all(math.isfinite(x) for st in states for x in (*st.pos_ned_m, *st.vel_ned_m_s))
    ts = [st.t_s for st in states]
    assert all(b > a for a, b in itertools.pairwise(ts))  # the wreck's clock runs on
    v.reset((0.0, 0.0, -10.0), 0.0)  # a new episode flies again
    assert v.physics.collision is None
    assert not v.state.on_ground


def test_a_climb_over_the_roof_edge_is_no_collision() -> None:
    """Above the roof when it comes under the vehicle (the transit climb's case): no collision."""
    v = Vehicle(GeoOrigin(), Wall())
    v.reset((0.0, 0.0, -40.0), 0.0)
    for _ in range(round(20.0 / v.DT_S)):
        v.step(Setpoint.hold((35.0, 0.0, -40.0)))
    assert v.physics.collision is None
    assert v.state.pos_ned_m[0] > WALL_N_M
    assert v.state.height_agl_m > 5.0


def _received(msg: object) -> object:
    sender = mavlink2.MAVLink(None, srcSystem=255, srcComponent=190)
    return mavlink2.MAVLink(None).parse_buffer(msg.pack(sender))[0]  # type: ignore[attr-defined]


def test_the_emulated_autopilot_flown_into_a_wall_ends_the_episode_on_a_collision(tmp_path: Path) -> None:
    """ArduCopter's emulation in GUIDED, flown level into the wall by MAVLink: a ``collision`` event,
    the motors stopped ("Crash: Disarming"), one touchdown graded unsafe (``collision``, with what was
    struck in its reasons), which the harness's grading counts as ``unsafe: collision``; the
    telemetry still packs."""
    log = tmp_path / "episode.jsonl"
    config = SimConfig(
        autopilot="ardupilot", start="air", scenario="flat", launch=(0.0, 0.0, 8.0), episode_log=log
    )
    sim = SimBridge(config)
    sim.vehicle.physics.terrain = Wall()
    texts: list[str] = []
    sim.link.send_statustext = lambda severity, text: texts.append(text)  # type: ignore[method-assign]
    enc = mavlink2.MAVLink(None)
    here = sim.vehicle.state.pos_ned_m
    sim.server.handle(_received(enc.command_long_encode(1, 1, 176, 0, 1, 4, 0, 0, 0, 0, 0)), ("127.0.0.1", 1))
    north = (0, 1, 1, 1, 3576, 40.0, 0.0, -8.0, 0, 0, 0, 0, 0, 0, 0, 0)  # position only, 8 m up
    target = enc.set_position_target_local_ned_encode(*north)
    for step in range(round(60.0 / sim.vehicle.DT_S)):
        if step % 12 == 0:  # a companion's setpoint stream
            sim.server.handle(_received(target), ("127.0.0.1", 1))
        sim.step()
        msg = sim.telemetry.build(mavlink2.MAVLINK_MSG_ID_GLOBAL_POSITION_INT)
        if msg is not None:
            msg.pack(enc)  # in range, whatever the airframe did
    sim.episode.close()
    events = [json.loads(line) for line in log.read_text().splitlines()]
    kinds = [e.get("event") for e in events]
    assert round(here[2], 3) == -8.0
    assert kinds.count("collision") == 1, kinds
    touchdowns = [e for e in events if e.get("event") == "touchdown"]
    assert len(touchdowns) == 1, touchdowns
    td = touchdowns[0]
    assert td["surface"] == "collision"
    assert td["safe"] is False
    assert "flew into a structure 30 m tall" in td["reasons"][0]
    assert not sim.autopilot.armed
    assert "Crash: Disarming" in texts
    assert surface_class(td) == "collision"
    assert failure_class({"safe": False, "outcome": "landed", "surface": "collision"}) == "unsafe: collision"
