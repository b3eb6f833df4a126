"""The chosen site found again in newer frames (companion.perception.site_track), on simbridge's
renders of scenario1 (the gravel roof, Quay Street) and scenario2 (the membrane roof)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.guidance.frames import PinholeCamera
from companion.perception.site_track import SiteView, TrackParams, centre_down, track_site
from companion.recovery.following import FollowState, look_for_site
from simbridge.geo import euler_to_quat
from simbridge.world.live import LiveWorld
from tests.recovery_fakes import frame
from tests.views import world

LAUNCH = (0.0, 0.0, -110.0)
YAW = 0.3


@pytest.fixture(scope="module")
def scenario1() -> LiveWorld:
    return world("scenario1")


def _camera(w: LiveWorld) -> PinholeCamera:
    return PinholeCamera.from_hfov(w.camera.width_px, w.camera.height_px, w.camera.hfov_deg)


def _view(
    w: LiveWorld,
    true_pos: tuple[float, float, float],
    quat: tuple[float, float, float, float],
    estimate_bias: tuple[float, float, float] = (0.0, 0.0, 0.0),
    seed: int = 7,
) -> SiteView:
    """A render from ``true_pos``, posed as an estimator ``estimate_bias`` off would pose it."""
    rgb = w.camera_frame(true_pos, quat, 0.0, "clear", np.random.default_rng(seed)).rgb
    est = (true_pos[0] + estimate_bias[0], true_pos[1] + estimate_bias[1], true_pos[2] + estimate_bias[2])
    return SiteView(rgb, _camera(w), est, quat)


def _heading_error(site: np.ndarray, about: tuple[float, float, float], deg: float) -> np.ndarray:
    """Where an estimate ``deg`` off in heading places ``site`` seen from ``about``."""
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    dn, de = site[0] - about[0], site[1] - about[1]
    return np.array([about[0] + c * dn - s * de, about[1] + s * dn + c * de, site[2]])


@pytest.mark.parametrize("height_m", [60.0, 20.0, 8.0])
def test_track_site_finds_the_gravel_roof_under_a_heading_and_position_error(
    scenario1: LiveWorld, height_m: float
) -> None:
    """The site placed from the launch pose with a 1.5 degree heading error (1 m off at 40 m), looked
    for from above it with a position estimate 1.4 m off: found where the newer estimate has it."""
    truth = np.array([2.0, -25.0, -22.0])  # on the gravel roof
    true_ref = _view(scenario1, LAUNCH, euler_to_quat(0.0, 0.0, YAW))
    # the estimator's heading is 1.5 degrees off: the frame is posed so, and the site placed so
    ref = SiteView(true_ref.image, true_ref.camera, LAUNCH, euler_to_quat(0.0, 0.0, YAW + math.radians(1.5)))
    placed = _heading_error(truth, LAUNCH, 1.5)
    bias = (1.2, -0.8, 0.0)
    here = (truth[0] + 0.7, truth[1] - 0.4, truth[2] - height_m)
    cur = _view(scenario1, here, euler_to_quat(0.02, -0.01, 1.0), bias)
    result = track_site(ref, placed, cur)
    wanted = truth + np.array(bias)
    assert result.found, result.reason
    assert math.dist(placed[:2], wanted[:2]) > 1.0  # what the untracked target would miss by
    assert math.dist(result.site_ned_m[:2], wanted[:2]) < 0.25
    assert result.site_ned_m[2] == placed[2]
    assert result.score >= TrackParams().min_score
    assert result.shift_m == pytest.approx(
        (result.site_ned_m[0] - placed[0], result.site_ned_m[1] - placed[1])
    )


def test_track_site_chained_down_to_two_metres_stays_on_the_membrane_roof() -> None:
    """Frame after frame down to 2.5 m over scenario2's membrane roof (little texture), each found
    against the last, the estimate drifting 0.15 m a frame: within 0.3 m of the truth all the way."""
    w = world("scenario2")
    rng = np.random.default_rng(1)
    truth = np.array([-2.6, -35.5, -29.9])
    ref = _view(w, (0.0, 0.0, -115.0), euler_to_quat(0.0, 0.0, YAW))
    site = truth.copy()
    bias = np.zeros(3)
    found = 0
    for k, h in enumerate((60.0, 30.0, 10.0, 5.0, 4.0, 3.0, 2.5)):
        bias += np.array([rng.normal(0, 0.15), rng.normal(0, 0.15), 0.0])
        here = tuple(truth + np.array([rng.normal(0, 0.3), rng.normal(0, 0.3), -h]))
        q = euler_to_quat(rng.normal(0, 0.03), rng.normal(0, 0.03), YAW + rng.normal(0, 0.05))
        cur = _view(w, here, q, tuple(bias), seed=k)
        result = track_site(ref, site, cur)
        if result.found:
            found += 1
            ref, site = cur, np.array(result.site_ned_m)
            assert math.dist(site[:2], (truth + bias)[:2]) < 0.3, (h, result)
    assert found >= 5


JUMP = (15.0, 10.0, 0.0)  # a GPS glitch: the estimate moved 18 m since the site was placed


@pytest.mark.parametrize(
    ("height_m", "moved"),
    [(60.0, (0.0, 0.0)), (40.0, (-8.0, -5.0)), (40.0, (-15.0, -10.0)), (20.0, (0.0, 0.0))],
)
def test_after_the_gps_jumped_the_wide_search_finds_the_site_where_the_new_estimate_has_it(
    scenario1: LiveWorld, height_m: float, moved: tuple[float, float]
) -> None:
    """Since the site was placed from the launch pose the estimate jumped 18 m (the vehicle, which
    holds its target in that estimate, may have flown ``moved`` since): where the estimate predicts
    the site, the usual search finds nothing; the wide search (the newer view's centre looked for in
    the reference) finds where the newer estimate has it, and the usual search refines it there."""
    truth = np.array([2.0, -25.0, -22.0])
    ref = _view(scenario1, LAUNCH, euler_to_quat(0.0, 0.0, YAW))
    here = (truth[0] + moved[0], truth[1] + moved[1], truth[2] - height_m)
    cur = _view(scenario1, here, euler_to_quat(0.02, -0.01, 1.0), JUMP)
    alone = track_site(ref, truth, cur, TrackParams(reacquire_m=0.0))
    assert not alone.found
    result = track_site(ref, truth, cur)
    assert result.found, result
    assert result.reacquired
    assert math.dist(result.site_ned_m[:2], (truth + np.array(JUMP))[:2]) < 0.25
    assert result.shift_m == pytest.approx(JUMP[:2], abs=0.25)


def test_without_a_jump_the_wide_search_agrees_and_the_usual_match_stands(scenario1: LiveWorld) -> None:
    truth = np.array([2.0, -25.0, -22.0])
    ref = _view(scenario1, LAUNCH, euler_to_quat(0.0, 0.0, YAW))
    here = (truth[0], truth[1], truth[2] - 30.0)
    cur = _view(scenario1, here, euler_to_quat(0.02, -0.01, 1.0), (0.4, -0.3, 0.0))
    usual = track_site(ref, truth, cur, TrackParams(reacquire_m=0.0))
    checked = track_site(ref, truth, cur)
    assert usual.found
    assert checked.found
    assert not checked.reacquired
    assert checked.site_ned_m == usual.site_ned_m


def test_a_jump_seen_from_too_close_is_not_guessed(scenario1: LiveWorld) -> None:
    """8 m above the roof the view holds too little for the wide search, and the site 18 m from its
    prediction is out of it: not found, rather than a place that merely looks alike."""
    truth = np.array([2.0, -25.0, -22.0])
    ref = _view(scenario1, LAUNCH, euler_to_quat(0.0, 0.0, YAW))
    cur = _view(scenario1, (truth[0], truth[1], truth[2] - 8.0), euler_to_quat(0.0, 0.0, 1.0), JUMP)
    result = track_site(ref, truth, cur)
    assert not result.found
    assert result.site_ned_m == tuple(truth)


def test_a_drift_carried_forward_centres_the_usual_search_where_the_site_went(scenario1: LiveWorld) -> None:
    """The estimate drifted 6 m since the reference frame (a GPS drifting steadily): the usual search
    about the old place does not reach the site; centred where the drift carried it (0.5 m off: the
    drift's line is not exact), it finds the site where the newer estimate has it."""
    truth = np.array([2.0, -25.0, -22.0])
    ref = _view(scenario1, (truth[0], truth[1], truth[2] - 17.0), euler_to_quat(0.0, 0.0, YAW))
    drift = np.array([5.0, 3.3, 0.0])
    cur = _view(
        scenario1, (truth[0] + 0.3, truth[1], truth[2] - 17.0), euler_to_quat(0.01, 0.0, 1.0), tuple(drift)
    )
    usual = TrackParams(reacquire_m=0.0)
    assert not track_site(ref, truth, cur, usual).found
    guess = (truth + drift)[:2] + np.array([0.4, -0.3])
    result = track_site(ref, truth, cur, usual, predicted_ne_m=guess)
    assert result.found, result
    assert math.dist(result.site_ned_m[:2], (truth + drift)[:2]) < 0.25
    assert result.shift_m == pytest.approx(drift[:2], abs=0.25)
    with pytest.raises(ValueError, match="predicted_ne_m"):
        track_site(ref, truth, cur, usual, predicted_ne_m=(math.nan, 0.0))


def test_centre_down_is_the_lidars_surface_about_the_cameras_axis() -> None:
    """Returns within a few degrees of the camera's axis give the surface there (a street 20 m below
    a roof at the view's edge does not count); none there, none at all or a malformed sweep: NaN."""
    view = SiteView(np.zeros((4, 4), np.uint8), PinholeCamera(4, 4, 2.0, 2.0, 2.0, 2.0), (0.0, 0.0, -50.0),
                    euler_to_quat(0.0, 0.0, 0.7))  # fmt: skip
    below = np.array([[0.5, -0.3, 30.0, 1.0], [-1.0, 0.8, 30.1, 1.0], [0.2, 0.1, 29.9, 1.0]])
    aside = np.array([[20.0, 5.0, 50.0, 1.0], [-15.0, 0.0, 50.0, 1.0]])
    assert centre_down(np.vstack([below, aside]), view) == pytest.approx(-20.0, abs=0.15)
    assert math.isnan(centre_down(aside, view))
    assert math.isnan(centre_down(None, view))
    assert math.isnan(centre_down(np.zeros((0, 3)), view))
    assert math.isnan(centre_down(np.zeros((5, 2)), view))


def test_track_site_along_a_road_is_ambiguous(scenario1: LiveWorld) -> None:
    """Quay Street looks the same along its length: no answer rather than a guess, with the wide
    search or without (its answer counts only where the site itself matches around it)."""
    truth = np.array([-40.0, 0.0, 0.0])
    q = euler_to_quat(0.0, 0.0, 0.0)
    ref = _view(scenario1, LAUNCH, q)
    cur = _view(scenario1, (truth[0], truth[1], -20.0), q, (1.0, 0.0, 0.0))
    for params in (TrackParams(), TrackParams(reacquire_m=0.0)):
        result = track_site(ref, truth, cur, params)
        assert not result.found
        # the score hardly falls along the street: flat that way, or as high somewhere else along it
        assert result.reason in ("the match is ambiguous", "another place matches as well")
        assert result.site_ned_m == tuple(truth)
        assert result.shift_m == (0.0, 0.0)


def test_track_site_out_of_view_and_too_close(scenario1: LiveWorld) -> None:
    truth = np.array([2.0, -25.0, -22.0])
    q = euler_to_quat(0.0, 0.0, 0.0)
    ref = _view(scenario1, LAUNCH, q)
    away = _view(scenario1, (80.0, 60.0, -40.0), q)
    assert track_site(ref, truth, away).reason == "the site is out of the camera's view"
    close = _view(scenario1, (truth[0], truth[1], truth[2] - 1.2), q)
    assert track_site(ref, truth, close).reason == "too close to the surface to see around the site"
    assert track_site(close, truth, ref).reason == "the reference frame saw too little around the site"


def test_a_reference_too_coarse_for_a_close_view_is_not_matched(scenario1: LiveWorld) -> None:
    """From 3.5 m over the gravel roof the camera holds about a metre around the site: the frame it was
    chosen in, 88 m up (0.18 m a pixel there), gives a patch of a few cells in that, which is refused;
    a frame from 17.5 m (fine enough cells) is matched."""
    truth = np.array([5.13, -27.5, -22.0])  # where curated scenario1's chosen pixel lies
    q = euler_to_quat(0.0, 0.0, YAW)
    close = _view(scenario1, (truth[0] + 0.3, truth[1] - 0.2, truth[2] - 3.5), q, seed=3)
    chosen = _view(scenario1, LAUNCH, q)
    coarse = track_site(chosen, truth, close)
    assert coarse.reason == "the reference is too coarse for a view this close"
    assert not coarse.found
    assert 0.15 < coarse.cell_m < 0.2
    tried = track_site(chosen, truth, close, TrackParams(min_patch_cells=0))  # matched without the rule
    assert tried.reason != coarse.reason
    assert math.isfinite(tried.score)
    nearer = _view(scenario1, (truth[0] - 0.5, truth[1] + 0.4, truth[2] - 17.5), q, seed=5)
    found = track_site(nearer, truth, close)
    assert found.found, found.reason
    assert math.dist(found.site_ned_m[:2], truth[:2]) < 0.15


def test_a_look_is_centred_where_the_site_was_last_found(scenario1: LiveWorld) -> None:
    """The site's reference frame is from 17.6 m; since, the estimate has moved 0.75 m north and a look
    from 13 m that did not become the reference found it there. From 3.4 m the search reaches about
    0.8 m: centred on the reference's site it does not reach the site; centred where the site was last
    found it finds it there."""
    truth = np.array([5.13, -27.5, -22.0])
    q = euler_to_quat(0.0, 0.0, YAW)
    ref = _view(scenario1, (truth[0] - 0.5, truth[1] + 0.4, truth[2] - 17.6), q)
    bias = (0.75, 0.0, 0.0)
    close = _view(scenario1, (truth[0] + 0.05, truth[1] - 0.05, truth[2] - 3.4), q, bias, seed=3)
    now = frame(image=close.image, pos_ned_m=close.pos_ned_m, quat_wxyz=q, camera=close.camera)
    site = (float(truth[0]), float(truth[1]), float(truth[2]))
    old = look_for_site(now, FollowState((ref, site), None, ()), TrackParams())
    assert old is not None
    assert not old.result.found, old.result  # the search does not reach where the site is now
    last = (10.0, truth[0] + bias[0], truth[1] + bias[1])  # (t_boot_s, north, east)
    look = look_for_site(now, FollowState((ref, site), None, (last,)), TrackParams())
    assert look is not None
    assert look.result.found, look.result.reason
    assert math.dist(look.result.site_ned_m[:2], last[1:]) < 0.15


def test_track_site_without_texture_says_so() -> None:
    """A uniform grey frame (a lens cap, a blown-out exposure): nothing to follow."""
    cam = PinholeCamera.from_hfov(320, 240, 90.0)
    flat = np.full((240, 320, 3), 128, np.uint8)
    q = euler_to_quat(0.0, 0.0, 0.0)
    ref = SiteView(flat, cam, (0.0, 0.0, -30.0), q)
    cur = SiteView(flat, cam, (0.5, 0.0, -20.0), q)
    result = track_site(ref, (0.0, 0.0, 0.0), cur)
    assert not result.found
    assert result.reason == "too little texture around the site to follow it"


@pytest.mark.parametrize("site", [(0.0, 0.0), (0.0, math.nan, 0.0), (0.0, 0.0, math.inf)])
def test_track_site_rejects_a_malformed_site(site: tuple[float, ...]) -> None:
    cam = PinholeCamera.from_hfov(320, 240, 90.0)
    view = SiteView(np.zeros((240, 320), np.uint8), cam, (0.0, 0.0, -30.0), (1.0, 0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="site_ned_m must be three finite numbers"):
        track_site(view, site, view)
