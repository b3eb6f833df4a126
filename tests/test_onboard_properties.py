"""Properties (hypothesis) of the recovery chain's third stage, the onboard reasoner (stage 3 of
tests/test_chain_properties.py): a rank of crops of any size down to one pixel and a confirmation of
any image give an answer, images that are not RGB uint8 are refused with ValueError, and the image
cues measure within their ranges at any size.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from companion.perception.site_check import SiteCheck
from companion.perception.surface_id import Candidate
from companion.reasoning.base import ConfirmRequest, Decision, Ranking, RankRequest
from companion.reasoning.image_cues import analyse
from companion.reasoning.onboard import ConfirmParams, OnboardReasoner
from tests.test_chain_properties import QUICK, spans

# --------------------------------------------------------------------------- 3. the onboard reasoner
EXTREME_SHAPES = [(1, 1), (1, 2), (2, 1), (2, 2), (1, 500), (500, 1), (1, 7), (7, 1), (3, 3), (16, 1)]
crop_shapes = st.one_of(st.sampled_from(EXTREME_SHAPES), st.tuples(st.integers(1, 48), st.integers(1, 48)))


@st.composite
def rgb_images(draw: st.DrawFn) -> np.ndarray:
    h, w = draw(crop_shapes)
    kind = draw(st.sampled_from(["noise", "flat", "blocks", "black", "white", "stripes"]))
    rng = np.random.default_rng(draw(st.integers(0, 2**16)))
    if kind == "noise":
        return rng.integers(0, 256, (h, w, 3), dtype=np.uint8)
    if kind == "flat":
        return np.broadcast_to(rng.integers(0, 256, 3, dtype=np.uint8), (h, w, 3)).copy()
    if kind == "blocks":
        small = rng.integers(0, 256, (max(1, h // 4), max(1, w // 4), 3), dtype=np.uint8)
        return np.ascontiguousarray(np.repeat(np.repeat(small, 4, 0), 4, 1)[:h, :w])
    if kind == "stripes":
        img = np.full((h, w, 3), 90, np.uint8)
        img[:, ::3] = 250
        return img
    return np.full((h, w, 3), 0 if kind == "black" else 255, np.uint8)


def candidates_for(n: int) -> st.SearchStrategy[tuple[Candidate, ...]]:
    nan_or = lambda lo, hi: st.one_of(st.just(math.nan), st.floats(lo, hi))  # noqa: E731
    one = st.builds(
        Candidate,
        index=st.just(0),
        box_px=st.just((0, 0, 1, 1)),
        centre_px=st.just((0.5, 0.5)),
        area_m2=nan_or(0.0, 1e5),
        roughness_m=nan_or(0.0, 2.0),
        height_above_m=nan_or(-50.0, 200.0),
        edge_distance_m=nan_or(0.0, 100.0),
        fallback=st.booleans(),
        slope_deg=nan_or(0.0, 90.0),
        landable_area_m2=nan_or(0.0, 1e5),
        measured_share=st.floats(0.0, 1.0),
    )
    return st.tuples(*[one] * n).map(
        lambda cs: tuple(dataclasses.replace(c, index=k) for k, c in enumerate(cs))
    )


@st.composite
def rank_requests(draw: st.DrawFn) -> RankRequest:
    crops = tuple(draw(st.lists(rgb_images(), min_size=1, max_size=5)))
    cands = draw(st.one_of(st.none(), candidates_for(len(crops))))
    cores = None
    if draw(st.booleans()):
        cores = []
        for img in crops:
            x0, x1 = draw(spans(img.shape[1], 4))
            y0, y1 = draw(spans(img.shape[0], 4))
            cores.append((x0, y0, x1, y1))
    return RankRequest(
        crops, cands, critical=draw(st.booleans()), cores=None if cores is None else tuple(cores)
    )


@QUICK
@given(rank_requests())
def test_onboard_rank_any_crop_size_gives_a_ranking(rank_request: RankRequest) -> None:
    ranking = OnboardReasoner().rank_sync(rank_request)
    assert isinstance(ranking, Ranking)
    assert sorted(ranking.order) == list(range(len(rank_request.crops)))
    assert ranking.rationale


site_checks = st.one_of(
    st.none(),
    st.builds(
        SiteCheck,
        points=st.integers(0, 500),
        surface_up_m=st.floats(allow_nan=True, allow_infinity=False),
        roughness_m=st.one_of(st.just(math.nan), st.floats(0.0, 5.0)),
        obstacle_m=st.one_of(st.just(math.nan), st.floats(-5.0, 50.0)),
        edge_distance_m=st.one_of(st.just(math.nan), st.just(math.inf), st.floats(0.0, 50.0)),
        reasons=st.lists(st.text(max_size=10), max_size=2).map(tuple),
    ),
)


@QUICK
@given(
    rgb_images(),
    site_checks,
    st.booleans(),
    st.one_of(st.none(), st.floats(-50.0, 200.0)),
    st.one_of(st.none(), st.floats(0.01, 1.0)),
)
def test_onboard_confirm_any_image_gives_a_decision(
    image: np.ndarray, check: SiteCheck | None, critical: bool, site_up_m: float | None, window: float | None
) -> None:
    reasoner = OnboardReasoner(confirm=ConfirmParams(site_window=window))
    decision = reasoner.confirm_sync(ConfirmRequest(image, check, critical=critical, site_up_m=site_up_m))
    assert isinstance(decision, Decision)
    assert isinstance(decision.accept, bool)
    assert decision.rationale
    if check is not None and not check.clear:
        assert not decision.accept


BAD_IMAGES = [
    np.zeros((4, 4), np.uint8),
    np.zeros((4, 4, 4), np.uint8),
    np.zeros((4, 4, 3), np.float32),
    np.zeros((0, 4, 3), np.uint8),
    np.zeros((4, 0, 3), np.uint8),
    np.zeros((4, 4, 3), np.int64),
]


@pytest.mark.parametrize("image", BAD_IMAGES, ids=lambda a: f"{a.shape}-{a.dtype}")
def test_onboard_rank_and_confirm_refuse_a_non_rgb_uint8_image(image: np.ndarray) -> None:
    reasoner = OnboardReasoner()
    with pytest.raises(ValueError, match="expected"):
        reasoner.rank_sync(RankRequest((image,)))
    with pytest.raises(ValueError, match="expected"):
        reasoner.confirm_sync(ConfirmRequest(image))


@QUICK
@given(rgb_images(), st.booleans())
def test_image_cues_any_size_down_to_one_pixel_measures_in_range(image: np.ndarray, site: bool) -> None:
    cues = analyse(image, site=site)
    assert cues.size_px == image.shape[:2]
    assert 0.0 <= cues.hazard < math.inf
    for share in (
        cues.shadow_share,
        cues.water_share,
        cues.vegetation_share,
        cues.asphalt_share,
        cues.other_surface_share,
    ):
        assert 0.0 <= share <= 1.0
    assert 0.0 < cues.site_share <= 1.0
    assert min(cues.work_px) >= 1
    assert all(math.isfinite(v) for _k, v in cues.terms)


@pytest.mark.parametrize("site", [False, True])
@pytest.mark.parametrize("shape", [(1, 1), (1, 9), (9, 1), (2, 2)])
def test_image_cues_tiny_water_image_is_water(shape: tuple[int, int], site: bool) -> None:
    """Tiny images are still measured, not skipped: a 1 x 1 px image of water says water."""
    image = np.full((*shape, 3), (30, 70, 160), np.uint8)
    cues = analyse(image, site=site)
    assert cues.water_share == pytest.approx(1.0)
    assert cues.term("water") > 0.0
