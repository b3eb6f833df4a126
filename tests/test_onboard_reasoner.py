"""The onboard tier (companion/reasoning/onboard.py) on simbridge renders.

Rank: a clear roof against a cluttered one, a road, the elevated highway, water and a roof with a
person on it; every case in both candidate orders, with geometry (Surface ID's on a real LiDAR sweep,
or candidates built from the scenario file's ground truth) and from images alone; clear, fog and rain.
Confirm: close-ups of a clear roof (yes), a cluttered roof, a road, water and a person on a roof (no),
with the LiDAR site check and without it, and what a critical alarm relaxes. Crop contents are checked
against the renderer's per-pixel ground truth before they are used.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from companion.guidance.frames import PinholeCamera
from companion.perception.crops import rank_crops
from companion.perception.depth import LidarDepth
from companion.perception.site_check import SiteCheck
from companion.perception.surface_id import Candidate, propose
from companion.reasoning.base import ConfirmRequest, Decision, Ranking, RankRequest, Reasoner
from companion.reasoning.image_cues import analyse
from companion.reasoning.onboard import ConfirmParams, GeometryWeights, OnboardReasoner, geometry_score
from simbridge.world.camera import Frame
from simbridge.world.live import LiveWorld
from simbridge.world.model import SurfaceClass as C
from tests.views import (
    CLEAR_ROOF,
    CLUTTERED_ROOF,
    HIGHWAY,
    HIGHWAY_CLASSES,
    LAUNCH,
    LEVEL,
    ROAD,
    ROAD_CLASSES,
    WATER,
    WEATHERS,
    Box,
    centre_window,
    close_up,
    crop,
    ground_box,
    render,
    share,
    site_cut,
)

ONBOARD = OnboardReasoner()
Rect = tuple[tuple[float, float], tuple[float, float], float]


def truth_candidate(
    box: Box, rect: Rect, *, up_m: float, edge_m: float, margin_m: float = 2.0, landable: bool = True
) -> Candidate:
    """A candidate as Surface ID would report the ground rectangle ``rect``: flat (0.3 deg, 1.5 cm),
    ``up_m`` above its surroundings, its landable part ``margin_m`` in from each edge."""
    (n0, n1), (e0, e1), _ = rect
    area = (n1 - n0) * (e1 - e0)
    land = max(n1 - n0 - 2 * margin_m, 0.0) * max(e1 - e0 - 2 * margin_m, 0.0) if landable else 0.0
    centre = ((box[0] + box[2]) / 2, (box[1] + box[3]) / 2)
    return Candidate(
        0, box, centre, area_m2=area, landable_area_m2=land, roughness_m=0.015, height_above_m=up_m,
        edge_distance_m=edge_m, slope_deg=0.3,
    )  # fmt: skip


def ranked_first(
    crops: list[np.ndarray], cands: list[Candidate] | None, *, reverse: bool, critical: bool = False
) -> tuple[int, Ranking]:
    """Rank (optionally in reversed order); return the original index of the winner and the ranking."""
    idx = list(range(len(crops)))[::-1] if reverse else list(range(len(crops)))
    request = RankRequest(
        tuple(crops[k] for k in idx),
        None if cands is None else tuple(dataclasses.replace(cands[k], index=j) for j, k in enumerate(idx)),
        critical=critical,
    )
    ranking = ONBOARD.rank_sync(request)
    assert sorted(ranking.order) == list(range(len(crops)))  # every candidate, once
    assert ranking.tier == "onboard"
    assert ranking.latency_s > 0.0
    return idx[ranking.order[0]], ranking


def site_of(ranking: Ranking, original: int, reverse: bool, n: int) -> str:
    """How the rationale calls the candidate that was ``original`` before reordering."""
    return f"site {n - 1 - original if reverse else original}"


# ------------------------------------------------------------------------------------------ rank
@pytest.mark.parametrize("weather", WEATHERS)
@pytest.mark.parametrize("reverse", [False, True])
@pytest.mark.parametrize("geometry", [True, False], ids=["geometry", "images-only"])
def test_onboard_rank_surface_id_candidates_clear_roof_first(
    city: LiveWorld, launch: dict[str, Frame], weather: str, reverse: bool, geometry: bool
) -> None:
    """Surface ID on a real LiDAR sweep finds the clear roof and slivers between the clutter."""
    frame = launch[weather]
    lidar = city.lidar_sweep(LAUNCH, LEVEL, 0.0, np.random.default_rng(1))
    cam = PinholeCamera.from_hfov(city.camera.width_px, city.camera.height_px, city.camera.hfov_deg)
    cands, _ = propose(
        LidarDepth(), cam, lidar_frd=lidar, quat_wxyz=LEVEL, pos_ned_m=LAUNCH, ground_up_m=LAUNCH[2]
    )
    clear = [
        k for k, c in enumerate(cands) if share(frame, c.box_px, [C.ROOF_FLAT]) == 1.0 and c.box_px[2] < 480
    ]
    cluttered = [k for k, c in enumerate(cands) if c.box_px[0] > 480]
    assert len(clear) == 1  # the clear roof, west of the street (left half of the image)
    assert len(cluttered) >= 2  # slivers of the cluttered roof, east of it
    x0, y0, x1, y1 = ground_box(city, LAUNCH, *CLUTTERED_ROOF)
    assert all(x0 <= cands[k].centre_px[0] <= x1 and y0 <= cands[k].centre_px[1] <= y1 for k in cluttered)
    crops = [crop(frame, c.box_px) for c in cands]
    best, ranking = ranked_first(crops, cands if geometry else None, reverse=reverse)
    assert best == clear[0]
    assert ranking.rationale.startswith(site_of(ranking, clear[0], reverse, len(cands)) + ": ")
    assert "no clutter" in ranking.rationale.split(";")[0]


@pytest.mark.parametrize("context", ["pad20", "pad40", "pad60"])
def test_onboard_rank_judges_the_candidate_not_its_context_padding(
    city: LiveWorld, launch: dict[str, Frame], context: str
) -> None:
    """Padded crops of the clear roof take in the street beside it (cars, lane markings). With the
    cores given, the onboard tier judges each candidate's own box, so its order is that of the exact
    crops; the padding is context for a model that can reason about surroundings."""
    frame = launch["clear"]
    lidar = city.lidar_sweep(LAUNCH, LEVEL, 0.0, np.random.default_rng(1))
    cam = PinholeCamera.from_hfov(city.camera.width_px, city.camera.height_px, city.camera.hfov_deg)
    cands, _ = propose(
        LidarDepth(), cam, lidar_frd=lidar, quat_wxyz=LEVEL, pos_ned_m=LAUNCH, ground_up_m=LAUNCH[2]
    )
    boxes = [c.box_px for c in cands]
    exact, _ = rank_crops(frame.rgb, boxes, "crop")
    padded, cores = rank_crops(frame.rgb, boxes, context)
    assert all(p.shape[0] > e.shape[0] for p, e in zip(padded, exact, strict=True))
    for p_img, e_img, (x0, y0, x1, y1) in zip(padded, exact, cores, strict=True):
        assert np.array_equal(p_img[y0:y1, x0:x1], e_img)
    by_exact = ONBOARD.rank_sync(RankRequest(exact, tuple(cands)))
    by_core = ONBOARD.rank_sync(RankRequest(padded, tuple(cands), cores=cores))
    assert by_core.order == by_exact.order
    with pytest.raises(ValueError, match="is not a box inside its"):
        RankRequest(padded, tuple(cands), cores=((0, 0, 10_000, 10),) * len(padded))


def _pair(frame: Frame, city: LiveWorld, rect: Rect, classes: tuple[C, ...]) -> tuple[np.ndarray, np.ndarray]:
    roof_box = ground_box(city, LAUNCH, *CLEAR_ROOF)
    other_box = ground_box(city, LAUNCH, *rect)
    assert share(frame, roof_box, [C.ROOF_FLAT]) == 1.0
    assert share(frame, other_box, classes) == 1.0
    return crop(frame, roof_box), crop(frame, other_box)


ROOF_GEOMETRY = {"up_m": 22.0, "edge_m": 13.0}  # the clear roof: 22 m up, 13 m from its parapet at most
CASES = {
    # name: (ground rectangle, its classes, its geometry as Surface ID would see it, word in the rationale)
    "cluttered roof": (CLUTTERED_ROOF, (C.ROOF_FLAT, C.ROOF_CLUTTER), {"up_m": 18.0, "edge_m": 3.0}, "HVAC"),
    "road": (ROAD, ROAD_CLASSES, {"up_m": 0.0, "edge_m": 5.0}, "lane markings|road texture"),
    # the deck is 9 m up and 16 m wide: geometrically a roof, and the study's small models chose it
    "highway": (HIGHWAY, HIGHWAY_CLASSES, {"up_m": 9.0, "edge_m": 6.0}, "lane markings"),
    "water": (WATER, (C.WATER,), {"up_m": 0.0, "edge_m": 8.0}, "water"),
}


@pytest.mark.parametrize("case", list(CASES))
@pytest.mark.parametrize("weather", WEATHERS)
@pytest.mark.parametrize("reverse", [False, True])
@pytest.mark.parametrize("geometry", [True, False], ids=["geometry", "images-only"])
def test_onboard_rank_clear_roof_beats(
    city: LiveWorld, launch: dict[str, Frame], case: str, weather: str, reverse: bool, geometry: bool
) -> None:
    rect, classes, geo, seen = CASES[case]
    frame = launch[weather]
    if case == "cluttered roof":
        box = ground_box(city, LAUNCH, *rect)
        assert share(frame, box, [C.ROOF_CLUTTER]) > 0.15
    roof, other = _pair(frame, city, rect, classes)
    cands = [
        truth_candidate(ground_box(city, LAUNCH, *CLEAR_ROOF), CLEAR_ROOF, **ROOF_GEOMETRY),
        truth_candidate(ground_box(city, LAUNCH, *rect), rect, **geo),
    ]
    best, ranking = ranked_first([roof, other], cands if geometry else None, reverse=reverse)
    assert best == 0, ranking.rationale
    chosen, rest = ranking.rationale.split(";", 1)
    assert chosen.startswith(site_of(ranking, 0, reverse, 2))
    assert site_of(ranking, 1, reverse, 2) in rest
    assert any(word in rest for word in seen.split("|"))  # it names what it saw on the runner-up
    if geometry:
        assert "elevated flat roof 22 m up" in chosen
    else:
        assert ranking.rationale.endswith("(no geometry: image cues only)")


def test_onboard_rank_the_highway_wins_on_geometry_alone_and_loses_on_sight(
    city: LiveWorld, launch: dict[str, Frame]
) -> None:
    """Why the image cues matter: a highway deck next to a smaller clear roof is the better surface by
    geometry; what it looks like (markings, traffic) puts it behind."""
    small_roof = ((-8.0, 8.0), (-33.0, -21.0), 22.0)  # the middle of the clear roof, 16 x 12 m
    roof_box, deck_box = ground_box(city, LAUNCH, *small_roof), ground_box(city, LAUNCH, *HIGHWAY)
    roof = truth_candidate(roof_box, small_roof, up_m=22.0, edge_m=6.0, margin_m=0.0)
    deck = truth_candidate(deck_box, HIGHWAY, **CASES["highway"][2])
    assert geometry_score(deck)[0] > geometry_score(roof)[0]
    frame = launch["clear"]
    best, ranking = ranked_first([crop(frame, roof_box), crop(frame, deck_box)], [roof, deck], reverse=False)
    assert best == 0
    assert "lane markings" in ranking.rationale


@pytest.mark.parametrize("reverse", [False, True])
@pytest.mark.parametrize("geometry", [True, False], ids=["geometry", "images-only"])
@pytest.mark.parametrize("weather", ["clear", "rain"])
def test_onboard_rank_a_roof_with_a_person_on_it_comes_second(
    scene: LiveWorld, reverse: bool, geometry: bool, weather: str
) -> None:
    cam = (0.0, 0.0, -80.0)  # both roofs of tests/onboard_scene.toml in view, 60 m above them
    frame = render(scene, cam, weather)
    clear_rect: Rect = ((-13.0, 13.0), (-48.0, -22.0), 20.0)
    walked_rect: Rect = ((-13.0, 13.0), (22.0, 48.0), 20.0)
    clear_box, walked_box = ground_box(scene, cam, *clear_rect), ground_box(scene, cam, *walked_rect)
    assert share(frame, clear_box, [C.ROOF_FLAT]) == 1.0
    assert share(frame, walked_box, [C.PEDESTRIAN]) > 0.0
    assert share(frame, walked_box, [C.ROOF_FLAT, C.PEDESTRIAN]) == 1.0
    # identical geometry: only the person tells them apart
    pairs = ((clear_box, clear_rect), (walked_box, walked_rect))
    cands = [truth_candidate(b, r, up_m=20.0, edge_m=13.0, margin_m=0.0) for b, r in pairs]
    crops = [crop(frame, clear_box), crop(frame, walked_box)]
    best, ranking = ranked_first(crops, cands if geometry else None, reverse=reverse)
    assert best == 0, ranking.rationale


def test_onboard_rank_fallback_candidates_come_last(city: LiveWorld, launch: dict[str, Frame]) -> None:
    """Quadrant-fallback candidates (no geometry) rank after every measured one, whatever they show."""
    frame = launch["clear"]
    water_box = ground_box(city, LAUNCH, *WATER)
    road_box = ground_box(city, LAUNCH, *ROAD)
    roof_box = ground_box(city, LAUNCH, *CLEAR_ROOF)
    cands = [
        truth_candidate(water_box, WATER, up_m=0.0, edge_m=8.0),
        Candidate(1, roof_box, (0.0, 0.0), fallback=True),
        truth_candidate(road_box, ROAD, up_m=0.0, edge_m=5.0),
    ]
    crops = [crop(frame, b) for b in (water_box, roof_box, road_box)]
    ranking = ONBOARD.rank_sync(RankRequest(tuple(crops), tuple(cands)))
    assert ranking.order[-1] == 1
    assert ranking.order[:2] == (2, 0)  # a road before water, both measured


async def test_onboard_rank_async_matches_sync_and_fills_the_transcript(
    city: LiveWorld, launch: dict[str, Frame]
) -> None:
    frame = launch["clear"]
    crops = tuple(crop(frame, ground_box(city, LAUNCH, *r)) for r in (ROAD, CLEAR_ROOF, CLUTTERED_ROOF))
    transcript: list[dict[str, object]] = []
    tier: Reasoner = ONBOARD
    ranking = await tier.rank(RankRequest(crops, transcript=transcript))
    assert ranking.order == ONBOARD.rank_sync(RankRequest(crops)).order == (1, 0, 2)
    assert tier.name == "onboard"
    assert len(transcript) == 1
    entry = transcript[0]
    assert entry["tier"] == "onboard"
    assert isinstance(entry["cues"], list)
    assert len(entry["cues"]) == 3


def test_onboard_rank_bad_crop_raises() -> None:
    good = np.full((20, 20, 3), 128, np.uint8)
    with pytest.raises(ValueError, match="dtype uint8"):
        ONBOARD.rank_sync(RankRequest((good, good.astype(np.float32))))
    with pytest.raises(ValueError, match="non-empty"):
        ONBOARD.rank_sync(RankRequest((good, np.zeros((0, 4, 3), np.uint8))))


def test_onboard_rank_blank_crops_keep_order_and_geometry_decides() -> None:
    blank = tuple(np.zeros((16, 16, 3), np.uint8) for _ in range(3))
    assert ONBOARD.rank_sync(RankRequest(blank)).order == (0, 1, 2)
    cands = (
        Candidate(0, (0, 0, 16, 16), (8.0, 8.0), area_m2=200.0, landable_area_m2=100.0, height_above_m=0.5,
                  edge_distance_m=4.0, slope_deg=0.5, roughness_m=0.01),
        Candidate(1, (0, 0, 16, 16), (8.0, 8.0), area_m2=900.0, landable_area_m2=700.0, height_above_m=15.0,
                  edge_distance_m=12.0, slope_deg=0.5, roughness_m=0.01),
        Candidate(2, (0, 0, 16, 16), (8.0, 8.0), area_m2=900.0, landable_area_m2=700.0, height_above_m=15.0,
                  edge_distance_m=12.0, slope_deg=6.0, roughness_m=0.05),
    )  # fmt: skip
    ranking = ONBOARD.rank_sync(RankRequest(blank, cands))
    assert ranking.order == (1, 2, 0)
    assert "sloped 6 deg" in ranking.rationale
    assert "rough 5 cm" in ranking.rationale


def test_onboard_geometry_score_terms() -> None:
    w = GeometryWeights()
    base = Candidate(
        0, (0, 0, 1, 1), (0.5, 0.5), area_m2=900.0, landable_area_m2=900.0, height_above_m=20.0,
        edge_distance_m=20.0, slope_deg=0.0, roughness_m=0.0,
    )  # fmt: skip
    top, words = geometry_score(base, w)
    assert top == pytest.approx(w.area + w.edge + w.elevated)
    assert words.startswith("elevated flat roof 20 m up")
    street, words = geometry_score(dataclasses.replace(base, height_above_m=0.0), w)
    assert top - street == pytest.approx(w.elevated - w.street_level)
    assert "at street level" in words
    unknown = dict.fromkeys(
        ("area_m2", "landable_area_m2", "height_above_m", "edge_distance_m", "slope_deg", "roughness_m"),
        math.nan,
    )
    relative = dataclasses.replace(base, **unknown)
    assert geometry_score(relative, w) == (0.0, "no metric geometry")
    assert geometry_score(dataclasses.replace(base, fallback=True), w)[0] == 0.0
    deck, words = geometry_score(dataclasses.replace(base, strip=True, length_m=118.0, width_m=9.0), w)
    assert deck == pytest.approx(street)  # an elevated strip scores as street level does, not as a roof
    assert "elevated strip 20 m up, 118 x 9 m" in words


# ------------------------------------------------------------------------------------------ confirm
def confirm(frame: Frame, check: SiteCheck | None, critical: bool = False) -> Decision:
    decision = ONBOARD.confirm_sync(ConfirmRequest(frame.rgb, check, critical))
    assert decision.tier == "onboard"
    assert decision.latency_s > 0.0
    return decision


@pytest.mark.parametrize("weather", WEATHERS)
@pytest.mark.parametrize("height_m", [10.0, 30.0, 66.0])
def test_onboard_confirm_accepts_the_clear_roof(city: LiveWorld, weather: str, height_m: float) -> None:
    frame, check = close_up(city, (0.0, -27.0), 22.0, height_m, weather)
    assert share(frame, centre_window(frame, 0.1), [C.ROOF_FLAT]) == 1.0  # under the vehicle: the roof
    assert share(frame, centre_window(frame), [C.ROOF_FLAT, C.PARAPET]) > 0.7  # around it: mostly
    assert check.clear
    for chk in (check, None):
        decision = confirm(frame, chk)
        assert decision.accept, decision.rationale
        assert decision.rationale.startswith("site clear: ")
        if height_m <= 30.0:  # higher up the site's rim takes in a parapet and a kerb line
            assert "no clutter" in decision.rationale
    assert "LiDAR" in confirm(frame, check).rationale
    assert "no LiDAR" in confirm(frame, None).rationale


@pytest.mark.parametrize("weather", WEATHERS)
@pytest.mark.parametrize("height_m", [12.0, 30.0])
@pytest.mark.parametrize(
    ("name", "ne", "up_m", "classes", "seen"),
    [
        ("cluttered roof", (0.0, 29.0), 18.0, (C.ROOF_CLUTTER,), "HVAC-like"),
        ("road", (0.0, 2.0), 0.0, (C.ROAD,), ""),
        ("water", (0.0, 150.0), -0.8, (C.WATER,), "water"),
    ],
)
def test_onboard_confirm_rejects(
    city: LiveWorld,
    weather: str,
    height_m: float,
    name: str,
    ne: tuple[float, float],
    up_m: float,
    classes: tuple[C, ...],
    seen: str,
) -> None:
    frame, check = close_up(city, ne, up_m, height_m, weather)
    assert share(frame, centre_window(frame), classes) > 0.1
    for chk in (None, check):
        decision = confirm(frame, chk)
        assert not decision.accept, f"{name}: {decision.rationale}"
        assert decision.rationale.startswith("rejected: ")
        assert seen in decision.rationale


@pytest.mark.parametrize("height_m", [10.0, 20.0])
@pytest.mark.parametrize("weather", ["clear", "rain"])
@pytest.mark.parametrize("critical", [False, True])
def test_onboard_confirm_rejects_a_person_on_the_roof(
    scene: LiveWorld, height_m: float, weather: str, critical: bool
) -> None:
    frame, check = close_up(scene, (0.0, 35.0), 20.0, height_m, weather)
    assert share(frame, centre_window(frame), [C.PEDESTRIAN]) > 0.0
    assert not check.clear  # the person stands inside the rotor-clearance disc
    without = confirm(frame, None, critical)  # no LiDAR: the image alone says no
    assert not without.accept
    assert "shadows" in without.rationale  # the person, or its shadow when its top looks like gravel
    assert not confirm(frame, check, critical).accept
    empty, empty_check = close_up(scene, (0.0, -35.0), 20.0, height_m, weather)  # the same roof, nobody on it
    assert confirm(empty, empty_check, critical).accept
    assert confirm(empty, None, critical).accept


@pytest.mark.parametrize("height_m", [10.0, 30.0, 60.0])
@pytest.mark.parametrize("weather", ["clear", "rain"])
def test_onboard_confirm_on_the_recovery_loops_square_close_up(
    city: LiveWorld, scene: LiveWorld, height_m: float, weather: str
) -> None:
    clear, _ = close_up(city, (0.0, -27.0), 22.0, height_m, weather)
    cluttered, _ = close_up(city, (0.0, 29.0), 18.0, height_m, weather)
    assert ONBOARD.confirm_sync(ConfirmRequest(site_cut(city, clear, height_m))).accept
    assert not ONBOARD.confirm_sync(ConfirmRequest(site_cut(city, cluttered, height_m))).accept
    if height_m <= 30.0:  # higher up a person is a few pixels of a 96 px cut: the LiDAR's to see
        walked, _ = close_up(scene, (0.0, 35.0), 20.0, height_m, weather)
        cut = site_cut(scene, walked, height_m)
        assert (walked.hit_class == C.PEDESTRIAN).any()
        assert not ONBOARD.confirm_sync(ConfirmRequest(cut)).accept


def test_onboard_confirm_site_window_must_be_a_share() -> None:
    grey = np.full((100, 100, 3), 140, np.uint8)
    with pytest.raises(ValueError, match=r"\(0, 1\]"):
        OnboardReasoner(confirm=ConfirmParams(site_window=1.5)).confirm_sync(ConfirmRequest(grey))
    assert OnboardReasoner(confirm=ConfirmParams(site_window=1.0)).confirm_sync(ConfirmRequest(grey)).accept


def test_onboard_confirm_critical_tolerates_one_object_outside_a_clear_rotor_disc(scene: LiveWorld) -> None:
    """40 m above the HVAC roof's middle: its one HVAC unit is in view, 6 m from the site. Normally that
    is a no; with a critical alarm and a clear LiDAR check it is tolerated; without a check it is not."""
    frame, check = close_up(scene, (-55.0, 35.0), 18.0, 40.0)
    assert share(frame, centre_window(frame), [C.ROOF_CLUTTER]) > 0.0
    assert check.clear
    assert not confirm(frame, check).accept
    relaxed = confirm(frame, check, critical=True)
    assert relaxed.accept
    assert "critical" in relaxed.rationale
    assert not confirm(frame, None, critical=True).accept


def test_onboard_confirm_reports_a_geometric_veto(city: LiveWorld) -> None:
    frame, _ = close_up(city, (0.0, -27.0), 22.0, 30.0)
    veto = SiteCheck(80, 22.0, 0.01, 0.6, 5.0, ("object 0.6 m tall within 2 m",))
    decision = confirm(frame, veto)
    assert not decision.accept
    assert "LiDAR: object 0.6 m tall within 2 m" in decision.rationale


async def test_onboard_confirm_async_and_bad_image() -> None:
    grey = np.full((540, 960, 3), 140, np.uint8)
    tier: Reasoner = ONBOARD
    decision = await tier.confirm(ConfirmRequest(grey))
    assert decision.accept == ONBOARD.confirm_sync(ConfirmRequest(grey)).accept
    with pytest.raises(ValueError, match=r"\(height, width, 3\)"):
        ONBOARD.confirm_sync(ConfirmRequest(grey[..., 0]))


@pytest.mark.parametrize("height_m", [20.0, 30.0, 60.0])
@pytest.mark.parametrize("weather", ["clear", "rain"])
def test_onboard_confirm_refuses_an_empty_street_measured_at_street_level(
    city: LiveWorld, height_m: float, weather: str
) -> None:
    """Quay Street south of the roofs, no car, no marking under the site: flat, level and clear to the
    LiDAR, and to the image only a dark even surface. Measured at street level it is a road (or a car
    park): refused, and the refusal is binding (no remote yes overrules it). Not claimed in fog: the
    haze lifts the asphalt's brightness into light paving's (docs/reasoning.md)."""
    frame, check = close_up(city, (-40.0, 0.0), 0.0, height_m, weather)
    assert check.clear
    assert share(frame, centre_window(frame, 0.15), [C.ROAD]) > 0.8
    cut = site_cut(city, frame, height_m)
    street = ONBOARD.confirm_sync(ConfirmRequest(cut, check, site_up_m=0.0))
    assert (street.accept, street.binding) == (False, True), street.rationale
    assert "asphalt at street level" in street.rationale
    unmeasured = ONBOARD.confirm_sync(ConfirmRequest(cut, check))  # elevation unknown: not this veto
    assert "asphalt at street level" not in unmeasured.rationale
    assert not unmeasured.binding
    roof, roof_check = close_up(city, (0.0, -27.0), 22.0, height_m, weather)
    clear = ONBOARD.confirm_sync(ConfirmRequest(site_cut(city, roof, height_m), roof_check, site_up_m=22.0))
    assert (clear.accept, clear.binding) == (True, False), clear.rationale


@pytest.mark.parametrize("height_m", [10.0, 30.0, 60.0])
@pytest.mark.parametrize("weather", WEATHERS)
def test_onboard_confirm_takes_a_measured_roof_for_a_tar_roof_not_a_road(
    scene: LiveWorld, city: LiveWorld, height_m: float, weather: str
) -> None:
    """A clear tar roof is dark, even asphalt to the image cues. Surface ID measured it 20 m above its
    surroundings (``site_up_m``): no road runs there, so its asphalt look is no reason to refuse. An
    elevated highway deck keeps its lane markings, which still veto."""
    frame, check = close_up(scene, (70.0, -35.0), 20.0, height_m, weather)
    assert share(frame, centre_window(frame, 0.15), [C.ROOF_FLAT]) == 1.0
    cut = site_cut(scene, frame, height_m)
    elevated = ONBOARD.confirm_sync(ConfirmRequest(cut, check, site_up_m=20.0))
    assert elevated.accept, elevated.rationale
    if height_m == 60.0 and weather == "clear":  # from high up the grain reads as a road's
        assert not ONBOARD.confirm_sync(ConfirmRequest(cut, check)).accept
        assert "a tar roof, not a road" in elevated.rationale
    deck, deck_check = close_up(city, (0.0, -80.0), 9.0, height_m, weather)
    deck_cut = site_cut(city, deck, height_m)
    assert not ONBOARD.confirm_sync(ConfirmRequest(deck_cut, deck_check, site_up_m=9.0)).accept


def _painted_line_site(length_frac: float) -> np.ndarray:
    """A light, even paving close-up (200 px square) with one short painted line across its middle."""
    rng = np.random.default_rng(0)
    img = np.clip(rng.normal(150, 6, (200, 200, 3)), 0, 255).astype(np.uint8)
    half = round(200 * length_frac / 2)
    img[99:102, 100 - half : 100 + half] = 245
    return img


@pytest.mark.parametrize("length_frac", [0.06, 0.1])
def test_onboard_confirm_a_painted_line_off_a_roof_vetoes_whatever_the_texture(length_frac: float) -> None:
    """One short painted line, too little paint for the lane-marking limit: on a roof it is no reason to
    refuse (a seam, a stain), but at street level or on an elevated strip it is a road's (a
    sidewalk accepted as "uniform gravel or tile texture" though the close-up saw a painted line)."""
    image = _painted_line_site(length_frac)
    cues = analyse(image, site=True)
    assert cues.lane_lines >= 1
    assert cues.line_length <= ONBOARD.confirm_params.max_markings  # too little for the old rule
    roof = ONBOARD.confirm_sync(ConfirmRequest(image, None, site_up_m=20.0))
    assert roof.accept, roof.rationale
    street = ONBOARD.confirm_sync(ConfirmRequest(image, None, site_up_m=0.0))
    assert (street.accept, street.binding) == (False, True), street.rationale
    assert "a painted line at street level" in street.rationale
    assert street.hazards == ("markings",)
    deck = ONBOARD.confirm_sync(ConfirmRequest(image, None, site_up_m=9.0, site_strip=True))
    assert (deck.accept, deck.binding) == (False, True), deck.rationale
    assert "a painted line on an elevated strip" in deck.rationale


@pytest.mark.parametrize("height_m", [10.0, 30.0])
@pytest.mark.parametrize("weather", ["clear", "rain"])
def test_onboard_confirm_an_elevated_strip_is_no_tar_roof(
    scene: LiveWorld, height_m: float, weather: str
) -> None:
    """The clear tar roof that passes as a roof (site_up_m 20 m) is refused once Surface ID measured it
    as an elevated strip: a dark, even surface up on a deck is a carriageway, and the refusal binds."""
    frame, check = close_up(scene, (70.0, -35.0), 20.0, height_m, weather)
    cut = site_cut(scene, frame, height_m)
    assert ONBOARD.confirm_sync(ConfirmRequest(cut, check, site_up_m=20.0)).accept
    deck = ONBOARD.confirm_sync(ConfirmRequest(cut, check, site_up_m=20.0, site_strip=True))
    assert (deck.accept, deck.binding) == (False, True), deck.rationale
    assert "on an elevated strip" in deck.rationale
    assert "street_asphalt" in deck.hazards


def test_onboard_confirm_names_what_vetoed_the_site_by_kind(city: LiveWorld) -> None:
    frame, check = close_up(city, (0.0, 150.0), -0.8, 20.0)  # the harbour
    water = ONBOARD.confirm_sync(ConfirmRequest(site_cut(city, frame, 20.0), check, site_up_m=0.0))
    assert "water" in water.hazards
    roof, roof_check = close_up(city, (0.0, -27.0), 22.0, 20.0)
    clear = ONBOARD.confirm_sync(ConfirmRequest(site_cut(city, roof, 20.0), roof_check, site_up_m=22.0))
    assert clear.accept
    assert clear.hazards == ()


def test_onboard_confirm_street_level_among_buildings_is_a_last_resort_only() -> None:
    """Clear light paving at street level: in open country (no roof measured) it is accepted; among
    buildings (``built_up``) it is refused, bindingly, as "street_level": a sidewalk or a plaza, where
    people walk between one look and the next. A roof is not affected."""
    image = _painted_line_site(0.0)  # no line at all: even paving
    country = ONBOARD.confirm_sync(ConfirmRequest(image, None, site_up_m=0.0))
    assert country.accept, country.rationale
    town = ONBOARD.confirm_sync(ConfirmRequest(image, None, site_up_m=0.0, built_up=True))
    assert (town.accept, town.binding, town.hazards) == (False, True, ("street_level",)), town.rationale
    assert "street level among buildings" in town.rationale
    roof = ONBOARD.confirm_sync(ConfirmRequest(image, None, site_up_m=20.0, built_up=True))
    assert roof.accept, roof.rationale


@pytest.mark.parametrize("judge", ["cues", "landnet"])
def test_a_warm_up_leaves_every_later_answer_as_it_was(city: LiveWorld, judge: str) -> None:
    """OnboardReasoner.warm_up reads plain grey images and keeps nothing: the rank and the
    confirmation of the same frame give the same answers after it as a reasoner never warmed."""
    frame, check = close_up(city, (0.0, -27.0), 22.0, 30.0)
    crops = (frame.rgb[:270, :480].copy(), frame.rgb[270:, 480:].copy())
    cold, warm = OnboardReasoner(judge=judge), OnboardReasoner(judge=judge)
    warm.warm_up()
    a, b = (r.confirm_sync(ConfirmRequest(frame.rgb, check)) for r in (cold, warm))
    assert (a.accept, a.rationale) == (b.accept, b.rationale)
    ra, rb = (r.rank_sync(RankRequest(crops)) for r in (cold, warm))
    assert (ra.order, ra.rationale) == (rb.order, rb.rationale)
