"""The emulated autopilots' precision landing on a companion's LANDING_TARGET, stepped
without processes: ArduCopter's in LAND, PX4's AUTO.PRECLAND (simbridge.autopilot.precland, its phases
one by one); and the message as the emulation's MAVLink server reads it for each. The companion's side,
flown end to end: tests/test_precision_landing.py."""

from __future__ import annotations

import math
from typing import Any

import pytest
from pymavlink.dialects.v20 import common as mavlink2

from simbridge.autopilot.core import Autopilot
from simbridge.autopilot.flavours import flavour_named
from simbridge.autopilot.precland import HORIZONTAL_SETTLE_S, PrecLand, PrecLandTune
from simbridge.autopilot.server import AutopilotServer
from simbridge.geo import GeoOrigin, rotate_body_to_ned
from simbridge.telemetry import Telemetry
from simbridge.terrain import FlatTerrain
from simbridge.vehicle import Vehicle

STEPS_S = round(1 / Vehicle.DT_S)


def _rig(
    flavour: str = "ardupilot", home: tuple[float, float, float] = (0.0, 0.0, 0.0)
) -> tuple[Autopilot, Vehicle, list[str]]:
    """An autopilot flying 6 m over ``home`` (the world's NED; its local frame's origin is there)."""
    texts: list[str] = []
    v = Vehicle(GeoOrigin(), FlatTerrain())
    ap = Autopilot(flavour_named(flavour), v, home, lambda _e, _f: None, lambda _s, t: texts.append(t))
    v.reset((home[0], home[1], -6.0), 0.0)
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


def test_ardupilot_places_a_late_line_of_sight_with_the_pose_at_its_stamp() -> None:
    """A line of sight drawn from the pose at one moment and heard 0.3 s later, while the vehicle
    flies toward a target 3 m off: placed with the pose at its stamp it lands on the target; placed with
    the pose when heard, it would be off by the way flown since (as ArduCopter's would with a
    ``PLND_LAG`` short of the link's latency)."""
    target = (3.0, 1.0)
    ap, v, _ = _rig()
    _land_with_target(ap, v, target, 1.5)  # flying across toward it, tilted
    s = v.state
    stamp = s.t_s
    est = ap.estimated_state
    rel = (target[0] - est.pos_ned_m[0], target[1] - est.pos_ned_m[1], -est.pos_ned_m[2])
    w, x, y, z = est.quat
    frd = rotate_body_to_ned((w, -x, -y, -z), rel)
    for _ in range(round(0.3 * STEPS_S)):
        v.step(ap.tick(v.state), ap.armed)
    moved = math.dist(v.state.pos_ned_m[:2], s.pos_ned_m[:2])
    assert moved > 0.15  # it flew on: a target placed from the pose now would be that far off
    ap.landing_target(frd, math.dist((0, 0, 0), rel), stamp)
    placed = ap._precision_target(v.state)
    assert placed is not None
    assert math.dist(placed, target) < 0.03
    ap.landing_target(frd, math.dist((0, 0, 0), rel))  # unstamped: the pose now
    unstamped = ap._precision_target(v.state)
    assert unstamped is not None
    assert math.dist(unstamped, target) > 0.1
    ap.landing_target(frd, math.dist((0, 0, 0), rel), stamp - 5.0)  # older than the history: now
    assert ap._precision_target(v.state) == pytest.approx(unstamped)


def test_ardupilot_land_ignores_the_target_with_precision_landing_off() -> None:
    ap, v, _ = _rig()
    ap.set_param("PLND_ENABLED", 0)
    _land_with_target(ap, v, (1.5, -1.0), 30.0)
    assert v.state.on_ground
    assert math.dist(v.state.pos_ned_m[:2], (0.0, 0.0)) < 0.2


def test_px4_auto_land_ignores_the_target() -> None:
    """PX4 lands on a target in AUTO.PRECLAND only: AUTO.LAND lands where it is."""
    ap, v, _ = _rig("px4")
    _land_with_target(ap, v, (1.5, -1.0), 30.0)
    assert v.state.on_ground
    assert math.dist(v.state.pos_ned_m[:2], (0.0, 0.0)) < 0.2


