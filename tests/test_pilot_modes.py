"""The emulated ArduPilot flavour's pilot modes with no transmitter: the sticks rest
centred and the throttle at its minimum, as in real ArduCopter SITL (RC3 = 1000). The same checks
against the firmware: tests/test_firmware_parity.py."""

from __future__ import annotations

import math

import pytest

from simbridge.autopilot.core import LANDED_ON_GROUND, Autopilot
from simbridge.autopilot.flavours import (
    MAV_RESULT_ACCEPTED,
    MAV_RESULT_DENIED,
    MAV_RESULT_FAILED,
    ModeSpec,
    flavour_named,
)
from simbridge.geo import GeoOrigin
from simbridge.terrain import FlatTerrain
from simbridge.vehicle import Vehicle

STEPS_S = round(1 / Vehicle.DT_S)


def _rig(start_d_m: float | None) -> tuple[Autopilot, Vehicle]:
    v = Vehicle(GeoOrigin(), FlatTerrain())
    ap = Autopilot(flavour_named("ardupilot"), v, (0.0, 0.0, 0.0), lambda *_: None, lambda *_: None)
    if start_d_m is not None:
        v.reset((0.0, 0.0, start_d_m), 0.0)
        ap.spawn_in_air(v.state)
    return ap, v


def _fly(ap: Autopilot, v: Vehicle, seconds: float) -> None:
    for _ in range(round(seconds * STEPS_S)):
        v.step(ap.tick(v.state), ap.armed)


def _mode(ap: Autopilot, number: int) -> int:
    spec = ap.flavour.decode_set_mode(1, number, 0)
    return ap.set_mode(spec).result if isinstance(spec, ModeSpec) else spec


def test_the_pilot_modes_are_accepted_and_armable_on_the_ground_and_never_auto_disarm() -> None:
    ap, v = _rig(None)
    _fly(ap, v, 1.0)
    assert _mode(ap, 13) == MAV_RESULT_FAILED  # SPORT: not built into ArduCopter 4.7
    assert _mode(ap, 3) == MAV_RESULT_DENIED  # AUTO: no mission
    for number, name in ((0, "STABILIZE"), (1, "ACRO"), (2, "ALT_HOLD"), (16, "POSHOLD")):
        assert _mode(ap, number) == MAV_RESULT_ACCEPTED
        assert ap.mode.name == name
        assert ap.arm(True).result == MAV_RESULT_ACCEPTED
        _fly(ap, v, 15.0)  # past DISARM_DELAY (10 s): the firmware stayed armed, on the ground
        assert ap.armed, name
        assert v.state.height_agl_m < 0.5
        assert ap.arm(False).result == MAV_RESULT_ACCEPTED


@pytest.mark.parametrize("name", ["ALT_HOLD", "POSHOLD"])
def test_alt_hold_and_poshold_descend_at_the_pilot_speed_and_land_armed(name: str) -> None:
    ap, v = _rig(-40.0)
    _fly(ap, v, 2.0)
    assert ap.set_mode(ap.flavour.mode(name)).result == MAV_RESULT_ACCEPTED
    _fly(ap, v, 1.5)
    d0, t0 = v.state.pos_ned_m[2], v.state.t_s
    _fly(ap, v, 3.0)
    sink = (v.state.pos_ned_m[2] - d0) / (v.state.t_s - t0)
    assert sink == pytest.approx(2.5, abs=0.1)  # PILOT_SPEED_UP 250, PILOT_SPEED_DN 0
    assert math.hypot(*v.state.pos_ned_m[:2]) < 0.5
    assert abs(v.state.euler_rad[0]) < 0.05
    assert abs(v.state.euler_rad[1]) < 0.05
    assert ap.set_param("PILOT_SPEED_DN", 100.0)
    _fly(ap, v, 2.0)
    d0, t0 = v.state.pos_ned_m[2], v.state.t_s
    _fly(ap, v, 2.0)
    assert (v.state.pos_ned_m[2] - d0) / (v.state.t_s - t0) == pytest.approx(1.0, abs=0.1)
    _fly(ap, v, 40.0)  # down, and 10 s and more on the ground: landed, still armed
    assert v.state.height_agl_m < 0.5
    assert ap.armed
    assert ap.landed
    assert ap.landed_state == LANDED_ON_GROUND


def test_stabilize_runs_the_motors_at_their_minimum_and_falls() -> None:
    ap, v = _rig(-40.0)
    _fly(ap, v, 2.0)
    assert ap.set_mode(ap.flavour.mode("STABILIZE")).result == MAV_RESULT_ACCEPTED
    d0 = v.state.pos_ned_m[2]
    _fly(ap, v, 1.0)
    assert v.state.pos_ned_m[2] - d0 == pytest.approx(4.4, abs=0.6)  # the firmware: 4.42 m
    assert v.state.vel_ned_m_s[2] > 7.0  # the firmware: 8.5 m/s down after 1 s
