"""A multicopter controller in the style of PX4's: position -> velocity -> acceleration ->
attitude + collective thrust -> body rates -> torques -> motor mixer -> ESC commands.

Everything runs at the physics rate (120 Hz) in plain floats: for 3-vectors this is several
times faster than NumPy, which matters for the real-time factor.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from simbridge.geo import Quat, Vec3
from simbridge.physics import VehicleState

G_M_S2 = 9.80665
MASS_KG = 1.4  # F450 Mass.xml
INERTIA_KG_M2 = (0.0190, 0.0190, 0.0252)
ARM_M = 0.1651  # motor offset along body x and y
THRUST_COEFF_N = 19.7  # static thrust per motor ~ THRUST_COEFF_N * esc**2 near hover, fitted on the model
YAW_MOMENT_M = 0.016  # rotor drag torque per newton of thrust, used only to scale the yaw mixer
# JSBSim engine order FR, AL, FL, AR: (x sign, y sign, yaw sign) of each motor.
_MOTORS = ((1.0, 1.0, 1.0), (-1.0, -1.0, 1.0), (1.0, -1.0, -1.0), (-1.0, 1.0, -1.0))


@dataclass(frozen=True, slots=True)
class ControlLimits:
    """Flight envelope enforced by the controller (PX4 names in brackets)."""

    max_speed_xy_m_s: float = 5.0  # MPC_XY_VEL_MAX
    max_speed_up_m_s: float = 3.0  # MPC_Z_VEL_MAX_UP
    max_speed_down_m_s: float = 1.5  # MPC_Z_VEL_MAX_DN
    max_tilt_rad: float = math.radians(35.0)  # MPC_TILTMAX_AIR
    max_accel_xy_m_s2: float = 3.0  # MPC_ACC_HOR
    # ArduCopter's PSC_JERK_XY: its position controller shapes each target's path within it (None:
    # PX4's offboard control, which flies its setpoints without a planned path)
    max_jerk_xy_m_s3: float | None = None
    max_accel_z_m_s2: float = 3.0  # MPC_ACC_UP_MAX / MPC_ACC_DOWN_MAX
    max_yaw_rate_rad_s: float = math.radians(60.0)  # MPC_YAWRAUTO_MAX

    def __post_init__(self) -> None:
        for name in self.__dataclass_fields__:
            value = getattr(self, name)
            if value is None and name == "max_jerk_xy_m_s3":
                continue
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"ControlLimits.{name} must be a positive number, got {value!r}")
        if self.max_tilt_rad >= math.radians(89):
            raise ValueError(f"ControlLimits.max_tilt_rad must be < 89 deg, got {self.max_tilt_rad}")


@dataclass(frozen=True, slots=True)
class Setpoint:
    """A flight target. Each axis group is either a position or a velocity.

    Args:
        pos_ne_m: horizontal position target (north, east) or None for velocity control.
        pos_d_m: vertical position target (down) or None for velocity control.
        vel_ned_m_s: velocity target for axes without a position, feed-forward otherwise.
        yaw_rad: heading target; None with ``yaw_rate_rad_s`` None holds the current heading.
        yaw_rate_rad_s: yaw-rate target, used when ``yaw_rad`` is None.
    """

    pos_ne_m: tuple[float, float] | None = None
    pos_d_m: float | None = None
    vel_ned_m_s: Vec3 = (0.0, 0.0, 0.0)
    yaw_rad: float | None = None
    yaw_rate_rad_s: float | None = None

    @staticmethod
    def hold(pos_ned_m: Vec3, yaw_rad: float | None = None) -> Setpoint:
        return Setpoint(pos_ne_m=(pos_ned_m[0], pos_ned_m[1]), pos_d_m=pos_ned_m[2], yaw_rad=yaw_rad)


def _clamp(x: float, lo: float, hi: float) -> float:
    return lo if x < lo else hi if x > hi else x


def _attitude_from_thrust_dir(z_b: Vec3, yaw_rad: float) -> Quat:
    """Quaternion whose body z axis is ``z_b`` (NED, unit) with heading ``yaw_rad``."""
    zx, zy, zz = z_b
    # y_c: the heading's right vector in the horizontal plane; x_b = y_c x z_b, y_b = z_b x x_b
    ycx, ycy = -math.sin(yaw_rad), math.cos(yaw_rad)
    xx, xy, xz = ycy * zz, -ycx * zz, ycx * zy - ycy * zx
    n = math.sqrt(xx * xx + xy * xy + xz * xz)
    xx, xy, xz = xx / n, xy / n, xz / n
    yx, yy, yz = zy * xz - zz * xy, zz * xx - zx * xz, zx * xy - zy * xx
    # rotation matrix with columns x_b, y_b, z_b -> quaternion (Shepperd)
    m00, m11, m22 = xx, yy, zz
    tr = m00 + m11 + m22
    if tr > 0:
        s = math.sqrt(tr + 1.0) * 2
        return (0.25 * s, (yz - zy) / s, (zx - xz) / s, (xy - yx) / s)
    if m00 > m11 and m00 > m22:
        s = math.sqrt(1.0 + m00 - m11 - m22) * 2
        return ((yz - zy) / s, 0.25 * s, (yx + xy) / s, (zx + xz) / s)
    if m11 > m22:
        s = math.sqrt(1.0 + m11 - m00 - m22) * 2
        return ((zx - xz) / s, (yx + xy) / s, 0.25 * s, (zy + yz) / s)
    s = math.sqrt(1.0 + m22 - m00 - m11) * 2
    return ((xy - yx) / s, (zx + xz) / s, (zy + yz) / s, 0.25 * s)


class MulticopterController:
    """Cascaded position/velocity/attitude/rate controller for the F450.

    Call :meth:`update` once per physics step; it returns ESC commands in JSBSim motor order.
    """

    # gains (PX4 parameter names where one exists)
    POS_P_XY = 0.95  # MPC_XY_P
    POS_P_Z = 1.0  # MPC_Z_P
    VEL_P_XY, VEL_I_XY, VEL_D_XY = 1.8, 0.4, 0.2  # MPC_XY_VEL_*_ACC
    VEL_P_Z, VEL_I_Z = 4.0, 2.0  # MPC_Z_VEL_*_ACC
    ATT_P = (6.5, 6.5, 2.8)  # MC_ROLL_P, MC_PITCH_P, MC_YAW_P
    RATE_P = (18.0, 18.0, 8.0)  # angular acceleration per rate error, 1/s
    RATE_I = (6.0, 6.0, 2.0)
    RATE_D = (0.35, 0.35, 0.0)
    BRAKE_FRACTION = 0.6  # plan stops with this share of the acceleration limit
    MAX_RATE_RAD_S = (math.radians(220), math.radians(220), math.radians(200))

    def __init__(self, limits: ControlLimits | None = None) -> None:
        self.limits = limits or ControlLimits()
        self.reset()

    def reset(self) -> None:
        """Forget integrators and filtered setpoints (call on arming or a vehicle reset)."""
        self._vel_int = [0.0, 0.0, 0.0]
        self._prev_vel: Vec3 | None = None
        self._vel_sp: list[float] | None = None
        self._acc_ff = [0.0, 0.0]
        self._rate_int = [0.0, 0.0, 0.0]
        self._prev_rates: Vec3 | None = None
        self._yaw_hold: float | None = None
        self.thrust_n = 0.0

    def update(self, s: VehicleState, sp: Setpoint, dt_s: float) -> tuple[float, float, float, float]:
        lim = self.limits
        # --- position -> velocity setpoint
        vn, ve, vd = sp.vel_ned_m_s
        if sp.pos_ne_m is not None:
            vn += self.POS_P_XY * (sp.pos_ne_m[0] - s.pos_ned_m[0])
            ve += self.POS_P_XY * (sp.pos_ne_m[1] - s.pos_ned_m[1])
        if sp.pos_d_m is not None:
            vd += self.POS_P_Z * (sp.pos_d_m - s.pos_ned_m[2])
        # speed cap: the envelope, and the speed from which we can still stop at the target
        cap_xy = lim.max_speed_xy_m_s
        if sp.pos_ne_m is not None:
            dist = math.hypot(sp.pos_ne_m[0] - s.pos_ned_m[0], sp.pos_ne_m[1] - s.pos_ned_m[1])
            cap_xy = min(cap_xy, math.sqrt(2 * self.BRAKE_FRACTION * lim.max_accel_xy_m_s2 * dist))
        h = math.hypot(vn, ve)
        if h > cap_xy:
            vn, ve = vn * cap_xy / h, ve * cap_xy / h
        cap_up, cap_down = lim.max_speed_up_m_s, lim.max_speed_down_m_s
        if sp.pos_d_m is not None:
            stop = math.sqrt(
                2 * self.BRAKE_FRACTION * lim.max_accel_z_m_s2 * abs(sp.pos_d_m - s.pos_ned_m[2])
            )
            cap_up, cap_down = min(cap_up, stop), min(cap_down, stop)
        vd = _clamp(vd, -cap_up, cap_down)
        # slew-limit the velocity setpoint (smooth starts and stops, like PX4's jerk-limited path)
        if self._vel_sp is None:
            self._vel_sp = list(s.vel_ned_m_s)
        prev = self._vel_sp
        dn, de = vn - prev[0], ve - prev[1]
        dh = math.hypot(dn, de)
        max_dh = lim.max_accel_xy_m_s2 * dt_s
        if dh > max_dh:
            dn, de = dn * max_dh / dh, de * max_dh / dh
        dz = _clamp(vd - prev[2], -lim.max_accel_z_m_s2 * dt_s, lim.max_accel_z_m_s2 * dt_s)
        vel_sp = (prev[0] + dn, prev[1] + de, prev[2] + dz)
        # the shaped setpoint's own acceleration fed forward, across changing at most at the jerk
        # limit: a step in the position target tilts the airframe over some tenths of a second, not
        # in one physics step (a tilt step, at the attitude loop's rate limit, rocked the airframe)
        fn, fe = dn / dt_s - self._acc_ff[0], de / dt_s - self._acc_ff[1]
        if lim.max_jerk_xy_m_s3 is not None:
            f, max_f = math.hypot(fn, fe), lim.max_jerk_xy_m_s3 * dt_s
            if f > max_f:
                fn, fe = fn * max_f / f, fe * max_f / f
        self._acc_ff = [self._acc_ff[0] + fn, self._acc_ff[1] + fe]
        acc_ff = (self._acc_ff[0], self._acc_ff[1], dz / dt_s)
        self._vel_sp = list(vel_sp)

        # --- velocity -> acceleration setpoint (PID, derivative on measurement)
        v = s.vel_ned_m_s
        pv = self._prev_vel or v
        self._prev_vel = v
        acc = [0.0, 0.0, 0.0]
        for i in range(3):
            err = vel_sp[i] - v[i]
            if i < 2:
                p, ki, kd = self.VEL_P_XY, self.VEL_I_XY, self.VEL_D_XY
            else:
                p, ki, kd = self.VEL_P_Z, self.VEL_I_Z, 0.0
            self._vel_int[i] = _clamp(self._vel_int[i] + ki * err * dt_s, -4.0, 4.0)
            acc[i] = acc_ff[i] + p * err + self._vel_int[i] - kd * (v[i] - pv[i]) / dt_s

        # --- acceleration -> thrust vector with tilt limit
        fx, fy, fz = acc[0], acc[1], acc[2] - G_M_S2  # specific force the rotors must produce
        up = max(-fz, 0.2 * G_M_S2)
        horiz = math.hypot(fx, fy)
        max_h = up * math.tan(lim.max_tilt_rad)
        if horiz > max_h:
            fx, fy = fx * max_h / horiz, fy * max_h / horiz
        fz = -up
        f_norm = math.sqrt(fx * fx + fy * fy + fz * fz)
        thrust_n = MASS_KG * f_norm
        z_b = (-fx / f_norm, -fy / f_norm, -fz / f_norm)

        # --- yaw target
        yaw = s.euler_rad[2]
        yaw_rate_ff = 0.0
        if sp.yaw_rad is not None:
            self._yaw_hold = sp.yaw_rad
        elif sp.yaw_rate_rad_s is not None:
            yaw_rate_ff = _clamp(sp.yaw_rate_rad_s, -lim.max_yaw_rate_rad_s, lim.max_yaw_rate_rad_s)
            self._yaw_hold = None
        elif self._yaw_hold is None:
            self._yaw_hold = yaw
        yaw_sp = yaw if self._yaw_hold is None else self._yaw_hold
        q_sp = _attitude_from_thrust_dir(z_b, yaw_sp)
        return self._attitude_rates_mix(s, q_sp, thrust_n, yaw_rate_ff, dt_s)

    def _attitude_rates_mix(
        self, s: VehicleState, q_sp: Quat, thrust_n: float, yaw_rate_ff: float, dt_s: float
    ) -> tuple[float, float, float, float]:
        lim = self.limits
        # attitude error quaternion q_e = q^-1 * q_sp (body frame)
        w, x, y, z = s.quat
        a, b, c, d = q_sp
        ew = w * a + x * b + y * c + z * d
        ex = w * b - x * a - y * d + z * c
        ey = w * c + x * d - y * a - z * b
        ez = w * d - x * c + y * b - z * a
        sgn = 1.0 if ew >= 0 else -1.0
        err = (2 * sgn * ex, 2 * sgn * ey, 2 * sgn * ez)
        rate_sp = [self.ATT_P[i] * err[i] for i in range(3)]
        rate_sp[2] += yaw_rate_ff
        rate_sp[2] = _clamp(rate_sp[2], -lim.max_yaw_rate_rad_s * 1.5, lim.max_yaw_rate_rad_s * 1.5)
        rates = s.rates_frd_rad_s
        prev = self._prev_rates or rates
        self._prev_rates = rates
        torque = [0.0, 0.0, 0.0]
        for i in range(3):
            r_sp = _clamp(rate_sp[i], -self.MAX_RATE_RAD_S[i], self.MAX_RATE_RAD_S[i])
            e = r_sp - rates[i]
            self._rate_int[i] = _clamp(self._rate_int[i] + self.RATE_I[i] * e * dt_s, -3.0, 3.0)
            alpha = self.RATE_P[i] * e + self._rate_int[i] - self.RATE_D[i] * (rates[i] - prev[i]) / dt_s
            torque[i] = INERTIA_KG_M2[i] * alpha
        self.thrust_n = thrust_n
        # mixer: roll torque = -y*T, pitch torque = x*T, yaw torque = sign*k*T per rotor
        base = thrust_n / 4
        tx = torque[0] / (4 * ARM_M)
        ty = torque[1] / (4 * ARM_M)
        tz = torque[2] / (4 * YAW_MOMENT_M)
        out = []
        for sx, sy, sz in _MOTORS:
            t_i = base - sy * tx + sx * ty + sz * tz
            out.append(math.sqrt(max(t_i, 0.0) / THRUST_COEFF_N))
        return (out[0], out[1], out[2], out[3])
