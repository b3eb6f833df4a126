"""simbridge.hil_wire against pymavlink: the same HIL_SENSOR bytes, the same HIL_ACTUATOR_CONTROLS read
back from a stream cut anywhere, other frames (signed ones too) left to pymavlink, corrupt bytes skipped."""

from __future__ import annotations

import math
import random
import struct

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pymavlink.dialects.v20 import common as M

from simbridge.hil_wire import ActuatorControls, HilWire

floats = st.floats(-1e6, 1e6, width=32)


@settings(max_examples=300, deadline=None)
@given(
    st.integers(0, 2**64 - 1),
    st.lists(floats, min_size=13, max_size=13),
    st.integers(0, 2**32 - 1),
    st.integers(0, 255),
    st.integers(0, 255),
)
def test_hil_sensor_frames_are_the_bytes_pymavlink_packs(
    usec: int, values: list[float], fields: int, sensor_id: int, seq: int
) -> None:
    ours, theirs = (
        M.MAVLink(None, srcSystem=1, srcComponent=51),
        M.MAVLink(None, srcSystem=1, srcComponent=51),
    )
    ours.seq = theirs.seq = seq
    args = (usec, *values, fields, sensor_id)
    assert HilWire(ours).hil_sensor(*args) == theirs.hil_sensor_encode(*args).pack(theirs)
    assert ours.seq == (seq + 1) % 256  # as sending it would (pack alone leaves it)
    assert ours.total_packets_sent == 1


def test_hil_sensor_with_trailing_zeros_keeps_one_byte() -> None:
    ours, theirs = (
        M.MAVLink(None, srcSystem=1, srcComponent=51),
        M.MAVLink(None, srcSystem=1, srcComponent=51),
    )
    args = (0, *([0.0] * 13), 0, 0)
    frame = HilWire(ours).hil_sensor(*args)
    assert frame == theirs.hil_sensor_encode(*args).pack(theirs)
    assert frame[1] == 1  # payload length


def _f32(v: float) -> float:
    return float(struct.unpack("<f", struct.pack("<f", v))[0])


def _actuators(rng: random.Random, px4: M.MAVLink) -> tuple[bytes, ActuatorControls]:
    controls = [rng.uniform(-1, 1) for _ in range(16)]
    if rng.random() < 0.3:
        controls[8:] = [0.0] * 8  # the unused outputs PX4 leaves at zero: a trimmed payload
    t, mode, flags = rng.getrandbits(63), rng.choice([0, 128, 208]), rng.choice([0, 1])
    frame = px4.hil_actuator_controls_encode(t, controls, mode, flags).pack(px4)
    return frame, ActuatorControls(t, flags, tuple(_f32(c) for c in controls), mode)


@pytest.mark.parametrize("seed", range(5))
def test_a_stream_cut_anywhere_gives_every_actuator_message_and_the_other_frames(seed: int) -> None:
    rng = random.Random(seed)
    px4 = M.MAVLink(None, srcSystem=1, srcComponent=1)
    stream, expected = b"\x00\x13garbage", []
    for k in range(60):
        frame, want = _actuators(rng, px4)
        stream += frame
        expected.append(want)
        if k % 7 == 3:
            stream += px4.heartbeat_encode(2, 12, 0, 0, 3).pack(px4)
            expected.append("HEARTBEAT")
        if k % 11 == 5:
            stream += px4.command_long_encode(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0).pack(
                px4, force_mavlink1=True
            )
            expected.append("COMMAND_LONG")
    sim = HilWire(M.MAVLink(None, srcSystem=1, srcComponent=51))
    got: list[object] = []
    i = 0
    while i < len(stream):
        step = rng.randint(1, 90)
        got += sim.feed(stream[i : i + step])
        i += step
    assert [g if isinstance(g, ActuatorControls) else g.get_type() for g in got] == expected  # type: ignore[attr-defined]
    assert sim.bad_frames == 0


def test_a_corrupt_actuator_frame_is_dropped_and_the_stream_found_again() -> None:
    rng = random.Random(1)
    px4 = M.MAVLink(None, srcSystem=1, srcComponent=1)
    broken = bytearray(_actuators(rng, px4)[0])
    broken[20] ^= 0xFF
    good = [_actuators(rng, px4) for _ in range(4)]
    sim = HilWire(M.MAVLink(None, srcSystem=1, srcComponent=51))
    got = sim.feed(bytes(broken) + b"".join(frame for frame, _ in good))
    assert sim.bad_frames >= 1
    assert not [g for g in got if not isinstance(g, ActuatorControls)]
    assert got[-3:] == [want for _, want in good[-3:]]  # a false start in the bad bytes may hide one


def test_a_signed_actuator_frame_goes_to_pymavlink() -> None:
    key = bytes(range(32))
    px4 = M.MAVLink(None, srcSystem=1, srcComponent=1)
    px4.signing.secret_key = key
    px4.signing.sign_outgoing = True
    frame = px4.hil_actuator_controls_encode(5, [0.5] * 16, 128, 0).pack(px4)
    assert frame[2] & 0x01  # signed
    sim_mav = M.MAVLink(None, srcSystem=1, srcComponent=51)
    sim_mav.signing.secret_key = key
    (msg,) = HilWire(sim_mav).feed(frame)
    assert msg.get_type() == "HIL_ACTUATOR_CONTROLS"
    assert math.isclose(msg.controls[0], 0.5)


def test_without_fastcrc_the_crc_is_pymavlinks_own(monkeypatch: pytest.MonkeyPatch) -> None:
    import simbridge.hil_wire as hil_wire

    ours, theirs = (
        M.MAVLink(None, srcSystem=1, srcComponent=51),
        M.MAVLink(None, srcSystem=1, srcComponent=51),
    )
    args = (123456, *[float(k) for k in range(13)], 0x1FFF, 0)
    fast = HilWire(ours).hil_sensor(*args)
    monkeypatch.setattr(hil_wire, "_mcrf4xx", None)
    ours.seq = 0
    assert HilWire(ours).hil_sensor(*args) == fast == theirs.hil_sensor_encode(*args).pack(theirs)
