"""The packaged LandNet-E (``onboard_model = "landnet-e"``): its files as landfall_train.package writes
them (float16 weights behind casts, the whole read beside the net, the rank cells), both runtimes, and
the judgement on simbridge's scenario1 with the LiDAR's geometry, as the flights use it, and from the
image alone over the harbour's water, high up and in fog (what its first cell head got wrong)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from companion.reasoning.base import ConfirmRequest, RankRequest
from companion.reasoning.landnet import PACKAGED, LandNet
from companion.reasoning.onboard import OnboardReasoner
from simbridge.world.camera import Frame
from simbridge.world.live import LiveWorld
from tests.test_landnet import _cut_decision
from tests.test_landnet_rank import RIVALS, rank_against_rival
from tests.views import CLEAR_ROOF, LAUNCH, close_up, crop, ground_box, landnet_judge, render

E = PACKAGED["landnet-e"]


@pytest.fixture(scope="module")
def judge() -> OnboardReasoner:
    return landnet_judge("landnet-e")


@pytest.fixture
def net(judge: OnboardReasoner) -> LandNet:
    assert judge.landnet is not None
    return judge.landnet


def test_the_packaged_model_carries_its_whole_read_and_says_how_its_weights_are_stored(net: LandNet) -> None:
    meta = json.loads(E.with_suffix(".json").read_text())
    assert net.name == "landnet-e"
    assert meta["pretrained"]  # where the backbone's weights came from (NOTICE)
    assert meta["storage"]["weights"].startswith("float16")
    whole = E.with_name(meta["whole_read"]["file"])
    assert whole.is_file()
    assert meta["whole_read"]["closeups"] > 0  # the roof close-ups joined its fit
    assert net.whole_side_px == meta["whole_read"]["side_px"]
    assert net.net_clear_threshold == meta["thresholds"]["net_clear"] > net.clear_threshold
    for path in (E, whole):  # half of EfficientNet-Lite0's float32 bytes each
        assert path.stat().st_size < 8_000_000


def test_onnxruntime_and_opencv_read_the_packaged_model_alike(net: LandNet) -> None:
    """The float16 weights' casts load in both runtimes and give one reading, the whole read's too."""
    cv = LandNet.load(E, backend="opencv")
    rgb = np.random.default_rng(5).integers(0, 256, (240, 320, 3), dtype=np.uint8)
    a, b = net.read(rgb), cv.read(rgb)
    assert a.clear_p == pytest.approx(b.clear_p, abs=1e-4)
    wa, wb = net.confirmation(a, rgb), cv.confirmation(b, rgb)
    assert wa.whole_p is not None
    assert wb.whole_p is not None
    assert wa.whole_p == pytest.approx(wb.whole_p, abs=1e-4)


def test_packaging_halves_the_file_and_keeps_the_readings_under_a_new_sha256(tmp_path: Path) -> None:
    pytest.importorskip("onnx", reason="packaging needs onnx: pip install -e '.[train]'")
    from landfall_train.package import package

    src = tmp_path / "trained"
    src.mkdir()
    light = PACKAGED["landnet-s"]
    for suffix in (".onnx", ".json"):
        shutil.copy(light.with_suffix(suffix), src / f"m{suffix}")
    meta = package(src / "m", tmp_path / "out")
    out = tmp_path / "out" / "m.onnx"
    assert out.stat().st_size < 0.6 * light.stat().st_size
    assert meta["storage"]["parity_max_abs_diff"] < 0.1
    assert json.loads(out.with_suffix(".json").read_text())["sha256"] == meta["sha256"]
    before, after = LandNet.load(light), LandNet.load(out)  # the new sha256 is checked here
    rgb = np.random.default_rng(2).integers(0, 256, (96, 128, 3), dtype=np.uint8)
    assert after.read(rgb).clear_p == pytest.approx(before.read(rgb).clear_p, abs=0.01)
    again = package(tmp_path / "out" / "m", tmp_path / "again")  # a packaged model packaged once more
    assert (tmp_path / "again" / "m.onnx").read_bytes() == out.read_bytes()
    assert again["storage"]["parity_max_abs_diff"] == meta["storage"]["parity_max_abs_diff"]
    full = package(src / "m", tmp_path / "full", full=True)
    assert full["storage"] == {"weights": "float32"}
    assert (tmp_path / "full" / "m.onnx").read_bytes() == light.read_bytes()
    with pytest.raises(FileNotFoundError, match="make model-e"):
        package(tmp_path / "nothing", tmp_path / "out")


def test_it_confirms_the_clear_gravel_roof_and_refuses_water_and_the_cluttered_roof(
    judge: OnboardReasoner, city: LiveWorld
) -> None:
    """Site cuts 20 m above scenario1's surfaces, from the image alone (tests/test_landnet.py)."""
    accept, why = _cut_decision(judge, city, (0.0, -27.0), 22.0)
    assert accept, why
    assert "[landnet-e: net " in why  # the net's and the whole read's probabilities, both stated
    for ne, up_m in (((0.0, 150.0), -0.8), ((0.0, 29.0), 18.0)):
        accept, why = _cut_decision(judge, city, ne, up_m)
        assert not accept, why


