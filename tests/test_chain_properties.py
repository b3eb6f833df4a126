"""Properties (hypothesis) of the recovery chain from a frame to a target, stage by stage and whole:
Surface ID -> crops per context variant -> the onboard rank -> IPM -> the confirm close-up -> the
onboard confirm and the LiDAR site check (companion/recovery/looking.py ``Looker``, as
companion/recovery/machine.py ``_round`` calls it). The crops' own properties (stage 2):
tests/test_crop_properties.py; the onboard reasoner's (stage 3): tests/test_onboard_properties.py; the
LiDAR site check's (stage 5): tests/test_site_check_properties.py.

Frames are synthetic and small: a camera at a random size, height and attitude over level ground,
with flat rectangles (roofs) placed anywhere in the image, down to one pixel or one depth cell, and
touching every edge and corner; rough ground, unknown (NaN) holes, LiDAR sweeps sampled from the same
geometry. The only exceptions allowed out of a stage are its own typed errors (``DepthError``,
``IpmError``, ``CropError`` / ``ValueError`` for invalid input), and what comes out must be usable by
the next stage: boxes inside the image and non-empty, crops non-empty, finite points.
"""

from __future__ import annotations

import asyncio
import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from companion.alarms import Criticality
from companion.guidance.frames import CAMERA_TO_BODY, PinholeCamera, quat_to_matrix
from companion.guidance.ipm import (
    IpmError,
    LidarPixelIndex,
    RayDoesNotDescend,
    pixel_to_ned,
    pixel_to_ned_flat,
)
from companion.perception.crops import (
    rank_crops,
)
from companion.perception.depth import ArrayDepth, DepthError, DepthMap, DepthSource, LidarDepth
from companion.perception.site_check import check_site
from companion.perception.surface_id import Candidate, SurfaceParams, propose
from companion.reasoning.onboard import OnboardReasoner
from companion.recovery.core import RecoveryParams
from companion.recovery.looking import Looker, onboard_tier
from companion.recovery.search_plan import SearchPlanner
from simbridge.geo import euler_to_quat
from tests import recovery_fakes

