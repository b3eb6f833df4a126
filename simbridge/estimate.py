"""The emulated autopilot's state estimate: the truth with an EKF's errors (``--ekf-error``).

A real autopilot knows where it is only through its estimator: GPS error that wanders over tens of
seconds, a little noise, a lag of some tens of milliseconds behind the airframe, a fraction of a degree of
attitude error. The emulation publishes its telemetry (LOCAL_POSITION_NED, ATTITUDE, ATTITUDE_QUATERNION,
GLOBAL_POSITION_INT, GPS_RAW_INT, VFR_HUD) from :meth:`EstimateError.estimate` and, like a real autopilot,
flies position targets in its *estimated* frame: a target ``p`` is reached when the estimate says so,
which puts the airframe at ``p - bias``.

Model (per axis, seeded by the episode's ``--seed``): position bias a first-order Gauss-Markov process
(``pos_bias_sigma_m`` horizontal, ``vert_bias_sigma_m`` vertical, correlation time ``pos_bias_tau_s``),
white position noise ``pos_noise_m``; attitude bias Gauss-Markov (``att_bias_sigma_deg``, ``att_bias_tau_s``)
plus white noise ``att_noise_deg``, as a small rotation applied to the true attitude; the estimate follows
the truth ``lag_s`` late. The position bias the vehicle flies on passes through two first-order lags
of half ``bias_smooth_s`` each as well: an EKF fuses its 5-10 Hz fixes through the IMU, so its error
moves smoothly, while a Gauss-Markov process steps afresh each physics step; the position controller,
which feeds its setpoint's own acceleration forward, turned those steps into 1-2 m/s2 of noise and
rocked the airframe at up to 77 degrees a second hovering (3 with the lags; tests/test_estimate.py).
``nominal`` is a healthy GPS + EKF multicopter (figures of the order ArduPilot
and PX4 logs show with a u-blox M8/M9 receiver); ``off`` is the truth.

A GPS fault (``--gps-fault``) is a lie on top: the first time the vehicle descends below a
height above the ground, the position the GPS reports moves by a fixed offset, at once (a glitch, a
spoofer taking over) or growing evenly over some seconds (a slow drift). :class:`GpsFault` decides when
and how much; the emulation's estimate follows the GPS at once (a real EKF takes a few seconds: with
real ArduCopter simbridge sets the firmware's own ``SIM_GPS1_GLTCH_X/Y`` instead).
"""

from __future__ import annotations

import collections
import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from simbridge.geo import Quat, Vec3, quat_to_euler
from simbridge.physics import VehicleState

__all__ = ["PRESETS", "EstimateError", "EstimateErrorConfig", "GpsFault", "GpsFaultConfig", "estimate_preset"]


@dataclass(frozen=True, slots=True)
class EstimateErrorConfig:
    pos_bias_sigma_m: float = 0.5
    vert_bias_sigma_m: float = 0.3
    pos_bias_tau_s: float = 60.0
    pos_noise_m: float = 0.05
    att_bias_sigma_deg: float = 0.3
    att_bias_tau_s: float = 30.0
    att_noise_deg: float = 0.1
    lag_s: float = 0.05
    bias_smooth_s: float = 1.0


PRESETS: dict[str, EstimateErrorConfig | None] = {"off": None, "nominal": EstimateErrorConfig()}
TRUTH = EstimateErrorConfig(0.0, 0.0, 60.0, 0.0, 0.0, 30.0, 0.0, 0.0)  # no error of its own


@dataclass(frozen=True, slots=True)
class GpsFaultConfig:
    """``offset_ne_m``: where the GPS's position moves (north, east metres); ``below_m``: the height
    above the ground whose first crossing downward starts it; ``ramp_s``: 0 a jump, else the seconds
    over which it grows evenly to the full offset (a drift)."""

    offset_ne_m: tuple[float, float]
    below_m: float = 40.0
    ramp_s: float = 0.0

    def __post_init__(self) -> None:
        if not all(math.isfinite(v) for v in self.offset_ne_m):
            raise ValueError(f"--gps-fault must be two finite numbers N,E, got {self.offset_ne_m}")
        if not self.below_m > 0:
            raise ValueError(f"--gps-fault-below must be > 0 m, got {self.below_m}")
        if not self.ramp_s >= 0:
            raise ValueError(f"--gps-fault-ramp must be >= 0 s, got {self.ramp_s}")


class GpsFault:
    """The GPS fault's offset now, fed each physics step's truth (:meth:`update`). ``on_start`` is
    called once, with the simulated time and the height, when it starts."""

    def __init__(
        self, config: GpsFaultConfig, on_start: Callable[[float, float], None] | None = None
    ) -> None:
        self.config = config
        self.on_start = on_start
        self.started_at_s: float | None = None
        self.offset_ne_m: tuple[float, float] = (0.0, 0.0)
        self._was_above = False

    def update(self, s: VehicleState) -> tuple[float, float]:
        c = self.config
        if self.started_at_s is None:
            above = s.height_agl_m >= c.below_m
            if self._was_above and not above:
                self.started_at_s = s.t_s
                if self.on_start is not None:
                    self.on_start(s.t_s, s.height_agl_m)
            self._was_above = self._was_above or above
        if self.started_at_s is not None:
            k = 1.0 if c.ramp_s <= 0 else min(1.0, (s.t_s - self.started_at_s) / c.ramp_s)
            self.offset_ne_m = (k * c.offset_ne_m[0], k * c.offset_ne_m[1])
        return self.offset_ne_m


