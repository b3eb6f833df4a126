"""The LiDAR site check on sloped ground (companion/perception/site_check.py): heights are measured from
the plane fitted to the surface's returns in the rotor disc, so a lawn on a gentle slope is level
ground, not "rough" (measured from one level, a smooth 5 degree slope read 9 cm rough and a 9 degree
one held a 0.3 m "object": hillside meadows the vehicle could land on were refused one after
another); a slope over Surface ID's 8 degrees is refused as such, and what stands on a slope or grows
in rows across it still counts."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from companion.perception.site_check import check_site
from companion.reasoning.onboard import lidar_kind
from companion.site_ledger import Hazard, hazard_of
from simbridge.geo import euler_to_quat
from simbridge.world.hillside import generate_hillside
from simbridge.world.live import LiveWorld
from simbridge.world.model import SurfaceClass

DOWN = euler_to_quat(0.0, 0.0, 0.0)


def _slope(deg: float, rng: np.random.Generator, extra: str = "") -> tuple[np.ndarray, tuple]:
    """A level sweep 40 m above ground rising ``deg`` degrees eastward through the site (0, 0), 2 cm
    of noise; ``extra``: a 0.4 m box 1 m north of the site, or a crop's rows (0.6 m leaves, soil
    between them)."""
    north, east = rng.uniform(-8.0, 8.0, (2, 8000))
    up = math.tan(math.radians(deg)) * east + rng.normal(0.0, 0.02, north.size)
    if extra == "box":
        up += np.where((np.abs(north - 1.0) < 0.3) & (np.abs(east) < 0.3), 0.4, 0.0)
    elif extra == "crop":
        up += np.where((north % 0.75) < 0.45, 0.6, 0.12)
    frd = np.stack([north, east, 40.0 - up, np.ones_like(up)], axis=1)
    return frd, (0.0, 0.0, -40.0)


@pytest.mark.parametrize("deg", [0.0, 3.0, 5.0, 7.0])
def test_a_smooth_slope_up_to_surface_ids_limit_is_clear_and_measured(deg: float) -> None:
    frd, pos = _slope(deg, np.random.default_rng(1))
    check = check_site(frd, pos, DOWN, (0.0, 0.0))
    assert check.clear, check
    assert check.slope_deg == pytest.approx(deg, abs=0.3)
    assert check.roughness_m < 0.03  # the LiDAR's noise, not the slope
    assert check.surface_up_m == pytest.approx(0.0, abs=0.05)  # the plane's height at the site


@pytest.mark.parametrize("deg", [9.0, 12.0, 20.0])
def test_a_slope_over_eight_degrees_is_refused_as_sloped(deg: float) -> None:
    """Refused as sloped, and named so: the veto's kind is ``lidar_slope`` (an obstructed site in the
    recovery's ledger), not an edge."""
    check = check_site(*_slope(deg, np.random.default_rng(2)), DOWN, (0.0, 0.0))
    assert check.reasons == (f"sloped {deg:.0f} deg",), check
    assert lidar_kind(check) == "lidar_slope"
    assert (
        hazard_of((lidar_kind(check),), accepted=False, street_level=True, strip=False) is Hazard.OBSTRUCTED
    )


@pytest.mark.parametrize("deg", [0.0, 6.0])
def test_what_stands_on_a_slope_or_grows_in_rows_across_it_still_counts(deg: float) -> None:
    box = check_site(*_slope(deg, np.random.default_rng(3), "box"), DOWN, (0.0, 0.0))
    assert any(r.startswith("object 0.4 m tall") for r in box.reasons), box
    crop = check_site(*_slope(deg, np.random.default_rng(4), "crop"), DOWN, (0.0, 0.0))
    assert any(r.startswith("rough") for r in crop.reasons), crop


def test_simbridges_hillside_meadows_are_clear_up_to_eight_degrees_and_refused_beyond() -> None:
    """Ten points deep inside meadows of hillside seed 5 at each of three slope bands (the terrain's own
    gradient), seen by simbridge's LiDAR 12 m above: below 7 degrees clear, the slope measured within
    a degree of the terrain's; 10-14 degrees refused as sloped."""
    world = generate_hillside(5, 800.0)
    live, g = LiveWorld(world), world.grid
    gn, ge = np.gradient(g.height, g.res)
    slope = np.degrees(np.arctan(np.hypot(gn, ge)))
    meadow = cv2.erode((g.cls == int(SurfaceClass.GRASS)).astype(np.uint8), np.ones((41, 41), np.uint8))
    for lo, hi, clear in ((0.0, 2.0, True), (3.0, 7.0, True), (10.0, 14.0, False)):
        i, j = np.nonzero(meadow.astype(bool) & (slope >= lo) & (slope < hi))
        assert len(i) >= 10, (lo, hi)
        for k in np.random.default_rng(0).choice(len(i), 10, replace=False):
            ne = (g.n0 + (i[k] + 0.5) * g.res, g.e0 + (j[k] + 0.5) * g.res)
            pos = (ne[0], ne[1], -(float(g.height[i[k], j[k]]) + 12.0))
            check = check_site(live.lidar_sweep(pos, DOWN, 0.0, np.random.default_rng(2)), pos, DOWN, ne)
            assert check.clear is clear, (lo, hi, ne, check)
            assert check.slope_deg == pytest.approx(float(slope[i[k], j[k]]), abs=1.0)
            if not clear:
                assert any(r.startswith("sloped") for r in check.reasons), check
