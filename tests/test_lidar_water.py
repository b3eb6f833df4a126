"""Water measured by the LiDAR (companion/perception/site_check.py, ``surface_intensity``): water returns
little of a near-infrared pulse, so a disc whose surface returns are as dark as water is refused as
water, bindingly, whatever the camera sees. In simbridge's fog the waterfront's harbour 20 m below reads
to the net as "at street level" with boats on it; nine fog flights of a waterfront campaign ran out
their search and landed on such water, measured close up as street level."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from companion.perception.site_check import WATER_MAX_INTENSITY, check_site
from companion.reasoning.base import ConfirmRequest
from companion.reasoning.landnet import PACKAGED, LandNet
from companion.reasoning.onboard import OnboardReasoner, lidar_kind
from companion.site_ledger import Hazard, hazard_of
from simbridge.geo import euler_to_quat
from simbridge.world.live import LiveWorld
from simbridge.world.model import SurfaceClass
from simbridge.world.waterfront import generate_waterfront
from tests.views import close_up, site_cut

DOWN = euler_to_quat(0.0, 0.0, 0.0)
HEIGHT_M = 20.0


def _sweep(intensity: float | None, n: int = 4000) -> np.ndarray:
    """Body-FRD returns of a level surface ``HEIGHT_M`` below, with one intensity (None: no column)."""
    rng = np.random.default_rng(0)
    north, east = rng.uniform(-6.0, 6.0, (2, n))
    down = HEIGHT_M + rng.normal(0.0, 0.02, n)
    xyz = np.stack([north, east, down], axis=1)
    if intensity is None:
        return xyz
    return np.column_stack([xyz, np.full(n, intensity)]).astype(np.float32)


def _check(sweep: np.ndarray):
    return check_site(sweep, (0.0, 0.0, -HEIGHT_M), DOWN, (0.0, 0.0))


def test_a_surface_as_dark_as_water_is_water_and_a_black_roof_is_not() -> None:
    water = _check(_sweep(0.02))
    assert not water.clear
    assert water.surface_intensity == pytest.approx(0.02)
    assert "returns as dark as water (median intensity 0.02)" in water.reasons
    assert lidar_kind(water) == "water"
    assert hazard_of([lidar_kind(water)], accepted=False, street_level=True, strip=False) == Hazard.WATER
    tar = _check(_sweep(0.07))  # black tar, seen from overhead
    assert tar.clear, tar.reasons
    assert tar.surface_intensity == pytest.approx(0.07)


def test_a_sweep_without_intensity_judges_no_water() -> None:
    for sweep in (_sweep(None), _sweep(0.0)):  # no column; a sensor that measures none sends zeros
        check = _check(sweep)
        assert check.clear, check.reasons
        assert math.isnan(check.surface_intensity)
    sweep = _sweep(0.02)
    off = check_site(sweep, (0.0, 0.0, -HEIGHT_M), DOWN, (0.0, 0.0), max_water_intensity=0.0)
    assert off.clear, off.reasons  # 0: not judged
    assert off.surface_intensity == pytest.approx(0.02)
    assert WATER_MAX_INTENSITY > 0.02
    # the same dark disc 40 m to the side of a vehicle 20 m up: its beams graze, nothing is judged
    aside = check_site(sweep - np.array([40.0, 0.0, 0.0, 0.0], np.float32), (0.0, 0.0, -HEIGHT_M), DOWN,
                       (-40.0, 0.0))  # fmt: skip
    assert aside.measured
    assert math.isnan(aside.surface_intensity)


@pytest.fixture(scope="module")
def harbour() -> tuple[LiveWorld, list[tuple[float, float]]]:
    """Waterfront seed 21 (600 m): four points with 10 m of water all round."""
    world = generate_waterfront(21, 600.0)
    g = world.grid
    water = (g.cls == int(SurfaceClass.WATER)).astype(np.uint8)
    deep = cv2.erode(water, np.ones((101, 101), np.uint8))
    i, j = np.nonzero(deep)
    assert len(i) >= 4
    k = np.random.default_rng(0).choice(len(i), 4, replace=False)
    return LiveWorld(world), [(g.n0 + (i[q] + 0.5) * g.res, g.e0 + (j[q] + 0.5) * g.res) for q in k]


@pytest.mark.slow
@pytest.mark.parametrize("weather", ["clear", "fog"])
def test_the_harbour_close_up_is_water_to_the_lidar_in_any_weather(
    harbour: tuple[LiveWorld, list[tuple[float, float]]], weather: str
) -> None:
    live, points = harbour
    judge = OnboardReasoner(judge="landnet", landnet=LandNet.load(PACKAGED["landnet-e"]))
    g = live.world.grid
    for ne in points:
        ij = g.index(*ne)
        assert ij is not None
        frame, check = close_up(live, ne, float(g.height[ij]), HEIGHT_M, weather=weather)
        assert check.surface_intensity < WATER_MAX_INTENSITY, check
        request = ConfirmRequest(site_cut(live, frame, HEIGHT_M), check=check, site_up_m=0.0, built_up=True,
                                 site_area_m2=1000.0, site_edge_m=14.0)  # fmt: skip
        d = judge.confirm_sync(request)
        assert not d.accept
        assert "water" in d.hazards, d.rationale
        assert d.binding
