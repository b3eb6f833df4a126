"""Frames, the pinhole camera and inverse perspective mapping against known geometry and simbridge."""

from __future__ import annotations

import math

import numpy as np
import pytest

from companion.guidance import (
    CAMERA_TO_BODY,
    GeometryInputError,
    IpmError,
    LidarPixelIndex,
    LidarUnavailable,
    NoReturnNearPixel,
    PinholeCamera,
    RayDoesNotDescend,
    frd_to_ned,
    ground_down_from_range,
    ipm,
    pixel_to_ned,
    pixel_to_ned_flat,
    pixel_to_ned_surface,
    quat_to_matrix,
)
from simbridge.geo import euler_to_quat, rotate_body_to_ned
from simbridge.world import camera as sim_camera
from simbridge.world.lidar import LidarModel, sweep
from simbridge.world.model import Material, SurfaceClass, WorldGrid
from simbridge.world.raycast import Pyramid
from simbridge.world.world import Sun

CAM = PinholeCamera.from_hfov(960, 540, 90.0)
LEVEL = (1.0, 0.0, 0.0, 0.0)
YAWED_TILTED = euler_to_quat(math.radians(8.0), math.radians(-5.0), math.radians(37.0))


def _ground_grid_frd(pos_ned_m: np.ndarray, quat: tuple[float, float, float, float]) -> np.ndarray:
    """Body FRD points of a 2 m grid on the ground (NED down = 0) around the vehicle."""
    n, e = np.meshgrid(np.arange(-80.0, 80.0, 2.0), np.arange(-80.0, 80.0, 2.0), indexing="ij")
    ned = np.stack([n.ravel() + pos_ned_m[0], e.ravel() + pos_ned_m[1], np.zeros(n.size)], axis=1)
    frd: np.ndarray = (ned - pos_ned_m) @ quat_to_matrix(quat)  # rows: R.T @ (p - pos)
    return frd


# ------------------------------------------------------------------------------------------ frames
def test_camera_to_body_matches_simbridge() -> None:
    np.testing.assert_array_equal(CAMERA_TO_BODY, sim_camera.CAMERA_TO_BODY)
    np.testing.assert_array_equal(CAMERA_TO_BODY @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])  # x_cam: right
    np.testing.assert_array_equal(CAMERA_TO_BODY @ [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0])  # y_cam: aft
    np.testing.assert_array_equal(CAMERA_TO_BODY @ [0.0, 0.0, 1.0], [0.0, 0.0, 1.0])  # z_cam: down


def test_quat_to_matrix_matches_simbridge_rotations() -> None:
    rng = np.random.default_rng(7)
    for _ in range(20):
        roll, pitch, yaw = rng.uniform(-math.pi / 3, math.pi / 3, 3).tolist()
        q = euler_to_quat(roll, pitch, yaw)
        r = quat_to_matrix(q)
        np.testing.assert_allclose(r, sim_camera.quat_matrix(q), atol=1e-12)
        v = tuple(rng.normal(size=3).tolist())
        np.testing.assert_allclose(r @ v, rotate_body_to_ned(q, v), atol=1e-12)
        np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-12)


def test_quat_to_matrix_yaw_90_turns_forward_to_east() -> None:
    r = quat_to_matrix(euler_to_quat(0.0, 0.0, math.pi / 2))
    np.testing.assert_allclose(r @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], atol=1e-12)


@pytest.mark.parametrize("quat", [(0.0, 0.0, 0.0, 0.0), (2.0, 0.0, 0.0, 0.0), (1.0, 0.0, math.nan, 0.0)])
def test_quat_to_matrix_rejects_non_unit_or_nan(quat: tuple[float, ...]) -> None:
    with pytest.raises(GeometryInputError, match="quat_wxyz"):
        quat_to_matrix(quat)


