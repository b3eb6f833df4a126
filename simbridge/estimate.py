"""The emulated autopilot's state estimate: the truth with an EKF's errors (``--ekf-error``, issue 19).

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
the truth ``lag_s`` late. ``nominal`` is a healthy GPS + EKF multicopter (figures of the order ArduPilot
and PX4 logs show with a u-blox M8/M9 receiver); ``off`` is the truth.
"""

from __future__ import annotations

import collections
import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from simbridge.geo import Quat, Vec3, quat_to_euler
from simbridge.physics import VehicleState

__all__ = ["PRESETS", "EstimateError", "EstimateErrorConfig", "estimate_preset"]


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


PRESETS: dict[str, EstimateErrorConfig | None] = {"off": None, "nominal": EstimateErrorConfig()}


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

    def __init__(self, config: EstimateErrorConfig, rng: np.random.Generator) -> None:
        self.config = config
        self.rng = rng
        c = config
        sig = np.array([c.pos_bias_sigma_m, c.pos_bias_sigma_m, c.vert_bias_sigma_m])
        self._pos_sigma = sig
        self._att_sigma = math.radians(c.att_bias_sigma_deg)
        self.pos_bias = rng.normal(0.0, 1.0, 3) * sig  # stationary from the start
        self.att_bias = rng.normal(0.0, 1.0, 3) * self._att_sigma
        self._history: collections.deque[VehicleState] = collections.deque()
        self._estimate: VehicleState | None = None
        self._t_last: float | None = None

    @property
    def bias_ned_m(self) -> Vec3:
        """The position bias now: the autopilot's frame is shifted by it, so a target ``p`` in that
        frame is flown to ``p - bias`` in the world."""
        b = self.pos_bias
        return (float(b[0]), float(b[1]), float(b[2]))

    def step(self, s: VehicleState) -> VehicleState:
        """The estimate at ``s.t_s`` given the truth ``s`` (this step's state)."""
        c = self.config
        dt = 0.0 if self._t_last is None else max(0.0, s.t_s - self._t_last)
        self._t_last = s.t_s
        if dt > 0.0:
            self.pos_bias = self._gauss_markov(self.pos_bias, self._pos_sigma, c.pos_bias_tau_s, dt)
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
        p0, p1, p2 = (float(p + b + n) for p, b, n in zip(pos_ned_m, self.pos_bias, noise, strict=True))
        att = self.att_bias + self.rng.normal(0.0, math.radians(c.att_noise_deg), 3)
        return (p0, p1, p2), _small_rotation(quat, float(att[0]), float(att[1]), float(att[2]))

    def estimate(self) -> VehicleState | None:
        return self._estimate
