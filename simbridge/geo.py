"""Small pure conversions: geodetic <-> local NED, Euler <-> quaternion.

Quaternions are ``(w, x, y, z)`` and rotate body FRD vectors into the NED world frame.
Euler angles follow the aerospace ZYX convention (yaw, then pitch, then roll).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

WGS84_A_M = 6378137.0
WGS84_E2 = 6.69437999014e-3

Quat = tuple[float, float, float, float]
Vec3 = tuple[float, float, float]


@dataclass(frozen=True, slots=True)
class GeoOrigin:
    """The geodetic position of NED (0, 0, 0): the scenario origin on the ground.

    Over a few kilometres a local tangent plane with the WGS-84 radii of curvature at the
    origin is accurate to centimetres, which is all the simulator needs.
    """

    lat_deg: float = 47.397742
    lon_deg: float = 8.545594
    alt_m: float = 488.0

    @property
    def _radii_m(self) -> tuple[float, float]:
        return _tangent_plane_radii_m(self.lat_deg, self.alt_m)

    def to_ned(self, lat_deg: float, lon_deg: float, alt_m: float) -> Vec3:
        """Geodetic (deg, deg, m above the ellipsoid) -> local NED metres."""
        r_north, r_east = self._radii_m
        return (
            math.radians(lat_deg - self.lat_deg) * r_north,
            math.radians(lon_deg - self.lon_deg) * r_east,
            self.alt_m - alt_m,
        )

    def to_geodetic(self, north_m: float, east_m: float, down_m: float) -> Vec3:
        """Local NED metres -> geodetic (lat deg, lon deg, alt m above the ellipsoid)."""
        r_north, r_east = self._radii_m
        return (
            self.lat_deg + math.degrees(north_m / r_north),
            self.lon_deg + math.degrees(east_m / r_east),
            self.alt_m - down_m,
        )


@functools.lru_cache(maxsize=8)
def _tangent_plane_radii_m(lat_deg: float, alt_m: float) -> tuple[float, float]:
    """Metres per radian of latitude and of longitude at a latitude and height (WGS-84)."""
    lat = math.radians(lat_deg)
    s2 = math.sin(lat) ** 2
    r_n = WGS84_A_M / math.sqrt(1.0 - WGS84_E2 * s2)  # prime vertical
    r_m = r_n * (1.0 - WGS84_E2) / (1.0 - WGS84_E2 * s2)  # meridian
    return r_m + alt_m, (r_n + alt_m) * math.cos(lat)


def euler_to_quat(roll_rad: float, pitch_rad: float, yaw_rad: float) -> Quat:
    """ZYX Euler angles -> quaternion (w, x, y, z), body FRD -> NED."""
    cr, sr = math.cos(roll_rad / 2), math.sin(roll_rad / 2)
    cp, sp = math.cos(pitch_rad / 2), math.sin(pitch_rad / 2)
    cy, sy = math.cos(yaw_rad / 2), math.sin(yaw_rad / 2)
    return (
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    )


def quat_to_euler(q: Quat) -> Vec3:
    """Quaternion (w, x, y, z) -> ZYX Euler (roll, pitch, yaw) in radians."""
    w, x, y, z = q
    roll = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2 * (w * y - z * x))))
    yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return roll, pitch, yaw


def rotate_body_to_ned(q: Quat, v_frd: Vec3) -> Vec3:
    """Rotate a body FRD vector into NED with quaternion (w, x, y, z)."""
    w, x, y, z = q
    vx, vy, vz = v_frd
    # v' = v + 2w (u x v) + 2 u x (u x v), u = (x, y, z)
    cx = y * vz - z * vy
    cy = z * vx - x * vz
    cz = x * vy - y * vx
    return (
        vx + 2 * (w * cx + y * cz - z * cy),
        vy + 2 * (w * cy + z * cx - x * cz),
        vz + 2 * (w * cz + x * cy - y * cx),
    )


def wrap_pi(angle_rad: float) -> float:
    """Wrap an angle to [-pi, pi)."""
    return (angle_rad + math.pi) % (2 * math.pi) - math.pi
