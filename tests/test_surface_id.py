"""Surface ID on synthetic depth with known geometry: metric flatness, components, boxes, crops, errors.

Depth images are computed exactly for a level nadir camera 100 m above flat ground, with roofs (and
tilted planes, clutter, noise) placed at known NED positions: every expected box and figure follows
from the geometry, not from a run of the code under test.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
import pytest

from companion.guidance.frames import PinholeCamera
from companion.perception.crops import (
    MIN_SITE_HALF_PX,
    PAD_LEVELS,
    context_crops,
    crop,
    pad_box,
    pad_of,
    site_box,
)
from companion.perception.depth import (
    ArrayDepth,
    DepthError,
    DepthMap,
    LidarDepth,
    ring_spacing_rad,
)
from companion.perception.sources import make_source
from companion.perception.surface_id import Candidate, SurfaceParams, propose, quadrant_fallback, surface_id
from simbridge.world.lidar import LidarModel

CAM = PinholeCamera.from_hfov(960, 540, 90.0)  # fx = 480 px
ALT = 100.0
POS = (0.0, 0.0, -ALT)


@dataclass(frozen=True)
class Slab:
    """A rectangle (north n0..n1, east e0..e1) at ``up`` metres, rising ``tilt`` metres per metre north."""

    n0: float
    n1: float
    e0: float
    e1: float
    up: float
    tilt: float = 0.0


def depth_image(slabs: list[Slab], noise_m: float = 0.0, seed: int = 0) -> np.ndarray:
    """Camera z-depth of flat ground at 0 m plus the slabs; the nearest surface along each ray wins."""
    u = np.arange(CAM.width) + 0.5
    v = np.arange(CAM.height) + 0.5
    xn = ((u - CAM.cx) / CAM.fx)[None, :]  # east per metre of depth
    yn = ((v - CAM.cy) / CAM.fy)[:, None]  # south per metre of depth
    z = np.full((CAM.height, CAM.width), ALT)
    for s in slabs:
        # Level camera: a point at depth z lies at north = -yn z, east = xn z, up = ALT - z.
        # On the slab: ALT - z = up + tilt * north  =>  z = (ALT - up) / (1 - tilt * yn).
        zs = (ALT - s.up) / (1.0 - s.tilt * yn) * np.ones_like(xn)
        n, e = -yn * zs, xn * zs
        hit = (n >= s.n0) & (n < s.n1) & (e >= s.e0) & (e < s.e1) & (zs < z)
        z = np.where(hit, zs, z)
    if noise_m:
        z = z + np.random.default_rng(seed).normal(0.0, noise_m, z.shape)
    return z.astype(np.float32)


def expected_box(n0: float, n1: float, e0: float, e1: float, up: float) -> tuple[float, ...]:
    z = ALT - up
    return (
        CAM.cx + CAM.fx * e0 / z,
        CAM.cy - CAM.fy * n1 / z,
        CAM.cx + CAM.fx * e1 / z,
        CAM.cy - CAM.fy * n0 / z,
    )


def iou(a: tuple[float, ...], b: tuple[float, ...]) -> float:
    iw = max(min(a[2], b[2]) - max(a[0], b[0]), 0.0)
    ih = max(min(a[3], b[3]) - max(a[1], b[1]), 0.0)
    inter = iw * ih
    return inter / ((a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - inter)


def run(depth: np.ndarray, metric: bool = True, params: SurfaceParams | None = None) -> list:
    cands, _ = propose(ArrayDepth(depth, metric), CAM, pos_ned_m=POS, ground_up_m=-ALT, params=params)
    return cands


ROOF = Slab(-15.0, 15.0, -37.0, -13.0, 20.0)  # 30 x 24 m at 20 m, west of the vehicle


def test_a_flat_roof_is_found_with_its_geometry() -> None:
    cands = run(depth_image([ROOF]))
    roof = [c for c in cands if c.height_above_m > 3]
    assert len(roof) == 1
    c = roof[0]
    m = SurfaceParams().edge_margin_m
    want = expected_box(ROOF.n0 + m, ROOF.n1 - m, ROOF.e0 + m, ROOF.e1 - m, ROOF.up)
    assert iou(c.box_px, want) > 0.9
    assert c.area_m2 == pytest.approx(30 * 24, rel=0.08)
    assert c.landable_area_m2 == pytest.approx((30 - 2 * m) * (24 - 2 * m), rel=0.12)
    assert c.slope_deg < 0.5
    assert c.roughness_m < 0.01
    assert c.height_above_m == pytest.approx(20.0, abs=0.2)
    assert c.edge_distance_m == pytest.approx(12.0, abs=1.0)  # half the roof's width
    assert c.site_ned_m is not None
    n, e, d = c.site_ned_m
    assert ROOF.n0 + 8 < n < ROOF.n1 - 8
    assert e == pytest.approx(-25.0, abs=1.0)
    assert d == pytest.approx(-20.0, abs=0.1)
    # The ground around it is a candidate too, but its box holds the roof (another height): the roof stays.
    assert any(c.height_above_m < 1 for c in cands)


def test_slope_is_measured_in_degrees_and_steep_planes_are_rejected() -> None:
    gentle = Slab(-40.0, 40.0, -60.0, 60.0, 10.0, tilt=math.tan(math.radians(4.0)))
    cands = run(depth_image([gentle]))
    assert not cands[0].fallback
    assert cands[0].slope_deg == pytest.approx(4.0, abs=0.4)
    steep = Slab(-80.0, 80.0, -120.0, 120.0, 30.0, tilt=math.tan(math.radians(15.0)))
    assert all(c.fallback for c in run(depth_image([steep])))  # the whole view slopes 15 deg


def test_roughness_is_measured_in_metres() -> None:
    smooth = run(depth_image([], noise_m=0.02))
    assert not smooth[0].fallback
    assert smooth[0].roughness_m == pytest.approx(0.02, abs=0.006)
    assert all(c.fallback for c in run(depth_image([], noise_m=0.15)))  # a rubble field


def test_clutter_splits_a_roof_in_two() -> None:
    roof = Slab(-20.0, 20.0, -40.0, -12.0, 20.0)
    hvac_row = Slab(-1.5, 1.5, -40.0, -12.0, 21.8)  # a 3 m wide row of units across the whole roof
    cands = [c for c in run(depth_image([roof, hvac_row])) if c.height_above_m > 3]
    assert len(cands) == 2
    v_row = CAM.cy  # north 0 is the image's middle row
    north, south = sorted(cands, key=lambda c: c.box_px[1])
    assert north.box_px[3] < v_row - 10
    assert south.box_px[1] > v_row + 10
    for c in cands:
        assert c.area_m2 == pytest.approx(18.5 * 28, rel=0.15)


def test_small_surfaces_and_narrow_strips_are_not_candidates() -> None:
    small = Slab(-2.0, 2.0, -32.0, -28.0, 20.0)  # 16 m2 < 30 m2
    strip = Slab(-20.0, 20.0, 20.0, 23.0, 15.0)  # 120 m2 but 3 m wide: no point 2 m from both edges
    cands = run(depth_image([small, strip]))
    assert not [c for c in cands if c.height_above_m > 3]


def test_nothing_flat_gives_the_quadrant_fallback() -> None:
    rubble = depth_image([], noise_m=0.5)
    cands = run(rubble)
    assert [c.fallback for c in cands] == [True] * 5
    assert [c.box_px for c in cands] == [c.box_px for c in quadrant_fallback(CAM)]
    assert cands[4].box_px == (240, 135, 720, 405)  # the centre crop
    assert all(math.isnan(c.area_m2) for c in cands)


def test_at_most_max_candidates_best_first() -> None:
    roofs = [
        Slab(n - 6, n + 6, e - 6, e + 6, 15.0) for n in (-30.0, 0.0, 30.0) for e in (-60.0, -20.0, 20.0, 60.0)
    ]
    cands = run(depth_image(roofs), params=SurfaceParams(max_candidates=3))
    assert len(cands) == 3
    assert [c.index for c in cands] == [0, 1, 2]
    assert [c.score for c in cands] == sorted((c.score for c in cands), reverse=True)


def test_relative_depth_finds_the_roof_without_metres() -> None:
    rel = 1.0 / depth_image([ROOF])  # inverse depth, as a monocular network gives, any scale
    cands = run(-rel, metric=False)  # larger = farther
    assert not cands[0].fallback
    x0, y0, x1, y1 = expected_box(ROOF.n0, ROOF.n1, ROOF.e0, ROOF.e1, ROOF.up)
    m = SurfaceParams().relative_margin_frac * CAM.width  # no metres: the margin is a share of the image
    assert max(iou(c.box_px, (x0 + m, y0 + m, x1 - m, y1 - m)) for c in cands) > 0.85
    assert all(math.isnan(c.area_m2) and math.isnan(c.slope_deg) for c in cands)


@pytest.mark.parametrize(
    ("depth", "message"),
    [
        (np.ones((540, 961), np.float32), "540 x 960"),
        (np.ones((540, 960, 3), np.float32), "540 x 960"),
        (np.full((540, 960), np.nan, np.float32), "no finite values"),
        (np.full((540, 960), -1.0, np.float32), "no positive values"),
        (np.array([["a"] * 960] * 540), "numbers"),
    ],
)
def test_bad_depth_images_raise_clear_errors(depth: np.ndarray, message: str) -> None:
    with pytest.raises(DepthError, match=message):
        run(depth)


def test_unknown_depth_is_never_flat() -> None:
    d = depth_image([ROOF])
    d[:, :480] = np.nan  # the west half unmeasured: the roof lies there
    cands = run(d)
    assert all(c.box_px[0] >= 480 - 4 for c in cands if not c.fallback)


@pytest.mark.parametrize(
    ("lidar", "message"),
    [
        (None, "no LiDAR sweep"),
        (np.empty((0, 4), np.float32), "no finite returns"),
        (np.full((100, 4), np.nan, np.float32), "no finite returns"),
        (np.ones((100, 2), np.float32), r"\(N, 3\)"),
        (np.tile([[-50.0, 0.0, -5.0, 1.0]], (100, 1)), "inside the camera image"),  # all above the horizon
    ],
)
def test_bad_lidar_raises_clear_errors(lidar: np.ndarray | None, message: str) -> None:
    with pytest.raises(DepthError, match=message):
        LidarDepth().depth_map(CAM, lidar_frd=lidar)


def test_lidar_rows_with_nan_are_dropped_not_fatal() -> None:
    pts = np.array([[0.0, 0.0, 80.0, 1.0], [np.nan, 0.0, 80.0, 1.0], [1.0, 1.0, 80.0, 1.0]], np.float32)
    dm = LidarDepth().depth_map(CAM, lidar_frd=pts)
    assert int(dm.measured.sum()) == 2
    assert np.nanmin(dm.depth) == pytest.approx(80.0)


def test_unknown_depth_source_is_refused() -> None:
    with pytest.raises(DepthError, match="lidar, depth-anything or auto"):
        make_source("radar")


def test_surface_id_refuses_a_depth_map_for_another_camera() -> None:
    dm = ArrayDepth(depth_image([ROOF])).depth_map(CAM)
    with pytest.raises(DepthError, match="does not match"):
        surface_id(dm, PinholeCamera.from_hfov(640, 480, 90.0))


# ------------------------------------------------------------------------------------------------ crops
def test_padding_grows_a_box_by_its_share_and_clamps_at_the_border() -> None:
    assert pad_box((100, 100, 200, 150), 0.2, 960, 540) == (90, 95, 210, 155)
    assert pad_box((100, 100, 200, 150), 0.6, 960, 540) == (70, 85, 230, 165)
    # At the top-left corner the box only grows inward; at the far corner it stops at the image edge.
    assert pad_box((0, 0, 100, 100), 0.6, 960, 540) == (0, 0, 130, 130)
    assert pad_box((900, 500, 960, 540), 0.5, 960, 540) == (885, 490, 960, 540)
    with pytest.raises(ValueError, match="inside a 960 x 540"):
        pad_box((0, 0, 961, 10), 0.2, 960, 540)
    with pytest.raises(ValueError, match=">= 0"):
        pad_box((0, 0, 10, 10), -0.1, 960, 540)


def test_site_box_keeps_the_site_in_the_middle_near_a_border() -> None:
    assert site_box(480, 270, 100, 960, 540) == (380, 170, 580, 370)
    # 60 px from the left edge: the box shrinks to +-60 px on every side, the site stays centred
    assert site_box(60, 270, 100, 960, 540) == (0, 210, 120, 330)
    # low over the site the box would be taller than the frame: square, as high as the frame
    assert site_box(480, 270, 400, 960, 540) == (210, 0, 750, 540)
    # closer than MIN_SITE_HALF_PX to a corner it keeps its minimum size and is clamped instead
    assert site_box(10, 530, 100, 960, 540) == (0, 530 - MIN_SITE_HALF_PX, 10 + MIN_SITE_HALF_PX, 540)
    with pytest.raises(ValueError, match="outside the 960 x 540"):
        site_box(960, 10, 50, 960, 540)


def test_context_variants_name_their_padding() -> None:
    assert [pad_of(c) for c in ("crop", "pad20", "pad35", "pad60", "full")] == [0.0, 0.2, 0.35, 0.6, 0.0]
    for bad in ("pad", "padxx", "pad0", "zoom"):
        with pytest.raises(ValueError, match="unknown context variant"):
            pad_of(bad)


def test_context_crops_cover_every_level_and_the_full_frame() -> None:
    image = np.random.default_rng(0).integers(0, 255, (540, 960, 3), dtype=np.uint8)
    box = (10, 20, 110, 70)
    crops = context_crops(image, box)
    assert list(crops) == ["exact", "pad20", "pad30", "pad40", "pad50", "pad60", "full"]
    assert crops["exact"].shape == (50, 100, 3)
    assert np.array_equal(crops["exact"], image[20:70, 10:110])
    sizes = [crops[f"pad{round(p * 100)}"].shape[1] for p in PAD_LEVELS]
    assert sizes == sorted(sizes)
    assert sizes[0] > 100
    assert crops["full"] is image
    assert crop(image, box, 0.0).flags.c_contiguous


# ------------------------------------------------------------------------- extension over unmeasured cells
EXTEND = SurfaceParams(extend_with_image=True)


def _roof_image(roof_rgb: tuple[int, int, int]) -> np.ndarray:
    """Grey ground, the roof in ``roof_rgb`` with a little texture, a dark parapet line round it."""
    rng = np.random.default_rng(3)
    img = np.full((CAM.height, CAM.width, 3), 110, np.uint8)
    x0, y0, x1, y1 = (round(v) for v in expected_box(ROOF.n0, ROOF.n1, ROOF.e0, ROOF.e1, ROOF.up))
    img[y0:y1, x0:x1] = roof_rgb
    img[y0:y1, x0:x1] += rng.integers(0, 4, (y1 - y0, x1 - x0, 3), dtype=np.uint8)
    img[y0 : y0 + 2, x0:x1] = img[y1 - 2 : y1, x0:x1] = 40
    img[y0:y1, x0 : x0 + 2] = img[y0:y1, x1 - 2 : x1] = 40
    return img


def _out_of_range(d: np.ndarray, range_m: float) -> np.ndarray:
    """The depth image as a sensor of ``range_m`` returns it: NaN wherever the surface is farther."""
    u = ((np.arange(CAM.width) + 0.5 - CAM.cx) / CAM.fx)[None, :]
    v = ((np.arange(CAM.height) + 0.5 - CAM.cy) / CAM.fy)[:, None]
    return np.where(d * np.sqrt(1.0 + u * u + v * v) > range_m, np.nan, d)


def _roof_of(depth: DepthMap, image: np.ndarray | None) -> list[Candidate]:
    cands = surface_id(depth, CAM, pos_ned_m=POS, ground_up_m=-ALT, image=image, params=EXTEND)
    return [c for c in cands if c.height_above_m > 3]


# The roof's plane, 80 m below the camera, is 85.4 m away where the image's x = 300 crosses it.
CUT_RANGE_M = 85.4


def test_the_image_extends_a_roof_past_the_range_of_the_depth() -> None:
    d = _out_of_range(depth_image([ROOF]), CUT_RANGE_M)  # the roof's west part and all the ground
    dm = dataclasses.replace(ArrayDepth(d).depth_map(CAM), max_range_m=CUT_RANGE_M)
    m = SurfaceParams().edge_margin_m
    want = expected_box(ROOF.n0 + m, ROOF.n1 - m, ROOF.e0 + m, ROOF.e1 - m, ROOF.up)

    (alike,) = _roof_of(dm, _roof_image((200, 196, 190)))
    assert iou(alike.box_px, want) > 0.9
    assert alike.box_px[0] == pytest.approx(want[0], abs=6)  # stopped at the parapet, not the ground
    assert 0.6 < alike.measured_share < 0.95
    assert alike.centre_px[0] > 300  # the landing site stays on measured cells
    (blind,) = _roof_of(dm, None)
    assert blind.box_px[0] >= 295
    assert blind.measured_share == 1.0
    # The unmeasured part looks different (another colour): no extension.
    img = _roof_image((200, 196, 190))
    img[:, :300] = (60, 120, 60)
    (other,) = _roof_of(dm, img)
    assert other.box_px[0] >= 295
    # A sensor that reaches 200 m would have answered from the roof's plane there: not the roof.
    (in_range,) = _roof_of(dataclasses.replace(dm, max_range_m=200.0), _roof_image((200, 196, 190)))
    assert in_range.box_px[0] >= 295


def test_a_roof_that_ends_inside_the_range_is_not_continued_round_its_corner() -> None:
    """Scenario1's case: the whole roof measured, its far edge close to the sensor's range, the
    ground beyond unknown (out of range) and looking just like the roof. Beside the roof the sensor
    would have answered from the roof's plane, so the roof ends at its edge; only straight out from
    where the roof itself reached the range could it go on."""
    corner_m = float(np.hypot(ALT - ROOF.up, np.hypot(ROOF.n1, ROOF.e0)))  # the farthest roof point: 89.2 m
    range_m = corner_m + 0.5
    d = _out_of_range(depth_image([ROOF]), range_m)
    dm = dataclasses.replace(ArrayDepth(d).depth_map(CAM), max_range_m=range_m)
    img = np.full((CAM.height, CAM.width, 3), 150, np.uint8)  # roof and ground alike, no parapet line
    img += np.random.default_rng(4).integers(0, 4, img.shape, dtype=np.uint8)
    (roof,) = _roof_of(dm, img)
    edge = expected_box(ROOF.n0, ROOF.n1, ROOF.e0, ROOF.e1, ROOF.up)
    assert roof.box_px[0] >= edge[0] - 3  # nothing west of the roof's west edge
    assert roof.box_px[1] >= edge[1] - 3
    assert roof.box_px[3] <= edge[3] + 3
    assert roof.measured_share > 0.97


def test_a_roof_edge_at_the_range_stops_the_image_at_its_parapet_line() -> None:
    """The roof's west edge lies right at the sensor's range, so the ground beyond could be roof as
    far as the range can tell; the ground looks just like the roof, but the parapet's line between
    them is an edge stronger than anything inside the roof: the growth stops at it."""
    west_m = float(np.hypot(ALT - ROOF.up, ROOF.e0))  # 88.1 m: the middle of the west edge
    range_m = west_m + 0.2  # the edge measured, the roof's corners (89.2 m) not
    r, w, top = ROOF, 0.4, ROOF.up + 1.0  # a parapet 1 m high, 0.4 m wide
    parapet = [
        Slab(r.n0, r.n0 + w, r.e0, r.e1, top),
        Slab(r.n1 - w, r.n1, r.e0, r.e1, top),
        Slab(r.n0, r.n1, r.e0, r.e0 + w, top),
        Slab(r.n0, r.n1, r.e1 - w, r.e1, top),
    ]
    d = _out_of_range(depth_image([ROOF, *parapet]), range_m)
    dm = dataclasses.replace(ArrayDepth(d).depth_map(CAM), max_range_m=range_m)
    img = _roof_image((110, 110, 110))  # the ground's grey, with the dark parapet line round it
    (roof,) = _roof_of(dm, img)
    edge = expected_box(ROOF.n0, ROOF.n1, ROOF.e0, ROOF.e1, ROOF.up)
    assert roof.box_px[0] >= edge[0] - 4
    assert roof.measured_share < 1.0  # the corners beyond the range were taken


def test_ring_spacing_from_a_sweep() -> None:
    model = LidarModel(channels=40, points_per_ring=64)
    pts = model.rays_body() * 30.0
    pts = pts[pts[:, 2] > 0.1]  # returns from below only
    noisy = pts * (1.0 + 0.001 * np.random.default_rng(0).standard_normal(len(pts)))[:, None]
    assert ring_spacing_rad(noisy) == pytest.approx(math.radians((90.0 - 0.5) / 39), rel=1e-6)
    scattered = np.random.default_rng(1).normal(size=(500, 3)) + np.array([0.0, 0.0, 5.0])
    assert ring_spacing_rad(scattered) is None  # no rings: a dense sensor's tolerance
    assert ring_spacing_rad(pts[:5]) is None


def test_the_image_never_extends_across_measured_cells() -> None:
    d = depth_image([ROOF])  # all measured: the roof's edges, and the ground beyond, are known
    cands = surface_id(
        ArrayDepth(d).depth_map(CAM),
        CAM,
        pos_ned_m=POS,
        ground_up_m=-ALT,
        image=_roof_image((110, 110, 110)),
        params=EXTEND,
    )
    assert all(c.measured_share == 1.0 for c in cands)


@pytest.mark.parametrize("agl_m", [60.0, 90.0])
def test_an_elevated_highway_deck_is_a_strip_and_a_roof_is_not(agl_m: float) -> None:
    """scenario1's highway deck (16 m wide, 9 m up, running north-south at east -80 m) crosses the view
    as a long band: Surface ID measures it as an elevated strip, which scores as street level; the clear
    gravel roof beside it (40 x 30 m, 22 m up) is a closed shape, a roof. (From 40 m the view is 45 m
    tall: no deck shows its length there, and the painted line decides at confirmation.)"""
    from simbridge.scenarios import load_scenario
    from simbridge.world.live import LiveWorld
    from simbridge.world.model import SurfaceClass as C

    world = load_scenario("scenario1", 0).terrain
    assert isinstance(world, LiveWorld)
    pos, quat = (0.0, -55.0, -(9.0 + agl_m)), (1.0, 0.0, 0.0, 0.0)
    rng = np.random.default_rng(3)
    image = world.camera_frame(pos, quat, 0.0, "clear", rng).rgb
    lidar = world.lidar_sweep(pos, quat, 0.0, rng)
    cm = world.camera
    camera = PinholeCamera.from_hfov(cm.width_px, cm.height_px, cm.hfov_deg)
    cands, _ = propose(
        LidarDepth(), camera, image=image, lidar_frd=lidar, quat_wxyz=quat, pos_ned_m=pos, ground_up_m=pos[2]
    )

    def on(c: Candidate) -> C:
        assert c.site_ned_m is not None
        ij = world.grid.index(c.site_ned_m[0], c.site_ned_m[1])
        assert ij is not None
        return C(int(world.grid.cls[ij]))

    decks = [c for c in cands if on(c) == C.HIGHWAY]
    roofs = [c for c in cands if on(c) == C.ROOF_FLAT]
    assert decks, [(on(c).name, c.height_above_m) for c in cands]
    assert roofs, [(on(c).name, c.height_above_m) for c in cands]
    for deck in decks:
        assert deck.height_above_m > 3.0
        assert deck.strip, (deck.length_m, deck.width_m)
        assert not deck.elevated
        assert deck.length_m > 2.5 * deck.width_m
        assert deck.to_json()["geometry"]["strip"] is True
    for roof in roofs:
        assert not roof.strip, (roof.length_m, roof.width_m)
        assert roof.elevated
        assert roof.length_m < 45.0