@pytest.mark.parametrize("home", [(0.0, 0.0, 0.0), (120.0, -80.0, 0.0)])
def test_px4_precland_flies_over_the_local_target_then_lands_on_it(home: tuple[float, float, float]) -> None:
    """The target is in the local frame, whose origin is home (a launch away from the world's origin,
    as every city launch is): the touchdown is at home + target in the world."""
    ap, v, _ = _rig("px4", home)
    local = (1.5, -1.0, -ap.local_origin_ned_m[2])  # on the ground
    ap.landing_target_local(local)  # sent before the switch, as the companion does
    assert ap.set_mode(ap.flavour.mode("AUTO.PRECLAND")).result == 0
    for step in range(30 * STEPS_S):
        if step % (STEPS_S // 5) == 0 and not v.state.on_ground:
            ap.landing_target_local(local)
        v.step(ap.tick(v.state), ap.armed)
        if step == 2 * STEPS_S:
            assert v.state.pos_ned_m[2] == pytest.approx(-6.0, abs=0.3)  # across first, at its height
    assert v.state.on_ground
    assert math.dist(v.state.pos_ned_m[:2], (home[0] + 1.5, home[1] - 1.0)) < 0.2


TUNE = PrecLandTune(
    timeout_s=5.0, hacc_rad_m=0.2, final_approach_alt_m=0.1, search_alt_m=10.0, search_timeout_s=10.0,
    max_searches=0,
)  # fmt: skip
HIGH = (0.0, 0.0, -30.0)  # the vehicle, 30 m above the local origin
SITE = (3.0, -4.0, -10.0)  # the target: a roof 10 m up


def _run(pl: PrecLand, t0: float, t1: float, pos: tuple[float, float, float], every_s: float | None):
    """Step ``pl`` at 50 Hz from ``t0`` to ``t1`` with the vehicle at ``pos``, hearing the target every
    ``every_s`` (None: never); the last command."""
    cmd = None
    t, next_heard = t0, t0
    while t < t1:
        if every_s is not None and t >= next_heard:
            pl.heard(t, SITE)
            next_heard += every_s
        cmd = pl.step(t, pos)
        t += 0.02
    return cmd


def test_a_target_heard_before_the_mode_starts_the_approach_at_the_height_it_began() -> None:
    pl = PrecLand(TUNE, 100.0, HIGH, last=(99.9, SITE))  # sent just before the switch, as the companion does
    cmd = pl.step(100.0, HIGH)
    assert pl.phase == "approach"
    assert cmd.land is False
    assert cmd.ne == SITE[:2]
    assert cmd.d == HIGH[2]


def test_over_the_target_for_two_seconds_then_down_onto_it() -> None:
    pl = PrecLand(TUNE, 0.0, HIGH, last=(0.0, SITE))
    above = (SITE[0] + 0.1, SITE[1] - 0.1, HIGH[2])
    _run(pl, 0.0, HORIZONTAL_SETTLE_S - 0.2, above, 0.2)
    assert pl.phase == "approach"  # not yet two seconds within PLD_HACC_RAD
    cmd = _run(pl, HORIZONTAL_SETTLE_S - 0.2, HORIZONTAL_SETTLE_S + 0.5, above, 0.2)
    assert pl.phase == "descend"
    assert cmd is not None
    assert cmd.land
    assert cmd.ne == SITE[:2]
    # 0.3 m off is not over it: the approach goes on
    off = PrecLand(TUNE, 0.0, HIGH, last=(0.0, SITE))
    _run(off, 0.0, 5.0, (SITE[0] + 0.3, SITE[1], HIGH[2]), 0.2)
    assert off.phase == "approach"


def test_a_target_lost_in_the_descent_lands_where_it_is_with_no_search_allowed() -> None:
    pl = PrecLand(TUNE, 0.0, HIGH, last=(0.0, SITE))
    low = (SITE[0], SITE[1], SITE[2] - 2.0)  # 2 m over the roof
    _run(pl, 0.0, 3.0, low, 0.2)
    assert pl.phase == "descend"
    cmd = _run(pl, 3.0, 3.0 + TUNE.timeout_s + 0.5, low, None)  # the camera loses it: PLD_BTOUT later
    assert pl.phase == "fallback"
    assert cmd is not None
    assert cmd.land
    assert cmd.ne == low[:2]
    # with one search allowed (PX4's default is 3), the same loss climbs to PLD_SRCH_ALT instead
    searching = PrecLand(PrecLandTune(5.0, 0.2, 0.1, 10.0, 10.0, 1), 0.0, HIGH, last=(0.0, SITE))
    _run(searching, 0.0, 3.0, low, 0.2)
    cmd = _run(searching, 3.0, 3.0 + TUNE.timeout_s + 1.6, low, None)
    assert searching.phase == "search"
    assert cmd is not None
    assert not cmd.land
    assert cmd.d == -10.0


def test_no_target_at_the_start_searches_or_with_no_search_time_lands_in_place() -> None:
    pl = PrecLand(TUNE, 0.0, HIGH)
    cmd = _run(pl, 0.0, 1.5, HIGH, None)
    assert pl.phase == "search"
    assert cmd is not None
    assert cmd.d == -TUNE.search_alt_m
    _run(pl, 1.5, 12.0, HIGH, None)
    assert pl.phase == "fallback"  # PLD_SRCH_TOUT ran out
    no_search = PrecLand(PrecLandTune(5.0, 0.2, 0.1, 10.0, 0.0, 0), 0.0, HIGH)
    cmd = _run(no_search, 0.0, 1.5, HIGH, None)
    assert no_search.phase == "fallback"
    assert cmd is not None
    assert cmd.land
    assert cmd.ne == HIGH[:2]


class _Sent:
    def __init__(self) -> None:
        self.msgs: list[Any] = []

    def __call__(self, msg: Any) -> None:
        self.msgs.append(msg)


def _server(ap: Autopilot) -> AutopilotServer:
    return AutopilotServer(ap, Telemetry(ap, GeoOrigin()), _Sent())


def _landing_target(
    frame: int, position_valid: int, xyz: tuple[float, float, float], time_usec: int = 0
) -> Any:
    mav = mavlink2.MAVLink(None)
    msg = mav.landing_target_encode(
        time_usec, 0, frame, 0.1, -0.2, 5.0, 0.0, 0.0, *xyz, [1.0, 0.0, 0.0, 0.0], 0, position_valid
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
    _t, unit, distance, stamp = ap._plnd_seen
    assert unit == pytest.approx((3 / 13, 4 / 13, 12 / 13))
    assert distance == 5.0  # the message's own distance field
    assert stamp is None  # time_usec 0: no stamp, the pose when heard
    server.handle(_landing_target(mavlink2.MAV_FRAME_BODY_FRD, 1, (3.0, 4.0, 12.0), 12_345_000), None)
    assert ap._plnd_seen[3] == pytest.approx(12.345)  # the boot clock's seconds


def test_server_reads_angles_as_arducopter_does() -> None:
    """position_valid 0: angle_x to the right, angle_y aft (ArduCopter's AC_PrecLand reading)."""
    ap, _v, _ = _rig()
    _server(ap).handle(_landing_target(mavlink2.MAV_FRAME_BODY_FRD, 0, (0.0, 0.0, 0.0)), None)
    assert ap._plnd_seen is not None
    _t, unit, _d, _stamp = ap._plnd_seen
    los = (-math.tan(-0.2), math.tan(0.1), 1.0)
    norm = math.sqrt(sum(c * c for c in los))
    assert unit == pytest.approx(tuple(c / norm for c in los))


def test_px4_server_reads_local_ned_positions_and_refuses_other_frames() -> None:
    ap, _v, texts = _rig("px4")
    server = _server(ap)
    server.handle(_landing_target(mavlink2.MAV_FRAME_BODY_FRD, 1, (3.0, 4.0, 12.0)), None)
    assert "landing target: coordinate frame 12 unsupported" in texts  # PX4's own words
    assert ap._pld_heard is None
    server.handle(_landing_target(mavlink2.MAV_FRAME_BODY_FRD, 0, (0.0, 0.0, 0.0)), None)  # angles only
    assert ap._pld_heard is None  # PX4's IR-LOCK path, not run here
    server.handle(_landing_target(mavlink2.MAV_FRAME_LOCAL_NED, 1, (1.0, -2.0, -8.0)), None)
    assert ap._pld_heard is not None
    o = ap.local_origin_ned_m
    assert ap._pld_heard[1] == (1.0 + o[0], -2.0 + o[1], -8.0 + o[2])  # world axes, as its pose
