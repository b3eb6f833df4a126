"""The companion places frames with the autopilot's estimate at capture time."""

from __future__ import annotations

import asyncio
import math

import pytest
from pymavlink.dialects.v20 import common as mavlink2

from companion.daemon import Companion
from companion.recovery import FrameUnavailable
from companion.telemetry import PoseHistory
from tests.test_sensorstream import make_frame

_MAV = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)


def _yaw_quat(yaw: float) -> tuple[float, float, float, float]:
    return (math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2))


def test_positions_interpolate_and_extrapolate_only_a_little() -> None:
    h = PoseHistory()
    h.add_position(10.0, (0.0, 0.0, -50.0), (2.0, 0.0, 0.0))
    h.add_position(10.1, (0.2, 0.0, -50.0), (2.0, 0.0, 0.0))
    h.add_attitude(10.0, _yaw_quat(0.0))
    h.add_attitude(10.1, _yaw_quat(0.2))
    mid = h.at(10.05)
    assert mid is not None
    assert mid.pos_ned_m == pytest.approx((0.1, 0.0, -50.0))
    yaw = 2 * math.atan2(mid.quat_wxyz[3], mid.quat_wxyz[0])
    assert yaw == pytest.approx(0.1, abs=1e-3)
    ahead = h.at(10.2)  # 0.1 s past the newest: dead reckoning on its velocity
    assert ahead is not None
    assert ahead.pos_ned_m == pytest.approx((0.4, 0.0, -50.0))
    assert h.at(10.1 + PoseHistory.EXTRAPOLATE_S + 0.01) is None
    assert h.at(9.99) is None  # before anything was heard


