"""The emulated ArduCopter's precision landing on a companion's LANDING_TARGET (issue 35), stepped
without processes; and the message as the emulation's MAVLink server reads it. The companion's side,
flown end to end: tests/test_precision_landing.py."""

from __future__ import annotations

import math
from typing import Any

import pytest
from pymavlink.dialects.v20 import common as mavlink2

from simbridge.autopilot.core import Autopilot
from simbridge.autopilot.flavours import flavour_named
from simbridge.autopilot.server import AutopilotServer
from simbridge.geo import GeoOrigin, rotate_body_to_ned
from simbridge.telemetry import Telemetry
from simbridge.terrain import FlatTerrain
from simbridge.vehicle import Vehicle

STEPS_S = round(1 / Vehicle.DT_S)


def _rig(flavour: str = "ardupilot") -> tuple[Autopilot, Vehicle, list[str]]:
    texts: list[str] = []
    v = Vehicle(GeoOrigin(), FlatTerrain())
    ap = Autopilot(
        flavour_named(flavour), v, (0.0, 0.0, 0.0), lambda _e, _f: None, lambda _s, t: texts.append(t)
    )
    v.reset((0.0, 0.0, -6.0), 0.0)
    ap.spawn_in_air(v.state)
    return ap, v, texts


def _land_with_target(ap: Autopilot, v: Vehicle, target_ne: tuple[float, float], seconds: float) -> None:
    """LAND, with a line of sight to ``target_ne`` (on the ground) five times a second."""
    assert ap.set_mode(ap.flavour.mode("LAND" if ap.flavour.name == "ardupilot" else "AUTO.LAND")).result == 0
    for step in range(round(seconds * STEPS_S)):
        if step % (STEPS_S // 5) == 0 and not v.state.on_ground:
            s = v.state
            rel = (target_ne[0] - s.pos_ned_m[0], target_ne[1] - s.pos_ned_m[1], -s.pos_ned_m[2])
            # NED -> body FRD: the inverse (conjugate) rotation of the attitude
            w, x, y, z = s.quat
            frd = rotate_body_to_ned((w, -x, -y, -z), rel)
            ap.landing_target(frd, math.dist((0, 0, 0), rel))
        v.step(ap.tick(v.state), ap.armed)


def test_ardupilot_land_follows_the_landing_target() -> None:
    ap, v, _ = _rig()
    _land_with_target(ap, v, (1.5, -1.0), 30.0)
    assert v.state.on_ground
    assert math.dist(v.state.pos_ned_m[:2], (1.5, -1.0)) < 0.2


def test_ardupilot_land_waits_over_a_target_farther_than_plnd_xy_dist_max() -> None:
    """4 m across (PLND_XY_DIST_MAX 2.5): the descent waits until the vehicle is near it."""
    ap, v, _ = _rig()
    _land_with_target(ap, v, (4.0, 0.0), 1.0)
    assert v.state.pos_ned_m[2] == pytest.approx(-6.0, abs=0.3)  # not come down yet
    _land_with_target(ap, v, (4.0, 0.0), 30.0)
    assert v.state.on_ground
    assert math.dist(v.state.pos_ned_m[:2], (4.0, 0.0)) < 0.2


def test_ardupilot_land_ignores_the_target_with_precision_landing_off() -> None:
    ap, v, _ = _rig()
    ap.set_param("PLND_ENABLED", 0)
    _land_with_target(ap, v, (1.5, -1.0), 30.0)
    assert v.state.on_ground
    assert math.dist(v.state.pos_ned_m[:2], (0.0, 0.0)) < 0.2


def test_px4_auto_land_ignores_the_target() -> None:
    """PX4's precision landing (AUTO.PRECLAND) is not emulated: AUTO.LAND lands where it is."""
    ap, v, _ = _rig("px4")
    _land_with_target(ap, v, (1.5, -1.0), 30.0)
    assert v.state.on_ground
    assert math.dist(v.state.pos_ned_m[:2], (0.0, 0.0)) < 0.2


class _Sent:
    def __init__(self) -> None:
        self.msgs: list[Any] = []

    def __call__(self, msg: Any) -> None:
        self.msgs.append(msg)


def _server(ap: Autopilot) -> AutopilotServer:
    return AutopilotServer(ap, Telemetry(ap, GeoOrigin()), _Sent())


def _landing_target(frame: int, position_valid: int, xyz: tuple[float, float, float]) -> Any:
    mav = mavlink2.MAVLink(None)
    msg = mav.landing_target_encode(
        0, 0, frame, 0.1, -0.2, 5.0, 0.0, 0.0, *xyz, [1.0, 0.0, 0.0, 0.0], 0, position_valid
    )
    return mavlink2.MAVLink(None).decode(bytearray(msg.pack(mav)))


def test_server_reads_body_frd_positions_and_refuses_other_frames() -> None:
    ap, _v, texts = _rig()
    server = _server(ap)
    server.handle(_landing_target(mavlink2.MAV_FRAME_LOCAL_NED, 1, (1.0, 0.0, 5.0)), None)
    assert "Plnd: Frame not supported" in texts
    assert ap._plnd_seen is None
    server.handle(_landing_target(mavlink2.MAV_FRAME_BODY_FRD, 1, (3.0, 4.0, 12.0)), None)
    assert ap._plnd_seen is not None
    _t, unit, distance = ap._plnd_seen
    assert unit == pytest.approx((3 / 13, 4 / 13, 12 / 13))
    assert distance == 5.0  # the message's own distance field


def test_server_reads_angles_as_arducopter_does() -> None:
    """position_valid 0: angle_x to the right, angle_y aft (ArduCopter's AC_PrecLand reading)."""
    ap, _v, _ = _rig()
    _server(ap).handle(_landing_target(mavlink2.MAV_FRAME_BODY_FRD, 0, (0.0, 0.0, 0.0)), None)
    assert ap._plnd_seen is not None
    _t, unit, _d = ap._plnd_seen
    los = (-math.tan(-0.2), math.tan(0.1), 1.0)
    norm = math.sqrt(sum(c * c for c in los))
    assert unit == pytest.approx(tuple(c / norm for c in los))