def test_quat_to_matrix_rejects_wrong_length() -> None:
    with pytest.raises(GeometryInputError, match="4 finite numbers"):
        quat_to_matrix((1.0, 0.0, 0.0))


def test_frd_to_ned_adds_rotated_offset() -> None:
    q = euler_to_quat(0.0, 0.0, math.pi / 2)
    np.testing.assert_allclose(frd_to_ned((10.0, 0.0, 5.0), (1.0, 2.0, -100.0), q), [1.0, 12.0, -95.0])


# ------------------------------------------------------------------------------------------ camera
def test_pinhole_from_hfov_matches_simbridge_camera_model() -> None:
    sim = sim_camera.CameraModel(width_px=960, height_px=540, hfov_deg=90.0)
    assert CAM.fx == pytest.approx(sim.focal_px) == pytest.approx(480.0)
    assert CAM.fy == CAM.fx
    assert (CAM.cx, CAM.cy) == sim.principal_px == (480.0, 270.0)
    rays = sim.unit_rays_body()
    for col, row in [(0, 0), (959, 0), (0, 539), (480, 270), (123, 456)]:
        np.testing.assert_allclose(CAM.pixel_ray_frd(col + 0.5, row + 0.5), rays[row * 960 + col], atol=1e-12)


def test_project_frd_point_below_lands_at_principal_point() -> None:
    uv, in_front = CAM.project_frd([[0.0, 0.0, 70.0]])
    assert in_front.tolist() == [True]
    np.testing.assert_allclose(uv, [[CAM.cx, CAM.cy]], atol=1e-12)


def test_project_frd_point_ahead_appears_above_centre() -> None:
    ((u, v),), _ = CAM.project_frd([[10.0, 0.0, 50.0]])
    assert u == pytest.approx(CAM.cx)
    assert v == pytest.approx(CAM.cy - 480.0 * 10.0 / 50.0)  # 96 px above the centre


def test_project_frd_point_right_appears_right_of_centre() -> None:
    ((u, v),), _ = CAM.project_frd([[0.0, 10.0, 50.0]])
    assert u == pytest.approx(CAM.cx + 96.0)
    assert v == pytest.approx(CAM.cy)


def test_project_frd_point_behind_is_nan_and_not_in_front() -> None:
    uv, in_front = CAM.project_frd([[0.0, 0.0, -5.0], [1.0, 0.0, 0.0], [0.0, 0.0, math.inf], [0.0, 0.0, 5.0]])
    assert in_front.tolist() == [False, False, False, True]
    assert np.isnan(uv[:3]).all()
    assert CAM.in_image(uv).tolist() == [False, False, False, True]


def test_project_frd_rejects_wrong_shape() -> None:
    with pytest.raises(GeometryInputError, match=r"\(N, 3\)"):
        CAM.project_frd(np.zeros((4, 2)))


def test_pixel_ray_frd_inverts_projection() -> None:
    point = np.array([12.0, -7.0, 40.0])
    ((u, v),), _ = CAM.project_frd(point[None, :])
    np.testing.assert_allclose(CAM.pixel_ray_frd(u, v), point / np.linalg.norm(point), atol=1e-12)


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"width": 0, "height": 540, "fx": 480.0, "fy": 480.0, "cx": 0.0, "cy": 0.0}, "width"),
        ({"width": 960, "height": 540, "fx": -1.0, "fy": 480.0, "cx": 0.0, "cy": 0.0}, "fx"),
        ({"width": 960, "height": 540, "fx": 480.0, "fy": 480.0, "cx": math.nan, "cy": 0.0}, "cx"),
    ],
)
def test_pinhole_camera_bad_intrinsics_raise(kwargs: dict[str, float], field: str) -> None:
    with pytest.raises(GeometryInputError) as info:
        PinholeCamera(**kwargs)  # type: ignore[arg-type]
    assert info.value.field_name == field


