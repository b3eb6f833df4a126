"""Properties (hypothesis) of the recovery chain's LiDAR site check (stage 5 of
tests/test_chain_properties.py): any cloud gives a SiteCheck, two levels with nothing between are
rough rather than NaN, and a sweep of another shape is not measured.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from companion.guidance.frames import quat_to_matrix
from companion.perception.site_check import SiteCheck, check_site
from tests.test_chain_properties import LEVEL, QUICK, attitudes


# ----------------------------------------------------------------------------------- 5. site check
@st.composite
def site_clouds(draw: st.DrawFn) -> np.ndarray:
    """Sweeps around a site, as (N, 3 or 4) rows of north, east, up metres from it: empty, NaN rows,
    all far away, all at one point, scattered, level with some noise, or two levels at every spot (a
    step seen through, an overhang) with nothing at their median."""
    kind = draw(st.sampled_from(["empty", "nan", "far", "one_point", "scattered", "two_levels", "flat"]))
    cols = draw(st.sampled_from([3, 4]))
    rng = np.random.default_rng(draw(st.integers(0, 2**16)))
    n = draw(st.integers(1, 300))
    pts = np.zeros((n, cols))
    pts[:, :2] = rng.uniform(-3.0, 3.0, (n, 2))
    if kind == "empty":
        return pts[:0]
    if kind == "nan":
        pts[rng.random(n) < draw(st.floats(0.0, 1.0)), rng.integers(0, 3)] = np.nan
    elif kind == "far":
        pts[:, 0] += draw(st.floats(10.0, 1e5))
    elif kind == "one_point":
        pts[:] = np.array([0.0, 0.0, draw(st.floats(-20.0, 20.0)), 0.5][:cols])
    elif kind == "two_levels":
        pts = np.repeat(pts, 2, axis=0)
        pts[1::2, 2] = draw(st.floats(0.5, 20.0))
    elif kind == "flat":
        pts[:, :2] *= 3.0
        pts[:, 2] = rng.normal(0.0, draw(st.floats(0.0, 0.2)), n)
    else:
        pts[:, :3] = rng.uniform(-40.0, 40.0, (n, 3))
    return pts


@QUICK
@given(site_clouds(), attitudes(30.0), st.tuples(st.floats(-10.0, 10.0), st.floats(-10.0, 10.0)))
def test_check_site_any_cloud_gives_a_site_check(
    around_site: np.ndarray, quat: tuple[float, float, float, float], site_ne: tuple[float, float]
) -> None:
    pos = np.array([site_ne[0] + 3.0, site_ne[1] - 1.0, -30.0])
    ned = np.asarray(around_site[:, :3]) * [1.0, 1.0, -1.0] + [site_ne[0], site_ne[1], 0.0]
    cloud = around_site.copy()
    cloud[:, :3] = (ned - pos) @ quat_to_matrix(quat)  # body FRD: R^T (ned - pos), row by row
    check = check_site(cloud, tuple(pos), quat, site_ne)
    assert isinstance(check, SiteCheck)
    assert check.points >= 0
    assert check.clear == (not check.reasons)
    if check.measured:
        assert math.isfinite(check.surface_up_m)
        assert 0.0 <= check.roughness_m < math.inf
        assert 0.0 <= check.obstacle_m < math.inf
        assert check.edge_distance_m >= 0.0
    else:
        assert not check.clear


def test_check_site_two_levels_and_nothing_between_is_rough_not_nan() -> None:
    """Half the disc 10 m up, half 20 m up: no return lies near their median (15 m), so no surface:
    the roughness is the disc's whole spread (5 m), not the NaN std of nothing."""
    pts = np.array([[0.0, 0.0, 20.0], [0.1, 0.0, 20.0], [0.0, 0.1, 20.0]] * 2)
    pts[3:, 2] = 10.0
    check = check_site(pts, (0.0, 0.0, -30.0), LEVEL, (0.0, 0.0))
    assert check.points == 6
    assert check.roughness_m == pytest.approx(5.0)
    assert any("rough" in r for r in check.reasons)


@pytest.mark.parametrize("cloud", [np.zeros(3), np.zeros((4, 2)), np.zeros((2, 2, 3))], ids=str)
def test_check_site_sweep_of_another_shape_is_not_measured(cloud: np.ndarray) -> None:
    check = check_site(cloud, (0.0, 0.0, -30.0), LEVEL, (0.0, 0.0))
    assert not check.measured
    assert not check.clear
