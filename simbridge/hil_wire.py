"""The two messages of PX4's HIL lock step, framed without a pymavlink message object per frame.

Each lock step (250 a simulated second) sends PX4 one HIL_SENSOR and waits for one HIL_ACTUATOR_CONTROLS.
pymavlink builds a message object, its header and its field list for every frame it encodes or parses: in
the lock step that was a third of simbridge's CPU time (py-spy, 2026-11-28; docs/px4-sitl.md). These two
frames are packed and unpacked here with pymavlink's own definitions (the field layout of each message,
its CRC extra, its id; pymavlink's CRC), MAVLink 2 framing as the protocol defines it: header, payload
with trailing zeros trimmed, X.25 CRC over both and the CRC extra. Every other frame PX4 sends on the
simulator link (a HEARTBEAT, a COMMAND_LONG) goes to pymavlink whole, as does a signed one.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Any

from pymavlink.dialects.v20 import common as M

__all__ = ["ActuatorControls", "HilWire"]

_V2, _V1 = 0xFD, 0xFE
_SIGNED = 0x01  # MAVLink 2 incompat flag: a 13-byte signature follows the CRC
_HEADER = struct.Struct("<BBBBBBBHB")  # magic, len, incompat, compat, seq, sysid, compid, msgid (24 bits)
_CRC = struct.Struct("<H")
_SENSOR = M.MAVLink_hil_sensor_message
_ACTUATORS = M.MAVLink_hil_actuator_controls_message
_ACTUATORS_LEN = _ACTUATORS.unpacker.size


@dataclass(frozen=True, slots=True)
class ActuatorControls:
    """One HIL_ACTUATOR_CONTROLS as PX4 sent it."""

    time_usec: int
    flags: int
    controls: tuple[float, ...]  # 16, PX4's output order
    mode: int  # MAV_MODE_FLAG bits


_mcrf4xx = getattr(M, "mcrf4xx", None)  # pymavlink's CRC-16/MCRF4XX from fastcrc, when it has it


def _crc(data: bytes, *, extra: int) -> int:
    """MAVLink's X.25 CRC over ``data`` (the frame after its magic byte) and the CRC extra."""
    if _mcrf4xx is not None:
        return int(_mcrf4xx(bytes((extra,)), _mcrf4xx(data, 0xFFFF)))
    crc = M.x25crc(data)
    crc.accumulate(bytes((extra,)))
    return int(crc.crc)


class HilWire:
    """Frames HIL_SENSOR out of and HIL_ACTUATOR_CONTROLS into ``mav`` (a pymavlink ``MAVLink``):
    its sequence number and ids for what goes out, its parser for every other frame that comes in.

    Args:
        mav: the link's pymavlink object (not signing what it sends: the simulator link is not
            signed); set to robust parsing.
    """

    def __init__(self, mav: Any) -> None:
        self.mav = mav
        mav.robust_parsing = True  # a damaged frame is a BAD_DATA message, not an exception
        self._buf = bytearray()
        self.bad_frames = 0  # starts of frames that were none (a wrong CRC, impossible flags)

    def hil_sensor(self, *fields: Any) -> bytes:
        """One HIL_SENSOR frame, fields in the order of ``mav.hil_sensor_encode``: the same bytes
        ``mav.hil_sensor_encode(*fields).pack(mav)`` gives."""
        mav = self.mav
        payload: bytes = _SENSOR.unpacker.pack(*fields)
        n = len(payload)
        while n > 1 and payload[n - 1] == 0:  # MAVLink 2 trims trailing zeros, keeping one byte
            n -= 1
        payload = payload[:n]
        mid = _SENSOR.id
        header = _HEADER.pack(_V2, n, 0, 0, mav.seq, mav.srcSystem, mav.srcComponent, mid & 0xFFFF, mid >> 16)
        mav.seq = (mav.seq + 1) % 256
        mav.total_packets_sent += 1
        mav.total_bytes_sent += len(header) + n + 2
        frame = header + payload
        return frame + _CRC.pack(_crc(frame[1:], extra=_SENSOR.crc_extra))

    def feed(self, data: bytes) -> list[ActuatorControls | Any]:
        """The complete frames in what came so far: an :class:`ActuatorControls` for each unsigned
        HIL_ACTUATOR_CONTROLS, pymavlink's message (or its bad-data message) for any other frame.
        Bytes that start no frame are skipped, and so is a frame that fails its CRC, one byte at a
        time (the next frame may start inside it); a frame cut short waits for the rest."""
        buf = self._buf
        buf += data
        out: list[ActuatorControls | Any] = []
        i, end = 0, len(buf)
        while i < end:
            magic = buf[i]
            if magic == _V2:
                if end - i < 10:
                    break
                n = buf[i + 1]
                size = 12 + n + (13 if buf[i + 2] & _SIGNED else 0)
                if end - i < size:
                    break
                msgid = buf[i + 7] | buf[i + 8] << 8 | buf[i + 9] << 16
                if msgid == _ACTUATORS.id and not buf[i + 2] & _SIGNED:
                    crc = buf[i + 10 + n] | buf[i + 11 + n] << 8
                    if crc != _crc(bytes(buf[i + 1 : i + 10 + n]), extra=_ACTUATORS.crc_extra):
                        self.bad_frames += 1
                        i += 1  # no frame here after all: look for the next start
                        continue
                    payload = bytes(buf[i + 10 : i + 10 + n]).ljust(_ACTUATORS_LEN, b"\0")
                    v = _ACTUATORS.unpacker.unpack(payload)
                    out.append(ActuatorControls(v[0], v[1], tuple(v[2:18]), v[18]))
                    i += size
                    continue
            elif magic == _V1:
                if end - i < 6:
                    break
                size = 8 + buf[i + 1]
                if end - i < size:
                    break
            else:
                i += 1
                continue
            impossible = magic == _V2 and buf[i + 2] & ~_SIGNED  # flags MAVLink 2 does not define
            got = [] if impossible else self.mav.parse_buffer(bytes(buf[i : i + size])) or []
            if impossible or any(m.get_type() == "BAD_DATA" for m in got):
                self.bad_frames += 1
                i += 1  # a false start (or a frame damaged): look for the next start
                continue
            out.extend(got)
            i += size
        del buf[:i]
        return out