@pytest.mark.parametrize("rival", list(RIVALS))
@pytest.mark.parametrize("reverse", [False, True])
def test_with_geometry_the_clear_roof_beats_every_rival(
    judge: OnboardReasoner, city: LiveWorld, launch: dict[str, Frame], rival: str, reverse: bool
) -> None:
    """The rank a flight makes from 110 m: each candidate's geometry less the net's hazard puts
    scenario1's clear roof before the cluttered roof, the road, the highway deck and the river."""
    best, ranking, _transcript = rank_against_rival(judge, city, launch["clear"], rival, reverse)
    assert best == 0, ranking.rationale
    assert "[landnet-e]" in ranking.rationale.split(";")[0]


HARBOUR = ((-25.0, 93.0), (5.0, 84.0))  # scenario1's water, at least 12 m from any quay or pier


@pytest.mark.parametrize("height_m", [20.0, 40.0, 60.0])
def test_without_lidar_a_close_up_over_the_water_is_refused(
    judge: OnboardReasoner, city: LiveWorld, height_m: float
) -> None:
    """The whole close-up a confirmation sends, 20-60 m above the harbour, from the image alone, is
    refused (by the water cells near the water, by the clear site higher up)."""
    for ne in HARBOUR:
        frame, _check = close_up(city, ne, -0.8, height_m)
        d = judge.confirm_sync(ConfirmRequest(frame.rgb))
        assert not d.accept, d.rationale


def test_in_fog_from_the_launch_pose_the_image_alone_sees_the_water_and_ranks_the_roof_first(
    judge: OnboardReasoner, city: LiveWorld
) -> None:
    """From 110 m in fog a crop of the harbour looks like a clear roof to the clear-site read; the rank
    cells (the second head) see the water in it, so its hazard is the higher and the roof comes first."""
    assert judge.landnet is not None
    frame = render(city, LAUNCH, "fog")
    roof = crop(frame, ground_box(city, LAUNCH, *CLEAR_ROOF))
    assert judge.landnet.read_rank(roof).share("water") == 0.0
    for n, e in HARBOUR:
        water = crop(frame, ground_box(city, LAUNCH, (n - 10.0, n + 10.0), (e - 10.0, e + 10.0), -0.8))
        reading = judge.landnet.read_rank(water)
        assert reading.share("water") > 0.05, reading.observations()
        for crops in ((roof, water), (water, roof)):
            ranking = judge.rank_sync(RankRequest(crops))
            assert crops[ranking.order[0]] is roof, ranking.rationale


def test_the_rank_cells_read_held_out_water_from_high_up_better_and_left_the_first_head_alone() -> None:
    meta = json.loads(E.with_suffix(".json").read_text())
    rank = meta["rank_cells"]
    figures = rank["figures"]
    assert figures["after"]["high_up"]["water"]["ap"] > figures["before"]["high_up"]["water"]["ap"] + 0.2
    assert rank["first_head_max_abs_diff"] == 0.0
    assert [*rank["thresholds"]] == meta["classes"] == [*figures["after"]["all"]]
