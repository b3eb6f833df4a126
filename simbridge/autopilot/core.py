"""The flight core shared by both flavours: arming, modes and what each mode flies,
the land detector, auto-disarm, the offboard-stream rules and failsafes, and the geofence.

It speaks in setpoints, modes and MAV_RESULT codes; MAVLink framing lives in
:mod:`simbridge.autopilot.server`.

Kept whole (one module over 600 lines, about 800): it is one sans-IO state machine, as a flight
controller's commander is; the modes, the land detector, the failsafes and the fence all read and change
the same armed state, mode, setpoint and estimate each tick, and which one wins depends on their order
in :meth:`Autopilot.tick`. Apart, each would hold a reference to the others' state (the mixins this
project avoids); the flavours' tables (:mod:`simbridge.autopilot.flavours`) and the precision landing
(:mod:`simbridge.autopilot.precland`) are already parts of their own.
"""

from __future__ import annotations

import bisect
import collections
import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from simbridge.autopilot.flavours import (
    BATTERY_LEVEL_NAMES,
    BATTERY_OK,
    MAV_RESULT_ACCEPTED,
    MAV_RESULT_DENIED,
    MAV_RESULT_FAILED,
    MAV_RESULT_TEMPORARILY_REJECTED,
    MAV_RESULT_UNSUPPORTED,
    NEEDS_POSITION,
    PILOT_NAVS,
    Flavour,
    ModeSpec,
    Nav,
    Tunables,
)
from simbridge.autopilot.precland import PrecLand
from simbridge.control import Setpoint
from simbridge.estimate import EstimateError
from simbridge.geo import Vec3, rotate_body_to_ned
from simbridge.physics import CONTACT_MARGIN_M, GEAR_HEIGHT_M, VehicleState
from simbridge.vehicle import Vehicle

# STATUSTEXT severities
SEV_CRITICAL, SEV_WARNING, SEV_NOTICE, SEV_INFO = 2, 4, 5, 6

# MAV_CMD_INJECT_FAILURE: FAILURE_UNIT_SENSOR_GPS; FAILURE_TYPE_OK, FAILURE_TYPE_OFF
_FAILURE_UNIT_GPS, _FAILURE_OK, _FAILURE_OFF = 4, 0, 1

# MAV_LANDED_STATE
LANDED_ON_GROUND, LANDED_IN_AIR, LANDED_TAKEOFF, LANDED_LANDING = 1, 2, 3, 4

EventSink = Callable[[str, dict[str, Any]], None]
TextSink = Callable[[int, str], None]

# the land detector's trigger time: ArduCopter's LAND_DETECTOR_TRIGGER_SEC and PX4's LNDMC_TRIG_TIME are
# both 1 s (real ArduCopter SITL on simbridge's F450 said ON_GROUND 1.5 s after the gear touched:
# tests/test_firmware_parity.py)
_LANDED_CONFIRM_S = 1.0
# a LANDING_TARGET's line of sight is placed with the estimated pose at its time stamp, looked up this
# far back (ArduCopter's AC_PrecLand keeps an inertial history for PLND_LAG, at most 0.25 s)
_PLND_POSE_HISTORY_S = 1.0
_TAKEOFF_REACHED_M = 0.3


@dataclass(frozen=True, slots=True)
class CommandOutcome:
    result: int
    text: str | None = None
    severity: int = SEV_WARNING


ACCEPTED = CommandOutcome(MAV_RESULT_ACCEPTED)


