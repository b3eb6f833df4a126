"""JSBSim's bundled F450 quadcopter, stepped at its own 120 Hz, with the world's ground under it.

The F450 model's own flight-control system is bypassed: its stability augmentation is disengaged
and our controller writes each ESC command directly (``fcs/cmd*_ext_nd``). Motor order everywhere
in simbridge is JSBSim's engine order: 0 front-right, 1 aft-left, 2 front-left, 3 aft-right.
"""

from __future__ import annotations

import contextlib
import math
import os
from collections.abc import Iterator
from dataclasses import dataclass, replace
from pathlib import Path

import jsbsim

from simbridge.geo import GeoOrigin, Quat, Vec3, euler_to_quat, wrap_pi
from simbridge.terrain import Terrain
from simbridge.wind import WindModel

FT_M = 0.3048
LBF_N = 4.4482216152605
_SLUG_KG = 14.593902937
GEAR_HEIGHT_M = 0.1524  # CG height above the ground when resting on the gear (F450 Gear.xml)
CONTACT_MARGIN_M = 0.15  # the gear springs bounce the CG ~7 cm above rest on a 0.7 m/s touchdown
MOTOR_COUNT = 4
CONTACT_DT_S = 1.0 / 240.0  # the longest JSBSim step while a gear leg touches
_ESC_PROPS = ("fcs/cmdFR_ext_nd", "fcs/cmdAL_ext_nd", "fcs/cmdFL_ext_nd", "fcs/cmdAR_ext_nd")
WALL_STEP_M = 1.0  # the ground under the vehicle rising more than this in one step is a wall, not a slope
G_M_S2 = 9.80665


@dataclass(frozen=True, slots=True)
class VehicleState:
    """Truth state of the airframe at simulated time ``t_s``."""

    t_s: float
    pos_ned_m: Vec3
    vel_ned_m_s: Vec3
    quat: Quat
    euler_rad: Vec3  # roll, pitch, yaw
    rates_frd_rad_s: Vec3
    ground_height_m: float  # terrain height under the vehicle, up positive
    on_ground: bool  # any landing-gear contact compressed
    thrust_n: float  # sum over the four rotors

    @property
    def height_agl_m(self) -> float:
        """Height of the CG above the ground directly under it."""
        return -self.pos_ned_m[2] - self.ground_height_m


@dataclass(frozen=True, slots=True)
class Collision:
    """The vehicle flew into something standing above it (a building's wall, a tree's crown): where
    and how fast it was going as the ground under it jumped from ``ground_before_m`` to ``struck_up_m``
    (heights up positive), at simulated time ``t_s``."""

    t_s: float
    pos_ned_m: Vec3
    speed_m_s: float
    ground_before_m: float
    struck_up_m: float

    def said(self) -> str:
        """In words, for the grade's reasons."""
        return (
            f"collision: flew into a structure {self.struck_up_m - self.ground_before_m:.0f} m tall "
            f"at {self.speed_m_s:.1f} m/s, {-self.pos_ned_m[2] - self.ground_before_m:.1f} m above the ground"
        )


@contextlib.contextmanager
def _quiet_fds() -> Iterator[None]:
    """JSBSim prints its banner and model warnings from C++ to fd 1/2; keep them off our stdout."""
    saved = [os.dup(1), os.dup(2)]
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 1)
        os.dup2(devnull, 2)
        yield
    finally:
        os.dup2(saved[0], 1)
        os.dup2(saved[1], 2)
        for fd in (*saved, devnull):
            os.close(fd)


