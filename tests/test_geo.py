"""Frame conventions: geodetic <-> NED, Euler <-> quaternion (w, x, y, z), body FRD -> NED."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from landfall_link.mavlink import LinkUrl, LinkUrlError, parse_signing_key
from simbridge.geo import GeoOrigin, euler_to_quat, quat_to_euler, rotate_body_to_ned, wrap_pi

angles = st.floats(min_value=-1.5, max_value=1.5)


@given(st.floats(-3000, 3000), st.floats(-3000, 3000), st.floats(-500, 100))
def test_geodetic_round_trip(n: float, e: float, d: float) -> None:
    origin = GeoOrigin()
    back = origin.to_ned(*origin.to_geodetic(n, e, d))
    assert back == pytest.approx((n, e, d), abs=1e-6)


def test_one_degree_of_latitude_is_about_111_km() -> None:
    origin = GeoOrigin(lat_deg=45.0, lon_deg=0.0, alt_m=0.0)
    n, _, _ = origin.to_ned(46.0, 0.0, 0.0)
    assert n == pytest.approx(111_132, rel=2e-3)


@given(angles, angles, st.floats(-3.1, 3.1))
def test_euler_quaternion_round_trip(roll: float, pitch: float, yaw: float) -> None:
    q = euler_to_quat(roll, pitch, yaw)
    assert math.fsum(c * c for c in q) == pytest.approx(1.0)
    assert quat_to_euler(q) == pytest.approx((roll, pitch, yaw), abs=1e-9)


def test_body_forward_points_along_heading() -> None:
    q = euler_to_quat(0.0, 0.0, math.pi / 2)  # facing east
    assert rotate_body_to_ned(q, (1.0, 0.0, 0.0)) == pytest.approx((0.0, 1.0, 0.0), abs=1e-12)
    assert rotate_body_to_ned(q, (0.0, 1.0, 0.0)) == pytest.approx((-1.0, 0.0, 0.0), abs=1e-12)
    nose_up = euler_to_quat(0.0, math.radians(30), 0.0)
    assert rotate_body_to_ned(nose_up, (1.0, 0.0, 0.0)) == pytest.approx(
        (math.cos(math.radians(30)), 0.0, -0.5)
    )


def test_wrap_pi() -> None:
    assert wrap_pi(3 * math.pi / 2) == pytest.approx(-math.pi / 2)
    assert wrap_pi(-0.1) == pytest.approx(-0.1)


def test_link_url_parsing() -> None:
    assert LinkUrl.parse("udpout:127.0.0.1:14550") == LinkUrl("udpout", "127.0.0.1", 14550)
    assert LinkUrl.parse("udp:14550") == LinkUrl("udpin", "0.0.0.0", 14550)
    assert LinkUrl.parse("udpin:0.0.0.0:14540") == LinkUrl("udpin", "0.0.0.0", 14540)
    for bad in ("14550", "tcp:5760", "udpout:host:port", "udp:70000"):
        with pytest.raises(LinkUrlError):
            LinkUrl.parse(bad)


def test_signing_key_parsing() -> None:
    assert parse_signing_key("00" * 32) == bytes(32)
    with pytest.raises(ValueError, match="32 bytes"):
        parse_signing_key("abcd")
    with pytest.raises(ValueError, match="hexadecimal"):
        parse_signing_key("zz" * 32)
