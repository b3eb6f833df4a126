"""What differs between PX4 and ArduPilot as seen over MAVLink: mode numbers, parameters,
arming and offboard rules. The flight behaviour itself lives in :mod:`simbridge.autopilot.core`.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass
from typing import ClassVar

from simbridge.autopilot.precland import PrecLandTune
from simbridge.battery import Battery
from simbridge.control import ControlLimits

# MAVLink enum values used here (common.xml)
MAV_AUTOPILOT_ARDUPILOTMEGA = 3
MAV_AUTOPILOT_PX4 = 12
MAV_PARAM_TYPE_INT8 = 2
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
    # PX4's ALTCTL with no RC (COM_RC_IN_MODE 4: the sticks rest centred): level, holding the altitude,
    # drifting; where real PX4's fallback ends when the estimator has no position
    ALT_DRIFT = "alt_drift"


PILOT_NAVS = frozenset({Nav.PILOT_THRUST, Nav.PILOT_ALT, Nav.PILOT_POS})
# what cannot be flown without a horizontal position estimate
NEEDS_POSITION = frozenset({Nav.HOLD, Nav.TAKEOFF, Nav.RTL, Nav.EXTERNAL, Nav.PILOT_POS})

# battery warning levels (PX4's battery_status warning, ArduPilot's low/critical)
BATTERY_OK, BATTERY_LOW, BATTERY_CRITICAL, BATTERY_EMERGENCY = 0, 1, 2, 3
BATTERY_LEVEL_NAMES = {BATTERY_LOW: "low", BATTERY_CRITICAL: "critical", BATTERY_EMERGENCY: "emergency"}


@dataclass(frozen=True, slots=True)
class BatteryReaction:
    """What the autopilot does at a battery warning level: says ``text``; then, ``delay_s`` later,
    switches to ``mode`` in a failsafe (None: a warning only), holding in ``hold_first`` meanwhile."""

    text: str
    mode: str | None
    delay_s: float = 0.0
    hold_first: str | None = None


@dataclass(frozen=True, slots=True)
class ModeSpec:
    name: str
    nav: Nav
    custom_mode: int
    armable: bool = True
    precision: bool = False  # a landing on a companion's target in a mode of its own (PX4's AUTO.PRECLAND)


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

    def battery_level(self, p: dict[str, float], battery: Battery) -> int:
        """The battery warning level (``BATTERY_*``) the autopilot's parameters give the pack."""
        raise NotImplementedError

    def battery_reaction(self, p: dict[str, float], level: int, battery: Battery) -> BatteryReaction:
        raise NotImplementedError

    def position_lost(self, p: dict[str, float]) -> tuple[float, str | None]:
        """(seconds without GPS before the estimator's position is gone, the failsafe's mode then:
        None keeps the mode)."""
        raise NotImplementedError

    def fence_breach_action(self, p: dict[str, float]) -> tuple[bool, str | None]:
        """(whether a breach of the fence around home is acted on at all, the failsafe's mode: None
        reports it only). Base: not emulated (targets beyond the fence are refused all the same)."""
        return False, None

    def precision_landing(self, p: dict[str, float]) -> PrecisionLandingTune | None:
        """How land mode follows a companion's LANDING_TARGET; None: it does not (PX4's precision
        landing is a mode of its own: :meth:`precland`)."""
        return None

    def precland(self, p: dict[str, float]) -> PrecLandTune | None:
        """PX4's AUTO.PRECLAND (:mod:`simbridge.autopilot.precland`); None: no such mode."""
        return None

    def external_mode_name(self) -> str:
        return next(m.name for m in self.modes if m.nav is Nav.EXTERNAL)


@dataclass(frozen=True, slots=True)
class PrecisionLandingTune:
    """ArduCopter's precision landing as land mode flies it: measurements are taken between
    ``alt_min_m`` and ``alt_max_m`` above the ground; the descent waits while the target is farther
    than ``xy_dist_max_m`` across (0: never waits); a target unheard for ``timeout_s`` is lost."""

    alt_min_m: float
    alt_max_m: float
    xy_dist_max_m: float
    timeout_s: float = 1.0  # AC_PrecLand's backends drop a line of sight older than 1 s


def _px4_custom(main: int, sub: int = 0) -> int:
    return (main << 16) | (sub << 24)