def test_a_gap_a_late_packet_and_a_reboot() -> None:
    h = PoseHistory()
    h.add_attitude(0.0, _yaw_quat(0.0))
    h.add_attitude(5.0, _yaw_quat(0.0))
    h.add_position(0.0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    h.add_position(5.0, (5.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    assert h.at(2.5) is None  # samples 5 s apart: nothing known in between
    h.add_position(4.0, (9.0, 9.0, 9.0), (0.0, 0.0, 0.0))  # late: ignored
    assert h.span() == (0.0, 5.0)
    h.add_position(0.5, (1.0, 1.0, -1.0), (0.0, 0.0, 0.0))  # far back: the autopilot rebooted
    assert h.span() == (0.5, 0.5)


def test_quaternions_take_the_short_way() -> None:
    h = PoseHistory()
    h.add_position(0.0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    h.add_position(0.1, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    q = _yaw_quat(0.1)
    h.add_attitude(0.0, q)
    h.add_attitude(0.1, (-q[0], -q[1], -q[2], -q[3]))  # the same attitude, other sign
    mid = h.at(0.05)
    assert mid is not None
    assert abs(mid.quat_wxyz[0]) == pytest.approx(q[0])
    assert math.isclose(math.fsum(c * c for c in mid.quat_wxyz), 1.0)


def _feed(c: Companion, t_ms: int, pos: tuple[float, float, float], yaw: float) -> None:
    q = _yaw_quat(yaw)
    for msg in (
        _MAV.heartbeat_encode(2, 3, 0, 4, 4),
        _MAV.local_position_ned_encode(t_ms, *pos, 0.0, 0.0, 0.0),
        _MAV.attitude_quaternion_encode(t_ms, *q, 0.0, 0.0, 0.0),
    ):
        raw = msg.pack(_MAV)
        c.tm.on_message(_MAV.decode(bytearray(raw)))


async def test_the_companion_never_uses_the_pose_a_frame_claims() -> None:
    """A frame's own pose (simbridge's truth) is replaced by the autopilot's estimate at its
    ``time_boot_ms``; a frame the telemetry does not cover is a clear sensor fault."""
    c = Companion(mavlink_url="udpin:127.0.0.1:0")
    frame = make_frame()  # claims POS_NED_M / QUAT_WXYZ, captured at time_boot_ms 123 456 789
    t = frame.time_boot_ms
    _feed(c, t - 50, (10.0, 20.0, -60.0), 0.5)
    _feed(c, t + 50, (11.0, 20.0, -60.0), 0.5)  # (2 m would be a reset for the zero velocity fed)
    posed = await c.view.posed(frame)
    assert posed.pos_ned_m == pytest.approx((10.5, 20.0, -60.0))
    assert posed.quat_wxyz == pytest.approx(_yaw_quat(0.5))
    assert posed.image_rgb is frame.image_rgb
    assert posed.time_boot_ms == t
    old = make_frame()
    c2 = Companion(mavlink_url="udpin:127.0.0.1:0")
    _feed(c2, t + 5_000, (0.0, 0.0, -50.0), 0.0)
    with pytest.raises(FrameUnavailable, match="no autopilot pose at the frame's capture time"):
        await asyncio.wait_for(c2.view.posed(old), 5.0)


def test_a_reset_of_the_estimate_is_a_step_its_velocity_does_not_explain() -> None:
    """ArduCopter's EKF resetting onto a GPS that jumped 18 m moves LOCAL_POSITION_NED 18 m in one
    sample at an unchanged velocity: a reset. Flying fast, braking hard, a repeated or late sample, a
    gap and the autopilot's reboot are not."""
    from companion.telemetry import ResetWatch

    watch = ResetWatch()
    t, n = 0.0, 0.0
    for k in range(100):  # 10 Hz: 8 m/s north, braking at 5 m/s^2 from the 50th sample
        v = 8.0 if k < 50 else max(0.0, 8.0 - 5.0 * (k - 50) * 0.1)
        t += 0.1
        n += v * 0.1
        watch.add(t, (n, 0.0, -40.0), (v, 0.0, 0.0))
        watch.add(t - 0.05, (n - 5.0, 0.0, -40.0), (v, 0.0, 0.0))  # a late one
        watch.add(t, (n, 0.0, -40.0), (v, 0.0, 0.0))  # a repeated one
    assert watch.resets == []
    watch.add(t + 0.1, (n + 15.0, 10.0, -40.0), (0.0, 0.0, 0.0))  # the reset
    watch.add(t + 0.2, (n + 15.0, 10.0, -40.0), (0.0, 0.0, 0.0))
    ((when, (dn, de)),) = watch.resets
    assert when == pytest.approx(t + 0.1)
    assert (dn, de) == pytest.approx((15.0, 10.0))
    watch.add(t + 2.0, (n + 30.0, 10.0, -40.0), (0.0, 0.0, 0.0))  # after a gap: not compared
    watch.add(0.5, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))  # the autopilot rebooted: its clock restarted
    watch.add(0.6, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    assert len(watch.resets) == 1
    assert watch.since(t) == pytest.approx((15.0, 10.0))
    assert watch.since(t + 0.1) == (0.0, 0.0)


def test_turn_rate_is_the_angle_turned_about_a_time_over_the_time_between() -> None:
    """Yawing 1 rad/s: the rate about a time inside the history; the newest sample bounds the window
    after it; NaN with too little history or none."""
    h = PoseHistory()
    assert math.isnan(h.turn_rate_at(10.0))
    for k in range(11):  # 10.0 .. 11.0 s, a sample every 0.1 s
        h.add_attitude(10.0 + 0.1 * k, _yaw_quat(0.1 * k))
    assert h.turn_rate_at(10.5) == pytest.approx(1.0, rel=1e-3)
    assert h.turn_rate_at(10.95) == pytest.approx(1.0, rel=1e-3)  # 10.85 .. 11.0
    assert math.isnan(h.turn_rate_at(11.0))  # only 0.1 s of history after 10.9
    assert math.isnan(h.turn_rate_at(9.0))  # before anything was heard
    steady = PoseHistory()
    for k in range(11):
        steady.add_attitude(10.0 + 0.1 * k, _yaw_quat(0.3))
    assert steady.turn_rate_at(10.5) == pytest.approx(0.0, abs=1e-6)


def test_a_time_between_the_samples_either_side_of_a_reset_is_placed_before_it() -> None:
    """The estimate resets 18 m between two samples: a frame taken between them is placed in the frame
    of reference before the reset (carried on from the earlier sample), not part of the way (which
    would put its site 12 m off in neither frame); between ordinary samples it is interpolated."""
    h = PoseHistory()
    h.add_attitude(10.0, _yaw_quat(0.0))
    h.add_attitude(10.2, _yaw_quat(0.0))
    h.add_position(10.0, (0.0, 0.0, -40.0), (1.0, 0.0, 0.0))
    h.add_position(10.1, (15.1, 10.0, -40.0), (1.0, 0.0, 0.0))  # reset by (15, 10) on top of 0.1 m
    h.add_position(10.2, (15.2, 10.0, -40.0), (1.0, 0.0, 0.0))
    before = h.at(10.07)
    assert before is not None
    assert before.pos_ned_m == pytest.approx((0.07, 0.0, -40.0))
    after = h.at(10.15)
    assert after is not None
    assert after.pos_ned_m == pytest.approx((15.15, 10.0, -40.0))
