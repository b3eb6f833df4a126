"""The autopilot's MAVLink face: commands, mode changes, setpoints, parameters, pings.

Incoming messages are decoded and checked here, turned into calls on :class:`Autopilot`, and
answered (COMMAND_ACK addressed to the sender's ids, PARAM_VALUE, PING, TIMESYNC).
"""

from __future__ import annotations

import logging
import math
import struct
from collections.abc import Callable
from typing import Any

from pymavlink.dialects.v20 import common as mavlink2

from simbridge.autopilot.core import Autopilot, CommandOutcome
from simbridge.autopilot.flavours import (
    MAV_PARAM_TYPE_REAL32,
    MAV_RESULT_ACCEPTED,
    MAV_RESULT_DENIED,
    MAV_RESULT_FAILED,
    MAV_RESULT_UNSUPPORTED,
    ModeSpec,
)
from simbridge.control import Setpoint
from simbridge.telemetry import Telemetry

M = mavlink2
Send = Callable[[Any], None]

MAV_FRAME_LOCAL_NED = 1
MAV_FRAME_LOCAL_OFFSET_NED = 7
MAV_FRAME_BODY_NED = 8
MAV_FRAME_BODY_OFFSET_NED = 9
_SUPPORTED_FRAMES = (
    MAV_FRAME_LOCAL_NED,
    MAV_FRAME_LOCAL_OFFSET_NED,
    MAV_FRAME_BODY_NED,
    MAV_FRAME_BODY_OFFSET_NED,
)
_IGNORE_X, _IGNORE_Y, _IGNORE_Z = 1, 2, 4
_IGNORE_VX, _IGNORE_VY, _IGNORE_VZ = 8, 16, 32
_IGNORE_YAW, _IGNORE_YAW_RATE = 1024, 2048
_FORCE_ARM_MAGIC = 21196


class SetpointError(ValueError):
    """A SET_POSITION_TARGET_LOCAL_NED that cannot be flown."""


def decode_local_ned_target(
    msg: Any, pos_ned_m: tuple[float, float, float], yaw_rad: float
) -> tuple[Setpoint, bool]:
    """SET_POSITION_TARGET_LOCAL_NED -> (local-frame setpoint, velocity-only?); ``pos_ned_m`` is the
    vehicle's position in the local frame (the offset frames' reference).

    Raises:
        SetpointError: unsupported frame or a mask that leaves an axis without position or velocity.
    """
    frame, mask = int(msg.coordinate_frame), int(msg.type_mask)
    if frame not in _SUPPORTED_FRAMES:
        raise SetpointError(f"frame {frame} unsupported (use 1, 7, 8 or 9)")
    use_xy = not mask & (_IGNORE_X | _IGNORE_Y)
    use_z = not mask & _IGNORE_Z
    use_vxy = not mask & (_IGNORE_VX | _IGNORE_VY)
    use_vz = not mask & _IGNORE_VZ
    if not (use_xy or use_vxy) or not (use_z or use_vz):
        raise SetpointError(f"type_mask {mask} leaves an axis without position or velocity")
    x, y, z = float(msg.x), float(msg.y), float(msg.z)
    vx, vy, vz = float(msg.vx), float(msg.vy), float(msg.vz)
    if frame in (MAV_FRAME_BODY_NED, MAV_FRAME_BODY_OFFSET_NED):
        c, s = math.cos(yaw_rad), math.sin(yaw_rad)
        x, y = c * x - s * y, s * x + c * y
        vx, vy = c * vx - s * vy, s * vx + c * vy
    if frame != MAV_FRAME_LOCAL_NED:
        x, y, z = x + pos_ned_m[0], y + pos_ned_m[1], z + pos_ned_m[2]
    sp = Setpoint(
        pos_ne_m=(x, y) if use_xy else None,
        pos_d_m=z if use_z else None,
        vel_ned_m_s=(vx if use_vxy else 0.0, vy if use_vxy else 0.0, vz if use_vz else 0.0),
        yaw_rad=float(msg.yaw) if not mask & _IGNORE_YAW else None,
        yaw_rate_rad_s=float(msg.yaw_rate) if not mask & _IGNORE_YAW_RATE else None,
    )
    return sp, not use_xy and not use_z