def estimate_preset(name: str) -> EstimateErrorConfig | None:
    try:
        return PRESETS[name]
    except KeyError:
        raise ValueError(f"--ekf-error must be one of {', '.join(PRESETS)}, got {name!r}") from None


def _small_rotation(q: Quat, rx: float, ry: float, rz: float) -> Quat:
    """``q`` followed by a small body rotation (radians about x, y, z)."""
    angle = math.sqrt(rx * rx + ry * ry + rz * rz)
    if angle < 1e-12:
        return q
    s = math.sin(angle / 2) / angle
    d = (math.cos(angle / 2), rx * s, ry * s, rz * s)
    w1, x1, y1, z1 = q
    w2, x2, y2, z2 = d
    return (
        w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
        w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
        w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
        w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
    )


class EstimateError:
    """Advance with :meth:`step` once per physics step; read :meth:`estimate` and :attr:`bias_ned_m`."""

    def __init__(
        self, config: EstimateErrorConfig, rng: np.random.Generator, fault: GpsFault | None = None
    ) -> None:
        self.config = config
        self.rng = rng
        self.fault = fault
        c = config
        sig = np.array([c.pos_bias_sigma_m, c.pos_bias_sigma_m, c.vert_bias_sigma_m])
        self._pos_sigma = sig
        self._att_sigma = math.radians(c.att_bias_sigma_deg)
        self._pos_bias_gm = rng.normal(0.0, 1.0, 3) * sig  # stationary from the start
        self._pos_bias_lag = self._pos_bias_gm.copy()
        self.pos_bias = self._pos_bias_gm.copy()  # what the estimate carries: the process, smoothed
        self.att_bias = rng.normal(0.0, 1.0, 3) * self._att_sigma
        self._history: collections.deque[VehicleState] = collections.deque()
        self._estimate: VehicleState | None = None
        self._t_last: float | None = None

    @property
    def bias_ned_m(self) -> Vec3:
        """The position bias now (with the GPS fault's offset): the autopilot's frame is shifted by
        it, so a target ``p`` in that frame is flown to ``p - bias`` in the world."""
        b = self.pos_bias
        fn, fe = self.fault.offset_ne_m if self.fault is not None else (0.0, 0.0)
        return (float(b[0]) + fn, float(b[1]) + fe, float(b[2]))

    def step(self, s: VehicleState) -> VehicleState:
        """The estimate at ``s.t_s`` given the truth ``s`` (this step's state)."""
        c = self.config
        dt = 0.0 if self._t_last is None else max(0.0, s.t_s - self._t_last)
        self._t_last = s.t_s
        if self.fault is not None:
            self.fault.update(s)
        if dt > 0.0:
            self._pos_bias_gm = self._gauss_markov(self._pos_bias_gm, self._pos_sigma, c.pos_bias_tau_s, dt)
            # two lags of half the time each: the bias's acceleration stays bounded as well as its speed
            k = 1.0 if c.bias_smooth_s <= 0 else 1.0 - math.exp(-2.0 * dt / c.bias_smooth_s)
            self._pos_bias_lag = self._pos_bias_lag + k * (self._pos_bias_gm - self._pos_bias_lag)
            self.pos_bias = self.pos_bias + k * (self._pos_bias_lag - self.pos_bias)
            self.att_bias = self._gauss_markov(self.att_bias, self._att_sigma, c.att_bias_tau_s, dt)
        self._history.append(s)
        while len(self._history) > 1 and self._history[1].t_s <= s.t_s - c.lag_s:
            self._history.popleft()
        late = self._history[0]
        pos, quat = self._apply(late.pos_ned_m, late.quat)
        self._estimate = dataclasses.replace(
            late, t_s=s.t_s, pos_ned_m=pos, quat=quat, euler_rad=quat_to_euler(quat)
        )
        return self._estimate

    def _gauss_markov(self, x: np.ndarray, sigma: Any, tau_s: float, dt: float) -> np.ndarray:
        """One step of a first-order Gauss-Markov process of stationary deviation ``sigma``."""
        a = math.exp(-dt / tau_s)
        out: np.ndarray = a * x + math.sqrt(1 - a * a) * sigma * self.rng.normal(0.0, 1.0, 3)
        return out

    def perturb(self, pos_ned_m: Vec3, quat: Quat) -> tuple[Vec3, Quat]:
        """A pose as the estimator would report it now, for a vehicle holding still (no lag)."""
        return self._apply(pos_ned_m, quat)

    def _apply(self, pos_ned_m: Vec3, quat: Quat) -> tuple[Vec3, Quat]:
        """The bias and a fresh draw of noise, on position and attitude."""
        c = self.config
        noise = self.rng.normal(0.0, c.pos_noise_m, 3)
        p0, p1, p2 = (float(p + b + n) for p, b, n in zip(pos_ned_m, self.bias_ned_m, noise, strict=True))
        att = self.att_bias + self.rng.normal(0.0, math.radians(c.att_noise_deg), 3)
        return (p0, p1, p2), _small_rotation(quat, float(att[0]), float(att[1]), float(att[2]))

    def estimate(self) -> VehicleState | None:
        return self._estimate
