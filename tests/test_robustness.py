"""Bad input never crashes simbridge: malformed frames, foreign targets, impossible setpoints,
unsigned/forged/replayed frames when signing is on; signals end it cleanly."""

from __future__ import annotations

import math
import signal
import struct
from collections.abc import Callable

import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink2

from tests.conftest import SimProcess
from tests.mavclient import MAV_RESULT_ACCEPTED, MavClient

pytestmark = pytest.mark.slow
MAV = mavutil.mavlink
KEY = bytes(range(32))


def _raw_send(c: MavClient, data: bytes) -> None:
    c.conn.write(data)  # raw bytes to the peer(s) this udpin socket has heard from


def _unknown_message_frame() -> bytes:
    """A well-formed MAVLink 2 frame with a message id no dialect defines (id 42424)."""
    payload = b"\x01\x02\x03"
    header = struct.pack("<BBBBBBBHB", 0xFD, len(payload), 0, 0, 9, 255, 0, 42424 & 0xFFFF, 42424 >> 16)
    crc = mavutil.x25crc(header[1:] + payload)
    return header + payload + struct.pack("<H", crc.crc)


def test_malformed_frames_and_foreign_targets_are_survived(
    start_sim: Callable[..., SimProcess], client_for: Callable[..., MavClient]
) -> None:
    sim = start_sim("--autopilot", "ardupilot", "--speed", "2")
    c = client_for(sim.port)
    c.wait_heartbeat()
    good = c.mav.command_long_encode(1, 1, MAV.MAV_CMD_DO_SET_MODE, 0, 1, 4, 0, 0, 0, 0, 0).pack(c.mav)
    bad_crc = good[:-1] + bytes([good[-1] ^ 0xFF])
    for junk in (
        b"\x00" * 40,
        bytes(range(256)),
        good[:9],
        bad_crc,
        b"\xfd\xff" + b"\x01" * 300,
        _unknown_message_frame(),
    ):
        _raw_send(c, junk)
    # the link still works: a valid command after the junk is answered
    assert c.set_mode_ap("GUIDED") == MAV_RESULT_ACCEPTED
    # commands for another vehicle or component are ignored: no answer at all
    c.mav.command_long_send(7, 1, MAV.MAV_CMD_COMPONENT_ARM_DISARM, 0, 0, 0, 0, 0, 0, 0, 0)
    c.mav.command_long_send(1, 42, MAV.MAV_CMD_COMPONENT_ARM_DISARM, 0, 0, 0, 0, 0, 0, 0, 0)
    with pytest.raises(TimeoutError):
        c.recv("COMMAND_ACK", timeout_s=1.0)
    assert c.heartbeat().base_mode & MAV.MAV_MODE_FLAG_SAFETY_ARMED  # still flying, armed
    # impossible setpoints are refused with a STATUSTEXT and the vehicle keeps holding
    nan = float("nan")
    c.mav.set_position_target_local_ned_send(0, 1, 1, 1, 3576, nan, 0, -100, 0, 0, 0, 0, 0, 0, 0, 0)
    c.statustext("NaN")
    c.send_position(5000.0, 0.0, -100.0)
    c.statustext("outside geofence")
    c.mav.set_position_target_local_ned_send(0, 1, 1, 3, 3576, 1, 1, -100, 0, 0, 0, 0, 0, 0, 0, 0)
    c.statustext("frame 3 unsupported")
    p = c.position()
    assert math.dist((p.x, p.y, p.z), (0.0, 0.0, -100.0)) < 0.5
    assert sim.stop() == 0
    stop = sim.events("stop")[0]
    assert int(stop["bad_frames"]) >= 4  # type: ignore[call-overload]
    assert int(stop["ignored_foreign"]) == 2  # type: ignore[call-overload]


