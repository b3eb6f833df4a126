"""Farmland (simbridge/world/farmland.py, ``--place farmland``): deterministic per seed, what stands in
it (fields, hedgerows, roads, farmyards, power lines), how the grader reads it, and how the camera and
the LiDAR see its overhead wires (simbridge/world/wire_sensing.py)."""

from __future__ import annotations

import numpy as np
import pytest

from simbridge.geo import euler_to_quat
from simbridge.world.city_parts import CityError
from simbridge.world.farmland import generate_farmland
from simbridge.world.grader import grade
from simbridge.world.live import LiveWorld
from simbridge.world.model import Material, SurfaceClass, WorldGrid
from simbridge.world.places import PLACES
from simbridge.world.world import Wire, World

SIZE_M = 800.0  # large enough for the village, the farmsteads and the third road
DOWN = euler_to_quat(0.0, 0.0, 0.0)


@pytest.fixture(scope="module")
def farm() -> World:
    return generate_farmland(5, SIZE_M)


def _share(w: World, *classes: SurfaceClass) -> float:
    return float(np.isin(w.grid.cls, [int(c) for c in classes]).mean())


def _pasture_grid(wires: tuple[Wire, ...]) -> World:
    """A 120 m square of pasture with ``wires`` over it."""
    g = WorldGrid.empty((-60.0, 60.0), (-60.0, 60.0), 0.2)
    g.cls.fill(int(SurfaceClass.GRASS))
    g.mat.fill(int(Material.GRASS))
    g.height.fill(0.05)
    return World("pasture", 0, g, wires=wires)


WIRE = Wire(((-55.0, 0.0, 10.0), (0.0, 0.0, 9.0), (55.0, 0.0, 10.0)), 0.02)  # north-south over east 0


def test_farmland_a_seed_is_one_place_and_bad_requests_are_refused(farm: World) -> None:
    again = generate_farmland(5, SIZE_M)
    assert again.digest() == farm.digest()
    assert (again.lanes, again.walkways, again.wires) == (farm.lanes, farm.walkways, farm.wires)
    assert generate_farmland(6, SIZE_M).digest() != farm.digest()
    assert farm.name == "farmland"
    assert "farmland" in PLACES
    with pytest.raises(CityError, match="non-negative"):
        generate_farmland(-1)
    with pytest.raises(CityError, match="at least 300 m"):
        generate_farmland(0, 200.0)


def test_farmland_fields_cover_most_of_the_land_with_crops_pasture_and_soil(farm: World) -> None:
    crop, pasture = _share(farm, SurfaceClass.CROP), _share(farm, SurfaceClass.GRASS)
    soil = float((farm.grid.mat == int(Material.SOIL)).mean())
    assert crop + pasture + soil > 0.8
    assert min(crop, pasture, soil) > 0.03
    assert (farm.grid.mat[farm.grid.cls == int(SurfaceClass.CROP)] == int(Material.CROP)).all()


