"""The JSBSim F450 under our controller: hold accuracy, limits, wind, ground contact."""

from __future__ import annotations

import math

import numpy as np
import pytest

from simbridge.control import ControlLimits, Setpoint
from simbridge.geo import GeoOrigin
from simbridge.physics import GEAR_HEIGHT_M
from simbridge.terrain import FlatTerrain
from simbridge.vehicle import Vehicle
from simbridge.wind import WindConfig, WindModel


def _vehicle(wind: WindConfig | None = None, ground_m: float = 0.0) -> Vehicle:
    model = WindModel(wind, np.random.default_rng(0)) if wind else None
    return Vehicle(GeoOrigin(), FlatTerrain(ground_m), wind=model)


def _run(v: Vehicle, sp: Setpoint, seconds: float) -> list[tuple[float, float, float]]:
    return [v.step(sp).pos_ned_m for _ in range(round(seconds / v.DT_S))]


def test_hold_stays_within_30cm_in_still_air() -> None:
    v = _vehicle()
    v.reset((0.0, 0.0, -100.0), 0.3)
    sp = Setpoint.hold((0.0, 0.0, -100.0), 0.3)
    _run(v, sp, 3.0)  # motors spin up from rest
    worst = max(math.dist(p, (0.0, 0.0, -100.0)) for p in _run(v, sp, 30.0))
    assert worst < 0.3
    assert v.state.euler_rad[2] == pytest.approx(0.3, abs=0.01)


def test_position_step_respects_speed_and_tilt_limits() -> None:
    v = _vehicle()
    v.reset((0.0, 0.0, -50.0), 0.0)
    limits = v.controller.limits
    sp = Setpoint.hold((60.0, 30.0, -50.0))
    max_speed, max_tilt = 0.0, 0.0
    for _ in range(round(30 / v.DT_S)):
        s = v.step(sp)
        max_speed = max(max_speed, math.hypot(*s.vel_ned_m_s[:2]))
        roll, pitch, _ = s.euler_rad
        max_tilt = max(max_tilt, math.acos(math.cos(roll) * math.cos(pitch)))
    assert math.dist(v.state.pos_ned_m, (60.0, 30.0, -50.0)) < 0.3
    assert max_speed < limits.max_speed_xy_m_s * 1.1
    assert max_tilt < limits.max_tilt_rad


def test_climb_and_descent_rates_are_limited() -> None:
    v = _vehicle()
    v.reset((0.0, 0.0, -20.0), 0.0)
    ups = [v.step(Setpoint.hold((0.0, 0.0, -60.0))).vel_ned_m_s[2] for _ in range(round(20 / v.DT_S))]
    downs = [v.step(Setpoint.hold((0.0, 0.0, -20.0))).vel_ned_m_s[2] for _ in range(round(40 / v.DT_S))]
    assert -min(ups) == pytest.approx(3.0, abs=0.25)
    assert max(downs) == pytest.approx(1.5, abs=0.15)


def test_steady_wind_is_rejected_by_the_integrators() -> None:
    v = _vehicle(WindConfig(steady_ned_m_s=(4.0, 3.0, 0.0)))
    v.reset((0.0, 0.0, -80.0), 0.0)
    sp = Setpoint.hold((0.0, 0.0, -80.0))
    _run(v, sp, 20.0)
    worst = max(math.dist(p, (0.0, 0.0, -80.0)) for p in _run(v, sp, 10.0))
    assert worst < 0.3
    roll, pitch, _ = v.state.euler_rad
    assert abs(roll) + abs(pitch) > math.radians(1)  # it is leaning into the wind


def test_gusts_push_but_hold_recovers() -> None:
    v = _vehicle(WindConfig(gust_sigma_m_s=2.0))
    v.reset((0.0, 0.0, -80.0), 0.0)
    track = _run(v, Setpoint.hold((0.0, 0.0, -80.0)), 40.0)
    errors = [math.dist(p, (0.0, 0.0, -80.0)) for p in track[round(5 / v.DT_S) :]]
    assert max(errors) < 2.0
    assert max(errors) > 0.05  # the gusts are real


def test_rests_on_raised_ground() -> None:
    v = _vehicle(ground_m=12.0)
    v.reset((0.0, 0.0, 0.0), 0.0)  # placed below the ground: lifted onto its gear
    for _ in range(240):
        s = v.step(None, armed=False)
    assert s.on_ground
    assert s.height_agl_m == pytest.approx(GEAR_HEIGHT_M, abs=0.02)
    assert -s.pos_ned_m[2] == pytest.approx(12.0 + GEAR_HEIGHT_M, abs=0.02)


def test_limits_are_validated() -> None:
    with pytest.raises(ValueError, match="max_speed_xy_m_s"):
        ControlLimits(max_speed_xy_m_s=-1.0)
    with pytest.raises(ValueError, match="max_tilt_rad"):
        ControlLimits(max_tilt_rad=math.radians(95))
