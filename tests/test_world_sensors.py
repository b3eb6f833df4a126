"""Camera, LiDAR, rangefinder, shadows, actors and the grader against hand-built geometry."""

from __future__ import annotations

import math

import numpy as np
import pytest

from simbridge.geo import euler_to_quat
from simbridge.world.actors import CAR_HEIGHT_M, Actors
from simbridge.world.camera import CameraModel, ShadowMap, body_to_neu, render
from simbridge.world.city import generate_city
from simbridge.world.grader import grade
from simbridge.world.lidar import LidarModel, rangefinder_m, sweep
from simbridge.world.live import LiveWorld
from simbridge.world.model import Material as M
from simbridge.world.model import SurfaceClass as C
from simbridge.world.model import WorldGrid
from simbridge.world.raycast import HIT_MISS, Pyramid, cast_rays
from simbridge.world.world import Lane, Sun, Walkway, World

LEVEL = euler_to_quat(0.0, 0.0, 0.0)


def _box_world(
    height_m: float = 30.0, size_m: float = 20.0, centre: tuple[float, float] = (0.0, 0.0)
) -> WorldGrid:
    g = WorldGrid.empty((-150.0, 150.0), (-150.0, 150.0), ground_cls=C.GRASS, ground_mat=M.GRASS)
    g.fill_rect(centre, size_m, size_m, 0.0, height_m=height_m, cls=C.ROOF_FLAT, mat=M.GRAVEL, region=1)
    return g


def test_rangefinder_reads_roof_below() -> None:
    g = _box_world(30.0)
    p = Pyramid(g.height)
    assert rangefinder_m(g, p, (0.0, 0.0, -100.0), LEVEL) == pytest.approx(70.0, abs=1e-3)
    assert rangefinder_m(g, p, (50.0, 0.0, -100.0), LEVEL) == pytest.approx(100.0, abs=1e-3)
    tilted = euler_to_quat(math.radians(5), 0.0, 0.0)  # rolled 5 deg: the beam slants onto the roof
    assert rangefinder_m(g, p, (0.0, 0.0, -100.0), tilted) == pytest.approx(
        70.0 / math.cos(math.radians(5)), rel=1e-3
    )