class AutopilotServer:
    """Dispatches MAVLink messages addressed to the autopilot (sysid, compid 1)."""

    def __init__(
        self,
        autopilot: Autopilot,
        telemetry: Telemetry,
        send: Send,
        system_id: int = 1,
        component_id: int = 1,
        logger: logging.Logger | None = None,
    ) -> None:
        self.ap = autopilot
        self.tm = telemetry
        self._send = send
        self.system_id = system_id
        self.component_id = component_id
        self._log = logger or logging.getLogger("simbridge.autopilot")
        self._mav = mavlink2.MAVLink(None)  # encode helpers only
        self.ignored_foreign = 0
        self._handlers: dict[str, Callable[[Any], None]] = {
            "COMMAND_LONG": self._on_command,
            "COMMAND_INT": self._on_command,
            "SET_MODE": self._on_set_mode_msg,
            "SET_POSITION_TARGET_LOCAL_NED": self._on_local_target,
            "PARAM_REQUEST_LIST": self._on_param_list,
            "PARAM_REQUEST_READ": self._on_param_read,
            "PARAM_SET": self._on_param_set,
            "PING": self._on_ping,
            "LANDING_TARGET": self._on_landing_target,
            "REQUEST_DATA_STREAM": self._on_request_data_stream,
            "TIMESYNC": self._on_timesync,
        }
        names = [p.name for p in autopilot.flavour.params]
        self._param_index = {n: i for i, n in enumerate(names)}
        self._param_types = {p.name: p.type for p in autopilot.flavour.params}

    def handle(self, msg: Any, addr: object) -> None:
        handler = self._handlers.get(msg.get_type())
        if handler is not None:
            handler(msg)

    # ------------------------------------------------------------------ targeting
    def _for_us(self, msg: Any) -> bool:
        sys_ok = getattr(msg, "target_system", 0) in (0, self.system_id)
        comp_ok = getattr(msg, "target_component", 0) in (0, self.component_id)
        if not (sys_ok and comp_ok):
            self.ignored_foreign += 1
        return sys_ok and comp_ok

    def _ack(self, msg: Any, command: int, result: int) -> None:
        self._send(
            self._mav.command_ack_encode(command, result, 0, 0, msg.get_srcSystem(), msg.get_srcComponent())
        )

    def _on_request_data_stream(self, msg: Any) -> None:
        if not self._for_us(msg) or self.ap.flavour.streams_unasked:
            return  # PX4 does not implement the legacy request (it streams anyway)
        if not self.tm.request_data_stream(
            int(msg.req_stream_id), float(msg.req_message_rate), bool(msg.start_stop)
        ):
            self._log.info("REQUEST_DATA_STREAM %d not served", msg.req_stream_id)

    # ------------------------------------------------------------------ commands
    def _on_command(self, msg: Any) -> None:
        if not self._for_us(msg):
            return
        cmd = int(msg.command)
        p = [msg.param1, msg.param2, msg.param3, msg.param4]
        p5, p6, p7 = (
            (msg.x, msg.y, msg.z) if msg.get_type() == "COMMAND_INT" else (msg.param5, msg.param6, msg.param7)
        )
        try:
            outcome = self._dispatch(cmd, p, float(p5), float(p6), float(p7))
        except Exception:
            # a bug here must still answer: the sender retries otherwise, and the vehicle flies on
            self._log.exception("command %d failed", cmd)
            outcome = CommandOutcome(MAV_RESULT_FAILED)
        self._ack(msg, cmd, outcome.result)
        if outcome.result == MAV_RESULT_ACCEPTED and cmd in (
            M.MAV_CMD_REQUEST_MESSAGE,
            M.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES,
        ):
            msg_id = int(p[0]) if cmd == M.MAV_CMD_REQUEST_MESSAGE else M.MAVLINK_MSG_ID_AUTOPILOT_VERSION
            msg = self.tm.build(msg_id)
            if msg is not None:  # a position without an estimate is not sent
                self._send(msg)

    def _dispatch(self, cmd: int, p: list[float], p5: float, p6: float, p7: float) -> CommandOutcome:
        ap = self.ap
        if cmd == M.MAV_CMD_COMPONENT_ARM_DISARM:
            if p[0] not in (0.0, 1.0):
                return CommandOutcome(MAV_RESULT_DENIED)
            return ap.arm(p[0] == 1.0, force=p[1] == _FORCE_ARM_MAGIC)
        if cmd == M.MAV_CMD_DO_SET_MODE:
            return self._set_mode(p[0], p[1], p[2])
        if cmd == M.MAV_CMD_NAV_TAKEOFF:
            return ap.takeoff(self._takeoff_climb_m(p7))
        if cmd == M.MAV_CMD_NAV_LAND:
            return ap.land()
        if cmd == M.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            return ap.rtl()
        if cmd == M.MAV_CMD_REQUEST_MESSAGE:
            ok = math.isfinite(p[0]) and self.tm.can_build(int(p[0]))
            return CommandOutcome(MAV_RESULT_ACCEPTED if ok else MAV_RESULT_UNSUPPORTED)
        if cmd == M.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES:
            return CommandOutcome(MAV_RESULT_ACCEPTED)
        if cmd == M.MAV_CMD_INJECT_FAILURE and ap.flavour.name == "px4":
            if not all(math.isfinite(v) for v in p[:2]):
                return CommandOutcome(MAV_RESULT_DENIED)
            return ap.inject_failure(int(p[0]), int(p[1]))
        if cmd == M.MAV_CMD_SET_MESSAGE_INTERVAL:
            ok = math.isfinite(p[0]) and self.tm.set_interval(int(p[0]), p[1])
            return CommandOutcome(MAV_RESULT_ACCEPTED if ok else MAV_RESULT_UNSUPPORTED)
        return CommandOutcome(MAV_RESULT_UNSUPPORTED)

    def _takeoff_climb_m(self, p7: float) -> float | None:
        """NAV_TAKEOFF param7: PX4 reads it as AMSL altitude, ArduPilot as height above ground."""
        if not math.isfinite(p7):
            return None
        if self.ap.flavour.name == "px4":
            if p7 == 0.0:
                return None
            s = self.ap.vehicle.state
            return p7 - (self.tm.origin.alt_m + s.ground_height_m)
        return p7 if p7 > 0 else None

    def _set_mode(self, base: float, main: float, sub: float) -> CommandOutcome:
        if not all(math.isfinite(v) for v in (base, main)):
            return CommandOutcome(MAV_RESULT_DENIED)
        spec = self.ap.flavour.decode_set_mode(base, main, sub if math.isfinite(sub) else 0.0)
        if not isinstance(spec, ModeSpec):
            return CommandOutcome(spec)
        return self.ap.set_mode(spec)

    def _on_set_mode_msg(self, msg: Any) -> None:
        if int(msg.target_system) not in (0, self.system_id):
            self.ignored_foreign += 1
            return
        custom = int(msg.custom_mode)
        if self.ap.flavour.param_bytewise:
            outcome = self._set_mode(msg.base_mode, (custom >> 16) & 0xFF, (custom >> 24) & 0xFF)
        else:
            outcome = self._set_mode(msg.base_mode, custom, 0)
        self._ack(msg, M.MAVLINK_MSG_ID_SET_MODE, outcome.result)

    # ------------------------------------------------------------------ setpoints
    def _on_local_target(self, msg: Any) -> None:
        if not self._for_us(msg):
            return
        s = self.ap.estimated_state  # offsets are from where the autopilot believes it is
        try:
            sp, is_velocity = decode_local_ned_target(msg, self.ap.to_local(s.pos_ned_m), s.euler_rad[2])
        except SetpointError as exc:
            self._log.warning("setpoint refused: %s", exc)
            self.ap.reject_setpoint(str(exc))
            return
        self.ap.external_setpoint(self.ap.from_local(sp), is_velocity)

    # ------------------------------------------------------------------ parameters
    def _encode_param(self, name: str) -> float:
        value, ptype = self.ap.params[name], self._param_types[name]
        if ptype == MAV_PARAM_TYPE_REAL32 or not self.ap.flavour.param_bytewise:
            return float(value)
        return float(struct.unpack("<f", struct.pack("<i", int(value)))[0])

    def _decode_param(self, name: str, value: float, ptype: int) -> float:
        if ptype == MAV_PARAM_TYPE_REAL32 or not self.ap.flavour.param_bytewise:
            return float(value)
        return float(struct.unpack("<i", struct.pack("<f", value))[0])

    def _param_value(self, name: str) -> Any:
        return self._mav.param_value_encode(
            name.encode(),
            self._encode_param(name),
            self._param_types[name],
            len(self._param_index),
            self._param_index[name],
        )

    def _on_param_list(self, msg: Any) -> None:
        if self._for_us(msg):
            for name in self._param_index:
                self._send(self._param_value(name))

    def _on_param_read(self, msg: Any) -> None:
        if not self._for_us(msg):
            return
        index = int(msg.param_index)
        names = list(self._param_index)
        if index >= 0:
            name = names[index] if index < len(names) else None
        else:
            name = str(msg.param_id).rstrip("\x00")
        if name in self._param_index:
            self._send(self._param_value(name))
        # unknown parameters get no answer, as on PX4: the client's request times out

    def _on_param_set(self, msg: Any) -> None:
        if not self._for_us(msg):
            return
        name = str(msg.param_id).rstrip("\x00")
        if name not in self._param_index:
            self.ap.text_warning(f"Param {name} unknown")
            return
        value = self._decode_param(name, float(msg.param_value), int(msg.param_type))
        self.ap.set_param(name, value)
        self._send(self._param_value(name))  # echo the value in force, accepted or not

    # ------------------------------------------------------------------ precision landing
    def _on_landing_target(self, msg: Any) -> None:
        """LANDING_TARGET (addressed to no one). ArduPilot: x, y, z in body FRD with position_valid, else
        the angles (angle_x right, angle_y aft); other frames are refused as ArduCopter does ("Plnd: Frame
        not supported"). PX4: x, y, z in its local frame with position_valid (the landing target pose);
        another frame is refused as PX4 does; the angles alone would go to its IR-LOCK estimator, which
        simbridge's PX4 does not run."""
        if self.ap.flavour.name == "px4":
            if int(msg.position_valid) != 1:
                return
            if int(msg.frame) != mavlink2.MAV_FRAME_LOCAL_NED:
                self.ap.text_critical(f"landing target: coordinate frame {int(msg.frame)} unsupported")
                return
            self.ap.landing_target_local((float(msg.x), float(msg.y), float(msg.z)))
            return
        if int(msg.position_valid) == 1:
            if int(msg.frame) != mavlink2.MAV_FRAME_BODY_FRD:
                self.ap.text_warning("Plnd: Frame not supported")
                return
            los = (float(msg.x), float(msg.y), float(msg.z))
        else:
            los = (-math.tan(float(msg.angle_y)), math.tan(float(msg.angle_x)), 1.0)
        stamp_us = int(msg.time_usec)  # on the boot clock, as the companion stamps it; 0: none
        self.ap.landing_target(los, float(msg.distance), stamp_us / 1e6 if stamp_us > 0 else None)

    # ------------------------------------------------------------------ liveness
    def _on_ping(self, msg: Any) -> None:
        if int(msg.target_system) == 0 and int(msg.target_component) == 0:
            self._send(
                self._mav.ping_encode(msg.time_usec, msg.seq, msg.get_srcSystem(), msg.get_srcComponent())
            )

    def _on_timesync(self, msg: Any) -> None:
        if int(msg.tc1) == 0:
            now_ns = int(self.ap.vehicle.state.t_s * 1e9)
            self._send(self._mav.timesync_encode(now_ns, msg.ts1))
