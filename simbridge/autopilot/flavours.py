"""What differs between PX4 and ArduPilot as seen over MAVLink: mode numbers, parameters,
arming and offboard rules. The flight behaviour itself lives in :mod:`simbridge.autopilot.core`.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass
from typing import ClassVar

from simbridge.control import ControlLimits

# MAVLink enum values used here (common.xml)
MAV_AUTOPILOT_ARDUPILOTMEGA = 3
MAV_AUTOPILOT_PX4 = 12
MAV_PARAM_TYPE_INT32 = 6
MAV_PARAM_TYPE_REAL32 = 9
MAV_RESULT_ACCEPTED = 0
MAV_RESULT_TEMPORARILY_REJECTED = 1
MAV_RESULT_DENIED = 2
MAV_RESULT_UNSUPPORTED = 3
MAV_RESULT_FAILED = 4


class Nav(enum.Enum):
    """Flight behaviour behind a mode."""

    HOLD = "hold"  # hold the position where the mode was entered (brake first)
    TAKEOFF = "takeoff"
    LAND = "land"
    RTL = "rtl"
    EXTERNAL = "external"  # follow setpoints from a companion/GCS (OFFBOARD, GUIDED)
    # flown by a pilot's sticks; simulated with no transmitter they rest centred, the throttle at its
    # minimum (ArduCopter SITL's RC3 = 1000):
    PILOT_THRUST = "pilot_thrust"  # STABILIZE, ACRO: attitude level, the motors at minimum thrust
    PILOT_ALT = "pilot_alt"  # ALT_HOLD: attitude level, descending at the pilot's full down speed
    PILOT_POS = "pilot_pos"  # POSHOLD: the same descent, holding its position


PILOT_NAVS = frozenset({Nav.PILOT_THRUST, Nav.PILOT_ALT, Nav.PILOT_POS})


@dataclass(frozen=True, slots=True)
class ModeSpec:
    name: str
    nav: Nav
    custom_mode: int
    armable: bool = True


@dataclass(frozen=True, slots=True)
class Param:
    name: str
    default: float
    type: int  # MAV_PARAM_TYPE_*


@dataclass(frozen=True, slots=True)
class Tunables:
    """Parameter values turned into the units the flight core uses."""

    limits: ControlLimits
    takeoff_alt_m: float
    land_speed_m_s: float
    land_slow_below_m: float
    rtl_alt_m: float
    disarm_after_land_s: float
    disarm_preflight_s: float
    offboard_loss_s: float | None  # None: no offboard-loss failsafe (ArduPilot position targets)
    offboard_loss_mode: str | None
    velocity_target_timeout_s: float | None
    fence_radius_m: float
    fence_alt_m: float
    # climb and descent rates at full stick in the pilot's altitude-holding modes (ArduPilot)
    pilot_speed_up_m_s: float = 0.0
    pilot_speed_down_m_s: float = 0.0


class Flavour:
    """Base for the two autopilot flavours."""

    name: str
    autopilot_id: int
    modes: tuple[ModeSpec, ...]
    params: tuple[Param, ...]
    air_start_mode: str
    ground_start_mode: str
    after_takeoff_mode: str | None  # None: stay in the mode that took off
    offboard_needs_stream: bool
    # MAVLink PARAM_VALUE encoding of integer parameters: PX4 copies the bytes, ArduPilot casts
    param_bytewise: bool
    # PX4 streams its telemetry unasked; ArduPilot sends heartbeats only until a ground station asks
    # (SET_MESSAGE_INTERVAL or REQUEST_DATA_STREAM), as real ArduCopter on a fresh serial port does
    streams_unasked: bool = True

    def mode(self, name: str) -> ModeSpec:
        for m in self.modes:
            if m.name == name:
                return m
        raise KeyError(f"{self.name} has no mode {name!r}")

    def mode_for_custom(self, custom_mode: int) -> ModeSpec | None:
        for m in self.modes:
            if m.custom_mode == custom_mode:
                return m
        return None

    def decode_set_mode(self, base_mode: float, main: float, sub: float) -> ModeSpec | int:
        """DO_SET_MODE params -> a mode, or the MAV_RESULT that refuses the request."""
        raise NotImplementedError

    def tunables(self, p: dict[str, float]) -> Tunables:
        raise NotImplementedError

    def external_mode_name(self) -> str:
        return next(m.name for m in self.modes if m.nav is Nav.EXTERNAL)


def _px4_custom(main: int, sub: int = 0) -> int:
    return (main << 16) | (sub << 24)


class Px4Flavour(Flavour):
    name = "px4"
    autopilot_id = MAV_AUTOPILOT_PX4
    modes = (
        ModeSpec("POSCTL", Nav.HOLD, _px4_custom(3)),
        ModeSpec("AUTO.TAKEOFF", Nav.TAKEOFF, _px4_custom(4, 2)),
        ModeSpec("AUTO.LOITER", Nav.HOLD, _px4_custom(4, 3)),
        ModeSpec("AUTO.RTL", Nav.RTL, _px4_custom(4, 5), armable=False),
        ModeSpec("AUTO.LAND", Nav.LAND, _px4_custom(4, 6), armable=False),
        ModeSpec("OFFBOARD", Nav.EXTERNAL, _px4_custom(6)),
    )
    params = (
        Param("MIS_TAKEOFF_ALT", 2.5, MAV_PARAM_TYPE_REAL32),
        Param("COM_OF_LOSS_T", 1.0, MAV_PARAM_TYPE_REAL32),
        Param("COM_OBL_RC_ACT", 0, MAV_PARAM_TYPE_INT32),
        Param("COM_DISARM_LAND", 2.0, MAV_PARAM_TYPE_REAL32),
        Param("COM_DISARM_PRFLT", 10.0, MAV_PARAM_TYPE_REAL32),
        Param("MPC_XY_VEL_MAX", 5.0, MAV_PARAM_TYPE_REAL32),
        Param("MPC_Z_VEL_MAX_UP", 3.0, MAV_PARAM_TYPE_REAL32),
        Param("MPC_Z_VEL_MAX_DN", 1.5, MAV_PARAM_TYPE_REAL32),
        Param("MPC_TILTMAX_AIR", 35.0, MAV_PARAM_TYPE_REAL32),
        Param("MPC_ACC_HOR", 3.0, MAV_PARAM_TYPE_REAL32),
        Param("MPC_LAND_SPEED", 0.7, MAV_PARAM_TYPE_REAL32),
        Param("MPC_LAND_ALT2", 5.0, MAV_PARAM_TYPE_REAL32),
        Param("RTL_RETURN_ALT", 60.0, MAV_PARAM_TYPE_REAL32),
        Param("GF_MAX_HOR_DIST", 2000.0, MAV_PARAM_TYPE_REAL32),
        Param("GF_MAX_VER_DIST", 500.0, MAV_PARAM_TYPE_REAL32),
    )
    air_start_mode = "AUTO.LOITER"
    ground_start_mode = "AUTO.LOITER"
    after_takeoff_mode = "AUTO.LOITER"
    offboard_needs_stream = True
    param_bytewise = True

    # COM_OBL_RC_ACT: 0 position, 1 altitude, 2 manual, 3 return, 4 land, 5 hold. Real PX4 1.15 in
    # SITL with no RC switches to POSCTL for 0 (and holds there: the sticks rest centred); the other
    # manual-ish choices hold too, here.
    _OBL_ACTIONS: ClassVar[dict[int, str]] = {0: "POSCTL", 3: "AUTO.RTL", 4: "AUTO.LAND"}
    _MANUAL_MAIN: ClassVar[dict[int, str]] = {
        1: "MANUAL",
        2: "ALTCTL",
        5: "ACRO",
        7: "STABILIZED",
        8: "RATTITUDE",
    }

    def decode_set_mode(self, base_mode: float, main: float, sub: float) -> ModeSpec | int:
        if not (int(base_mode) & 1):
            return MAV_RESULT_UNSUPPORTED  # only custom modes are meaningful on PX4
        main_i, sub_i = int(main), int(sub)
        if main_i in self._MANUAL_MAIN:
            return MAV_RESULT_DENIED  # no RC link in simulation: manual modes cannot be flown
        custom = _px4_custom(main_i, sub_i if main_i == 4 else 0)
        spec = self.mode_for_custom(custom)
        return spec if spec is not None else MAV_RESULT_UNSUPPORTED

    def tunables(self, p: dict[str, float]) -> Tunables:
        return Tunables(
            limits=ControlLimits(
                max_speed_xy_m_s=p["MPC_XY_VEL_MAX"],
                max_speed_up_m_s=p["MPC_Z_VEL_MAX_UP"],
                max_speed_down_m_s=p["MPC_Z_VEL_MAX_DN"],
                max_tilt_rad=math.radians(p["MPC_TILTMAX_AIR"]),
                max_accel_xy_m_s2=p["MPC_ACC_HOR"],
            ),
            takeoff_alt_m=p["MIS_TAKEOFF_ALT"],
            land_speed_m_s=p["MPC_LAND_SPEED"],
            land_slow_below_m=p["MPC_LAND_ALT2"],
            rtl_alt_m=p["RTL_RETURN_ALT"],
            disarm_after_land_s=p["COM_DISARM_LAND"],
            disarm_preflight_s=p["COM_DISARM_PRFLT"],
            offboard_loss_s=p["COM_OF_LOSS_T"],
            offboard_loss_mode=self._OBL_ACTIONS.get(int(p["COM_OBL_RC_ACT"]), "AUTO.LOITER"),
            velocity_target_timeout_s=None,
            fence_radius_m=p["GF_MAX_HOR_DIST"],
            fence_alt_m=p["GF_MAX_VER_DIST"],
        )


class ArduPilotFlavour(Flavour):
    name = "ardupilot"
    autopilot_id = MAV_AUTOPILOT_ARDUPILOTMEGA
    modes = (
        ModeSpec("GUIDED", Nav.EXTERNAL, 4),
        ModeSpec("LOITER", Nav.HOLD, 5),
        ModeSpec("RTL", Nav.RTL, 6, armable=False),
        ModeSpec("LAND", Nav.LAND, 9, armable=False),
        ModeSpec("BRAKE", Nav.HOLD, 17, armable=False),
        ModeSpec("STABILIZE", Nav.PILOT_THRUST, 0),
        ModeSpec("ACRO", Nav.PILOT_THRUST, 1),
        ModeSpec("ALT_HOLD", Nav.PILOT_ALT, 2),
        ModeSpec("POSHOLD", Nav.PILOT_POS, 16),
    )
    params = (
        Param("WPNAV_SPEED", 500.0, MAV_PARAM_TYPE_REAL32),
        Param("WPNAV_SPEED_UP", 300.0, MAV_PARAM_TYPE_REAL32),
        Param("WPNAV_SPEED_DN", 150.0, MAV_PARAM_TYPE_REAL32),
        Param("WPNAV_ACCEL", 300.0, MAV_PARAM_TYPE_REAL32),
        Param("ANGLE_MAX", 3500.0, MAV_PARAM_TYPE_INT32),
        Param("LAND_SPEED", 50.0, MAV_PARAM_TYPE_INT32),
        Param("LAND_ALT_LOW", 1000.0, MAV_PARAM_TYPE_INT32),
        Param("RTL_ALT", 1500.0, MAV_PARAM_TYPE_INT32),
        Param("DISARM_DELAY", 10.0, MAV_PARAM_TYPE_INT32),
        Param("GUID_TIMEOUT", 3.0, MAV_PARAM_TYPE_REAL32),
        Param("FENCE_RADIUS", 2000.0, MAV_PARAM_TYPE_REAL32),
        Param("FENCE_ALT_MAX", 500.0, MAV_PARAM_TYPE_REAL32),
        Param("PILOT_SPEED_UP", 250.0, MAV_PARAM_TYPE_INT32),
        Param("PILOT_SPEED_DN", 0.0, MAV_PARAM_TYPE_INT32),  # 0: PILOT_SPEED_UP
    )
    air_start_mode = "LOITER"
    ground_start_mode = "LOITER"
    after_takeoff_mode = None
    offboard_needs_stream = False
    param_bytewise = False
    streams_unasked = False

    # ArduCopter 4.7 as built for SITL has no SPORT: "No such mode 13", FAILED
    # (tests/test_firmware_parity.py); AUTO without a mission is refused
    _NOT_BUILT: ClassVar[frozenset[int]] = frozenset({13})
    _NO_MISSION: ClassVar[dict[int, str]] = {3: "AUTO"}

    def decode_set_mode(self, base_mode: float, main: float, sub: float) -> ModeSpec | int:
        mode_number = int(main)
        if mode_number in self._NOT_BUILT:
            return MAV_RESULT_FAILED
        if mode_number in self._NO_MISSION:
            return MAV_RESULT_DENIED
        spec = self.mode_for_custom(mode_number)
        return spec if spec is not None else MAV_RESULT_UNSUPPORTED

    def tunables(self, p: dict[str, float]) -> Tunables:
        return Tunables(
            limits=ControlLimits(
                max_speed_xy_m_s=p["WPNAV_SPEED"] / 100,
                max_speed_up_m_s=p["WPNAV_SPEED_UP"] / 100,
                max_speed_down_m_s=p["WPNAV_SPEED_DN"] / 100,
                max_tilt_rad=math.radians(p["ANGLE_MAX"] / 100),
                max_accel_xy_m_s2=p["WPNAV_ACCEL"] / 100,
            ),
            takeoff_alt_m=2.5,
            land_speed_m_s=p["LAND_SPEED"] / 100,
            land_slow_below_m=p["LAND_ALT_LOW"] / 100,
            rtl_alt_m=p["RTL_ALT"] / 100,
            disarm_after_land_s=0.0,
            disarm_preflight_s=p["DISARM_DELAY"],
            offboard_loss_s=None,
            offboard_loss_mode=None,
            velocity_target_timeout_s=p["GUID_TIMEOUT"],
            fence_radius_m=p["FENCE_RADIUS"],
            fence_alt_m=p["FENCE_ALT_MAX"],
            pilot_speed_up_m_s=abs(p["PILOT_SPEED_UP"]) / 100,
            # ArduCopter: PILOT_SPEED_DN 0 means "as PILOT_SPEED_UP"
            pilot_speed_down_m_s=abs(p["PILOT_SPEED_DN"] or p["PILOT_SPEED_UP"]) / 100,
        )


def flavour_named(name: str) -> Flavour:
    """``"px4"`` or ``"ardupilot"`` -> the flavour object."""
    if name == "px4":
        return Px4Flavour()
    if name == "ardupilot":
        return ArduPilotFlavour()
    raise ValueError(f"unknown autopilot flavour {name!r}; expected 'px4' or 'ardupilot'")
