"""Trees near open ground, measured (companion/perception/site_check.py ``tallest_near_m``;
companion/reasoning/net_judge.py ``_nothing_tall``): the LiDAR's tallest return within the close-up's
reach of the site, and the net's tree cells on open ground counted only where something stands there.
In simbridge's rain the net reads a suburb lawn 30 m below as 16-35 % trees; a tree's crown is metres
above the ground and in every sweep, so those lawns are open ground again while a lawn beside a real
tree is still refused."""

from __future__ import annotations

import math
import re

import cv2
import numpy as np
import pytest

from companion.perception.site_check import MIN_NEAR_RETURNS, NEAR_M, SiteCheck, check_site
from companion.reasoning.base import ConfirmRequest, Decision
from companion.reasoning.landnet import PACKAGED, LandNet
from companion.reasoning.onboard import OnboardReasoner
from companion.reasoning.onboard_params import ConfirmParams
from simbridge.geo import euler_to_quat
from simbridge.world.live import LiveWorld
from simbridge.world.model import SurfaceClass
from simbridge.world.suburb import generate_suburb
from tests.views import close_up, site_cut

DOWN = euler_to_quat(0.0, 0.0, 0.0)
HEIGHT_M = 30.0  # the close look's height at which rain turns lawns into "trees"
MAX_VEGETATION = ConfirmParams().max_vegetation  # trees on open ground the net's reading allows


def _sweep(north: np.ndarray, east: np.ndarray, up: np.ndarray) -> tuple[np.ndarray, tuple]:
    """Body-FRD returns of points (north, east, up) seen level from ``HEIGHT_M`` above the site (0, 0)."""
    return np.stack([north, east, -(up - HEIGHT_M)], axis=1), (0.0, 0.0, -HEIGHT_M)


def test_the_tallest_return_near_the_site_is_measured_beyond_the_rotor_disc() -> None:
    rng = np.random.default_rng(0)
    north, east = rng.uniform(-8.0, 8.0, (2, 8000))
    up = rng.normal(0.0, 0.02, north.size)
    crown = np.hypot(north - 4.0, east) < 1.5  # a crown 4 m north of the site, 6 m up
    frd, pos = _sweep(north, east, np.where(crown, 6.0, up))
    check = check_site(frd, pos, DOWN, (0.0, 0.0))
    assert check.clear, check.reasons  # the rotor disc is clear: the crown is 2.5 m beyond it
    assert check.tallest_near_m == pytest.approx(6.0, abs=0.1)
    lawn = check_site(*_sweep(north, east, up), DOWN, (0.0, 0.0))
    assert lawn.tallest_near_m < 0.1
    far = np.hypot(north, east) > NEAR_M + 0.5  # a crown beyond the close-up's reach does not count
    crown_far = np.hypot(north - 7.5, east) < 1.0
    beyond = check_site(*_sweep(north, east, np.where(crown_far & far, 6.0, up)), DOWN, (0.0, 0.0))
    assert beyond.tallest_near_m < 0.1


def test_a_sparse_sweep_does_not_measure_what_stands_near() -> None:
    rng = np.random.default_rng(1)
    north, east = rng.uniform(-1.5, 1.5, (2, MIN_NEAR_RETURNS - 1))  # only the disc, barely
    check = check_site(*_sweep(north, east, np.zeros(north.size)), DOWN, (0.0, 0.0))
    assert check.measured
    assert math.isnan(check.tallest_near_m)