def test_pinhole_from_hfov_rejects_180_deg() -> None:
    with pytest.raises(GeometryInputError, match="hfov_deg"):
        PinholeCamera.from_hfov(960, 540, 180.0)


# --------------------------------------------------------------------------------------------- IPM
def test_pixel_to_ned_roof_corner_round_trip_yawed_tilted() -> None:
    pos = np.array([10.0, -5.0, -100.0])
    corner_ned = np.array([15.0, 3.0, -30.0])
    rot = quat_to_matrix(YAWED_TILTED)
    corner_frd = rot.T @ (corner_ned - pos)
    cloud = np.vstack([_ground_grid_frd(pos, YAWED_TILTED), corner_frd])
    index = LidarPixelIndex(cloud, CAM)
    ((u, v),), _ = CAM.project_frd(corner_frd[None, :])
    hit = index.nearest(u, v)
    assert hit.pixel_distance == pytest.approx(0.0, abs=1e-9)
    np.testing.assert_allclose(hit.point_frd, corner_frd, atol=1e-12)
    assert hit.range_m == pytest.approx(float(np.linalg.norm(corner_ned - pos)))
    np.testing.assert_allclose(pixel_to_ned(u, v, index, pos, YAWED_TILTED), corner_ned, atol=1e-9)
    # a pixel half a pixel off still finds the corner: ground points are > 5 px away in the image
    np.testing.assert_allclose(
        pixel_to_ned(u + 0.4, v - 0.3, index, pos, YAWED_TILTED), corner_ned, atol=1e-9
    )


def test_lidar_pixel_index_agrees_with_simbridge_render() -> None:
    grid = WorldGrid.empty((-80.0, 80.0), (-80.0, 80.0), res=0.25, ground_cls=SurfaceClass.GRASS,
                           ground_mat=Material.GRASS)  # fmt: skip
    grid.fill_rect((0.0, 0.0), 20.0, 20.0, 0.0, height_m=30.0, cls=SurfaceClass.ROOF_FLAT,
                   mat=Material.GRAVEL, region=1)  # fmt: skip
    pyramid = Pyramid(grid.height)
    sun = Sun().direction_neu()
    sim_cam = sim_camera.CameraModel(width_px=320, height_px=180, hfov_deg=90.0)
    pos = (3.0, -2.0, -80.0)
    quat = euler_to_quat(math.radians(4.0), math.radians(-3.0), math.radians(25.0))
    frame = sim_camera.render(
        grid, pyramid, sim_camera.ShadowMap(grid, pyramid, sun), sim_cam, pos, quat, sun
    )
    lidar = sweep(grid, pyramid, LidarModel(), pos, quat, np.random.default_rng(0))
    camera = PinholeCamera.from_hfov(320, 180, 90.0)
    index = LidarPixelIndex(lidar, camera)

    ned = np.asarray(pos) + index.points_frd @ quat_to_matrix(quat).T
    inner_roof = (np.abs(ned[:, 2] + 30.0) < 0.1) & (np.abs(ned[:, :2]).max(axis=1) < 9.5)
    assert np.count_nonzero(inner_roof) > 100
    cols, rows = np.floor(index.uv[inner_roof]).astype(int).T
    assert (frame.hit_class[rows, cols] == SurfaceClass.ROOF_FLAT).all()
    # and back: the pixel over the roof's centre maps onto the roof
    ((u, v),), _ = camera.project_frd((quat_to_matrix(quat).T @ (np.array([0.0, 0.0, -30.0]) - pos))[None, :])
    assert frame.hit_class[int(v), int(u)] == SurfaceClass.ROOF_FLAT
    roof_point = pixel_to_ned(u, v, index, pos, quat)
    assert roof_point[2] == pytest.approx(-30.0, abs=0.1)
    assert np.abs(roof_point[:2]).max() < 2.0