def test_signing_rejects_unsigned_forged_and_replayed_frames(
    start_sim: Callable[..., SimProcess], client_for: Callable[..., MavClient]
) -> None:
    sim = start_sim("--autopilot", "px4", "--speed", "2", "--signing-key", KEY.hex())
    c = client_for(sim.port, signing_key=KEY)
    c.wait_heartbeat()  # simbridge signs its frames: a signing client accepts them
    mode_cmd = (1, 1, MAV.MAV_CMD_DO_SET_MODE, 0, 1, 3, 0, 0, 0, 0, 0)

    c.mav.signing.sign_outgoing = False
    c.mav.command_long_send(*mode_cmd)
    with pytest.raises(TimeoutError):
        c.recv("COMMAND_ACK", timeout_s=1.0)

    c.mav.signing.sign_outgoing = True
    c.mav.signing.secret_key = bytes(32)  # forged: signed with the wrong key
    c.mav.command_long_send(*mode_cmd)
    with pytest.raises(TimeoutError):
        c.recv("COMMAND_ACK", timeout_s=1.0)

    c.mav.signing.secret_key = KEY
    frame = c.mav.command_long_encode(*mode_cmd).pack(c.mav)
    _raw_send(c, frame)
    assert c.recv("COMMAND_ACK").result == MAV_RESULT_ACCEPTED
    _raw_send(c, frame)  # replayed: same signature timestamp
    with pytest.raises(TimeoutError):
        c.recv("COMMAND_ACK", timeout_s=1.0)

    assert sim.stop() == 0
    stop = sim.events("stop")[0]
    assert stop["rejected_unsigned"] == 1
    assert int(stop["rejected_bad_signature"]) >= 1  # type: ignore[call-overload]
    assert [e["mode"] for e in sim.events("mode")] == ["POSCTL"]


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_signal_exits_cleanly(
    start_sim: Callable[..., SimProcess], client_for: Callable[..., MavClient], sig: signal.Signals
) -> None:
    sim = start_sim("--speed", "2")
    client_for(sim.port).wait_heartbeat()
    sim.proc.send_signal(sig)
    assert sim.proc.wait(timeout=10) == 0
    assert len(sim.events("stop")) == 1
    assert "Traceback" not in sim.stderr_path.read_text()


def test_bad_command_line_names_the_flag(tmp_path: object) -> None:
    import subprocess
    import sys

    for args, needle in (
        (["--mavlink", "tcp:1.2.3.4:5"], "--mavlink"),
        (["--signing-key", "abc"], "--signing-key"),
        (["--scenario", "atlantis"], "--scenario"),
        (["--speed", "0"], "--speed"),
    ):
        out = subprocess.run(
            [sys.executable, "-m", "simbridge", *args], capture_output=True, text=True, timeout=30
        )
        assert out.returncode == 2, args
        assert needle in out.stderr, out.stderr


def test_decoder_rejects_partial_masks() -> None:
    from simbridge.autopilot.server import SetpointError, decode_local_ned_target

    mav = mavlink2.MAVLink(None)
    accel_only = mav.set_position_target_local_ned_encode(
        0, 1, 1, 1, 0b110000111111, 0, 0, 0, 0, 0, 0, 1, 1, 1, 0, 0
    )
    with pytest.raises(SetpointError, match="without position or velocity"):
        decode_local_ned_target(accel_only, (0.0, 0.0, 0.0), 0.0)
    body = mav.set_position_target_local_ned_encode(0, 1, 1, 8, 3576, 10, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0)
    sp, is_velocity = decode_local_ned_target(body, (1.0, 2.0, -50.0), math.pi / 2)
    assert not is_velocity
    assert sp.pos_ne_m == pytest.approx((1.0, 12.0))  # 10 m forward while facing east
    assert sp.pos_d_m == pytest.approx(-50.0)


def test_decoder_velocity_and_position_yaw_masks() -> None:
    from simbridge.autopilot.server import decode_local_ned_target

    mav = mavlink2.MAVLink(None)
    velocity = mav.set_position_target_local_ned_encode(
        0, 1, 1, 1, 3527, 0, 0, 0, 1.0, -2.0, 0.5, 0, 0, 0, 0, 0
    )
    sp, is_velocity = decode_local_ned_target(velocity, (5.0, 5.0, -20.0), 0.0)
    assert is_velocity
    assert sp.pos_ne_m is None
    assert sp.pos_d_m is None
    assert sp.vel_ned_m_s == (1.0, -2.0, 0.5)
    pos_yaw = mav.set_position_target_local_ned_encode(0, 1, 1, 1, 2552, 3, 4, -10, 0, 0, 0, 0, 0, 0, 1.2, 0)
    sp, is_velocity = decode_local_ned_target(pos_yaw, (0.0, 0.0, 0.0), 0.0)
    assert not is_velocity
    assert sp.pos_ne_m == (3.0, 4.0)
    assert sp.yaw_rad == pytest.approx(1.2)
    assert sp.yaw_rate_rad_s is None