@pytest.fixture(scope="module")
def suburb() -> tuple[LiveWorld, list[tuple[float, float]], list[tuple[float, float]]]:
    """Suburb seed 21 (600 m): four points deep inside lawns (15 m of grass all round) and six on grass
    (2.5 m of it all round: the rotor disc) within 5 m of a tree's cells."""
    world = generate_suburb(21, 600.0)
    g = world.grid
    grass = (g.cls == int(SurfaceClass.GRASS)).astype(np.uint8)
    tree = (g.cls == int(SurfaceClass.TREE)).astype(np.uint8)
    deep = cv2.erode(grass, np.ones((151, 151), np.uint8))
    beside = cv2.erode(grass, np.ones((25, 25), np.uint8)) & cv2.dilate(tree, np.ones((51, 51), np.uint8))

    def pick(mask: np.ndarray, seed: int, n: int = 4) -> list[tuple[float, float]]:
        i, j = np.nonzero(mask)
        assert len(i) >= n
        k = np.random.default_rng(seed).choice(len(i), n, replace=False)
        return [(g.n0 + (i[q] + 0.5) * g.res, g.e0 + (j[q] + 0.5) * g.res) for q in k]

    return LiveWorld(world), pick(deep, 0), pick(beside, 1, 6)


def _confirm(judge: OnboardReasoner, live: LiveWorld, ne: tuple[float, float]) -> tuple[Decision, SiteCheck]:
    g = live.world.grid
    ij = g.index(*ne)
    assert ij is not None
    frame, check = close_up(live, ne, float(g.height[ij]), HEIGHT_M, weather="rain")
    request = ConfirmRequest(site_cut(live, frame, HEIGHT_M), check=check, site_up_m=0.0, built_up=True,
                             site_area_m2=5000.0, site_edge_m=30.0)  # fmt: skip
    return judge.confirm_sync(request), check


def test_in_rain_a_lawn_read_as_trees_is_open_ground_when_nothing_stands_on_it(
    suburb: tuple[LiveWorld, list[tuple[float, float]], list[tuple[float, float]]],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    from companion.reasoning import net_judge

    live, lawns, _ = suburb
    judge = OnboardReasoner(judge="landnet", landnet=LandNet.load(PACKAGED["landnet-e"]))
    for ne in lawns:
        d, check = _confirm(judge, live, ne)
        assert check.tallest_near_m < net_judge.TREE_MIN_M, check
        assert d.accept, d.rationale
        assert d.open_ground
    # by the image alone (no height makes a tree) most of these lawns were trees in the rain
    monkeypatch.setattr(net_judge, "TREE_MIN_M", -1.0)
    refused = [d for d, _ in (_confirm(judge, live, ne) for ne in lawns) if not d.accept]
    assert len(refused) >= 2, "rain no longer reads these lawns as trees: the test needs other lawns"
    assert all("trees" in d.rationale for d in refused), [d.rationale for d in refused]


def test_in_rain_a_lawn_beside_a_tree_the_lidar_measures_is_still_refused(
    suburb: tuple[LiveWorld, list[tuple[float, float]], list[tuple[float, float]]],
) -> None:
    from companion.reasoning import net_judge

    live, _, beside = suburb
    judge = OnboardReasoner(judge="landnet", landnet=LandNet.load(PACKAGED["landnet-e"]))
    seen = 0
    for ne in beside:
        d, check = _confirm(judge, live, ne)
        trees = re.search(r"trees \((\d+) %", d.rationale)
        if check.tallest_near_m >= net_judge.TREE_MIN_M and trees and int(trees[1]) > 100 * MAX_VEGETATION:
            seen += 1
            assert not d.accept, d.rationale
    assert seen >= 2, "fewer than two lawns beside a measured tree read as trees: the test needs other points"


def test_open_ground_refused_for_a_little_water_says_water() -> None:
    """Water under the veto's share still keeps a site from being open ground; the rationale named only
    the trees then ("trees (1 %: bottom)"), which is not why it was refused."""
    from companion.reasoning.landnet import SceneReading
    from companion.reasoning.net_judge import _not_open_ground

    r = SceneReading(
        "landnet-e", (100, 100), (16, 16), 0.9,
        (("low_vegetation", 0.98), ("tree", 0.01), ("water", 0.02)),
        (("tree", ("bottom",)), ("water", ("left",))), (),
    )  # fmt: skip
    _kind, text = _not_open_ground(r, 0, 0.99)
    assert "water (2 %: left)" in text, text