class Px4Flavour(Flavour):
    name = "px4"
    autopilot_id = MAV_AUTOPILOT_PX4
    modes = (
        ModeSpec("ALTCTL", Nav.ALT_DRIFT, _px4_custom(2)),  # entered by the failsafe only (no RC)
        ModeSpec("POSCTL", Nav.HOLD, _px4_custom(3)),
        ModeSpec("AUTO.TAKEOFF", Nav.TAKEOFF, _px4_custom(4, 2)),
        ModeSpec("AUTO.LOITER", Nav.HOLD, _px4_custom(4, 3)),
        ModeSpec("AUTO.RTL", Nav.RTL, _px4_custom(4, 5), armable=False),
        ModeSpec("AUTO.LAND", Nav.LAND, _px4_custom(4, 6), armable=False),
        ModeSpec("AUTO.PRECLAND", Nav.LAND, _px4_custom(4, 9), armable=False, precision=True),
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
        # the battery failsafe (PX4 1.15 defaults: warnings only)
        Param("BAT_LOW_THR", 0.15, MAV_PARAM_TYPE_REAL32),
        Param("BAT_CRIT_THR", 0.07, MAV_PARAM_TYPE_REAL32),
        Param("BAT_EMERGEN_THR", 0.05, MAV_PARAM_TYPE_REAL32),
        Param("COM_LOW_BAT_ACT", 0, MAV_PARAM_TYPE_INT32),
        Param("COM_BAT_ACT_T", 5.0, MAV_PARAM_TYPE_REAL32),
        # the estimator without GPS (EKF2_NOAID_TOUT, microseconds) and failure injection
        # (MAV_CMD_INJECT_FAILURE needs SYS_FAILURE_EN 1, as on real PX4)
        Param("EKF2_NOAID_TOUT", 5000000, MAV_PARAM_TYPE_INT32),
        Param("SYS_FAILURE_EN", 0, MAV_PARAM_TYPE_INT32),
        # precision land (navigator's precland, AUTO.PRECLAND; simbridge.autopilot.precland): PX4's
        # defaults but PLD_MAX_SRCH, 0 on simbridge's vehicle as on its real PX4 (simbridge.px4_sitl.PARAMS;
        # PX4 ships 3): a lost target lands where the vehicle is
        Param("PLD_BTOUT", 5.0, MAV_PARAM_TYPE_REAL32),
        Param("PLD_HACC_RAD", 0.2, MAV_PARAM_TYPE_REAL32),
        Param("PLD_FAPPR_ALT", 0.1, MAV_PARAM_TYPE_REAL32),
        Param("PLD_SRCH_ALT", 10.0, MAV_PARAM_TYPE_REAL32),
        Param("PLD_SRCH_TOUT", 10.0, MAV_PARAM_TYPE_REAL32),
        Param("PLD_MAX_SRCH", 0, MAV_PARAM_TYPE_INT32),
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

    def precland(self, p: dict[str, float]) -> PrecLandTune | None:
        return PrecLandTune(
            p["PLD_BTOUT"], p["PLD_HACC_RAD"], p["PLD_FAPPR_ALT"], p["PLD_SRCH_ALT"], p["PLD_SRCH_TOUT"],
            round(p["PLD_MAX_SRCH"]),
        )  # fmt: skip

    def decode_set_mode(self, base_mode: float, main: float, sub: float) -> ModeSpec | int:
        if not (int(base_mode) & 1):
            return MAV_RESULT_UNSUPPORTED  # only custom modes are meaningful on PX4
        main_i, sub_i = int(main), int(sub)
        if main_i in self._MANUAL_MAIN:
            return MAV_RESULT_DENIED  # no RC link in simulation: manual modes cannot be flown
        custom = _px4_custom(main_i, sub_i if main_i == 4 else 0)
        spec = self.mode_for_custom(custom)
        return spec if spec is not None else MAV_RESULT_UNSUPPORTED

    # COM_LOW_BAT_ACT: 0 warning, 1 return, 2 land, 3 return at critical, land at emergency
    # (failsafe.cpp, fromBatteryWarningActParam); a low level is always a warning
    _BAT_ACTIONS: ClassVar[dict[int, dict[int, str]]] = {
        1: {BATTERY_CRITICAL: "AUTO.RTL", BATTERY_EMERGENCY: "AUTO.RTL"},
        2: {BATTERY_CRITICAL: "AUTO.LAND", BATTERY_EMERGENCY: "AUTO.LAND"},
        3: {BATTERY_CRITICAL: "AUTO.RTL", BATTERY_EMERGENCY: "AUTO.LAND"},
    }
    _BAT_TEXTS: ClassVar[dict[int, str]] = {
        BATTERY_LOW: "Low battery level, return advised",
        BATTERY_CRITICAL: "Critical battery level, landing advised",
        BATTERY_EMERGENCY: "Emergency battery level, land immediately",
    }

    def battery_level(self, p: dict[str, float], battery: Battery) -> int:
        left = battery.remaining_fraction
        for level, name in ((BATTERY_EMERGENCY, "BAT_EMERGEN_THR"), (BATTERY_CRITICAL, "BAT_CRIT_THR")):
            if left < p[name]:
                return level
        return BATTERY_LOW if left < p["BAT_LOW_THR"] else BATTERY_OK

    def battery_reaction(self, p: dict[str, float], level: int, battery: Battery) -> BatteryReaction:
        mode = self._BAT_ACTIONS.get(int(p["COM_LOW_BAT_ACT"]), {}).get(level)
        delay = p["COM_BAT_ACT_T"]
        # real PX4 1.15 in SITL held in AUTO.LOITER (failsafe) before its battery action
        # (tests/test_autopilot_failsafes.py)
        hold = "AUTO.LOITER" if mode is not None and delay > 0 else None
        return BatteryReaction(self._BAT_TEXTS[level], mode, delay, hold)

    def position_lost(self, p: dict[str, float]) -> tuple[float, str | None]:
        # EKF2 dead-reckons for EKF2_NOAID_TOUT; then no mode that needs a position can run, and real
        # PX4 1.15 in OFFBOARD fell back to ALTCTL (tests/test_autopilot_failsafes.py)
        return p["EKF2_NOAID_TOUT"] / 1e6, "ALTCTL"

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
        Param("PSC_JERK_XY", 5.0, MAV_PARAM_TYPE_REAL32),
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
        # the battery failsafe (ArduCopter's defaults: a low-voltage warning for a 3S pack, no action;
        # simbridge's pack is 4S, so nothing fires unless these are set)
        Param("BATT_LOW_VOLT", 10.5, MAV_PARAM_TYPE_REAL32),
        Param("BATT_CRT_VOLT", 0.0, MAV_PARAM_TYPE_REAL32),
        Param("BATT_LOW_MAH", 0.0, MAV_PARAM_TYPE_REAL32),
        Param("BATT_CRT_MAH", 0.0, MAV_PARAM_TYPE_REAL32),
        Param("BATT_FS_LOW_ACT", 0, MAV_PARAM_TYPE_INT32),
        Param("BATT_FS_CRT_ACT", 0, MAV_PARAM_TYPE_INT32),
        # the EKF failsafe (FS_EKF_ACTION: 1 land, 2 AltHold, 3 land even in STABILIZE) and SITL's own
        # GPS switch, SIM_GPS1_ENABLE, as real ArduCopter SITL has it (0: the GPS stops; GPS1_TYPE 0 too)
        Param("FS_EKF_ACTION", 1, MAV_PARAM_TYPE_INT32),
        # the fence's breach (ArduCopter's defaults: disabled; when enabled, RTL or land)
        Param("FENCE_ENABLE", 0, MAV_PARAM_TYPE_INT32),
        Param("FENCE_ACTION", 1, MAV_PARAM_TYPE_INT32),
        # as the firmware ships them (7: altitude, circle and polygon; 2 m), for a companion to read:
        # the emulation keeps its circle and altitude whatever they say, and has no polygon
        Param("FENCE_TYPE", 7, MAV_PARAM_TYPE_INT8),
        Param("FENCE_MARGIN", 2.0, MAV_PARAM_TYPE_REAL32),
        Param("SIM_GPS1_ENABLE", 1, MAV_PARAM_TYPE_INT32),
        # the first GPS's driver (1: auto-detect; 0: none, which ArduCopter reads at every update)
        Param("GPS1_TYPE", 1, MAV_PARAM_TYPE_INT8),
        # precision landing on a companion's LANDING_TARGET: ArduCopter ships with it off
        # (PLND_ENABLED 0, PLND_TYPE 0); simbridge's vehicle is set up for Landfall's (as the SITL
        # runs with simbridge.sitl.PARAMS); PLND_ALT_MIN / MAX and PLND_XY_DIST_MAX as the firmware's
        Param("PLND_ENABLED", 1, MAV_PARAM_TYPE_INT8),
        Param("PLND_TYPE", 1, MAV_PARAM_TYPE_INT8),
        Param("PLND_ALT_MIN", 0.75, MAV_PARAM_TYPE_REAL32),
        Param("PLND_ALT_MAX", 8.0, MAV_PARAM_TYPE_REAL32),
        Param("PLND_XY_DIST_MAX", 2.5, MAV_PARAM_TYPE_REAL32),
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

    # BATT_FS_*_ACT: 0 none, 1 land, 2 RTL, 3 SmartRTL or RTL, 4 SmartRTL or land, 5 terminate,
    # 6 DO_LAND_START or RTL, 7 brake or land. The emulation has no SmartRTL path, no mission and no
    # terminate: 3 and 6 fly RTL, 4 and 7 land (ArduCopter's own fallbacks), 5 is a warning only.
    _BATT_ACTIONS: ClassVar[dict[int, str]] = {1: "LAND", 2: "RTL", 3: "RTL", 4: "LAND", 6: "RTL", 7: "LAND"}

    def battery_level(self, p: dict[str, float], battery: Battery) -> int:
        """ArduCopter's two levels, by remaining capacity (``BATT_*_MAH``) or resting voltage
        (``BATT_*_VOLT``); 0 disables a threshold."""
        left_mah = battery.config.capacity_mah - battery.consumed_mah
        volts = battery.voltage_v
        for level, mah, volt in (
            (BATTERY_CRITICAL, p["BATT_CRT_MAH"], p["BATT_CRT_VOLT"]),
            (BATTERY_LOW, p["BATT_LOW_MAH"], p["BATT_LOW_VOLT"]),
        ):
            if (mah > 0 and left_mah < mah) or (volt > 0 and volts < volt):
                return level
        return BATTERY_OK

    def battery_reaction(self, p: dict[str, float], level: int, battery: Battery) -> BatteryReaction:
        act = p["BATT_FS_CRT_ACT"] if level >= BATTERY_CRITICAL else p["BATT_FS_LOW_ACT"]
        text = (
            f"Battery 1 is {BATTERY_LEVEL_NAMES[min(level, BATTERY_CRITICAL)]} {battery.voltage_v:.2f}V "
            f"used {battery.consumed_mah:.0f} mAh"
        )
        return BatteryReaction(text, self._BATT_ACTIONS.get(int(act)))

    # ArduCopter's EKF failsafe: its variances over FS_EKF_THRESH for a second; without GPS that takes
    # a few seconds of dead reckoning (2 s here)
    _EKF_FS_S = 2.0
    _EKF_ACTIONS: ClassVar[dict[int, str]] = {1: "LAND", 2: "ALT_HOLD", 3: "LAND"}

    def position_lost(self, p: dict[str, float]) -> tuple[float, str | None]:
        return self._EKF_FS_S, self._EKF_ACTIONS.get(int(p["FS_EKF_ACTION"]))

    # FENCE_ACTION: 0 report only, 1 RTL or land, 2 always land, 3 SmartRTL or RTL or land, 4 brake or
    # land, 5 SmartRTL or land (no SmartRTL path here: its fallbacks)
    _FENCE_ACTIONS: ClassVar[dict[int, str]] = {1: "RTL", 2: "LAND", 3: "RTL", 4: "BRAKE", 5: "LAND"}

    def fence_breach_action(self, p: dict[str, float]) -> tuple[bool, str | None]:
        return p["FENCE_ENABLE"] != 0, self._FENCE_ACTIONS.get(int(p["FENCE_ACTION"]))

    def precision_landing(self, p: dict[str, float]) -> PrecisionLandingTune | None:
        if int(p["PLND_ENABLED"]) != 1 or int(p["PLND_TYPE"]) != 1:
            return None
        return PrecisionLandingTune(p["PLND_ALT_MIN"], p["PLND_ALT_MAX"], p["PLND_XY_DIST_MAX"])

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
                max_jerk_xy_m_s3=p["PSC_JERK_XY"],
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