class F450Physics:
    """The JSBSim F450 as a plant: throttles in, truth state out.

    Args:
        origin: geodetic position of NED (0, 0, 0).
        terrain: the ground; its height under the vehicle is JSBSim's terrain elevation.
        wind: optional wind model, advanced once per step.
    """

    DT_S = 1.0 / 120.0

    def __init__(self, origin: GeoOrigin, terrain: Terrain, wind: WindModel | None = None) -> None:
        self.dt_s = self.DT_S
        self.origin = origin
        self.terrain = terrain
        self.wind = wind
        # the data beside the module that is imported (jsbsim's own default looks in the interpreter's
        # site-packages folders only, which misses an install on PYTHONPATH or in another environment)
        root = Path(jsbsim.__file__).parent
        with _quiet_fds():
            fdm = jsbsim.FGFDMExec(str(root) if (root / "aircraft").is_dir() else None)
            fdm.set_debug_level(0)
            if not fdm.load_model("F450"):
                raise RuntimeError("JSBSim could not load its bundled F450 model")
        fdm.set_dt(self.DT_S)
        self._fdm = fdm
        pm = fdm.get_property_manager()

        def node(name: str) -> jsbsim.FGPropertyNode:
            n = pm.get_node(name, True)
            if n is None:
                raise RuntimeError(f"JSBSim property {name!r} is missing from the F450 model")
            return n

        self._esc = [node(p) for p in _ESC_PROPS]
        self._lat = node("position/lat-geod-deg")
        self._lon = node("position/long-gc-deg")
        self._alt = node("position/h-sl-meters")
        self._vel = [node(f"velocities/v-{a}-fps") for a in ("north", "east", "down")]
        self._euler = [node(f"attitude/{a}-rad") for a in ("phi", "theta", "psi")]
        self._rates = [node(f"velocities/{a}-rad_sec") for a in ("p", "q", "r")]
        self._wow = [node(f"gear/unit[{i}]/WOW") for i in range(3)]
        self._thrust = [node(f"propulsion/engine[{i}]/thrust-lbs") for i in range(MOTOR_COUNT)]
        self._terrain_ft = node("position/terrain-elevation-asl-ft")
        self._wind = [node(f"atmosphere/wind-{a}-fps") for a in ("north", "east", "down")]
        self._sim_time = node("simulation/sim-time-sec")
        self._force = [node(f"forces/fb{a}-total-lbs") for a in ("x", "y", "z")]  # all but gravity
        self._mass_slugs = node("inertia/mass-slugs")
        # what state() reads every step, as bound getters in one tuple (a lock step reads it 250 times
        # a simulated second: one comprehension instead of a generator per group)
        head = (self._lat, self._lon, self._alt, *self._euler, *self._vel, *self._rates, self._sim_time)
        self._state_reads = tuple(n.get_double_value for n in (*head, *self._wow, *self._thrust))
        self._wow_at = (len(head), len(head) + len(self._wow))  # the gear legs in what state() reads
        self._force_reads = tuple(n.get_double_value for n in (*self._force, self._mass_slugs))
        self._ground_height_m = 0.0
        self._t0_s = 0.0
        self._last_pos: Vec3 = (0.0, 0.0, 0.0)
        self._prev_pos: Vec3 = (0.0, 0.0, 0.0)  # a step before _last_pos
        self._contact = True
        # after a collision the airframe is a wreck at the foot of what it struck: JSBSim is stepped
        # no more (its ground reaction inside a wall blows up), the wreck's clock runs on
        self.collision: Collision | None = None
        self._wreck: VehicleState | None = None
        fdm["fcs/ScasEngage"] = 0.0
        self.reset((0.0, 0.0, -GEAR_HEIGHT_M), 0.0)

    def reset(self, pos_ned_m: Vec3, yaw_rad: float) -> None:
        """Place the vehicle at rest at ``pos_ned_m`` with heading ``yaw_rad``, motors stopped.

        A vehicle placed below ``GEAR_HEIGHT_M`` above the ground is lifted onto its gear.
        """
        n, e, d = pos_ned_m
        ground = self.terrain.height_m(n, e)
        d = min(d, -(ground + GEAR_HEIGHT_M))
        lat, lon, alt = self.origin.to_geodetic(n, e, d)
        fdm = self._fdm
        self._ground_height_m = ground
        fdm["ic/lat-geod-deg"] = lat
        fdm["ic/long-gc-deg"] = lon
        fdm["ic/h-sl-ft"] = alt / FT_M
        fdm["ic/terrain-elevation-ft"] = (self.origin.alt_m + ground) / FT_M
        fdm["ic/psi-true-deg"] = math.degrees(yaw_rad)
        fdm["ic/theta-deg"] = 0.0
        fdm["ic/phi-deg"] = 0.0
        for k in ("ic/u-fps", "ic/v-fps", "ic/w-fps", "ic/p-rad_sec", "ic/q-rad_sec", "ic/r-rad_sec"):
            fdm[k] = 0.0
        for esc in self._esc:
            esc.set_double_value(0.0)
        with _quiet_fds():
            fdm.run_ic()
        fdm["propulsion/set-running"] = -1
        self._t0_s = self._sim_time.get_double_value()
        self._last_pos = self._prev_pos = (n, e, d)
        self.collision = None
        self._wreck = None

    def set_dt(self, dt_s: float) -> None:
        """Step length from now on (``DT_S`` unless an external autopilot sets its own rate)."""
        if not 0.0 < dt_s <= 0.05:
            raise ValueError(f"physics step must be in (0, 0.05] s, got {dt_s}")
        self.dt_s = dt_s
        self._fdm.set_dt(dt_s)

    def specific_force_frd(self) -> Vec3:
        """What an accelerometer at the CG reads, body FRD, m/s^2: every force but gravity over the
        mass (at rest on the gear, (0, 0, -g))."""
        if self._wreck is not None:
            return (0.0, 0.0, -G_M_S2)
        fx, fy, fz, mass_slugs = (read() for read in self._force_reads)
        k = LBF_N / (mass_slugs * _SLUG_KG)
        return (fx * k, fy * k, fz * k)

    def step(self, throttles: tuple[float, float, float, float]) -> None:
        """Advance one JSBSim step (``dt_s``) with ESC commands in [0, 1], JSBSim motor order."""
        if self._wreck is not None:
            self._wreck = replace(self._wreck, t_s=self._wreck.t_s + self.dt_s)
            return
        for esc, th in zip(self._esc, throttles, strict=True):
            esc.set_double_value(min(1.0, max(0.0, th)))
        if self.wind is not None:
            w = self.wind.step(self.dt_s)
            for node, v in zip(self._wind, w, strict=True):
                node.set_double_value(v / FT_M)
        pos = self._last_pos  # the ground under the vehicle at the start of the step
        ground = self.terrain.height_m(pos[0], pos[1])
        if ground - self._ground_height_m > WALL_STEP_M and ground > -pos[2] - GEAR_HEIGHT_M:
            self._crash(ground)
            return
        if ground != self._ground_height_m:
            self._ground_height_m = ground
            self._terrain_ft.set_double_value((self.origin.alt_m + ground) / FT_M)
        if self._contact and self.dt_s > CONTACT_DT_S:
            # on the gear: JSBSim's ground reactions need a finer step (at 120 Hz a resting F450 creeps
            # about 3 cm/s and bounces a few mm; at 240 Hz and finer it stays put)
            k = math.ceil(self.dt_s / CONTACT_DT_S - 1e-9)
            self._fdm.set_dt(self.dt_s / k)
            for _ in range(k):
                self._fdm.run()
            self._fdm.set_dt(self.dt_s)
        else:
            self._fdm.run()

    def _crash(self, struck_up_m: float) -> None:
        """The ground under the vehicle rose above it in one step (:data:`WALL_STEP_M`): it flew into
        a wall. Recorded as :attr:`collision`; the wreck rests where the vehicle was a step before,
        on the ground it flew over, motors stopped."""
        n, e, _d = self._prev_pos
        s = self.state()
        before = self._ground_height_m
        self.collision = Collision(s.t_s, s.pos_ned_m, math.hypot(*s.vel_ned_m_s), before, struck_up_m)
        yaw = s.euler_rad[2]
        self._wreck = VehicleState(
            t_s=s.t_s + self.dt_s,  # this step's time passes
            pos_ned_m=(n, e, -(before + GEAR_HEIGHT_M)),
            vel_ned_m_s=(0.0, 0.0, 0.0),
            quat=euler_to_quat(0.0, 0.0, yaw),
            euler_rad=(0.0, 0.0, yaw),
            rates_frd_rad_s=(0.0, 0.0, 0.0),
            ground_height_m=before,
            on_ground=True,
            thrust_n=0.0,
        )

    def state(self) -> VehicleState:
        """Read the truth state after the last step."""
        if self._wreck is not None:
            return self._wreck
        v = [read() for read in self._state_reads]
        w0, w1 = self._wow_at
        lat, lon, alt, roll, pitch, psi, vn, ve, vd, p, q, r, t = v[:w0]
        pos = self.origin.to_ned(lat, lon, alt)
        yaw = wrap_pi(psi)
        self._prev_pos, self._last_pos = self._last_pos, pos
        self._contact = max(v[w0:w1]) > 0.5  # a gear leg's weight on wheels
        return VehicleState(
            t_s=t - self._t0_s,
            pos_ned_m=pos,
            vel_ned_m_s=(vn * FT_M, ve * FT_M, vd * FT_M),
            quat=euler_to_quat(roll, pitch, yaw),
            euler_rad=(roll, pitch, yaw),
            rates_frd_rad_s=(p, q, r),
            ground_height_m=self._ground_height_m,
            on_ground=self._contact,
            thrust_n=sum(v[w1:]) * LBF_N,
        )
