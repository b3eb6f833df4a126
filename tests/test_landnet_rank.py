"""LandNet-S ranking with Surface ID's geometry (companion/reasoning/net_judge.py's ranks): each
candidate's geometry less the net's hazard orders scenario1's clear roof before its rivals, and what a
net sure of a hazard says. LandNet-E on the same rivals: tests/test_landnet_e.py."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from companion.perception.surface_id import Candidate
from companion.reasoning.base import Ranking, RankRequest
from companion.reasoning.landnet import SceneReading
from companion.reasoning.onboard import OnboardReasoner
from simbridge.world.camera import Frame
from simbridge.world.live import LiveWorld
from simbridge.world.model import SurfaceClass as C
from tests.views import (
    CLEAR_ROOF,
    CLUTTERED_ROOF,
    HIGHWAY,
    LAUNCH,
    ROAD,
    WATER,
    WEATHERS,
    crop,
    ground_box,
    landnet_judge,
    render,
    share,
)


@pytest.fixture(scope="module")
def judge() -> OnboardReasoner:
    return landnet_judge("landnet-s")


# --- rank with Surface ID's geometry: the net's reading in place of the cues' hazard terms ------------
def _geometry_rank(
    judge: OnboardReasoner, crops: list[np.ndarray], cands: list[Candidate], reverse: bool
) -> tuple[int, Ranking, list[dict[str, object]]]:
    idx = [1, 0] if reverse else [0, 1]
    transcript: list[dict[str, object]] = []
    request = RankRequest(
        tuple(crops[k] for k in idx),
        tuple(dataclasses.replace(cands[k], index=j) for j, k in enumerate(idx)),
        transcript=transcript,
    )
    ranking = judge.rank_sync(request)
    assert sorted(ranking.order) == [0, 1]
    return idx[ranking.order[0]], ranking, transcript


RIVALS = {  # name: (ground rectangle, its geometry as Surface ID would see it)
    "cluttered roof": (CLUTTERED_ROOF, {"up_m": 18.0, "edge_m": 3.0}),
    "road": (ROAD, {"up_m": 0.0, "edge_m": 5.0}),
    "highway": (HIGHWAY, {"up_m": 9.0, "edge_m": 6.0}),  # a deck 9 m up: geometrically a roof
    "water": (WATER, {"up_m": 0.0, "edge_m": 8.0}),
}


def rank_against_rival(
    judge: OnboardReasoner, city: LiveWorld, frame: Frame, rival: str, reverse: bool
) -> tuple[int, Ranking, list[dict[str, object]]]:
    """scenario1's clear roof against ``rival`` (``RIVALS``) in ``frame`` from the launch pose, each
    candidate as Surface ID would measure it; the winner's original index, the ranking, the transcript."""
    from tests.test_onboard_reasoner import truth_candidate

    rect, geo = RIVALS[rival]
    roof_box, other_box = ground_box(city, LAUNCH, *CLEAR_ROOF), ground_box(city, LAUNCH, *rect)
    cands = [
        truth_candidate(roof_box, CLEAR_ROOF, up_m=22.0, edge_m=13.0),
        truth_candidate(other_box, rect, **geo),
    ]
    return _geometry_rank(judge, [crop(frame, roof_box), crop(frame, other_box)], cands, reverse)


@pytest.mark.parametrize("rival", list(RIVALS))
@pytest.mark.parametrize("weather", WEATHERS)
@pytest.mark.parametrize("reverse", [False, True])
def test_landnet_rank_with_geometry_reads_the_crops_with_the_net(
    judge: OnboardReasoner, city: LiveWorld, launch: dict[str, Frame], rival: str, weather: str, reverse: bool
) -> None:
    """With the net as judge, the rank with geometry scores each candidate by its geometry less the
    net's hazard (not the image cues'): scenario1's clear roof still beats the cluttered roof, the road,
    the highway deck and the river, and the rationale and transcript carry the net's reading."""
    best, ranking, transcript = rank_against_rival(judge, city, launch[weather], rival, reverse)
    assert best == 0, ranking.rationale
    chosen = ranking.rationale.split(";")[0]
    assert "elevated flat roof 22 m up" in chosen
    assert "[landnet-s]" in chosen  # the net's confidence, not a cue
    assert "no geometry" not in ranking.rationale
    assert transcript[0]["judge"] == "landnet"
    readings = transcript[0]["readings"]
    assert isinstance(readings, list)
    assert len(readings) == 2
    assert "cues" not in transcript[0]


def test_landnet_rank_with_geometry_a_roof_with_a_person_on_it_comes_second(
    judge: OnboardReasoner, scene: LiveWorld
) -> None:
    from tests.test_onboard_reasoner import truth_candidate

    cam = (0.0, 0.0, -80.0)
    frame = render(scene, cam, "clear")
    clear_rect = ((-13.0, 13.0), (-48.0, -22.0), 20.0)
    walked_rect = ((-13.0, 13.0), (22.0, 48.0), 20.0)
    boxes = [ground_box(scene, cam, *clear_rect), ground_box(scene, cam, *walked_rect)]
    assert share(frame, boxes[1], [C.PEDESTRIAN]) > 0.0
    cands = [
        truth_candidate(b, r, up_m=20.0, edge_m=13.0, margin_m=0.0)
        for b, r in zip(boxes, (clear_rect, walked_rect), strict=True)
    ]
    for reverse in (False, True):
        best, ranking, _t = _geometry_rank(judge, [crop(frame, b) for b in boxes], cands, reverse)
        assert best == 0, ranking.rationale


def test_a_roof_the_net_is_sure_is_not_clear_is_not_a_soft_doubt() -> None:
    """Refused under the clear-site threshold with nothing counted: a soft doubt ("hazard", a roof the
    search may settle for) unless the net is sure (clear-site confidence under 0.2: "not_clear", which
    the least-bad ranking counts as obstructed: city 0 on real ArduCopter landed on such a site, a
    parapet 1.9 m away, once the round budget was spent)."""
    from companion.reasoning.net_judge import FIRM_NOT_CLEAR_P, _not_clear
    from companion.site_ledger import Hazard, hazard_of

    def reading(clear_p: float) -> SceneReading:
        shares = (("roof", 0.93), ("edge", 0.26), ("ground", 0.65))
        return SceneReading("landnet-s", (64, 64), (16, 16), clear_p, shares, (), (), 0.3)

    soft, text = _not_clear(reading(0.45), 0.6, 0, 0.0, 0.1)
    assert soft == "hazard"
    assert "clear-site confidence 0.45 under 0.60" in text
    firm, text = _not_clear(reading(FIRM_NOT_CLEAR_P - 0.09), 0.6, 0, 0.0, 0.1)
    assert firm == "not_clear"
    assert "edges or walls" in text
    assert hazard_of([soft], accepted=False, street_level=False, strip=False) is Hazard.DOUBTED
    assert hazard_of([firm], accepted=False, street_level=False, strip=False) is Hazard.OBSTRUCTED
    assert _not_clear(reading(0.05), 0.6, 2, 0.0, 0.1)[0] == "raised"  # counted things come first