CHAIN = settings(
    max_examples=40,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
QUICK = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
CONTEXTS = ("crop", "pad20", "pad30", "pad40", "pad50", "pad60", "full")
LEVEL = (1.0, 0.0, 0.0, 0.0)
Box = tuple[int, int, int, int]


def assert_box_inside(box: Box, width: int, height: int) -> None:
    x0, y0, x1, y1 = box
    assert 0 <= x0 < x1 <= width, f"box {box} is not a non-empty span of a {width} px wide image"
    assert 0 <= y0 < y1 <= height, f"box {box} is not a non-empty span of a {height} px tall image"


# ------------------------------------------------------------------------------------- synthetic frames
@dataclass(frozen=True)
class Patch:
    """A flat rectangle of pixels ``[x0, x1) x [y0, y1)`` seen at ``up`` metres above the ground."""

    x0: int
    y0: int
    x1: int
    y1: int
    up: float


@dataclass(frozen=True)
class Scene:
    camera: PinholeCamera
    cell_px: int
    quat: tuple[float, float, float, float]
    alt_m: float
    patches: tuple[Patch, ...]
    rough_m: float  # noise on the ground's depth (0: the ground is flat too)
    holes: tuple[Box, ...]  # unknown depth
    seed: int

    @property
    def pos(self) -> tuple[float, float, float]:
        return (0.0, 0.0, -self.alt_m)


def pixel_rays_cam(camera: PinholeCamera) -> np.ndarray:
    """(H, W, 3) camera-frame rays through the pixel centres, z = 1."""
    u = (np.arange(camera.width) + 0.5 - camera.cx) / camera.fx
    v = (np.arange(camera.height) + 0.5 - camera.cy) / camera.fy
    x, y = np.meshgrid(u, v)
    return np.stack([x, y, np.ones_like(x)], axis=-1)


def scene_depth(s: Scene) -> np.ndarray:
    """Camera z-depth per pixel (H, W) float32: the patches and the ground are level planes; NaN where
    the ray never reaches them (above the horizon), farther than 5 km, or in a hole."""
    rays = pixel_rays_cam(s.camera)
    down = rays @ (quat_to_matrix(s.quat) @ CAMERA_TO_BODY)[2]  # NED down per unit camera z
    below = np.full(down.shape, s.alt_m)
    for p in s.patches:
        below[p.y0 : p.y1, p.x0 : p.x1] = s.alt_m - p.up
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.where(down > 1e-3, below / down, np.nan)
    ground = below == s.alt_m
    if s.rough_m > 0:
        z = np.where(ground, z + np.random.default_rng(s.seed).normal(0.0, s.rough_m, z.shape), z)
    z[~(z < 5000.0) | (z <= 0.01)] = np.nan
    for x0, y0, x1, y1 in s.holes:
        z[y0:y1, x0:x1] = np.nan
    return z.astype(np.float32)


def scene_image(s: Scene) -> np.ndarray:
    """RGB uint8: grey ground, each patch its own colour, a little noise."""
    rng = np.random.default_rng(s.seed)
    img = np.full((s.camera.height, s.camera.width, 3), 110, np.uint8)
    for p in s.patches:
        img[p.y0 : p.y1, p.x0 : p.x1] = rng.integers(40, 230, 3, dtype=np.uint8)
    img += rng.integers(0, 5, img.shape, dtype=np.uint8)
    return img


def scene_lidar(s: Scene, depth_px: np.ndarray, stride: int, range_m: float) -> np.ndarray:
    """(N, 4) float32 body FRD returns sampled from the depth image every ``stride`` pixels, within
    ``range_m`` of the sensor, plus a NaN row and a return behind the camera (the sensor's junk)."""
    rays = pixel_rays_cam(s.camera)[::stride, ::stride]
    z = depth_px[::stride, ::stride].astype(np.float64)
    pts_cam = rays * z[..., None]
    keep = np.isfinite(z) & (np.linalg.norm(pts_cam, axis=-1) <= range_m)
    pts_frd = pts_cam[keep] @ CAMERA_TO_BODY.T
    junk = np.array([[math.nan, 0.0, 10.0], [0.0, 0.0, -5.0]])
    xyz = np.concatenate([pts_frd, junk])
    return np.concatenate([xyz, np.full((len(xyz), 1), 0.5)], axis=1).astype(np.float32)


@st.composite
def spans(draw: st.DrawFn, size: int, cell_px: int) -> tuple[int, int]:
    """A half-open span of ``[0, size)``: anywhere, touching either end, the whole, one pixel, one cell."""
    kind = draw(st.sampled_from(["free", "low", "high", "whole", "pixel", "cell", "pixel_end"]))
    if kind == "whole":
        return 0, size
    if kind == "pixel_end":
        return size - 1, size
    if kind == "low":
        return 0, draw(st.integers(1, size))
    if kind == "high":
        return draw(st.integers(0, size - 1)), size
    a = draw(st.integers(0, size - 1))
    if kind == "pixel":
        return a, a + 1
    if kind == "cell":
        a = a // cell_px * cell_px
        return a, min(a + cell_px, size)
    return a, draw(st.integers(a + 1, size))


def attitudes(max_tilt_deg: float) -> st.SearchStrategy[tuple[float, float, float, float]]:
    tilt = st.floats(-max_tilt_deg, max_tilt_deg)
    return st.tuples(tilt, tilt, st.floats(-180.0, 180.0)).map(
        lambda rpy: euler_to_quat(*(math.radians(a) for a in rpy))
    )


cameras = st.one_of(
    st.builds(PinholeCamera.from_hfov, st.integers(24, 320), st.integers(16, 240), st.floats(40.0, 120.0)),
    st.just(PinholeCamera.from_hfov(960, 540, 90.0)),
)


@st.composite
def scenes(draw: st.DrawFn, max_tilt_deg: float = 30.0) -> Scene:
    camera = draw(cameras)
    cell_px = draw(st.sampled_from([2, 3, 4, 5]))
    alt = draw(st.floats(8.0, 150.0))
    patches = []
    for _ in range(draw(st.integers(0, 4))):
        x0, x1 = draw(spans(camera.width, cell_px))
        y0, y1 = draw(spans(camera.height, cell_px))
        patches.append(Patch(x0, y0, x1, y1, draw(st.floats(0.0, 0.9 * alt))))
    holes = []
    for _ in range(draw(st.integers(0, 2))):
        x0, x1 = draw(spans(camera.width, cell_px))
        y0, y1 = draw(spans(camera.height, cell_px))
        holes.append((x0, y0, x1, y1))
    return Scene(
        camera=camera,
        cell_px=cell_px,
        quat=draw(attitudes(max_tilt_deg)),
        alt_m=alt,
        patches=tuple(patches),
        rough_m=draw(st.sampled_from([0.0, 0.0, 0.03, 0.3])),
        holes=tuple(holes),
        seed=draw(st.integers(0, 2**16)),
    )


# Every setting the configuration allows, its extremes included (window_cells = 3, edge_margin_m = 0).
surface_params = st.builds(
    SurfaceParams,
    window_cells=st.sampled_from([3, 5, 7, 9]),
    min_area_m2=st.floats(0.01, 60.0),
    edge_margin_m=st.one_of(st.just(0.0), st.floats(0.01, 4.0)),
    max_candidates=st.integers(1, 5),
    min_area_frac=st.floats(0.0, 0.05),
    relative_margin_frac=st.floats(0.001, 0.05),
)


@st.composite
def depth_inputs(
    draw: st.DrawFn, s: Scene
) -> tuple[DepthSource, np.ndarray | None, np.ndarray | None, np.ndarray]:
    """A depth source for the scene and what it reads: (source, image, lidar_frd, depth_px)."""
    depth_px = scene_depth(s)
    image = draw(st.one_of(st.none(), st.just(scene_image(s))))
    kind = draw(st.sampled_from(["lidar", "metric", "relative"]))
    if kind == "lidar":
        range_m = draw(st.floats(5.0, 250.0))
        lidar = scene_lidar(s, depth_px, draw(st.integers(1, 6)), range_m)
        return LidarDepth(cell_px=s.cell_px, range_m=range_m), image, lidar, depth_px
    return ArrayDepth(depth_px, kind == "metric", s.cell_px), image, None, depth_px


def _propose(
    source: DepthSource,
    scene: Scene,
    image: np.ndarray | None,
    lidar: np.ndarray | None,
    params: SurfaceParams,
) -> tuple[list[Candidate], DepthMap]:
    """Surface ID on a drawn scene, as the recovery calls it (pose and ground from the scene)."""
    return propose(
        source,
        scene.camera,
        image=image,
        lidar_frd=lidar,
        quat_wxyz=scene.quat,
        pos_ned_m=scene.pos,
        ground_up_m=-scene.alt_m,
        params=params,
    )


# ------------------------------------------------------------------------------------ 1. Surface ID
@CHAIN
@given(st.data(), scenes(), surface_params)
def test_surface_id_boxes_and_centres_lie_inside_the_image(
    data: st.DataObject, scene: Scene, params: SurfaceParams
) -> None:
    source, image, lidar, _ = data.draw(depth_inputs(scene))
    cam = scene.camera
    try:
        cands, depth = _propose(source, scene, image, lidar, params)
    except DepthError:
        return
    assert cands
    assert [c.index for c in cands] == list(range(len(cands)))
    assert all(not c.fallback for c in cands) or len(cands) == 5
    assert depth.shape == (math.ceil(cam.height / scene.cell_px), math.ceil(cam.width / scene.cell_px))
    for c in cands:
        assert_box_inside(c.box_px, cam.width, cam.height)
        u, v = c.centre_px
        assert 0.0 <= u < cam.width, f"centre {c.centre_px} outside the {cam.width} px wide image"
        assert 0.0 <= v < cam.height, f"centre {c.centre_px} outside the {cam.height} px tall image"
        if not c.fallback:
            assert len(cands) <= params.max_candidates


def rubble_with_roof(cam: PinholeCamera, roof: Box) -> np.ndarray:
    """Rough ground 100 m below a level camera (nothing flat) and a flat roof 20 m up over ``roof``."""
    z = 100.0 + np.random.default_rng(0).normal(0.0, 0.3, (cam.height, cam.width))
    x0, y0, x1, y1 = roof
    z[y0:y1, x0:x1] = 80.0
    return z.astype(np.float32)


def test_surface_id_window_of_three_keeps_the_centre_inside_the_image() -> None:
    cam = PinholeCamera.from_hfov(960, 540, 90.0)
    depth = rubble_with_roof(cam, (300, 440, 700, 540))  # a roof cut by the bottom of the frame
    # 8 px cells: 68 rows, the last one (pixels 536..543) half outside the 540 px tall image
    params = SurfaceParams(window_cells=3, extend_with_image=False)
    (c,) = [c for c in propose(ArrayDepth(depth, cell_px=8), cam, params=params)[0] if not c.fallback]
    assert_box_inside(c.box_px, cam.width, cam.height)
    assert 0.0 <= c.centre_px[1] < cam.height  # got 540.0
    assert math.isfinite(c.roughness_m)  # got NaN: the border cells were never fitted


def test_surface_id_window_of_three_whole_flat_view_has_a_finite_edge_distance() -> None:
    cam = PinholeCamera.from_hfov(960, 540, 90.0)
    depth = np.full((cam.height, cam.width), 100.0, np.float32)
    params = SurfaceParams(window_cells=3, extend_with_image=False)
    (c,) = propose(ArrayDepth(depth, cell_px=4), cam, params=params)[0]
    assert not c.fallback
    assert c.edge_distance_m < 100.0  # the view is 200 x 112 m; got 2.8e38


def test_surface_id_frame_filling_surface_has_a_finite_edge_distance() -> None:
    cam = PinholeCamera.from_hfov(960, 540, 90.0)
    depth = np.full((cam.height, cam.width), 100.0, np.float32)
    depth[:, :8] = np.nan  # unmeasured: the image extends the ground over it
    image = np.full((cam.height, cam.width, 3), 120, np.uint8)
    (c,) = propose(ArrayDepth(depth), cam, image=image)[0]
    assert not c.fallback
    assert c.edge_distance_m < 1000.0  # the view is 200 x 112 m; got 2.8e38
    assert c.centre_px[0] > 100.0  # got (18, 10): the first cell, in the corner


def test_surface_id_zero_edge_margin_gives_candidates() -> None:
    cam = PinholeCamera.from_hfov(960, 540, 90.0)
    depth = rubble_with_roof(cam, (200, 100, 500, 300))
    cands, _ = propose(ArrayDepth(depth), cam, params=SurfaceParams(edge_margin_m=0.0))
    assert not cands[0].fallback
    assert_box_inside(cands[0].box_px, cam.width, cam.height)


def test_surface_id_depth_known_only_between_cell_centres_gives_the_fallback() -> None:
    """Cells sample their centre pixel: a depth image finite elsewhere leaves no cell measured, and
    the flatness fit has no point to centre on (it once took the mean of nothing)."""
    cam = PinholeCamera.from_hfov(64, 48, 90.0)
    depth = np.full((cam.height, cam.width), np.nan, np.float32)
    depth[0, 0] = 10.0  # cell (0, 0) samples pixel (2, 2)
    cands, dm = propose(ArrayDepth(depth), cam)
    assert not dm.valid.any()
    assert [c.fallback for c in cands] == [True] * 5


def single_cell_margin_depth(cam: PinholeCamera, col: int, row: int, half_cells: int) -> np.ndarray:
    """Rubble ground 100 m below a level camera, with a flat roof 20 m up whose flat part is a square
    of ``2 * half_cells + 1`` cells (4 px) centred on cell (col, row): the flatness window (5 cells)
    must lie on the roof, so the roof reaches 2 cells further on every side."""
    s = 4
    rng = np.random.default_rng(1)
    z = 100.0 + rng.normal(0.0, 0.3, (cam.height, cam.width))
    r = half_cells + 2
    z[(row - r) * s : (row + r + 1) * s, (col - r) * s : (col + r + 1) * s] = 80.0
    return z.astype(np.float32)


def test_surface_id_single_landable_cell_at_the_margin_gets_a_one_pixel_box() -> None:
    """A component whose landable part is one cell exactly at the edge margin had a box of
    no width, (526, 382, 526, 382) in a 960 x 540 frame, and cropping it for the reasoner raised."""
    cam = PinholeCamera.from_hfov(960, 540, 90.0)
    # cell (131, 95) holds pixel (526, 382) at its centre: (131.5 * 4, 95.5 * 4)
    source = ArrayDepth(single_cell_margin_depth(cam, 131, 95, 2), metric=True, cell_px=4)
    loose = SurfaceParams(min_area_m2=1.0, edge_margin_m=0.01, extend_with_image=False)
    (first,) = [c for c in propose(source, cam, params=loose)[0] if not c.fallback]
    assert first.centre_px == (526.0, 382.0)  # the cell farthest from the roof's edge
    # the margin is that cell's own edge distance: it alone is landable, with no reach past its centre
    tight = dataclasses.replace(loose, edge_margin_m=first.edge_distance_m)
    (c,) = [c for c in propose(source, cam, params=tight)[0] if not c.fallback]
    cell_m = 4 * 80.0 / cam.fx
    assert c.landable_area_m2 == pytest.approx(cell_m**2, rel=1e-4)  # one cell
    assert c.box_px == (526, 382, 527, 383)
    # what the recovery loop did with it: 20 % of one pixel pads it to the pixels either side
    crops, cores = rank_crops(np.zeros((540, 960, 3), np.uint8), [c.box_px], "pad20")
    assert crops[0].shape == (3, 3, 3)
    assert cores[0] == (1, 1, 2, 2)


# ------------------------------------------------------------------------------------------- 4. IPM
@st.composite
def clouds(draw: st.DrawFn, cam: PinholeCamera) -> np.ndarray:
    """(N, 3 or 4) LiDAR rows: empty, all NaN, one point, one point repeated, scattered (with NaN rows,
    returns behind the camera and far away), or a ground grid under the camera."""
    cols = draw(st.sampled_from([3, 4]))
    kind = draw(st.sampled_from(["empty", "nan", "one", "repeated", "scattered", "grid", "behind"]))
    rng = np.random.default_rng(draw(st.integers(0, 2**16)))
    if kind == "empty":
        return np.empty((0, cols))
    if kind == "nan":
        return np.full((draw(st.integers(1, 20)), cols), np.nan)
    if kind in ("one", "repeated"):
        row = [draw(st.floats(-200.0, 200.0)), draw(st.floats(-200.0, 200.0)), draw(st.floats(-5.0, 300.0))]
        n = 1 if kind == "one" else draw(st.integers(2, 100))
        return np.tile(np.array(row + [0.5] * (cols - 3)), (n, 1))
    if kind == "behind":
        pts = rng.uniform(-50.0, 50.0, (30, cols))
        pts[:, 2] = -np.abs(pts[:, 2]) - 0.01
        return pts
    if kind == "grid":
        step = draw(st.integers(2, 40))
        u, v = np.meshgrid(np.arange(0, cam.width, step) + 0.5, np.arange(0, cam.height, step) + 0.5)
        z = draw(st.floats(1.0, 500.0))
        cam_pts = np.stack([(u - cam.cx) / cam.fx * z, (v - cam.cy) / cam.fy * z, np.full(u.shape, z)], -1)
        pts = cam_pts.reshape(-1, 3) @ CAMERA_TO_BODY.T
        return np.concatenate([pts, np.full((len(pts), cols - 3), 0.5)], axis=1)
    n = draw(st.integers(1, 200))
    pts = rng.uniform(-300.0, 300.0, (n, cols))
    pts[rng.random(n) < 0.2, rng.integers(0, 3)] = np.nan
    pts[rng.random(n) < 0.1] *= 1e4
    return pts


@st.composite
def border_pixels(draw: st.DrawFn, cam: PinholeCamera) -> tuple[float, float]:
    """Continuous pixel coordinates in ``[0, W) x [0, H)``, the last pixel and the corners included."""

    def coord(size: int) -> st.SearchStrategy[float]:
        return st.one_of(
            st.sampled_from([0.0, 0.5, size - 1.0, size - 0.5, math.nextafter(size, 0.0)]),
            st.floats(0.0, size, exclude_max=True),
        )

    return draw(coord(cam.width)), draw(coord(cam.height))


@QUICK
@given(st.data(), cameras, attitudes(89.0), st.floats(-500.0, 500.0))
def test_pixel_to_ned_near_the_border_is_finite_or_an_ipm_error(
    data: st.DataObject, cam: PinholeCamera, quat: tuple[float, float, float, float], down_m: float
) -> None:
    cloud = data.draw(clouds(cam))
    u, v = data.draw(border_pixels(cam))
    pos = (12.0, -4.0, down_m)
    try:
        index = LidarPixelIndex(cloud, cam)
        out = pixel_to_ned(u, v, index, pos, quat)
    except IpmError:
        return
    assert out.shape == (3,)
    assert np.isfinite(out).all()


@QUICK
@given(
    st.data(),
    cameras,
    st.one_of(attitudes(89.0), attitudes(180.0)),
    st.floats(-1e4, 1e4),
    st.floats(-1e4, 1e4),
)
def test_pixel_to_ned_flat_is_finite_on_the_plane_or_ray_does_not_descend(
    data: st.DataObject,
    cam: PinholeCamera,
    quat: tuple[float, float, float, float],
    down_m: float,
    ground_down_m: float,
) -> None:
    u, v = data.draw(border_pixels(cam))
    ray_down = float((quat_to_matrix(quat) @ cam.pixel_ray_frd(u, v))[2])
    pose = ((0.0, 0.0, down_m), quat)
    if ground_down_m <= down_m or ray_down <= 0.0:  # a plane above, a ray at or above the horizon
        with pytest.raises(RayDoesNotDescend):
            pixel_to_ned_flat(u, v, cam, *pose, ground_down_m)
    elif ray_down >= 0.01:  # (below that the fallback may refuse grazing rays)
        out = pixel_to_ned_flat(u, v, cam, *pose, ground_down_m)
        assert np.isfinite(out).all()
        assert out[2] == ground_down_m


def test_lidar_pixel_index_empty_flat_list_is_lidar_unavailable() -> None:
    """An empty sweep given as ``[]`` (shape (0,)) is as empty as one of shape (0, 4)."""
    with pytest.raises(IpmError, match="empty"):
        LidarPixelIndex(np.empty((0,)), PinholeCamera.from_hfov(960, 540, 90.0))


# ---------------------------------------------------------------------------------------- 6. end to end
def _looker(reasoner: OnboardReasoner | None = None, **params: Any) -> Looker:
    """The recovery's looker (companion/recovery/looking.py) on a fake vehicle, with these parameters."""
    reasoner = reasoner or OnboardReasoner()
    return Looker(
        recovery_fakes.context(params=RecoveryParams(**params)),
        reasoner=reasoner,
        onboard=onboard_tier(reasoner),
        plan=SearchPlanner(Criticality.HIGH),
    )


@CHAIN
@given(st.data(), scenes(max_tilt_deg=25.0), st.floats(5.0, 250.0), st.integers(1, 6))
def test_chain_from_a_frame_to_a_confirmed_target_raises_only_typed_errors(
    data: st.DataObject, scene: Scene, range_m: float, stride: int
) -> None:
    """The recovery's looker from one frame to a confirmed target, every context variant of the
    ranking: Surface ID (no depth: the quadrant fallback), the rank, IPM (through the LiDAR, else flat
    ground at the rangefinder's distance), the close-up, and the confirmation with the LiDAR check."""
    cam = scene.camera
    image = scene_image(scene)
    lidar = scene_lidar(scene, scene_depth(scene), stride, range_m)
    down = float(quat_to_matrix(scene.quat)[2, 2])
    frame = recovery_fakes.frame(
        image=image, lidar_frd=lidar, pos_ned_m=scene.pos, quat_wxyz=scene.quat,
        rangefinder_m=scene.alt_m / down, camera=cam,
    )  # fmt: skip
    depth = LidarDepth(cell_px=scene.cell_px, range_m=range_m)
    surface = data.draw(surface_params)
    reasoner = OnboardReasoner()

    async def chain() -> None:
        looker = _looker(reasoner, surface=surface, depth_source=depth)
        cands = looker.surface_id(frame, cam)
        chosen: Candidate | None = None
        for context in CONTEXTS:
            looker = _looker(reasoner, surface=surface, depth_source=depth, context=context)
            ranking, k = await looker.rank(cands, frame)
            assert sorted(ranking.order) == list(range(len(cands)))
            chosen = cands[k] if k is not None else None
            assert chosen is None or not chosen.fallback
        if chosen is None:
            return  # the recovery explores
        target = looker.ipm(chosen, frame, cam)
        if target is None:
            return  # the round moves on
        assert np.isfinite(target).all()
        assert looker.closeup(image, frame, target).size > 0
        check = check_site(lidar, scene.pos, scene.quat, (target[0], target[1]))
        decision = await looker.confirm(check, frame, target, chosen)
        assert isinstance(decision.accept, bool)
        if check.measured and not check.clear:
            assert not decision.accept
        assert looker.ctx.ledger.near((target[0], target[1])) is not None  # judged into the ledger

    asyncio.run(chain())


def test_recovery_ipm_with_no_lidar_and_a_zero_rangefinder_places_nothing() -> None:
    """The recovery's IPM (companion/recovery/looking.py ``Looker.ipm``): no LiDAR, and a rangefinder that
    reads 0 (the flat-ground plane through the camera: no ray meets it). Neither way places the site:
    None, and the round moves on, instead of an IpmError escaping the round."""
    cam = PinholeCamera.from_hfov(960, 540, 90.0)
    frame = recovery_fakes.frame(pos_ned_m=(0.0, 0.0, -50.0), rangefinder_m=0.0, camera=cam)
    looker = _looker()
    cand = Candidate(0, (470, 260, 490, 280), (480.0, 270.0))
    assert looker.ipm(cand, frame, cam) is None
    frame = dataclasses.replace(frame, rangefinder_m=50.0)  # flat ground 50 m below: under the pixel
    target = looker.ipm(cand, frame, cam)
    assert target is not None
    assert target[2] == pytest.approx(0.0)
