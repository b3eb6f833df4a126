"""Roof-like cells at street level (companion/reasoning/net_judge.py, ``tinted_share``): both packaged
nets read a ploughed field as "roof surface", which at street level counted as paving, a road; a road
is grey and a field is not, so the tinted share of the window does not count as paving. In simbridge's
farmland a ploughed field's interior is open ground again, in fog too (fog greys its saturation, not
its chroma); a plain grey road at street level is still refused in either weather (tests/test_landnet.py,
``test_landnet_confirm_refuses_a_plain_road_at_street_level_in_open_country``)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from companion.reasoning.base import ConfirmRequest
from companion.reasoning.landnet import PACKAGED, LandNet
from companion.reasoning.net_judge import tinted_share
from companion.reasoning.onboard import OnboardReasoner
from simbridge.world.farmland import generate_farmland
from simbridge.world.live import LiveWorld
from simbridge.world.model import Material, SurfaceClass
from tests.views import close_up, site_cut

HEIGHT_M = 15.0


def test_a_grey_surface_is_not_tinted_and_soil_and_brick_are() -> None:
    def share(rgb: tuple[int, int, int]) -> float:
        noise = np.random.default_rng(0).integers(-6, 7, (120, 160, 3))
        return tinted_share(np.clip(np.array(rgb) + noise, 0, 255).astype(np.uint8))

    assert share((78, 78, 82)) == 0.0  # asphalt
    assert share((150, 148, 140)) < 0.01  # concrete: the noise's extremes only (chroma 10 +- 12)
    assert share((122, 92, 62)) == 1.0  # bare soil
    assert share((150, 70, 55)) == 1.0  # brick
    assert share((10, 8, 6)) == 0.0  # too dark to have a hue


FOG_RGB = np.array([0.78, 0.80, 0.82]) * 255  # simbridge's fog light (simbridge/world/camera.py)


@pytest.mark.parametrize("transmission", [0.3, 0.58, 0.7])
def test_fog_light_leaves_soil_tinted_and_paving_grey(transmission: float) -> None:
    """Haze adds a near-grey light of its own: a surface's saturation falls, its chroma only scales
    with the transmission. A ploughed field seen through 25-40 m of simbridge's fog keeps its tint
    (its saturation there is under ``TINT_MIN_SATURATION``); asphalt and concrete stay grey however much
    fog light is added."""

    def fogged(rgb: tuple[int, int, int]) -> float:
        noise = np.random.default_rng(0).integers(-6, 7, (120, 160, 3))
        seen = (np.array(rgb) + noise) * transmission + FOG_RGB * (1.0 - transmission)
        return tinted_share(np.clip(seen, 0, 255).astype(np.uint8))

    assert fogged((78, 78, 82)) == 0.0  # asphalt
    assert fogged((150, 148, 140)) == 0.0  # concrete (its chroma scaled down too)
    if transmission >= 0.58:  # simbridge's fog 40 m down: exp(-3 * 40 / 220) = 0.58
        assert fogged((122, 92, 62)) == 1.0  # bare soil
        assert fogged((150, 70, 55)) == 1.0  # brick
    else:  # 88 m of it: the colour is gone, no tint to read
        assert fogged((122, 92, 62)) == 0.0


@pytest.fixture(scope="module")
def farm() -> tuple[LiveWorld, dict[str, list[tuple[float, float]]]]:
    """Farmland seed 5 and six points deep inside its ploughed fields."""
    world = generate_farmland(5, 800.0)
    g = world.grid
    soil = (g.cls == int(SurfaceClass.GROUND)) & (g.mat == int(Material.SOIL))
    where = {"ploughed": cv2.erode(soil.astype(np.uint8), np.ones((61, 61), np.uint8))}
    points: dict[str, list[tuple[float, float]]] = {}
    for name, mask in where.items():
        i, j = np.nonzero(mask)
        assert len(i) >= 6, name
        pick = np.random.default_rng(0).choice(len(i), 6, replace=False)
        points[name] = [(g.n0 + (i[k] + 0.5) * g.res, g.e0 + (j[k] + 0.5) * g.res) for k in pick]
    return LiveWorld(world), points


def _requests(
    live: LiveWorld, points: list[tuple[float, float]], height_m: float = HEIGHT_M, weather: str = "clear"
) -> list[ConfirmRequest]:
    """Close-ups ``height_m`` above each point, as open country of a wide measured surface."""
    g = live.world.grid
    out = []
    for ne in points:
        ij = g.index(*ne)
        assert ij is not None
        frame, check = close_up(live, ne, float(g.height[ij]), height_m, weather=weather)
        assert check.clear, check.reasons  # shallow furrows: the LiDAR finds it level
        out.append(
            ConfirmRequest(site_cut(live, frame, height_m), check=check, site_up_m=0.0, built_up=False,
                           site_area_m2=5000.0, site_edge_m=30.0)
        )  # fmt: skip
    return out


@pytest.mark.parametrize("model", ["landnet-e", "landnet-s"])
def test_in_farmland_a_ploughed_field_is_open_ground(
    farm: tuple[LiveWorld, dict[str, list[tuple[float, float]]]], model: str
) -> None:
    live, points = farm
    judge = OnboardReasoner(judge="landnet", landnet=LandNet.load(PACKAGED[model]))
    for request in _requests(live, points["ploughed"]):
        d = judge.confirm_sync(request)
        assert d.accept, d.rationale
        assert d.open_ground


def test_without_the_tint_landnet_e_took_ploughed_fields_for_paving(
    farm: tuple[LiveWorld, dict[str, list[tuple[float, float]]]], monkeypatch: pytest.MonkeyPatch
) -> None:
    """What the tint changes: LandNet-E reads these fields' close-ups as roof-like (LandNet-S, at this
    height, as ground), and with every roof-like cell counted as paving it refused them as a road."""
    from companion.reasoning import net_judge

    live, points = farm
    judge = OnboardReasoner(judge="landnet", landnet=LandNet.load(PACKAGED["landnet-e"]))
    monkeypatch.setattr(net_judge, "tinted_share", lambda _window: 0.0)
    refused = [judge.confirm_sync(r) for r in _requests(live, points["ploughed"])]
    assert any("street_asphalt" in d.hazards for d in refused), [d.rationale for d in refused]


FOG_HEIGHT_M = 40.0  # a close look from this high sees through 40 m of simbridge's fog (transmission 0.58)


def test_in_fog_a_ploughed_field_is_still_open_ground_and_was_paving_by_saturation_alone(
    farm: tuple[LiveWorld, dict[str, list[tuple[float, float]]]], monkeypatch: pytest.MonkeyPatch
) -> None:
    """40 m above ploughed fields in fog LandNet-E reads roof-like cells; their saturation is greyed
    under ``TINT_MIN_SATURATION``, their chroma is not: all six fields are open ground. Judged by
    saturation alone (the chroma limit out of reach) all six were refused as a road."""
    from companion.reasoning import net_judge

    live, points = farm
    judge = OnboardReasoner(judge="landnet", landnet=LandNet.load(PACKAGED["landnet-e"]))
    requests = _requests(live, points["ploughed"], FOG_HEIGHT_M, "fog")
    for request in requests:
        d = judge.confirm_sync(request)
        assert d.accept, d.rationale
        assert d.open_ground
    monkeypatch.setattr(net_judge, "TINT_MIN_CHROMA", 2.0)
    refused = [judge.confirm_sync(r) for r in requests]
    assert all("street_asphalt" in d.hazards for d in refused), [d.rationale for d in refused]