def test_lidar_pixel_index_drops_nan_rows_and_out_of_view_returns() -> None:
    cloud = np.array(
        [
            [0.0, 0.0, 50.0, 0.3],
            [math.nan, 0.0, 50.0, 0.3],
            [0.0, 0.0, math.inf, 0.3],
            [0.0, 0.0, -50.0, 0.3],
            [500.0, 0.0, 1.0, 0.3],
        ],
        np.float32,
    )
    index = LidarPixelIndex(cloud, CAM)
    assert (index.n_rows, index.n_finite, len(index)) == (5, 3, 1)
    np.testing.assert_allclose(index.points_frd, [[0.0, 0.0, 50.0]])


def test_nearest_many_returns_none_where_nothing_is_near() -> None:
    index = LidarPixelIndex(np.array([[0.0, 0.0, 50.0]]), CAM)
    hits = index.nearest_many([[CAM.cx + 3.0, CAM.cy + 4.0], [10.0, 10.0]], max_px=10.0)
    assert hits[1] is None
    assert hits[0] is not None
    assert hits[0].pixel_distance == pytest.approx(5.0)
    assert hits[0].range_m == pytest.approx(50.0)


def test_nearest_many_in_blocks_finds_each_pixels_nearest_return(monkeypatch: pytest.MonkeyPatch) -> None:
    rng = np.random.default_rng(7)
    cloud = np.column_stack([rng.uniform(-20, 20, (300, 2)), rng.uniform(30, 60, 300)])
    index = LidarPixelIndex(cloud, CAM)
    pixels = rng.uniform(0, [CAM.width, CAM.height], (57, 2))
    d = np.hypot(index.uv[None, :, 0] - pixels[:, 0, None], index.uv[None, :, 1] - pixels[:, 1, None])
    whole = index.nearest_many(pixels, max_px=1e9)
    monkeypatch.setattr(ipm, "NEAREST_BLOCK", len(index) * 5)  # five pixels a block, the last one short
    blocked = index.nearest_many(pixels, max_px=1e9)
    for k, (a, b) in enumerate(zip(whole, blocked, strict=True)):
        assert a is not None
        assert b == a
        assert a.pixel_distance == pytest.approx(d[k].min())
    hit = index.nearest(*pixels[3].tolist(), max_px=1e9)
    assert hit == whole[3]


def test_nearest_far_from_every_return_raises_no_return_near_pixel() -> None:
    index = LidarPixelIndex(np.array([[0.0, 0.0, 50.0]]), CAM)
    with pytest.raises(NoReturnNearPixel) as info:
        index.nearest(CAM.cx + 30.0, CAM.cy + 40.0, max_px=25.0)
    assert (info.value.u, info.value.v) == (CAM.cx + 30.0, CAM.cy + 40.0)
    assert info.value.nearest_px == pytest.approx(50.0)
    assert isinstance(info.value, IpmError)


@pytest.mark.parametrize(
    ("cloud", "reason"),
    [
        (None, "no point cloud"),
        (np.empty((0, 4), np.float32), "empty"),
        (np.full((10, 4), np.nan, np.float32), "all 10 returns"),
        (np.array([[0.0, 0.0, -50.0]]), "none of the 1 valid returns"),
    ],
)
def test_lidar_pixel_index_without_usable_returns_raises_lidar_unavailable(
    cloud: np.ndarray | None, reason: str
) -> None:
    with pytest.raises(LidarUnavailable, match=reason):
        LidarPixelIndex(cloud, CAM)


def test_lidar_pixel_index_wrong_shape_raises_geometry_input_error() -> None:
    with pytest.raises(GeometryInputError, match=r"\(N, 3\+\)"):
        LidarPixelIndex(np.zeros((5, 2)), CAM)


def test_nearest_nan_pixel_raises_geometry_input_error() -> None:
    index = LidarPixelIndex(np.array([[0.0, 0.0, 50.0]]), CAM)
    with pytest.raises(GeometryInputError, match="u"):
        index.nearest(math.nan, 10.0)