def test_camera_pixel_footprint_of_a_box_building() -> None:
    g = _box_world(30.0, 20.0)
    p = Pyramid(g.height)
    cam = CameraModel()
    frame = render(
        g, p, ShadowMap(g, p, Sun().direction_neu()), cam, (0.0, 0.0, -100.0), LEVEL, Sun().direction_neu()
    )
    row = frame.hit_class[cam.height_px // 2]
    roof_px = int(np.sum(row == C.ROOF_FLAT))
    expected = 20.0 * cam.focal_px / 70.0  # 137.1 px
    assert roof_px == pytest.approx(expected, abs=2)
    centre_depth = frame.depth_m[cam.height_px // 2, cam.width_px // 2]
    assert centre_depth == pytest.approx(70.0, abs=0.01)
    assert frame.rgb.shape == (540, 960, 3)
    assert frame.rgb.dtype == np.uint8


def test_image_top_is_the_vehicle_nose() -> None:
    g = _box_world(30.0, 20.0, centre=(40.0, 0.0))  # building 40 m north
    p = Pyramid(g.height)
    sun = Sun().direction_neu()
    shadow = ShadowMap(g, p, sun)
    cam = CameraModel()
    north_up = render(g, p, shadow, cam, (0.0, 0.0, -100.0), euler_to_quat(0, 0, 0), sun).hit_class
    rows = np.nonzero((north_up == C.ROOF_FLAT).any(axis=1))[0]
    assert rows.max() < cam.height_px // 2  # facing north: the building is in the top half
    facing_west = render(
        g, p, shadow, cam, (0.0, 0.0, -100.0), euler_to_quat(0, 0, -math.pi / 2), sun
    ).hit_class
    cols = np.nonzero((facing_west == C.ROOF_FLAT).any(axis=0))[0]
    assert cols.min() > cam.width_px // 2  # facing west: north is to the right


def test_off_centre_building_shows_its_wall() -> None:
    g = _box_world(40.0, 20.0, centre=(0.0, 60.0))  # east of the camera
    p = Pyramid(g.height)
    sun = Sun().direction_neu()
    cam = CameraModel()
    origin = np.array([[0.0, 0.0, 100.0]])
    dirs = np.ascontiguousarray(cam.unit_rays_body() @ np.diag([1.0, 1.0, -1.0]))  # level, facing north
    _, _, _, kinds, steps = cast_rays(g.height, p.maps, p.h_max, g.res, g.n0, g.e0, origin, dirs, 600.0)
    walls = kinds == 2  # crossed an east boundary: the west-facing wall
    assert walls.sum() > 500
    assert np.all(steps[walls] == 1)
    _ = sun


def test_shadows_fall_away_from_the_sun() -> None:
    g = _box_world(30.0, 20.0)
    p = Pyramid(g.height)
    sun = Sun(azimuth_deg=90.0, elevation_deg=45.0)  # sun in the east
    sm = ShadowMap(g, p, sun.direction_neu())
    sm.ensure_all()
    west = g.index(0.0, -10.0 - 15.0)  # 15 m west of the west wall: inside the 30 m shadow
    east = g.index(0.0, 10.0 + 15.0)
    far_west = g.index(0.0, -10.0 - 35.0)  # beyond the shadow's reach
    assert west is not None
    assert east is not None
    assert far_west is not None
    assert sm.shadow[west]
    assert not sm.shadow[east]
    assert not sm.shadow[far_west]
    roof = g.index(0.0, 0.0)
    assert roof is not None
    assert not sm.shadow[roof]


def test_lidar_returns_match_the_geometry() -> None:
    g = _box_world(30.0, 20.0)
    p = Pyramid(g.height)
    model = LidarModel(noise_sigma_m=0.0, dropout=0.0)
    pts = sweep(g, p, model, (0.0, 0.0, -100.0), LEVEL, np.random.default_rng(0))
    assert pts.shape[1] == 4
    assert pts.dtype == np.float32
    on_roof = (np.abs(pts[:, 0]) < 9.5) & (np.abs(pts[:, 1]) < 9.5)
    assert on_roof.sum() > 100
    assert np.allclose(pts[on_roof, 2], 70.0, atol=0.01)  # body z (down) = 100 - 30
    ground = (np.abs(pts[:, 0]) > 12) | (np.abs(pts[:, 1]) > 12)
    far = ground & (np.hypot(pts[:, 0], pts[:, 1]) < 40)
    assert np.allclose(pts[far, 2], 100.0, atol=0.05)
    assert np.all(np.linalg.norm(pts[:, :3], axis=1) <= model.range_m + 1e-3)


def test_beyond_the_modelled_area_the_lidar_sees_the_open_ground_the_camera_and_rangefinder_see() -> None:
    """Off the grid the world is open ground at height 0 for the camera and the rangefinder; the LiDAR
    returned nothing there (a companion that searched past a city's edge descended to 70 m and still
    saw nothing). It sees the same ground, within its range only."""
    g = _box_world(30.0, 20.0)
    p = Pyramid(g.height)
    model = LidarModel(noise_sigma_m=0.0, dropout=0.0)
    pos = (400.0, 0.0, -70.0)  # 250 m beyond the grid's edge
    pts = sweep(g, p, model, pos, LEVEL, np.random.default_rng(0))
    assert rangefinder_m(g, p, pos, LEVEL) == pytest.approx(70.0, abs=1e-3)
    assert len(pts) > 1000
    assert np.allclose(pts[:, 2], 70.0, atol=0.01)  # level ground 70 m below, in body FRD
    assert np.all(np.linalg.norm(pts[:, :3], axis=1) <= model.range_m + 1e-3)
    assert np.all(pts[:, 3] > 0.0)
    assert len(sweep(g, p, model, (400.0, 0.0, -120.0), LEVEL, np.random.default_rng(0))) == 0  # out of range


def test_lidar_noise_and_dropouts_are_seeded() -> None:
    g = _box_world()
    p = Pyramid(g.height)
    model = LidarModel()
    a = sweep(g, p, model, (0.0, 0.0, -60.0), LEVEL, np.random.default_rng(3))
    b = sweep(g, p, model, (0.0, 0.0, -60.0), LEVEL, np.random.default_rng(3))
    c = sweep(g, p, model, (0.0, 0.0, -60.0), LEVEL, np.random.default_rng(4))
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)
    full = sweep(g, p, LidarModel(dropout=0.0), (0.0, 0.0, -60.0), LEVEL, np.random.default_rng(3))
    assert 0.95 * len(full) < len(a) < len(full)  # about 2 % dropped


def test_ray_cast_matches_brute_force() -> None:
    rng = np.random.default_rng(5)
    g = WorldGrid.empty((-60.0, 60.0), (-60.0, 60.0))
    for _ in range(40):
        g.fill_rect((rng.uniform(-50, 50), rng.uniform(-50, 50)), rng.uniform(2, 15), rng.uniform(2, 15),
                    rng.uniform(0, 3), height_m=rng.uniform(1, 40))  # fmt: skip
    p = Pyramid(g.height)
    dirs = rng.normal(size=(400, 3))
    dirs[:, 2] = -np.abs(dirs[:, 2]) - 0.2
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    origin = np.array([[3.0, -4.0, 60.0]])
    ts, _, _, kinds, _ = cast_rays(g.height, p.maps, p.h_max, g.res, g.n0, g.e0, origin, dirs, 300.0)
    steps = np.arange(0.0, 300.0, 0.005)  # the brute force: every 5 mm along each ray, in numpy
    rows, cols = g.shape
    for k in range(len(dirs)):
        q = origin[0] + steps[:, None] * dirs[k]
        i = np.floor((q[:, 0] - g.n0) / g.res).astype(np.int64)  # WorldGrid.index, for every sample
        j = np.floor((q[:, 1] - g.e0) / g.res).astype(np.int64)
        inside = (i >= 0) & (i < rows) & (j >= 0) & (j < cols)
        out = np.flatnonzero(~inside)
        end = out[0] if len(out) else len(steps)  # the march stops where it leaves the grid
        hit = np.flatnonzero(q[:end, 2] <= g.height[i[:end], j[:end]])
        expected = float(steps[hit[0]]) if len(hit) else 300.0
        assert ts[k] == pytest.approx(expected, abs=0.02), k
    assert (kinds != HIT_MISS).sum() > 150  # not vacuous: most rays hit something


@pytest.mark.parametrize("scenario", ["scenario1", "scenario2"])
def test_image_rays_through_the_neighbours_plane_give_the_march_s_answer(scenario: str) -> None:
    """Camera and LiDAR casts that first try the plane of a neighbouring pixel's hit (row > 0) find
    exactly what the march alone finds: same hit kinds, cells and distances, from high and low,
    level and tilted, in both scenarios (thin clutter, parapets, a dome, moving actors' cells)."""
    from simbridge.world.scenario_file import BUILTIN_SCENARIO_DIR, load_scenario_file

    live = LiveWorld(load_scenario_file(BUILTIN_SCENARIO_DIR / f"{scenario}.toml", 0))
    g, p = live.grid, live.pyramid
    camera = CameraModel(320, 180, 90.0)
    lidar = LidarModel(channels=32, points_per_ring=256)
    hits = 0
    for n, e, alt, roll, pitch, yaw in [
        (0.0, 0.0, 110.0, 0.0, 0.0, 0.0),
        (20.0, -30.0, 60.0, 4.0, -9.0, 30.0),
        (0.0, -27.0, 25.0, 0.0, 0.0, 10.0),
        (5.0, -27.0, 6.0, 0.0, 0.0, 0.0),
        (-40.0, 40.0, 300.0, 20.0, 0.0, 90.0),
    ]:
        q = euler_to_quat(math.radians(roll), math.radians(pitch), math.radians(yaw))
        origin = np.array([[n, e, alt]])
        for rays, row, t_max in (
            (camera.unit_rays_body(), camera.width_px, 600.0),
            (lidar.rays_body(), lidar.points_per_ring, lidar.range_m),
        ):
            dirs = body_to_neu(rays, q)
            march = cast_rays(g.height, p.maps, p.h_max, g.res, g.n0, g.e0, origin, dirs, t_max)
            planes = cast_rays(g.height, p.maps, p.h_max, g.res, g.n0, g.e0, origin, dirs, t_max, row)
            tiles = cast_rays(g.height, p.maps, p.h_max, g.res, g.n0, g.e0, origin, dirs, t_max, row, 8)
            for a, b, c in zip(march, planes, tiles, strict=True):
                np.testing.assert_array_equal(a, b)
                np.testing.assert_array_equal(a, c)
            hits += int((march[3] != HIT_MISS).sum())
    assert hits > 100_000  # not vacuous


def test_actors_move_arrive_and_leave_deterministically() -> None:
    lane = Lane(((0.0, 0.0), (400.0, 0.0)), speed_m_s=(10.0, 10.0), arrivals_per_min=12.0)
    a, b = Actors((lane,), (), seed=1), Actors((lane,), (), seed=1)
    first = [p.centre_ne for p in a.poses()]
    a.advance(5.0)
    b.advance(5.0)
    moved = [p.centre_ne for p in a.poses()]
    assert moved == [p.centre_ne for p in b.poses()]
    assert len(first) > 0
    # every car still on the lane drove 10 m/s for 5 s (leavers are gone, newcomers start at 0)
    expected = {round(n + 50.0, 6) for n, _ in first if n + 50.0 < 400.0}
    assert expected
    assert expected <= {round(n, 6) for n, _ in moved}
    counts = []
    for t in range(10, 400, 10):
        a.advance(float(t))
        counts.append(len(a.poses()))
    assert len(set(counts)) > 1  # traffic comes and goes
    assert all(0.0 <= p.centre_ne[0] <= 400.0 for p in a.poses())
    c = Actors((lane,), (), seed=2)
    assert [p.centre_ne for p in c.poses()] != first


def test_stamped_actor_is_seen_by_camera_and_grader() -> None:
    g = WorldGrid.empty((-100.0, 100.0), (-100.0, 100.0), ground_cls=C.ROAD, ground_mat=M.ASPHALT)
    lanes = (Lane(((-100.0, 0.0), (100.0, 0.0)), arrivals_per_min=30.0),)
    walkways = (Walkway(((-50.0, 5.0), (50.0, 5.0)), count=3),)
    world = World(name="t", seed=0, grid=g, lanes=lanes, walkways=walkways)
    live = LiveWorld(world)
    cars = [p for p in live.actors.poses() if p.kind is C.VEHICLE]
    assert cars
    car = cars[0]
    assert g.class_at(*car.centre_ne) is C.VEHICLE
    assert g.height_at(*car.centre_ne) == pytest.approx(CAR_HEIGHT_M)
    pos = (car.centre_ne[0], car.centre_ne[1], -50.0)
    assert live.rangefinder_m(pos, LEVEL) == pytest.approx(50.0 - CAR_HEIGHT_M, abs=0.01)
    verdict = live.grade_touchdown(car.centre_ne[0], car.centre_ne[1] + 1.5, live.t_s)
    assert not verdict.safe
    live.sync(live.t_s + 30.0)  # the car has driven on: its old cells are road again
    assert g.class_at(*car.centre_ne) in (C.ROAD, C.VEHICLE)


def test_a_sensor_sees_the_same_actors_as_if_every_actor_were_stamped() -> None:
    """Sensors stamp only the actors within their reach (a city has thousands); a frame rendered
    that way equals one rendered with every actor in the grid, and the max maps, raised per actor
    only at their low levels, still bound every actor's cells from above at every level."""
    world = generate_city(3, size_m=600.0)
    near, every = LiveWorld(world), LiveWorld(generate_city(3, size_m=600.0))
    q = euler_to_quat(0.02, -0.03, 0.4)
    for t in (5.0, 20.0):
        pos = (40.0, -60.0, -90.0)
        frame = near.camera_frame(pos, q, t, "clear", np.random.default_rng(1))
        stamped = len(near.actors._stamped)
        every.sync(t)
        assert stamped < len(every.actors._stamped)  # fewer actors stamped...
        full = render(
            every.grid, every.pyramid, every.shadow, every.camera, pos, q, every.sun_neu, "clear",
            np.random.default_rng(1),
        )  # fmt: skip
        assert np.array_equal(frame.rgb, full.rgb)  # ...and the same picture
        assert np.array_equal(frame.hit_class, full.hit_class)
        assert (frame.hit_class == C.VEHICLE).any()
        # every level bounds every actor: the grid's coarse maxima under each map's window
        from simbridge.world.raycast import COARSE, max_pool

        base = max_pool(every.grid.height, COARSE)
        for k in range(every.pyramid.maps.shape[0]):
            assert (every.pyramid.maps[k] >= base).all()


def test_each_max_map_is_the_brute_force_maximum_over_its_window() -> None:
    """The pyramid's maps against their definition computed cell by cell: map ``k`` at coarse cell
    (bi, bj) is the tallest fine cell of every coarse cell within ``2**k`` (Chebyshev), an offset
    past the grid's edge clamped to it; on a grid with partial coarse cells at its far edges."""
    from simbridge.world.raycast import COARSE, LEVELS

    rng = np.random.default_rng(7)
    height = rng.gamma(1.0, 5.0, size=(4 * 37 + 3, 4 * 29 + 1)).astype(np.float32)
    p = Pyramid(height)
    rows, cols = -(-height.shape[0] // COARSE), -(-height.shape[1] // COARSE)
    base = np.array(
        [
            [height[i * COARSE : (i + 1) * COARSE, j * COARSE : (j + 1) * COARSE].max() for j in range(cols)]
            for i in range(rows)
        ]
    )
    assert p.maps.shape == (LEVELS, rows, cols)
    for k in range(LEVELS):
        r = 1 << k
        for bi, bj in [(0, 0), (rows - 1, cols - 1), (5, 17), (rows // 2, 0), (rows - 2, cols // 3)]:
            window = base[max(bi - r, 0) : bi + r + 1, max(bj - r, 0) : bj + r + 1]
            assert p.maps[k, bi, bj] == window.max(), (k, bi, bj)
    assert p.h_max == float(height.max())


def _graded_block() -> WorldGrid:
    g = WorldGrid.empty((-60.0, 60.0), (-60.0, 60.0), ground_cls=C.ROAD, ground_mat=M.ASPHALT)
    g.fill_rect((0.0, 0.0), 30.0, 30.0, 0.0, height_m=20.0, cls=C.ROOF_FLAT, mat=M.GRAVEL, region=1)
    g.fill_rect((8.0, 8.0), 3.0, 2.0, 0.0, height_m=22.0, cls=C.ROOF_CLUTTER, mat=M.METAL)
    g.fill_rect((40.0, 0.0), 10.0, 10.0, 0.0, height_m=-0.8, cls=C.WATER, mat=M.WATER)
    g.fill_pitched((0.0, 40.0), 14.0, 10.0, 0.0, 6.0, 10.0, region=2)
    g.fill_rect((-8.0, -8.0), 0.6, 0.6, 0.0, height_m=21.75, cls=C.PEDESTRIAN, mat=M.CLOTH)
    return g


@pytest.mark.parametrize(
    ("point", "safe", "surface", "reason"),
    [
        ((0.0, 0.0), True, "rooftop_clear", None),
        ((8.0, 6.0), False, "rooftop_clear", "rooftop object within"),
        ((14.5, 0.0), False, "rooftop_clear", "from an edge"),
        ((-7.0, -8.0), False, "rooftop_clear", "person within"),
        ((0.0, 25.0), False, "road", "landed on road"),
        ((40.0, 0.0), False, "water", "landed on water"),
        ((0.0, 38.0), False, "rooftop_obstructed", "slope"),
    ],
)
def test_grader_hand_placed_cases(
    point: tuple[float, float], safe: bool, surface: str, reason: str | None
) -> None:
    verdict = grade(_graded_block(), *point)
    assert verdict.safe is safe
    assert verdict.surface == surface
    if reason is not None:
        assert any(reason in r for r in verdict.reasons), verdict.reasons
    else:
        assert verdict.reasons == ()


def test_weather_changes_the_image() -> None:
    g = _box_world()
    p = Pyramid(g.height)
    sun = Sun().direction_neu()
    sm = ShadowMap(g, p, sun)
    cam = CameraModel(320, 180, 90.0)
    pose = (0.0, 0.0, -110.0)
    imgs = {
        w: render(g, p, sm, cam, pose, LEVEL, sun, w, np.random.default_rng(0)).rgb.astype(float)
        for w in ("clear", "fog", "rain")
    }
    assert imgs["fog"].std() < 0.6 * imgs["clear"].std()  # haze flattens contrast
    assert imgs["fog"].mean() > imgs["clear"].mean()
    assert imgs["rain"].mean() < imgs["clear"].mean()  # wet darkening
    with pytest.raises(ValueError, match="unknown weather"):
        render(g, p, sm, cam, (0.0, 0.0, -110.0), LEVEL, sun, "snow")


def _label_scene() -> tuple[WorldGrid, Pyramid, ShadowMap, tuple[float, float, float]]:
    g = WorldGrid.empty((-60.0, 60.0), (-60.0, 60.0), ground_cls=C.GRASS, ground_mat=M.GRASS)
    g.fill_rect((0.0, 0.0), 20.0, 20.0, 0.0, height_m=30.0, cls=C.ROOF_FLAT, mat=M.GRAVEL, region=1)
    g.fill_rect((5.0, 5.0), 2.0, 2.0, 0.0, height_m=31.0, cls=C.ROOF_CLUTTER, mat=M.METAL, region=1)
    p = Pyramid(g.height)
    sun = Sun().direction_neu()
    return g, p, ShadowMap(g, p, sun), sun


# sha256 (first 16 hex digits) of rgb + depth + class of the frames below, rendered by the camera as it
# was before per-pixel labels and palettes existed: the flight path's frames must not change.
_FRAME_DIGESTS = {"clear": "6992fa820f4b9ae0", "fog": "855b91c7357205d8", "rain": "1566a64c71e52350"}


@pytest.mark.parametrize("weather", ["clear", "fog", "rain"])
def test_render_without_labels_is_byte_identical_to_before(weather: str) -> None:
    import hashlib

    g, p, sm, sun = _label_scene()
    pose, q = (3.0, -2.0, -60.0), euler_to_quat(0.05, -0.03, 0.4)
    cam = CameraModel(96, 64, 90.0)
    plain = render(g, p, sm, cam, pose, q, sun, weather, np.random.default_rng(5))
    digest = hashlib.sha256(plain.rgb.tobytes() + plain.depth_m.tobytes() + plain.hit_class.tobytes())
    assert digest.hexdigest()[:16] == _FRAME_DIGESTS[weather]
    assert plain.hit_material is None
    assert plain.hit_kind is None
    labelled = render(g, p, sm, cam, pose, q, sun, weather, np.random.default_rng(5), labels=True)
    assert np.array_equal(labelled.rgb, plain.rgb)
    assert np.array_equal(labelled.hit_class, plain.hit_class)


def test_render_labels_name_material_and_kind_per_pixel() -> None:
    from simbridge.world.camera import LABEL_SKY
    from simbridge.world.raycast import HIT_TOP

    g, p, sm, sun = _label_scene()
    cam = CameraModel(160, 160, 90.0)
    f = render(g, p, sm, cam, (0.0, 0.0, -60.0), LEVEL, sun, labels=True)
    assert f.hit_material is not None
    assert f.hit_kind is not None
    assert f.hit_material.shape == f.hit_kind.shape == (160, 160)
    assert f.hit_material[80, 80] == M.GRAVEL  # the roof under the camera, seen from the top
    assert f.hit_kind[80, 80] == HIT_TOP
    clutter = f.hit_class == C.ROOF_CLUTTER
    assert set(np.unique(f.hit_material[clutter]).tolist()) == {int(M.METAL)}
    grass = f.hit_class == C.GRASS
    assert (f.hit_material[grass] == M.GRASS).all()
    assert (f.hit_kind != LABEL_SKY).all()
    beside = render(g, p, sm, cam, (0.0, 25.0, -60.0), LEVEL, sun, labels=True)  # sees the east wall
    assert beside.hit_kind is not None
    walls = (beside.hit_kind != HIT_TOP) & (beside.hit_kind != LABEL_SKY)
    assert walls.sum() > 100
    # a wall carries its roof's class (hit_class); hit_kind tells it is a wall
    assert np.isin(beside.hit_class[walls], [C.ROOF_FLAT, C.ROOF_CLUTTER]).all()


def test_render_palette_recolours_and_is_checked() -> None:
    from simbridge.world.camera_textures import MAT_RGB as _MAT_RGB

    g, p, sm, sun = _label_scene()
    cam = CameraModel(64, 64, 60.0)
    palette = _MAT_RGB.copy()
    palette[int(M.GRAVEL)] = (0.2, 0.3, 0.8)
    base = render(g, p, sm, cam, (0.0, 0.0, -60.0), LEVEL, sun, rng=np.random.default_rng(1))
    blue = render(g, p, sm, cam, (0.0, 0.0, -60.0), LEVEL, sun, rng=np.random.default_rng(1), palette=palette)
    centre = (slice(24, 40), slice(24, 40))
    assert blue.rgb[centre][..., 2].mean() > base.rgb[centre][..., 2].mean() + 30
    with pytest.raises(ValueError, match="palette"):
        render(g, p, sm, cam, (0.0, 0.0, -60.0), LEVEL, sun, palette=np.zeros((3, 3), np.float32))


def test_sensors_in_several_threads_move_the_traffic_one_at_a_time() -> None:
    """simbridge renders the sensor stream's frames and its RTP camera's in worker threads, and each
    moves the actors before it reads the grid: three threads doing so at once, unlocked, broke the
    traffic's arrays (an IndexError here; a shape mismatch that killed an episode). Locked, the actors
    end where the latest time puts them."""
    import threading

    from tests.views import world

    w = world("scenario1")
    errors: list[str] = []

    def run(offset: float) -> None:
        try:
            for k in range(200):
                w.sync(1.0 + 0.05 * k + offset, (0.0, 0.0, 400.0))
        except Exception as exc:  # any error in a thread is the failure
            errors.append(repr(exc))

    threads = [threading.Thread(target=run, args=(o,)) for o in (0.0, 0.01, 0.02)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert errors == []
    assert w.actors.t_s == pytest.approx(1.0 + 0.05 * 199 + 0.02)  # moved on to the latest time asked
