"""The LiDAR site check over standing crops (companion/perception/site_check.py): a canopy in rows whose
top alone is smooth is refused for the ground seen between its rows, a lawn and a flat roof are not,
and in simbridge's farmland every crop field's interior is refused and every pasture's is clear."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from companion.perception.site_check import MAX_SUNKEN_SHARE, check_site
from simbridge.geo import euler_to_quat
from simbridge.world.farmland import generate_farmland
from simbridge.world.live import LiveWorld
from simbridge.world.model import SurfaceClass

DOWN = euler_to_quat(0.0, 0.0, 0.0)
ROW_M, COVER = 0.75, 0.6  # rows 0.75 m apart, 60 % of the spacing leaves (simbridge's farmland)


def _sweep(up: np.ndarray, north: np.ndarray, east: np.ndarray, height_m: float) -> tuple[np.ndarray, tuple]:
    """Body-FRD returns of points (north, east, up) seen level from ``height_m`` above the site (0, 0)."""
    pos = (0.0, 0.0, -height_m)
    frd = np.stack([north, east, -(up - height_m)], axis=1)  # level: body FRD = NED less the position
    return frd, pos


def _ground(surface: str, rng: np.random.Generator, crop_m: float = 0.6) -> tuple[np.ndarray, tuple]:
    north, east = rng.uniform(-4.0, 4.0, (2, 6000))
    up = rng.normal(0.0, 0.02, north.size)  # the LiDAR's 2 cm noise
    if surface == "crop":  # leaves at the crop's height, the soil between the rows a fifth of it up
        leaf = (east % ROW_M) < COVER * ROW_M
        up += np.where(leaf, crop_m, 0.2 * crop_m)
    elif surface == "gravel roof":
        up += 22.0 + rng.uniform(0.0, 0.03, north.size)
    elif surface == "step":  # a terrace 0.5 m lower 1.2 m east of the site
        up -= np.where(east > 1.2, 0.5, 0.0)
    return _sweep(up, north, east, 15.0 + (22.0 if surface == "gravel roof" else 0.0))


@pytest.mark.parametrize("crop_m", [0.5, 0.6, 0.7, 0.8])
def test_a_crop_whose_top_is_smooth_is_refused_for_the_ground_between_its_rows(crop_m: float) -> None:
    frd, pos = _ground("crop", np.random.default_rng(1), crop_m)
    check = check_site(frd, pos, DOWN, (0.0, 0.0))
    assert check.roughness_m < 0.08  # the canopy's top alone passes
    assert check.obstacle_m < 0.3
    assert check.sunken_share > 0.3, check
    assert not check.clear
    assert any(r.startswith("rough (") and "below the surface" in r for r in check.reasons), check.reasons


@pytest.mark.parametrize("surface", ["lawn", "gravel roof"])
def test_a_lawn_and_a_flat_roof_have_nothing_below_them(surface: str) -> None:
    frd, pos = _ground(surface, np.random.default_rng(2))
    check = check_site(frd, pos, DOWN, (0.0, 0.0))
    assert check.clear, check.reasons
    assert check.sunken_share == 0.0


def test_a_step_down_within_the_rotor_disc_is_refused_too() -> None:
    frd, pos = _ground("step", np.random.default_rng(3))
    check = check_site(frd, pos, DOWN, (0.0, 0.0))
    assert check.sunken_share > MAX_SUNKEN_SHARE
    assert not check.clear


def test_an_unmeasured_check_has_no_share() -> None:
    assert math.isnan(check_site(None, (0.0, 0.0, -10.0), DOWN, (0.0, 0.0)).sunken_share)


def test_in_simbridges_farmland_crops_are_refused_and_pasture_is_clear() -> None:
    """Ten points deep inside crop fields and ten inside pastures of farmland seed 5, each seen by
    simbridge's LiDAR 8 and 15 m above it: every crop refused (rough, an object or the ground between
    the rows), every pasture clear."""
    farm = generate_farmland(5, 800.0)
    live, g = LiveWorld(farm), farm.grid
    for cls, clear in ((SurfaceClass.CROP, False), (SurfaceClass.GRASS, True)):
        inside = cv2.erode((g.cls == int(cls)).astype(np.uint8), np.ones((41, 41), np.uint8))
        i, j = np.nonzero(inside)
        for k in np.random.default_rng(0).choice(len(i), 10, replace=False):
            ne = (g.n0 + (i[k] + 0.5) * g.res, g.e0 + (j[k] + 0.5) * g.res)
            top = float(g.height[i[k], j[k]])
            for height_m in (8.0, 15.0):
                pos = (ne[0], ne[1], -(top + height_m))
                check = check_site(live.lidar_sweep(pos, DOWN, 0.0, np.random.default_rng(2)), pos, DOWN, ne)
                assert check.measured
                assert check.clear is clear, (cls, ne, height_m, check)