def test_pixel_to_ned_surface_is_the_pixels_own_point_between_sparse_returns() -> None:
    """A 2 m grid of returns on the ground seen from 100 m (about 10 px apart): a pixel between them
    maps to its own point on the ground, where the nearest return is up to a metre off."""
    pos = np.array([10.0, -5.0, -100.0])
    index = LidarPixelIndex(_ground_grid_frd(pos, YAWED_TILTED), CAM)
    target_ned = np.array([25.3, 14.7, 0.0])  # between grid points (even metres)
    target_frd = quat_to_matrix(YAWED_TILTED).T @ (target_ned - pos)
    ((u, v),), _ = CAM.project_frd(target_frd[None, :])
    nearest = pixel_to_ned(u, v, index, pos, YAWED_TILTED)
    assert math.dist(nearest[:2], target_ned[:2]) > 0.5  # the return, not the pixel's point
    out = pixel_to_ned_surface(u, v, index, pos, YAWED_TILTED)
    np.testing.assert_allclose(out, target_ned, atol=1e-6)


def test_pixel_to_ned_surface_without_a_return_near_raises_like_pixel_to_ned() -> None:
    pos = np.array([0.0, 0.0, -100.0])
    one = quat_to_matrix(LEVEL).T @ (np.array([[0.0, 0.0, 0.0]]) - pos).T
    index = LidarPixelIndex(one.T, CAM)
    with pytest.raises(NoReturnNearPixel):
        pixel_to_ned_surface(10.0, 10.0, index, pos, LEVEL)


# ------------------------------------------------------------------------------------ degraded mode
def test_pixel_to_ned_flat_hits_known_ground_point_yawed_tilted() -> None:
    pos = np.array([10.0, -5.0, -100.0])
    target_ned = np.array([25.0, 14.0, -2.0])  # ground plane 2 m above the origin's level
    target_frd = quat_to_matrix(YAWED_TILTED).T @ (target_ned - pos)
    ((u, v),), _ = CAM.project_frd(target_frd[None, :])
    out = pixel_to_ned_flat(u, v, CAM, pos, YAWED_TILTED, ground_down_m=-2.0)
    np.testing.assert_allclose(out, target_ned, atol=1e-9)


def test_pixel_to_ned_flat_level_centre_pixel_is_straight_below() -> None:
    out = pixel_to_ned_flat(CAM.cx, CAM.cy, CAM, (1.0, 2.0, -100.0), LEVEL, ground_down_m=0.0)
    np.testing.assert_allclose(out, [1.0, 2.0, 0.0], atol=1e-12)


def test_ground_down_from_range_accounts_for_tilt() -> None:
    assert ground_down_from_range((0.0, 0.0, -100.0), LEVEL, 70.0) == pytest.approx(-30.0)
    rolled = euler_to_quat(math.radians(20.0), 0.0, 0.0)
    assert ground_down_from_range((0.0, 0.0, -100.0), rolled, 70.0) == pytest.approx(
        -100.0 + 70.0 * math.cos(math.radians(20.0))
    )


def test_pixel_to_ned_flat_ray_above_horizon_raises_ray_does_not_descend() -> None:
    pitched_up = euler_to_quat(0.0, math.radians(80.0), 0.0)  # camera looks forward and up the image top
    with pytest.raises(RayDoesNotDescend, match="below the horizon") as info:
        pixel_to_ned_flat(CAM.cx, 0.0, CAM, (0.0, 0.0, -100.0), pitched_up, ground_down_m=0.0)
    assert info.value.ray_ned[2] < 0.0


def test_pixel_to_ned_flat_plane_above_vehicle_raises_ray_does_not_descend() -> None:
    with pytest.raises(RayDoesNotDescend, match="above the vehicle"):
        pixel_to_ned_flat(CAM.cx, CAM.cy, CAM, (0.0, 0.0, -10.0), LEVEL, ground_down_m=-20.0)