def test_farmland_holds_trees_roads_buildings_and_machinery(farm: World) -> None:
    assert 0.005 < _share(farm, SurfaceClass.TREE) < 0.1  # hedgerows and tree lines
    assert 0.003 < _share(farm, SurfaceClass.ROAD) < 0.05  # narrow country roads
    assert _share(farm, SurfaceClass.SIDEWALK) == 0.0
    assert _share(farm, SurfaceClass.ROOF_PITCHED) > 0.002  # village houses, farmhouses, barns
    # machinery stands in gravel or concrete yards (poles apart: on their own, in the fields)
    g = farm.grid
    tall = (g.cls == int(SurfaceClass.MACHINERY)) & (g.height > 1.0) & (g.height < 5.0)
    assert tall.sum() * g.res**2 > 50.0
    i, j = np.nonzero(tall)
    k = np.arange(0, len(i), max(1, len(i) // 50))
    yard = [int(Material.GRAVEL), int(Material.CONCRETE)]
    near_yard = [
        np.isin(g.mat[max(a - 15, 0) : a + 15, max(b - 15, 0) : b + 15], yard).any()
        for a, b in zip(i[k], j[k], strict=True)
    ]
    assert np.mean(near_yard) > 0.9
    assert "farmsteads" in farm.description
    assert "village" in farm.description


def test_farmland_wires_sag_between_poles_standing_under_their_ends(farm: World) -> None:
    g = farm.grid
    assert len(farm.wires) >= 3
    for wire in farm.wires:
        pts = np.asarray(wire.points_neh)
        assert len(pts) > 10
        assert 0.005 <= wire.diameter_m <= 0.03
        for n, e, up in (pts[0], pts[-1]):
            win = g.window(n - 1.5, n + 1.5, e - 1.5, e + 1.5)
            assert win is not None
            i0, i1, j0, j1 = win
            pole = (g.cls[i0:i1, j0:j1] == int(SurfaceClass.MACHINERY)) & (g.height[i0:i1, j0:j1] > up - 1.0)
            assert pole.any(), f"no pole under the wire's end at {n:.0f} N {e:.0f} E"
            assert 7.0 < up < 13.0
        # sag: mid-span lower than the straight line between its poles, by 1-2 m
        mid = pts[8]
        chord = (pts[0][2] + pts[16][2]) / 2
        assert 0.9 <= chord - mid[2] <= 2.1


def test_farmland_people_walk_open_ground_and_traffic_uses_roads_and_tracks(farm: World) -> None:
    g = farm.grid
    open_ground = {SurfaceClass.GRASS, SurfaceClass.GROUND, SurfaceClass.CROP}
    assert len(farm.walkways) >= 4
    for walk in farm.walkways:
        for n, e in walk.points_ne:
            assert g.class_at(n, e) in open_ground, f"walkway point {n:.0f} N {e:.0f} E on {g.class_at(n, e)}"
    road_lanes = [ln for ln in farm.lanes if ln.speed_m_s[1] > 7.0]
    track_lanes = [ln for ln in farm.lanes if ln.speed_m_s[1] <= 6.0]
    assert len(road_lanes) >= 4
    assert track_lanes
    for lane in road_lanes:
        on_road = [g.class_at(n, e) == SurfaceClass.ROAD for n, e in lane.points_ne]
        assert np.mean(on_road) > 0.9
    assert max(ln.speed_m_s[1] for ln in farm.lanes) <= 14.0


def test_farmland_grader_lands_on_clear_pasture_not_in_crops_nor_under_a_wire(farm: World) -> None:
    g = farm.grid
    wires = farm.wires
    people = np.array([(n, e, 0.0) for w in farm.walkways for n, e in w.points_ne])
    rng = np.random.default_rng(0)
    safe = None
    for _ in range(4000):
        n, e = rng.uniform(-SIZE_M / 2 + 20, SIZE_M / 2 - 20, 2)
        if g.class_at(n, e) != SurfaceClass.GRASS or min(w.ground_gap_m(n, e) for w in wires) < 20.0:
            continue
        if np.hypot(people[:, 0] - n, people[:, 1] - e).min() < 30.0:
            continue
        got = grade(g, n, e, wires=wires)
        if got.safe:
            safe = got
            break
    assert safe is not None
    assert safe.surface == "park"
    i, j = np.nonzero(g.cls == int(SurfaceClass.CROP))
    cn, ce = g.cell_centres(i[len(i) // 2], i[len(i) // 2] + 1, j[len(j) // 2], j[len(j) // 2] + 1)
    crop = grade(g, float(cn.ravel()[0]), float(ce.ravel()[0]), wires=wires)
    assert not crop.safe
    assert crop.surface == "crops"
    # a standing crop is no smooth surface: rows of plants with the soil seen between them
    assert any("rough surface" in r for r in crop.reasons), crop.reasons
    mid = farm.wires[0].points_neh[8]
    under = grade(g, mid[0], mid[1], wires=wires)
    assert not under.safe
    assert any("overhead wire" in r for r in under.reasons)


@pytest.mark.parametrize(("above_m", "dark"), [(5.0, (120, 1000)), (30.0, (8, 80))])
def test_camera_draws_a_wire_as_a_dark_line_where_it_projects(above_m: float, dark: tuple[int, int]) -> None:
    """Straight down over a wire running north-south under the camera: the image's middle column(s)
    darken (plainly 5 m above the wire, faintly 30 m above), the rest is byte for byte the same."""
    pos = (0.0, 0.0, -(9.0 + above_m))
    plain = LiveWorld(_pasture_grid(())).camera_frame(pos, DOWN, 0.0, "clear", np.random.default_rng(1))
    wired = LiveWorld(_pasture_grid((WIRE,))).camera_frame(pos, DOWN, 0.0, "clear", np.random.default_rng(1))
    diff = plain.rgb.astype(int).sum(axis=2) - wired.rgb.astype(int).sum(axis=2)
    rows, cols = np.nonzero(diff)
    assert (diff >= 0).all()  # darker only
    assert set(cols.tolist()) <= {478, 479, 480, 481}  # the image's centre column: east 0
    assert len(set(rows.tolist())) > 500  # along the whole height of the image
    assert dark[0] <= diff.max() <= dark[1]
    assert np.array_equal(plain.depth_m, wired.depth_m, equal_nan=True)


def test_camera_keeps_a_wire_hidden_behind_a_building() -> None:
    world = _pasture_grid((WIRE,))
    world.grid.fill_rect(
        (0.0, 0.0), 120.0, 30.0, height_m=20.0, cls=SurfaceClass.ROOF_FLAT, mat=Material.MEMBRANE
    )
    plain = _pasture_grid(())
    plain.grid.fill_rect(
        (0.0, 0.0), 120.0, 30.0, height_m=20.0, cls=SurfaceClass.ROOF_FLAT, mat=Material.MEMBRANE
    )
    pos = (0.0, 0.0, -40.0)
    a = LiveWorld(plain).camera_frame(pos, DOWN, 0.0, "clear", np.random.default_rng(1))
    b = LiveWorld(world).camera_frame(pos, DOWN, 0.0, "clear", np.random.default_rng(1))
    assert np.array_equal(a.rgb, b.rgb)


def test_lidar_returns_a_few_points_from_a_wire_and_none_without_wires() -> None:
    pos = (0.0, 4.0, -20.0)  # 11 m above the wire, 4 m beside it
    plain = LiveWorld(_pasture_grid(())).lidar_sweep(pos, DOWN, 0.0, np.random.default_rng(2))
    again = LiveWorld(_pasture_grid(())).lidar_sweep(pos, DOWN, 0.0, np.random.default_rng(2))
    assert plain.tobytes() == again.tobytes()
    assert not (plain[:, 2] < 15.0).any()  # nothing between the vehicle and the pasture 20 m below
    wired = LiveWorld(_pasture_grid((WIRE,))).lidar_sweep(pos, DOWN, 0.0, np.random.default_rng(2))
    at_wire = wired[wired[:, 2] < 15.0]
    assert 3 <= len(at_wire) <= 0.01 * len(wired)
    # body FRD, yaw 0: x north, y east, z down; the wire is 9-10 m up, at east 0
    assert np.all(np.abs(at_wire[:, 1] + 4.0) < 0.3)
    assert np.all((at_wire[:, 2] > 9.5) & (at_wire[:, 2] < 11.5))


def test_farmland_sensors_see_the_place(farm: World) -> None:
    live = LiveWorld(farm)
    mid = farm.wires[0].points_neh[8]
    pos = (mid[0], mid[1], -(mid[2] + 6.0))
    frame = live.camera_frame(pos, DOWN, 0.0, "clear", np.random.default_rng(0))
    assert frame.rgb.std() > 5.0
    assert not np.isnan(frame.depth_m).any()
    pts = live.lidar_sweep(pos, DOWN, 0.0, np.random.default_rng(0))
    assert len(pts) > 10_000