class Autopilot:
    """One vehicle's autopilot state machine.

    Args:
        flavour: PX4 or ArduPilot rules.
        vehicle: the airframe it flies.
        home_ned_m: home position (ground level) in the world frame.
        emit_event: called with (event name, fields) for the episode log.
        emit_text: called with (severity, text) for STATUSTEXT.
        estimate: the estimator's errors (``--ekf-error``); None: the autopilot knows the truth.
    """

    def __init__(
        self,
        flavour: Flavour,
        vehicle: Vehicle,
        home_ned_m: Vec3,
        emit_event: EventSink,
        emit_text: TextSink,
        estimate: EstimateError | None = None,
    ) -> None:
        self.flavour = flavour
        self.estimate = estimate
        # the local frame's origin (LOCAL_POSITION_NED, position targets): the EKF origin, set where
        # the estimator first had a position: the vehicle resting at home, under the launch point
        self.local_origin_ned_m = (home_ned_m[0], home_ned_m[1], home_ned_m[2] - GEAR_HEIGHT_M)
        self.vehicle = vehicle
        self.home_ned_m = home_ned_m
        self._emit_event = emit_event
        self._emit_text = emit_text
        self.params: dict[str, float] = {p.name: float(p.default) for p in flavour.params}
        self.tun: Tunables = flavour.tunables(self.params)
        self.armed = False
        self.mode: ModeSpec = flavour.mode(flavour.ground_start_mode)
        self.failsafe = False
        self.landed = True
        self.landed_state = LANDED_ON_GROUND
        self._landed_since: float | None = None
        self._t_s = 0.0
        self._armed_at_s = 0.0
        self._has_flown = False
        self._hold: Setpoint | None = None
        self._takeoff_target_d: float | None = None
        self._rtl_phase = "climb"
        self._external: Setpoint | None = None
        self._external_is_velocity = False
        self._external_at_s = -math.inf
        self._offboard_lost_to: ModeSpec | None = None  # the offboard-loss failsafe's mode, while in it
        self._last_reject = ("", -math.inf)
        self._battery_level = BATTERY_OK  # the worst battery warning of this flight so far
        self._battery_level_at_arming = BATTERY_OK
        self._battery_action: tuple[str, float, int] | None = None  # (mode, when, level) pending
        # the GPS and the estimator: SITL's SIM_GPS1_ENABLE or GPS1_TYPE 0 (ArduPilot),
        # MAV_CMD_INJECT_FAILURE (PX4)
        self.gps_enabled = True
        self.position_valid = True  # False: no position estimate, none sent (LOCAL_POSITION_NED, ...)
        self._gps_off_at: float | None = None
        self._before_position_loss: ModeSpec | None = None
        self._fence_breached = False  # latched for the flight: one breach, one action
        # precision landing: the last LANDING_TARGET (when, the line of sight in body FRD, its
        # distance) and the target's world position estimated from it (held through the landing)
        self._plnd_seen: tuple[float, Vec3, float, float | None] | None = None
        # the estimated pose of the last _PLND_POSE_HISTORY_S (when, position, attitude): the history
        # each line of sight is placed from
        self._pose_history: collections.deque[tuple[float, Vec3, tuple[float, float, float, float]]] = (
            collections.deque()
        )
        self._plnd_target_ne: tuple[float, float] | None = None
        self._plnd_wait_d: float | None = None  # the height held while the target is too far across
        # PX4's AUTO.PRECLAND: the newest LANDING_TARGET in the local frame (when, where), and the mode's run
        self._pld_heard: tuple[float, Vec3] | None = None
        self._precland: PrecLand | None = None
        self._apply_limits()

    # ------------------------------------------------------------------ spawn
    def spawn_in_air(self, state: VehicleState) -> None:
        """Armed, in the air, holding where the vehicle is (``--start air``)."""
        self.armed = True
        self._has_flown = True
        self.landed = False
        self.landed_state = LANDED_IN_AIR
        self._armed_at_s = state.t_s
        self._arm_watches()
        self._set_mode(self.flavour.mode(self.flavour.air_start_mode), state, announce=False)

    # ------------------------------------------------------------------ parameters
    def set_param(self, name: str, value: float) -> bool:
        if name not in self.params or not math.isfinite(value):
            return False
        old = self.params[name]
        self.params[name] = value
        try:
            tun = self.flavour.tunables(self.params)
        except ValueError as exc:
            self.params[name] = old
            self._emit_text(SEV_WARNING, f"Param {name} rejected: {exc}")
            return False
        self.tun = tun
        self._apply_limits()
        if name in ("SIM_GPS1_ENABLE", "GPS1_TYPE"):  # SITL's switch, or the GPS driver's type 0 (none)
            self.gps_enabled = all(self.params.get(n, 1) != 0 for n in ("SIM_GPS1_ENABLE", "GPS1_TYPE"))
        return True

    def inject_failure(self, unit: int, failure: int) -> CommandOutcome:
        """MAV_CMD_INJECT_FAILURE (PX4): the GPS off (type 1) or back (type 0); refused unless
        SYS_FAILURE_EN is 1, as real PX4 does."""
        if self.params.get("SYS_FAILURE_EN", 0) != 1:
            return self._refuse("Failure injection disabled", MAV_RESULT_DENIED)
        if unit != _FAILURE_UNIT_GPS or failure not in (_FAILURE_OK, _FAILURE_OFF):
            return CommandOutcome(MAV_RESULT_UNSUPPORTED)
        self.gps_enabled = failure == _FAILURE_OK
        return ACCEPTED

    def _apply_limits(self) -> None:
        """The controller's envelope: the navigation limits, or in the pilot's altitude-holding
        modes the pilot's climb and descent speeds (ArduCopter's PILOT_SPEED_UP / _DN)."""
        limits = self.tun.limits
        if self.mode.nav in PILOT_NAVS:
            limits = dataclasses.replace(
                limits,
                max_speed_up_m_s=self.tun.pilot_speed_up_m_s,
                max_speed_down_m_s=self.tun.pilot_speed_down_m_s,
            )
        self.vehicle.set_limits(limits)

    # ------------------------------------------------------------------ commands
    def arm(self, arm: bool, force: bool = False) -> CommandOutcome:
        s = self.vehicle.state
        if arm:
            if self.armed:
                return ACCEPTED
            if not self.mode.armable and not force:
                text = (
                    f"Arming denied: {self.mode.name} mode"
                    if self._px4
                    else f"Arm: {self.mode.name} mode not armable"  # ArduCopter 4.7's words
                )
                return self._refuse(text, self._arm_refusal())
            if not self.landed and not force:
                return self._refuse("Arming denied: vehicle not landed", self._arm_refusal())
            self.armed = True
            self._armed_at_s = s.t_s
            self._arm_watches()
            self._has_flown = False
            self._landed_since = s.t_s
            self.vehicle.controller.reset()
            self._hold = Setpoint.hold(s.pos_ned_m, s.euler_rad[2])
            self._emit_event("armed", {})
            self._emit_text(SEV_INFO, "Armed by external command" if self._px4 else "Arming motors")
            return ACCEPTED
        if not self.armed:
            return ACCEPTED
        if not self.landed and not force:
            return self._refuse("Disarming denied: not landed", self._arm_refusal())
        self._disarm("external command")
        return ACCEPTED

    @property
    def _px4(self) -> bool:
        return self.flavour.name == "px4"

    def _arm_refusal(self) -> int:
        return MAV_RESULT_TEMPORARILY_REJECTED if self._px4 else MAV_RESULT_FAILED

    def set_mode(self, spec: ModeSpec) -> CommandOutcome:
        s = self.vehicle.state
        if spec.nav is Nav.EXTERNAL and self.flavour.offboard_needs_stream and not self._stream_ok():
            return self._refuse(
                "Switching to Offboard rejected: no setpoint stream", MAV_RESULT_TEMPORARILY_REJECTED
            )
        if spec.nav is Nav.TAKEOFF and self.armed and not self.landed:
            return self._refuse("Takeoff denied: already flying", MAV_RESULT_TEMPORARILY_REJECTED)
        if not self.position_valid and (spec.nav in NEEDS_POSITION or (self._px4 and spec.nav is Nav.LAND)):
            # real PX4 answered TEMPORARILY_REJECTED to OFFBOARD and to AUTO.LAND without a position
            # estimate; ArduCopter lands without one (level, drifting)
            result = MAV_RESULT_TEMPORARILY_REJECTED if self._px4 else MAV_RESULT_FAILED
            return self._refuse(f"{spec.name} needs a position estimate", result)
        self.failsafe = False
        self._battery_action = None  # a user takeover cancels a failsafe action still waiting
        self._set_mode(spec, s)
        return ACCEPTED

    def crash(self) -> None:
        """The airframe struck something (the simulator says so): the motors stop, as ArduCopter's
        crash check and PX4's failure detector disarm a vehicle that has crashed."""
        if self.armed:
            self._emit_text(SEV_CRITICAL, "Crash: Disarming" if not self._px4 else "Critical: crash detected")
            self._disarm("crash")

    def takeoff(self, alt_m: float | None) -> CommandOutcome:
        """NAV_TAKEOFF; ``alt_m`` is relative to the ground under the vehicle (NaN/None: default)."""
        if alt_m is not None and not (math.isfinite(alt_m) and 0.5 <= alt_m <= self.tun.fence_alt_m):
            return self._refuse(f"Takeoff altitude {alt_m} m out of range", MAV_RESULT_DENIED)
        if not self.armed:
            return self._refuse("Takeoff denied: disarmed", self._arm_refusal())
        if not self.landed:
            return self._refuse("Takeoff denied: already flying", MAV_RESULT_TEMPORARILY_REJECTED)
        if self.flavour.name == "ardupilot" and self.mode.nav is not Nav.EXTERNAL:
            return self._refuse("Takeoff requires GUIDED mode", MAV_RESULT_FAILED)
        s = self.vehicle.state
        if self.flavour.name == "px4":
            self._set_mode(self.flavour.mode("AUTO.TAKEOFF"), s)
        climb = alt_m if alt_m is not None else self.tun.takeoff_alt_m
        self._takeoff_target_d = -(s.ground_height_m + climb)
        self._hold = Setpoint.hold((s.pos_ned_m[0], s.pos_ned_m[1], self._takeoff_target_d), s.euler_rad[2])
        if self.flavour.name == "ardupilot":
            self._external = self._hold
            self._external_is_velocity = False
        self.landed_state = LANDED_TAKEOFF
        return ACCEPTED

    def land(self) -> CommandOutcome:
        land = next(m for m in self.flavour.modes if m.nav is Nav.LAND)
        return self.set_mode(land)

    def rtl(self) -> CommandOutcome:
        rtl = next(m for m in self.flavour.modes if m.nav is Nav.RTL)
        return self.set_mode(rtl)

    def to_local(self, p: Vec3) -> Vec3:
        """World NED -> the autopilot's local frame (relative to its EKF origin)."""
        o = self.local_origin_ned_m
        return (p[0] - o[0], p[1] - o[1], p[2] - o[2])

    def from_local_ned(self, p: Vec3) -> Vec3:
        """The autopilot's local frame -> world NED axes (the inverse of :meth:`to_local`)."""
        o = self.local_origin_ned_m
        return (p[0] + o[0], p[1] + o[1], p[2] + o[2])

    def from_local(self, sp: Setpoint) -> Setpoint:
        """A setpoint in the local frame -> the same in world axes (still the estimated frame)."""
        on, oe, od = self.local_origin_ned_m
        ne = (sp.pos_ne_m[0] + on, sp.pos_ne_m[1] + oe) if sp.pos_ne_m is not None else None
        d = sp.pos_d_m + od if sp.pos_d_m is not None else None
        return dataclasses.replace(sp, pos_ne_m=ne, pos_d_m=d)

    @property
    def estimated_state(self) -> VehicleState:
        """What the autopilot believes (its telemetry says this): the truth, or the truth with the
        estimator's errors."""
        est = self.estimate.estimate() if self.estimate is not None else None
        return est if est is not None else self.vehicle.state

    def external_setpoint(self, sp: Setpoint, is_velocity: bool) -> CommandOutcome:
        """A SET_POSITION_TARGET_LOCAL_NED already decoded into the local frame (the autopilot's
        estimated one: with an estimator error its positions sit ``bias`` away in the world)."""
        s = self.vehicle.state
        problem = self._fence_problem(sp)
        if problem is not None:
            self.reject_setpoint(problem)
            return CommandOutcome(MAV_RESULT_DENIED)
        if not self.flavour.offboard_needs_stream and self.mode.nav is not Nav.EXTERNAL:
            return CommandOutcome(MAV_RESULT_DENIED)  # ArduPilot acts on targets only in GUIDED
        self._external_at_s = s.t_s
        self._external = self._to_world(sp)
        self._external_is_velocity = is_velocity
        return ACCEPTED

    def _to_world(self, sp: Setpoint) -> Setpoint:
        if self.estimate is None:
            return sp
        bn, be, bd = self.estimate.bias_ned_m
        ne = (sp.pos_ne_m[0] - bn, sp.pos_ne_m[1] - be) if sp.pos_ne_m is not None else None
        d = sp.pos_d_m - bd if sp.pos_d_m is not None else None
        return dataclasses.replace(sp, pos_ne_m=ne, pos_d_m=d)

    def reject_setpoint(self, problem: str) -> None:
        """A setpoint that cannot be flown: say so (the same problem at most once a second)."""
        t = self.vehicle.state.t_s
        last_problem, last_t = self._last_reject
        if problem != last_problem or t - last_t > 1.0:
            self._last_reject = (problem, t)
            self._emit_text(SEV_WARNING, f"Setpoint rejected: {problem}")

    def text_warning(self, text: str) -> None:
        self._emit_text(SEV_WARNING, text)

    def text_critical(self, text: str) -> None:
        self._emit_text(SEV_CRITICAL, text)

    # ------------------------------------------------------------------ per-step
    def tick(self, s: VehicleState) -> Setpoint | None:
        """Decide what to fly for the next step. ``None``: motors idle if armed, else stopped."""
        self._t_s = s.t_s
        if self.estimate is not None:
            self.estimate.step(s)
        self._remember_pose(s.t_s)
        self._update_land_detector(s)
        self._watch_estimator(s)
        if not self.armed:
            return None
        if not self.landed:
            self._watch_battery(s)
            self._watch_fence(s)
        if self.landed:
            return self._on_ground(s)
        return self._fly(s)

    def _fly(self, s: VehicleState) -> Setpoint | None:
        self._offboard_back(s)
        nav = self.mode.nav
        if nav is Nav.EXTERNAL:
            return self._fly_external(s)
        if nav is Nav.TAKEOFF:
            return self._fly_takeoff(s)
        if nav is Nav.LAND:
            if self._precland is not None:
                return self._fly_precland(s, self._precland)
            return self._fly_land(s, self._hold, self._precision_target(s))
        if nav is Nav.RTL:
            return self._fly_rtl(s)
        if nav in PILOT_NAVS:
            return self._fly_pilot_at_rest(s)
        if nav is Nav.ALT_DRIFT:
            vn, ve, _ = s.vel_ned_m_s
            hold_d = self._hold.pos_d_m if self._hold is not None else None
            return Setpoint(pos_d_m=hold_d, vel_ned_m_s=(vn, ve, 0.0))
        return self._hold

    def _fly_pilot_at_rest(self, s: VehicleState) -> Setpoint | None:
        """The pilot's modes with the sticks centred and the throttle at its minimum: STABILIZE and
        ACRO run the motors at their minimum and fall; ALT_HOLD and POSHOLD descend at the pilot's
        full down speed, ALT_HOLD level (drifting with what speed it had), POSHOLD holding position."""
        nav = self.mode.nav
        if nav is Nav.PILOT_THRUST:
            return None  # motors at idle thrust
        yaw = self._hold.yaw_rad if self._hold is not None else None
        down = self.tun.pilot_speed_down_m_s
        if nav is Nav.PILOT_POS:
            return Setpoint(pos_ne_m=self._hold_ne(s), vel_ned_m_s=(0.0, 0.0, down), yaw_rad=yaw)
        vn, ve, _ = s.vel_ned_m_s
        return Setpoint(vel_ned_m_s=(vn, ve, down), yaw_rad=yaw)

    def _on_ground(self, s: VehicleState) -> Setpoint | None:
        t = self.tun
        since = self._landed_since if self._landed_since is not None else s.t_s
        wants_up = self._wants_climb(s)
        if self.mode.nav in PILOT_NAVS:
            # the throttle at its minimum keeps it down, motors at idle; real ArduCopter SITL
            # (RC3 = 1000) armed in STABILIZE or ALT_HOLD on the ground, or landed there in ALT_HOLD,
            # never auto-disarmed (160 s simulated; tests/test_firmware_parity.py)
            return None
        if not wants_up:
            limit = t.disarm_after_land_s if self._has_flown else t.disarm_preflight_s
            if s.t_s - since >= limit:
                self._disarm("landed" if self._has_flown else "auto-disarm: no takeoff")
                return None
            return None  # armed on the ground: motors at idle
        nav = self.mode.nav
        if nav is Nav.TAKEOFF:
            return self._fly_takeoff(s)
        if nav is Nav.EXTERNAL:
            return self._fly_external(s)
        return self._hold

    def _wants_climb(self, s: VehicleState) -> bool:
        nav = self.mode.nav
        if nav is Nav.TAKEOFF:
            return True
        if nav is Nav.EXTERNAL and self._external is not None:
            sp = self._external
            if sp.pos_d_m is not None:
                return sp.pos_d_m < s.pos_ned_m[2] - 0.3
            return sp.vel_ned_m_s[2] < -0.1
        if nav is Nav.HOLD and self._hold is not None and self._hold.pos_d_m is not None:
            return self._hold.pos_d_m < s.pos_ned_m[2] - 0.5
        return False

    def _fly_takeoff(self, s: VehicleState) -> Setpoint | None:
        if self._hold is None or self._takeoff_target_d is None:
            # the takeoff altitude is over the resting vehicle (home, the local frame's origin)
            self._takeoff_target_d = -(s.ground_height_m + GEAR_HEIGHT_M + self.tun.takeoff_alt_m)
            self._hold = Setpoint.hold((s.pos_ned_m[0], s.pos_ned_m[1], self._takeoff_target_d))
        if abs(s.pos_ned_m[2] - self._takeoff_target_d) < _TAKEOFF_REACHED_M:
            target_d, self._takeoff_target_d = self._takeoff_target_d, None
            after = self.flavour.after_takeoff_mode
            if after is not None:
                self._set_mode(self.flavour.mode(after), s, announce=True)
                self._hold = Setpoint.hold((s.pos_ned_m[0], s.pos_ned_m[1], target_d))  # hold up there
            self._emit_text(SEV_INFO, "Takeoff complete")
        return self._hold

    # ------------------------------------------------------------------ precision landing
    def landing_target(self, los_frd: Vec3, distance_m: float, stamp_s: float | None = None) -> None:
        """A LANDING_TARGET: the line of sight to the target in body FRD (any length), its distance
        (0: unknown, the height above the ground scales it) and when it was true on the boot clock
        (``time_usec``; None: now)."""
        norm = math.sqrt(sum(v * v for v in los_frd))
        if not (math.isfinite(norm) and norm > 0 and math.isfinite(distance_m)):
            return
        unit = (los_frd[0] / norm, los_frd[1] / norm, los_frd[2] / norm)
        self._plnd_seen = (self.vehicle.state.t_s, unit, max(0.0, distance_m), stamp_s)

    def _remember_pose(self, t_s: float) -> None:
        """The estimated pose this step, kept ``_PLND_POSE_HISTORY_S`` (:meth:`_pose_at`)."""
        est = self.estimated_state
        h = self._pose_history
        if h and t_s <= h[-1][0]:  # a reset clock (a new episode) or the same step twice
            h.clear()
        h.append((t_s, est.pos_ned_m, est.quat))
        while len(h) > 1 and h[0][0] < t_s - _PLND_POSE_HISTORY_S:
            h.popleft()

    def _pose_at(self, stamp_s: float | None) -> tuple[Vec3, tuple[float, float, float, float]]:
        """The estimated pose at ``stamp_s``: the newest of the history at or before it (telemetry
        reports the estimate made at one step with the clock of the next, in whole milliseconds, and a
        step is 1/600 s: this is the estimate that telemetry carried). Unstamped, or older than the
        history: the pose now.

        ArduCopter's precision landing takes the pose ``PLND_LAG`` back (its inertial history), a lag
        set once to the link's latency; here it is what each line of sight's stamp says: a simulation
        run faster than real time delivers a message late by a varying number of simulated milliseconds
        (the machine's load, times the speed), where a real link's latency is steady."""
        h = self._pose_history
        if stamp_s is None or not h or stamp_s < h[0][0]:
            est = self.estimated_state
            return est.pos_ned_m, est.quat
        i = bisect.bisect_right(h, stamp_s, key=lambda e: e[0]) - 1
        _t, pos, quat = h[i]
        return pos, quat

    def _precision_target(self, s: VehicleState) -> tuple[float, float] | None:
        """Where land mode goes (world north, east) on the companion's target: each fresh line of sight
        between PLND_ALT_MIN and PLND_ALT_MAX places the target from the estimated pose at its stamp
        (as the firmware does: an attitude or position error moves the target with it); the last place
        holds for the rest of the landing. None: no target (land where the vehicle is)."""
        tune = self.flavour.precision_landing(self.params)
        if tune is None:
            self._plnd_target_ne = None
            return None
        seen = self._plnd_seen
        agl = s.height_agl_m
        if seen is not None and s.t_s - seen[0] <= tune.timeout_s and tune.alt_min_m <= agl <= tune.alt_max_m:
            _t, unit, distance, stamp_s = seen
            if unit[2] > 0.05:
                pos, quat = self._pose_at(stamp_s)
                rng = distance if distance > 0 else agl / unit[2]
                dn, de, _dd = rotate_body_to_ned(quat, (unit[0] * rng, unit[1] * rng, unit[2] * rng))
                bn, be = self.estimate.bias_ned_m[:2] if self.estimate is not None else (0.0, 0.0)
                # estimated target -> world: the estimator's bias is where the vehicle flies it
                self._plnd_target_ne = (pos[0] + dn - bn, pos[1] + de - be)
            self._plnd_seen = None  # each line of sight places the target once
        return self._plnd_target_ne

    def landing_target_local(self, target_ned: Vec3) -> None:
        """A LANDING_TARGET in the local frame, relative to the EKF origin (PX4: the landing target pose,
        whatever the mode); kept in world axes of the estimated frame, as the estimated pose is."""
        if not all(math.isfinite(v) for v in target_ned):
            return
        self._pld_heard = (self.vehicle.state.t_s, self.from_local_ned(target_ned))
        if self._precland is not None:
            self._precland.heard(*self._pld_heard)

    def _fly_precland(self, s: VehicleState, run: PrecLand) -> Setpoint:
        """AUTO.PRECLAND (:mod:`simbridge.autopilot.precland`): its answer, from the estimate's frame
        into the world's (an estimator's bias moves where the vehicle flies, as with every target)."""
        cmd = run.step(s.t_s, self.estimated_state.pos_ned_m)
        bn, be, bd = self.estimate.bias_ned_m if self.estimate is not None else (0.0, 0.0, 0.0)
        ne = (cmd.ne[0] - bn, cmd.ne[1] - be)
        yaw = self._hold.yaw_rad if self._hold is not None else None
        if cmd.land:
            return self._fly_land(s, Setpoint(pos_ne_m=ne, yaw_rad=yaw))
        d = cmd.d - bd if cmd.d is not None else s.pos_ned_m[2]
        return Setpoint.hold((ne[0], ne[1], d), yaw)

    def _fly_land(
        self, s: VehicleState, over: Setpoint | None, target_ne: tuple[float, float] | None = None
    ) -> Setpoint:
        t = self.tun
        agl = s.height_agl_m
        if agl > 2 * t.land_slow_below_m:
            vz = t.limits.max_speed_down_m_s
        elif agl > t.land_slow_below_m:
            frac = (agl - t.land_slow_below_m) / t.land_slow_below_m
            vz = t.land_speed_m_s + frac * (t.limits.max_speed_down_m_s - t.land_speed_m_s)
        else:
            vz = t.land_speed_m_s
        self.landed_state = LANDED_LANDING
        yaw = over.yaw_rad if over is not None else None
        if not self.position_valid:  # no horizontal position to hold: level, drifting as it goes
            vn, ve, _ = s.vel_ned_m_s
            return Setpoint(vel_ned_m_s=(vn, ve, vz), yaw_rad=yaw)
        ne = over.pos_ne_m if over is not None else (s.pos_ned_m[0], s.pos_ned_m[1])
        hold_d = None
        if target_ne is not None:
            tune = self.flavour.precision_landing(self.params)
            away = math.hypot(target_ne[0] - s.pos_ned_m[0], target_ne[1] - s.pos_ned_m[1])
            if tune is not None and tune.xy_dist_max_m > 0 and away > tune.xy_dist_max_m:
                # ArduCopter holds its height until the target is near enough across
                if self._plnd_wait_d is None:
                    self._plnd_wait_d = s.pos_ned_m[2]
                hold_d, vz = self._plnd_wait_d, 0.0
            else:
                self._plnd_wait_d = None
            ne = target_ne
        return Setpoint(pos_ne_m=ne, pos_d_m=hold_d, vel_ned_m_s=(0.0, 0.0, vz), yaw_rad=yaw)

    def _fly_rtl(self, s: VehicleState) -> Setpoint:
        hn, he, hd = self.home_ned_m
        ret_d = min(hd - self.tun.rtl_alt_m, s.pos_ned_m[2])  # never descend to return
        if self._rtl_phase == "climb":
            if s.pos_ned_m[2] - ret_d < 0.5:
                self._rtl_phase = "return"
            return Setpoint(pos_ne_m=self._hold_ne(s), pos_d_m=ret_d)
        if self._rtl_phase == "return":
            if math.hypot(s.pos_ned_m[0] - hn, s.pos_ned_m[1] - he) < 1.0:
                self._rtl_phase = "land"
            return Setpoint(pos_ne_m=(hn, he), pos_d_m=ret_d)
        return self._fly_land(s, Setpoint(pos_ne_m=(hn, he)))

    def _hold_ne(self, s: VehicleState) -> tuple[float, float]:
        if self._hold is not None and self._hold.pos_ne_m is not None:
            return self._hold.pos_ne_m
        return (s.pos_ned_m[0], s.pos_ned_m[1])

    def _offboard_back(self, s: VehicleState) -> None:
        """PX4 (1.15, seen in SITL): once setpoints flow again after an offboard-loss failsafe, and
        nobody has changed the mode since, the vehicle goes back to OFFBOARD by itself: the failsafe
        clears and the user's choice of mode stands again."""
        lost_to = self._offboard_lost_to
        if lost_to is None:
            return
        if self.mode != lost_to or not self.armed:
            self._offboard_lost_to = None  # a new choice of mode (or the ground) ends it
            return
        if self._stream_ok():
            self._offboard_lost_to = None
            self.failsafe = False
            self._set_mode(self.flavour.mode("OFFBOARD"), s, announce=False)
            self._emit_event("failsafe_cleared", {"reason": "offboard_loss", "mode": "OFFBOARD"})

    def _fly_external(self, s: VehicleState) -> Setpoint | None:
        t = self.tun
        age = s.t_s - self._external_at_s
        if t.offboard_loss_s is not None and age > t.offboard_loss_s and self._external_at_s > -math.inf:
            mode_name = t.offboard_loss_mode or "POSCTL"
            self.failsafe = True
            self._set_mode(self.flavour.mode(mode_name), s, announce=False)
            self._offboard_lost_to = self.mode
            self._emit_event("failsafe", {"reason": "offboard_loss", "action": mode_name})
            self._emit_text(SEV_CRITICAL, f"Failsafe: offboard lost, {mode_name}")
            return self._fly(s)
        sp = self._external
        if sp is None:
            return self._hold
        if (
            self._external_is_velocity
            and t.velocity_target_timeout_s is not None
            and age > t.velocity_target_timeout_s
        ):
            # ArduPilot GUID_TIMEOUT: a stale velocity target becomes a stop
            self._external = Setpoint.hold(s.pos_ned_m, s.euler_rad[2])
            self._external_is_velocity = False
            return self._external
        return sp

    # ------------------------------------------------------------------ fence and battery failsafes
    def _watch_fence(self, s: VehicleState) -> None:
        """The fence around home (the flavour's, when enabled): the vehicle itself beyond its radius or
        above its altitude is a breach, said and recorded (``fence_breach``) once a flight; with an
        action, the autopilot switches to that mode in a failsafe."""
        enabled, mode = self.flavour.fence_breach_action(self.params)
        if not enabled or self._fence_breached:
            return
        hn, he, hd = self.home_ned_m
        n, e, d = s.pos_ned_m
        if math.hypot(n - hn, e - he) > self.tun.fence_radius_m:
            what = "radius"
        elif hd - d > self.tun.fence_alt_m:
            what = "altitude"
        else:
            return
        self._fence_breached = True
        self._emit_event("fence_breach", {"what": what, "action": mode})
        self._emit_text(
            SEV_CRITICAL, "Max Alt fence breached" if what == "altitude" else "Circle fence breached"
        )
        if mode is None or self.mode.name == mode or self.mode.nav is Nav.LAND:
            return
        # not "critical" in the heartbeat: real ArduCopter's fence is not among the failsafes that make
        # its system status critical (tests/test_autopilot_failsafes.py)
        self._set_mode(self.flavour.mode(mode), s, announce=False)
        self._emit_event("failsafe", {"reason": "geofence", "action": mode})

    def _arm_watches(self) -> None:
        """At arming: the battery level the flight starts with (PX4 acts only on a worse one), no
        action pending, the fence not breached."""
        level = self.flavour.battery_level(self.params, self.vehicle.battery)
        self._battery_level = self._battery_level_at_arming = level
        self._battery_action = None
        self._fence_breached = False

    def _watch_battery(self, s: VehicleState) -> None:
        """The autopilot's battery failsafe (flavour rules): a warning level worse than the flight's
        worst so far is said (STATUSTEXT) and recorded (``battery_warning``); where the parameters
        give it an action, the autopilot switches to that mode in a failsafe (system status critical,
        ``failsafe`` event) after the flavour's delay (PX4's COM_BAT_ACT_T). PX4 acts only on a level
        worse than the one at arming, as its failsafe.cpp does; a landing is never turned into a
        return."""
        battery = self.vehicle.battery
        level = self.flavour.battery_level(self.params, battery)
        if level > self._battery_level:
            self._battery_level = level
            reaction = self.flavour.battery_reaction(self.params, level, battery)
            name = BATTERY_LEVEL_NAMES[level]
            self._emit_event(
                "battery_warning",
                {"level": name, "remaining_pct": round(100 * battery.remaining_fraction, 1),
                 "action": reaction.mode},
            )  # fmt: skip
            self._emit_text(SEV_WARNING if reaction.mode is None else SEV_CRITICAL, reaction.text)
            if reaction.mode is not None and not (self._px4 and level <= self._battery_level_at_arming):
                self._battery_action = (reaction.mode, s.t_s + reaction.delay_s, level)
                if reaction.hold_first is not None and self.mode.nav is not Nav.LAND:
                    # PX4 holds while its action waits: a mode commanded meanwhile is the user taking
                    # over, which cancels the action (set_mode)
                    self.failsafe = True
                    self._set_mode(self.flavour.mode(reaction.hold_first), s, announce=False)
                    self._emit_event("failsafe", {"reason": f"battery_{name}", "action": reaction.hold_first})
        pending = self._battery_action
        if pending is None or s.t_s < pending[1]:
            return
        self._battery_action = None
        mode, _, level = pending
        spec = self.flavour.mode(mode)
        if spec == self.mode or (spec.nav is Nav.RTL and self.mode.nav is Nav.LAND):
            return
        self.failsafe = True
        self._set_mode(spec, s, announce=False)
        self._emit_event("failsafe", {"reason": f"battery_{BATTERY_LEVEL_NAMES[level]}", "action": mode})
        self._emit_text(SEV_CRITICAL, f"Failsafe: battery {BATTERY_LEVEL_NAMES[level]}, {mode}")

    # ------------------------------------------------------------------ GPS and estimator
    def _watch_estimator(self, s: VehicleState) -> None:
        """Without GPS the estimator dead-reckons for the flavour's time, then has no position: none
        is sent, and in flight the flavour's failsafe takes a mode that needs none (PX4: ALTCTL, as
        real PX4 1.15 fell back to; ArduCopter's EKF failsafe: FS_EKF_ACTION). GPS back: the position
        returns; PX4's fallback clears back to the mode it replaced, ArduCopter stays in its mode."""
        if self.gps_enabled:
            self._gps_off_at = None
            if not self.position_valid:
                self.position_valid = True
                self._emit_event("position_restored", {})
                self._emit_text(SEV_INFO, "GPS fix regained, position estimate back")
                back, self._before_position_loss = self._before_position_loss, None
                if back is not None and self._px4 and self.armed and self.failsafe:
                    self.failsafe = False
                    self._set_mode(back, s, announce=False)
                    self._emit_event("failsafe_cleared", {"reason": "position_lost", "mode": back.name})
            return
        if self._gps_off_at is None:
            self._gps_off_at = s.t_s
            self._emit_event("gps_lost", {})
            self._emit_text(SEV_CRITICAL, "GPS lost: no fix")
        delay, mode = self.flavour.position_lost(self.params)
        if not self.position_valid or s.t_s - self._gps_off_at < delay:
            return
        self.position_valid = False
        self._emit_event("position_lost", {"gps_off_s": round(s.t_s - self._gps_off_at, 2)})
        if not self.armed or self.landed or mode is None or self.mode.name == mode:
            return
        self._before_position_loss = self.mode
        self.failsafe = True
        self._set_mode(self.flavour.mode(mode), s, announce=False)
        self._emit_event("failsafe", {"reason": "position_lost", "action": mode})
        self._emit_text(SEV_CRITICAL, f"Failsafe: position estimate lost, {mode}")

    # ------------------------------------------------------------------ land detector
    def _update_land_detector(self, s: VehicleState) -> None:
        # contact by geometry (the gear's springs bounce their weight-on-wheels flags)
        near_ground = s.on_ground or s.height_agl_m < GEAR_HEIGHT_M + CONTACT_MARGIN_M
        if self.landed:
            if not near_ground and s.height_agl_m > GEAR_HEIGHT_M + 0.25:
                self.landed = False
                self._has_flown = True
                self._landed_since = None
                self.landed_state = LANDED_IN_AIR if self.mode.nav is not Nav.TAKEOFF else LANDED_TAKEOFF
            return
        if near_ground and abs(s.vel_ned_m_s[2]) < 0.5 and not self._wants_climb(s):
            if self._landed_since is None:
                self._landed_since = s.t_s
            elif s.t_s - self._landed_since >= _LANDED_CONFIRM_S:
                self.landed = True
                self.landed_state = LANDED_ON_GROUND
                self._emit_event("touchdown", {"pos_ned_m": [round(v, 3) for v in s.pos_ned_m]})
                self._emit_text(SEV_INFO, "Landing detected")
        else:
            self._landed_since = None
            if self.landed_state == LANDED_ON_GROUND:
                self.landed_state = LANDED_IN_AIR

    # ------------------------------------------------------------------ helpers
    def _disarm(self, why: str) -> None:
        self.armed = False
        self._external = None
        self._external_at_s = -math.inf
        self.failsafe = False
        self._offboard_lost_to = None
        self._emit_event("disarmed", {"reason": why})
        self._emit_text(SEV_INFO, f"Disarmed ({why})" if self._px4 else "Disarming motors")
        # ArduCopter stays in its mode (LAND after a landing); PX4 falls back to its ground mode
        if self._px4 and self.mode.nav in (Nav.LAND, Nav.RTL, Nav.TAKEOFF, Nav.EXTERNAL):
            self._set_mode(self.flavour.mode(self.flavour.ground_start_mode), self.vehicle.state)

    def _set_mode(self, spec: ModeSpec, s: VehicleState, announce: bool = True) -> None:
        changed = spec != self.mode
        self.mode = spec
        self._apply_limits()
        self._hold = Setpoint.hold(self._stopping_point(s), s.euler_rad[2])
        if spec.nav is not Nav.TAKEOFF:
            self._takeoff_target_d = None
        if changed:
            self._plnd_target_ne = None  # a target is followed within one landing only
            self._plnd_wait_d = None
            tune = self.flavour.precland(self.params) if spec.precision else None
            self._precland = (
                PrecLand(tune, s.t_s, self.estimated_state.pos_ned_m, self._pld_heard)
                if tune is not None
                else None
            )
        if spec.nav is Nav.RTL:
            self._rtl_phase = "climb"
        if spec.nav is Nav.EXTERNAL and not self.flavour.offboard_needs_stream:
            # ArduPilot GUIDED starts by holding where it is until a target arrives
            self._external = self._hold
            self._external_is_velocity = False
            self._external_at_s = s.t_s
        if changed:
            self._emit_event("mode", {"mode": spec.name})
            if announce and self._px4:  # ArduCopter says nothing when a ground station sets a mode
                self._emit_text(SEV_INFO, f"Mode {spec.name}")

    def _stopping_point(self, s: VehicleState) -> Vec3:
        """Where the vehicle comes to rest braking at the horizontal acceleration limit."""
        vn, ve, _ = s.vel_ned_m_s
        speed = math.hypot(vn, ve)
        if speed < 0.05:
            return s.pos_ned_m
        brake = 0.5 * self.tun.limits.max_accel_xy_m_s2
        k = speed / (2 * brake)  # distance v^2 / 2a along the unit velocity
        n, e, d = s.pos_ned_m
        return (n + vn * k, e + ve * k, d)

    def _stream_ok(self) -> bool:
        """PX4's rule for entering OFFBOARD: the last setpoint is younger than COM_OF_LOSS_T (one
        setpoint just before the switch is enough: MAVSDK's documented ``set_position_ned`` then
        ``start()``). PX4 docs older than v1.15 asked for "more than a second" of stream; the
        firmware's offboard check never did."""
        loss = self.tun.offboard_loss_s
        return self._t_s - self._external_at_s <= (loss if loss is not None else 1.0)

    def _fence_problem(self, sp: Setpoint) -> str | None:
        values = [*sp.vel_ned_m_s]
        if sp.pos_ne_m is not None:
            values += list(sp.pos_ne_m)
        if sp.pos_d_m is not None:
            values.append(sp.pos_d_m)
        for v in (sp.yaw_rad, sp.yaw_rate_rad_s):
            if v is not None:
                values.append(v)
        if not all(math.isfinite(v) for v in values):
            return "NaN or infinite value"
        hn, he, hd = self.home_ned_m
        if (
            sp.pos_ne_m is not None
            and math.hypot(sp.pos_ne_m[0] - hn, sp.pos_ne_m[1] - he) > self.tun.fence_radius_m
        ):
            return f"outside geofence ({self.tun.fence_radius_m:.0f} m from home)"
        if sp.pos_d_m is not None and hd - sp.pos_d_m > self.tun.fence_alt_m:
            return f"above geofence ({self.tun.fence_alt_m:.0f} m over home)"
        return None

    def _refuse(self, text: str, result: int) -> CommandOutcome:
        self._emit_text(SEV_WARNING, text)
        return CommandOutcome(result, text)
