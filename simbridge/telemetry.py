"""The messages an autopilot streams unasked, their builders, and the per-message scheduler.

Rates are in simulated time (a client sees them relative to ``time_boot_ms``) and can be changed
with SET_MESSAGE_INTERVAL.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from pymavlink.dialects.v20 import common as mavlink2

from simbridge.autopilot.flavours import PILOT_NAVS, Nav
from simbridge.control import THRUST_COEFF_N
from simbridge.geo import GeoOrigin
from simbridge.physics import MOTOR_COUNT

if TYPE_CHECKING:
    from simbridge.autopilot.core import Autopilot

M = mavlink2
MAV_TYPE_QUADROTOR = 2
MAV_STATE_STANDBY, MAV_STATE_ACTIVE, MAV_STATE_CRITICAL = 3, 4, 5
MAV_MODE_FLAG_CUSTOM_MODE_ENABLED = 1
MAV_MODE_FLAG_AUTO_ENABLED = 4
MAV_MODE_FLAG_GUIDED_ENABLED = 8
MAV_MODE_FLAG_STABILIZE_ENABLED = 16
MAV_MODE_FLAG_SAFETY_ARMED = 128
_PREARM_CHECK = 0x10000000  # MAV_SYS_STATUS_PREARM_CHECK
_SENSORS = (
    1
    | 2
    | 4
    | 8
    | 32  # gyro, accel, mag, baro, GPS
    | 1024
    | 2048
    | 4096
    | 8192
    | 16384
    | 32768  # rate, attitude, yaw, z, xy control, motors
    | 0x100000
    | 0x400000  # AHRS, laser position (rangefinder)
)
RANGEFINDER_MAX_CM = 20000  # the downward rangefinder's range, 0.1-200 m (real firmware too: sitl.py)
RANGEFINDER_MIN_CM = 10

# default stream intervals, seconds of simulated time
DEFAULT_INTERVALS_S: dict[int, float] = {
    M.MAVLINK_MSG_ID_HEARTBEAT: 1.0,
    M.MAVLINK_MSG_ID_SYS_STATUS: 0.5,
    M.MAVLINK_MSG_ID_BATTERY_STATUS: 1.0,
    M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: 0.2,
    M.MAVLINK_MSG_ID_HOME_POSITION: 2.0,
    M.MAVLINK_MSG_ID_ATTITUDE: 0.05,
    M.MAVLINK_MSG_ID_ATTITUDE_QUATERNION: 0.05,
    M.MAVLINK_MSG_ID_LOCAL_POSITION_NED: 0.05,
    M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: 0.1,
    M.MAVLINK_MSG_ID_GPS_RAW_INT: 0.2,
    M.MAVLINK_MSG_ID_VFR_HUD: 0.25,
    M.MAVLINK_MSG_ID_DISTANCE_SENSOR: 0.1,
    M.MAVLINK_MSG_ID_SYSTEM_TIME: 1.0,
}


# REQUEST_DATA_STREAM groups (MAV_DATA_STREAM_*) -> the messages simbridge builds, after ArduCopter's
# GCS stream groups
DATA_STREAMS: dict[int, tuple[int, ...]] = {
    2: (M.MAVLINK_MSG_ID_SYS_STATUS, M.MAVLINK_MSG_ID_GPS_RAW_INT, M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE),
    6: (M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, M.MAVLINK_MSG_ID_LOCAL_POSITION_NED),
    10: (M.MAVLINK_MSG_ID_ATTITUDE, M.MAVLINK_MSG_ID_ATTITUDE_QUATERNION),
    11: (M.MAVLINK_MSG_ID_VFR_HUD,),
    12: (M.MAVLINK_MSG_ID_SYSTEM_TIME, M.MAVLINK_MSG_ID_DISTANCE_SENSOR, M.MAVLINK_MSG_ID_BATTERY_STATUS,
         M.MAVLINK_MSG_ID_HOME_POSITION),
}  # fmt: skip
DATA_STREAMS[0] = tuple(m for ids in DATA_STREAMS.values() for m in ids)  # MAV_DATA_STREAM_ALL


def _cm_s(v_m_s: float) -> int:
    """A velocity in the int16 cm/s of GLOBAL_POSITION_INT, held to its range (a tumbling airframe,
    an estimate gone wild): a message out of range cannot be packed and would end the telemetry."""
    if not math.isfinite(v_m_s):
        return 0
    return max(-32767, min(32767, int(v_m_s * 100)))


def rangefinder_m(autopilot: Autopilot) -> float:
    """Downward rangefinder reading: distance along body +z to the first surface of the world."""
    s = autopilot.vehicle.state
    return autopilot.vehicle.physics.terrain.rangefinder_m(s.pos_ned_m, s.quat, RANGEFINDER_MAX_CM / 100)


class Telemetry:
    """Builds MAVLink messages from the autopilot's state and schedules the unasked streams."""

    def __init__(self, autopilot: Autopilot, origin: GeoOrigin, boot_unix_s: float | None = None) -> None:
        self.ap = autopilot
        self.origin = origin
        self._boot_unix_s = time.time() if boot_unix_s is None else boot_unix_s
        self._mav = mavlink2.MAVLink(None)  # only for *_encode helpers; never packs
        self._builders: dict[int, Callable[[], Any]] = {
            M.MAVLINK_MSG_ID_HEARTBEAT: self.heartbeat,
            M.MAVLINK_MSG_ID_SYS_STATUS: self.sys_status,
            M.MAVLINK_MSG_ID_BATTERY_STATUS: self.battery_status,
            M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: self.extended_sys_state,
            M.MAVLINK_MSG_ID_HOME_POSITION: self.home_position,
            M.MAVLINK_MSG_ID_ATTITUDE: self.attitude,
            M.MAVLINK_MSG_ID_ATTITUDE_QUATERNION: self.attitude_quaternion,
            M.MAVLINK_MSG_ID_LOCAL_POSITION_NED: self.local_position_ned,
            M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: self.global_position_int,
            M.MAVLINK_MSG_ID_GPS_RAW_INT: self.gps_raw_int,
            M.MAVLINK_MSG_ID_VFR_HUD: self.vfr_hud,
            M.MAVLINK_MSG_ID_DISTANCE_SENSOR: self.distance_sensor,
            M.MAVLINK_MSG_ID_SYSTEM_TIME: self.system_time,
            M.MAVLINK_MSG_ID_AUTOPILOT_VERSION: self.autopilot_version,
        }
        self._builders[M.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN] = self.gps_global_origin
        unasked = (
            DEFAULT_INTERVALS_S
            if autopilot.flavour.streams_unasked
            else {M.MAVLINK_MSG_ID_HEARTBEAT: DEFAULT_INTERVALS_S[M.MAVLINK_MSG_ID_HEARTBEAT]}
        )
        self._interval_s: dict[int, float] = dict(unasked)
        self._next_due_s: dict[int, float] = dict.fromkeys(self._interval_s, 0.0)

    # ------------------------------------------------------------------ scheduling
    def can_build(self, msg_id: int) -> bool:
        return msg_id in self._builders

    def build(self, msg_id: int) -> Any:
        return self._builders[msg_id]()

    def request_data_stream(self, stream_id: int, rate_hz: float, start: bool) -> bool:
        """The legacy REQUEST_DATA_STREAM (ArduPilot's SRn_ groups; MAVProxy and Mission Planner use it):
        every message of the group at ``rate_hz``; stopped when ``start`` is false or the rate is 0, as
        ArduPilot does."""
        ids = DATA_STREAMS.get(stream_id)
        if ids is None or not math.isfinite(rate_hz) or rate_hz < 0:
            return False
        for msg_id in ids:
            self.set_interval(msg_id, 1e6 / rate_hz if start and rate_hz > 0 else -1)
        return True

    def set_interval(self, msg_id: int, interval_us: float) -> bool:
        """SET_MESSAGE_INTERVAL semantics: -1 stops, 0 restores the default, else microseconds."""
        if msg_id not in self._builders or not math.isfinite(interval_us):
            return False
        if interval_us < 0:
            self._interval_s.pop(msg_id, None)
            self._next_due_s.pop(msg_id, None)
            return True
        if interval_us == 0:
            default = DEFAULT_INTERVALS_S.get(msg_id)
            if default is None:
                self._interval_s.pop(msg_id, None)
                self._next_due_s.pop(msg_id, None)
                return True
            interval_s = default
        else:
            interval_s = max(interval_us / 1e6, 0.005)
        self._interval_s[msg_id] = interval_s
        self._next_due_s.setdefault(msg_id, 0.0)
        return True

    def due(self, t_s: float) -> list[Any]:
        """Messages whose interval has elapsed at simulated time ``t_s``."""
        out = []
        for msg_id, due in self._next_due_s.items():
            if t_s >= due:
                interval = self._interval_s[msg_id]
                nxt = due + interval
                # after a stall (or a fresh stream) restart the cadence from now, never burst
                self._next_due_s[msg_id] = nxt if nxt > t_s else t_s + interval
                msg = self._builders[msg_id]()
                if msg is not None:  # None: nothing to say (a position without an estimate)
                    out.append(msg)
        return out

    # ------------------------------------------------------------------ helpers
    @property
    def time_boot_ms(self) -> int:
        return int(self.ap.vehicle.state.t_s * 1000)

    def _geo(self) -> tuple[int, int, int]:
        lat, lon, alt = self.origin.to_geodetic(*self.ap.vehicle.state.pos_ned_m)
        return round(lat * 1e7), round(lon * 1e7), round(alt * 1000)

    # ------------------------------------------------------------------ builders
    def heartbeat(self) -> Any:
        ap = self.ap
        base = MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | MAV_MODE_FLAG_STABILIZE_ENABLED
        if ap.mode.nav is not Nav.HOLD and ap.mode.nav not in PILOT_NAVS:
            base |= MAV_MODE_FLAG_GUIDED_ENABLED | MAV_MODE_FLAG_AUTO_ENABLED
        if ap.armed:
            base |= MAV_MODE_FLAG_SAFETY_ARMED
        status = MAV_STATE_CRITICAL if ap.failsafe else MAV_STATE_ACTIVE if ap.armed else MAV_STATE_STANDBY
        return self._mav.heartbeat_encode(
            MAV_TYPE_QUADROTOR, ap.flavour.autopilot_id, base, ap.mode.custom_mode, status
        )

    def sys_status(self) -> Any:
        """Sensor health, and the pre-arm check bit as PX4 and ArduPilot set it (what MAVSDK's
        ``Health.is_armable`` reads): healthy while the mode allows arming."""
        b = self.ap.vehicle.battery
        prearm = _PREARM_CHECK if self.ap.mode.armable else 0
        return self._mav.sys_status_encode(
            _SENSORS | _PREARM_CHECK,
            _SENSORS | _PREARM_CHECK,
            _SENSORS | prearm,
            250,
            int(b.voltage_v * 1000),
            int(b.current_a * 100),
            round(b.remaining_fraction * 100),
            0,
            0,
            0,
            0,
            0,
            0,
        )

    def battery_status(self) -> Any:
        b = self.ap.vehicle.battery
        cells = b.config.cells
        cell_mv = int(b.voltage_v * 1000 / cells)
        voltages = [cell_mv] * cells + [65535] * (10 - cells)
        return self._mav.battery_status_encode(
            0,
            0,
            1,
            32767,
            voltages,
            int(b.current_a * 100),
            int(b.consumed_mah),
            -1,
            round(b.remaining_fraction * 100),
        )

    def gps_global_origin(self) -> Any:
        """The EKF origin: home (where the estimator first had a position)."""
        lat, lon, alt = self.origin.to_geodetic(*self.ap.local_origin_ned_m)
        return self._mav.gps_global_origin_encode(
            round(lat * 1e7), round(lon * 1e7), round(alt * 1000), int(self.ap.vehicle.state.t_s * 1e6)
        )

    def extended_sys_state(self) -> Any:
        return self._mav.extended_sys_state_encode(0, self.ap.landed_state)

    def home_position(self) -> Any:
        hn, he, hd = self.ap.home_ned_m
        lat, lon, alt = self.origin.to_geodetic(hn, he, hd)
        x, y, z = self.ap.to_local(self.ap.home_ned_m)
        return self._mav.home_position_encode(
            round(lat * 1e7),
            round(lon * 1e7),
            round(alt * 1000),
            x,
            y,
            z,
            [1.0, 0.0, 0.0, 0.0],
            0.0,
            0.0,
            0.0,
            int(self.ap.vehicle.state.t_s * 1e6),
        )

    def attitude(self) -> Any:
        s = self.ap.estimated_state
        r, p, y = s.euler_rad
        return self._mav.attitude_encode(
            self.time_boot_ms, r, p, math.remainder(y, 2 * math.pi), *s.rates_frd_rad_s
        )

    def attitude_quaternion(self) -> Any:
        s = self.ap.estimated_state
        return self._mav.attitude_quaternion_encode(self.time_boot_ms, *s.quat, *s.rates_frd_rad_s)

    def local_position_ned(self) -> Any:
        if not self.ap.position_valid:
            return None
        s = self.ap.estimated_state
        local = self.ap.to_local(s.pos_ned_m)  # relative to the EKF origin (home), as real autopilots
        return self._mav.local_position_ned_encode(self.time_boot_ms, *local, *s.vel_ned_m_s)

    def global_position_int(self) -> Any:
        if not self.ap.position_valid:
            return None
        s = self.ap.estimated_state
        lat, lon, alt_mm = self._geo()
        home_alt_m = self.origin.alt_m - self.ap.home_ned_m[2]
        vn, ve, vd = s.vel_ned_m_s
        hdg = round(math.degrees(s.euler_rad[2]) * 100) % 36000
        return self._mav.global_position_int_encode(
            self.time_boot_ms,
            lat,
            lon,
            alt_mm,
            round(alt_mm - home_alt_m * 1000),
            _cm_s(vn),
            _cm_s(ve),
            _cm_s(vd),
            hdg,
        )

    def gps_raw_int(self) -> Any:
        s = self.ap.estimated_state
        lat, lon, alt_mm = self._geo()
        vn, ve, _ = s.vel_ned_m_s
        cog = round(math.degrees(math.atan2(ve, vn)) * 100) % 36000
        if not self.ap.gps_enabled:  # no fix: nothing but the time
            return self._mav.gps_raw_int_encode(int(s.t_s * 1e6), 0, 0, 0, 0, 65535, 65535, 65535, 65535, 0)
        return self._mav.gps_raw_int_encode(
            int(s.t_s * 1e6),
            3,
            lat,
            lon,
            alt_mm,
            80,
            120,
            int(math.hypot(vn, ve) * 100),
            cog,
            16,
        )

    def vfr_hud(self) -> Any:
        s = self.ap.estimated_state
        vn, ve, vd = s.vel_ned_m_s
        gs = math.hypot(vn, ve)
        max_thrust_n = MOTOR_COUNT * THRUST_COEFF_N  # all four ESCs at full command
        throttle = int(min(100, max(0, 100 * s.thrust_n / max_thrust_n)))
        heading = round(math.degrees(s.euler_rad[2])) % 360
        return self._mav.vfr_hud_encode(gs, gs, heading, throttle, self.origin.alt_m - s.pos_ned_m[2], -vd)

    def distance_sensor(self) -> Any:
        cm = round(rangefinder_m(self.ap) * 100)
        cm = min(max(cm, RANGEFINDER_MIN_CM), RANGEFINDER_MAX_CM)
        return self._mav.distance_sensor_encode(
            self.time_boot_ms,
            RANGEFINDER_MIN_CM,
            RANGEFINDER_MAX_CM,
            cm,
            0,
            0,
            M.MAV_SENSOR_ROTATION_PITCH_270,
            0,
        )

    def system_time(self) -> Any:
        t = self.ap.vehicle.state.t_s
        return self._mav.system_time_encode(int((self._boot_unix_s + t) * 1e6), int(t * 1000))

    def autopilot_version(self) -> Any:
        ap = self.ap
        caps = (
            M.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
            | M.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
            | M.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
            | M.MAV_PROTOCOL_CAPABILITY_MAVLINK2
        )
        if ap.flavour.param_bytewise:
            caps |= M.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE
            version = (1 << 24) | (15 << 16) | (0 << 8) | 255  # PX4 v1.15.0 official
        else:
            caps |= M.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST
            version = (4 << 24) | (5 << 16) | (0 << 8) | 255  # ArduCopter 4.5.0 official
        return self._mav.autopilot_version_encode(
            caps,
            version,
            0,
            0,
            0,
            [0] * 8,
            [0] * 8,
            [0] * 8,
            0,
            0,
            0x5349_4D42_5249_4447,  # "SIMBRIDG"
        )
