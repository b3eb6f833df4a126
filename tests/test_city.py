"""The procedural city: determinism, contents, heights, roofs, traffic and parameter checks."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from simbridge.geo import euler_to_quat
from simbridge.world.camera import CameraModel, body_to_neu
from simbridge.world.city import CityError, CityParams, generate_city
from simbridge.world.live import LiveWorld
from simbridge.world.model import SurfaceClass, WorldGrid
from simbridge.world.raycast import HIT_MISS, HIT_TOP, cast_rays
from simbridge.world.world import World

SMALL_M = 400.0


@pytest.fixture(scope="module")
def small_city() -> World:
    return generate_city(11, size_m=SMALL_M)


@pytest.fixture(scope="module")
def default_city() -> World:
    return generate_city(5)


def _sample_polyline(points: tuple[tuple[float, float], ...], step_m: float = 1.0) -> np.ndarray:
    """(k, 2) points every ``step_m`` metres along a polyline, ends included."""
    out = []
    for (n1, e1), (n2, e2) in itertools.pairwise(points):
        k = max(2, math.ceil(math.hypot(n2 - n1, e2 - e1) / step_m) + 1)
        f = np.linspace(0.0, 1.0, k)
        out.append(np.stack([n1 + f * (n2 - n1), e1 + f * (e2 - e1)], axis=1))
    return np.concatenate(out)


def _cells(grid: WorldGrid, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    i = np.floor((pts[:, 0] - grid.n0) / grid.res).astype(int)
    j = np.floor((pts[:, 1] - grid.e0) / grid.res).astype(int)
    rows, cols = grid.shape
    assert ((i >= 0) & (i < rows) & (j >= 0) & (j < cols)).all()
    return i, j


def _region_boxes(grid: WorldGrid) -> dict[int, tuple[int, int, int, int]]:
    """Bounding box (i0, i1, j0, j1) of every positive region id."""
    rows, cols = np.nonzero(grid.region > 0)
    ids = grid.region[rows, cols]
    top = int(ids.max()) + 1
    i0 = np.full(top, 1 << 30)
    j0 = np.full(top, 1 << 30)
    i1 = np.full(top, -1)
    j1 = np.full(top, -1)
    np.minimum.at(i0, ids, rows)
    np.minimum.at(j0, ids, cols)
    np.maximum.at(i1, ids, rows + 1)
    np.maximum.at(j1, ids, cols + 1)
    return {int(r): (int(i0[r]), int(i1[r]), int(j0[r]), int(j1[r])) for r in np.unique(ids)}


def test_generate_city_same_seed_identical() -> None:
    a = generate_city(3, size_m=SMALL_M)
    b = generate_city(3, size_m=SMALL_M)
    for name in ("height", "cls", "mat", "region"):
        assert np.array_equal(getattr(a.grid, name), getattr(b.grid, name)), name
    assert a.lanes == b.lanes
    assert a.walkways == b.walkways
    assert a.sun == b.sun


def test_generate_city_different_seed_differs() -> None:
    a = generate_city(3, size_m=SMALL_M)
    b = generate_city(4, size_m=SMALL_M)
    assert not np.array_equal(a.grid.height, b.grid.height)
    assert not np.array_equal(a.grid.cls, b.grid.cls)
    assert a.lanes != b.lanes


def test_generate_city_default_has_every_class(default_city: World) -> None:
    present = set(np.flatnonzero(np.bincount(default_city.grid.cls.ravel(), minlength=len(SurfaceClass))))
    wanted = {
        SurfaceClass.ROOF_FLAT, SurfaceClass.ROOF_CLUTTER, SurfaceClass.PARAPET, SurfaceClass.ROAD,
        SurfaceClass.SIDEWALK, SurfaceClass.CROSSWALK, SurfaceClass.HIGHWAY, SurfaceClass.GUARD_RAIL,
        SurfaceClass.PARKING_LOT, SurfaceClass.GRASS, SurfaceClass.TREE, SurfaceClass.WATER,
        SurfaceClass.PIER, SurfaceClass.VEHICLE, SurfaceClass.ROOF_PITCHED, SurfaceClass.PARKING_ROOF,
    }  # fmt: skip
    missing = {c.name for c in wanted if int(c) not in present}
    assert not missing
    assert int(SurfaceClass.UNKNOWN) not in present
    assert int(SurfaceClass.PEDESTRIAN) not in present  # actors are stamped at run time only


def test_generate_city_default_memory_and_extent(default_city: World) -> None:
    g = default_city.grid
    assert g.extent_m == pytest.approx((-600.0, 600.0, -600.0, 600.0))
    assert g.shape == (6000, 6000)
    assert g.memory_bytes() <= 1.5e9
    assert default_city.name == "city"
    assert default_city.launch_ne_m == (0.0, 0.0)
    assert default_city.launch_height_m == 110.0
    assert 90.0 <= default_city.sun.azimuth_deg <= 270.0
    assert 35.0 <= default_city.sun.elevation_deg <= 65.0


def test_generate_city_heights_sane(default_city: World) -> None:
    g = default_city.grid
    h, c = g.height, g.cls
    assert np.isfinite(h).all()
    assert h.max() <= 100.0
    assert (h[c == SurfaceClass.WATER] < 0).all()
    for roof in (
        SurfaceClass.ROOF_FLAT,
        SurfaceClass.ROOF_PITCHED,
        SurfaceClass.ROOF_CLUTTER,
        SurfaceClass.PARAPET,
    ):
        assert (h[c == roof] > 3.0).all(), roof.name
    deck = h[c == SurfaceClass.PARKING_ROOF]
    assert deck.min() >= 10.0
    assert deck.max() <= 15.0
    assert (h[c == SurfaceClass.ROAD] == 0.0).all()
    assert np.allclose(h[c == SurfaceClass.PIER], 0.6)
    trees = h[c == SurfaceClass.TREE]
    assert trees.max() <= 14.0
    assert trees.max() >= 6.0
    assert h[c == SurfaceClass.HIGHWAY].max() <= 12.0
    roofs = h[c == SurfaceClass.ROOF_FLAT]
    assert (roofs < 25.0).mean() > 0.3  # many low roofs
    assert roofs.max() > 40.0  # and some tall ones


def test_generate_city_highway_deck_elevated_over_streets(default_city: World) -> None:
    g = default_city.grid
    highway = [ln for ln in default_city.lanes if ln.deck_height_m > 0]
    assert len(highway) >= 4
    for ln in highway:
        assert 8.0 <= ln.deck_height_m <= 12.0
        assert 15.0 <= ln.speed_m_s[0] <= ln.speed_m_s[1] <= 25.0
        i, j = _cells(g, _sample_polyline(ln.points_ne))
        assert (g.cls[i, j] == SurfaceClass.HIGHWAY).all()
        assert np.allclose(g.height[i, j], ln.deck_height_m)
    # the deck spans the whole city east-west, passing over the north-south streets and the river
    i_deck = _cells(g, np.array([highway[0].points_ne[0]]))[0][0]
    assert (g.cls[i_deck] == SurfaceClass.HIGHWAY).all()
    i_off = i_deck + round(60.0 / g.res)
    assert (g.cls[i_off] == SurfaceClass.WATER).any()
    assert (g.cls[i_off] == SurfaceClass.ROAD).sum() > 0.05 * g.shape[1]
    # ramps bring it down to street level, guard rails line it
    ramp = g.cls == SurfaceClass.HIGHWAY
    assert (ramp & (g.height > 0.5) & (g.height < 7.0)).any()
    rails = g.height[g.cls == SurfaceClass.GUARD_RAIL]
    assert rails.size > 0
    assert rails.max() == pytest.approx(max(ln.deck_height_m for ln in highway) + 0.9)


def test_generate_city_roofs_clear_and_cluttered(small_city: World) -> None:
    g = small_city.grid
    erode = round(2.0 / g.res)
    clear = cluttered = 0
    for rid, (i0, i1, j0, j1) in _region_boxes(g).items():
        if i1 - i0 <= 2 * erode + 2 or j1 - j0 <= 2 * erode + 2:
            continue
        inner = (slice(i0 + erode, i1 - erode), slice(j0 + erode, j1 - erode))
        assert (g.region[inner] == rid).all()  # buildings are solid rectangles
        cls = g.cls[inner]
        if not (cls == SurfaceClass.ROOF_FLAT).any():
            continue  # pitched roofs and parking decks
        if (cls == SurfaceClass.ROOF_FLAT).all():
            clear += 1
        if (cls == SurfaceClass.ROOF_CLUTTER).any():
            cluttered += 1
    assert clear >= 3
    assert cluttered >= 10


def test_generate_city_clutter_stands_on_roofs(small_city: World) -> None:
    """Clutter heights are absolute: above the roof of the building it stands on."""
    g = small_city.grid
    for rid, (i0, i1, j0, j1) in _region_boxes(g).items():
        win = (slice(i0, i1), slice(j0, j1))
        mine = g.region[win] == rid
        cls, h = g.cls[win][mine], g.height[win][mine]
        roof = h[cls == SurfaceClass.ROOF_FLAT]
        clutter = h[cls == SurfaceClass.ROOF_CLUTTER]
        if roof.size and clutter.size:
            assert clutter.min() > roof.max() - 1e-3, rid


def test_generate_city_region_ids_unique_per_building(small_city: World) -> None:
    g = small_city.grid
    ids = np.unique(g.region)
    assert ids[0] == 0
    assert ids.size > 30
    assert (g.region[g.cls == SurfaceClass.ROAD] == 0).all()
    assert (g.region[g.cls == SurfaceClass.ROOF_FLAT] > 0).all()


def test_generate_city_lanes_on_road(small_city: World) -> None:
    g = small_city.grid
    drivable = np.array([SurfaceClass.ROAD, SurfaceClass.HIGHWAY, SurfaceClass.CROSSWALK])
    streets = [ln for ln in small_city.lanes if ln.deck_height_m == 0.0]
    assert len(streets) >= 8
    for ln in small_city.lanes:
        i, j = _cells(g, _sample_polyline(ln.points_ne))
        on = np.isin(g.cls[i, j], drivable)
        assert on.all(), (ln.points_ne, np.unique(g.cls[i, j][~on]))
        assert 3.0 <= ln.arrivals_per_min <= 12.0
    for ln in streets:
        assert 8.0 <= ln.speed_m_s[0] <= ln.speed_m_s[1] <= 14.0
    # both directions: east- and westbound, north- and southbound
    headings = set()
    for ln in streets:
        (n1, e1), (n2, e2) = ln.points_ne[0], ln.points_ne[-1]
        headings.add((int(np.sign(round(n2 - n1))), int(np.sign(round(e2 - e1)))))
    assert headings == {(1, 0), (-1, 0), (0, 1), (0, -1)}


def test_generate_city_walkways_on_sidewalks_and_roofs(small_city: World) -> None:
    g = small_city.grid
    ground = [w for w in small_city.walkways if w.surface_height_m < 1.0]
    roofs = [w for w in small_city.walkways if w.surface_height_m >= 1.0]
    assert len(ground) >= 5
    assert roofs
    for w in small_city.walkways:
        assert 1 <= w.count <= 6
    for w in ground:
        assert w.count >= 2
    on_walk = []
    for w in ground:
        i, j = _cells(g, _sample_polyline(w.points_ne))
        on_walk.append(
            np.isin(g.cls[i, j], [SurfaceClass.SIDEWALK, SurfaceClass.CROSSWALK, SurfaceClass.GRASS])
        )
    assert np.concatenate(on_walk).mean() > 0.85
    for w in roofs:
        i, j = _cells(g, _sample_polyline(w.points_ne))
        assert (g.cls[i, j] == SurfaceClass.ROOF_FLAT).all()
        assert np.allclose(g.height[i, j], w.surface_height_m)


def test_generate_city_parked_cars_are_car_sized(small_city: World) -> None:
    """Parked cars stand 1.5 m tall on a lot (ground) or on a parking structure's deck (10-15 m)."""
    g = small_city.grid
    car = g.cls == SurfaceClass.VEHICLE
    assert car.sum() * g.res**2 > 4.5 * 1.9 * 10  # at least ten cars' worth
    tops = g.height[car]
    on_lot = np.isclose(tops, 1.5)
    on_deck = (tops >= 11.5) & (tops <= 16.5)
    assert (on_lot | on_deck).all()
    assert on_lot.any()


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"block_m": (110.0, 60.0)}, "block_m"),
        ({"street_width_m": (-1.0, 12.0)}, "street_width_m"),
        ({"street_lanes": (2, 8)}, "too narrow"),
        ({"park_fraction": 1.5}, "park_fraction"),
        ({"park_fraction": 0.6, "parking_lot_fraction": 0.6}, "must be <= 1"),
        ({"height_mix": ((2.0, 10.0, 1.0),)}, "height_mix"),
        ({"height_mix": ()}, "height_mix"),
        ({"parked_occupancy": (0.5, 1.5)}, "parked_occupancy"),
        ({"walkway_count": (0, 3)}, "walkway_count"),
        ({"tree_per_m2": -0.1}, "tree_per_m2"),
    ],
)
def test_city_params_bad_values_rejected(kwargs: dict[str, object], match: str) -> None:
    with pytest.raises(CityError, match=match):
        CityParams(**kwargs)  # type: ignore[arg-type]


def test_generate_city_explicit_default_params_same_city(small_city: World) -> None:
    again = generate_city(11, size_m=SMALL_M, params=CityParams())
    assert np.array_equal(again.grid.cls, small_city.grid.cls)
    assert isinstance(CityError("x"), ValueError)  # callers may catch ValueError


@pytest.mark.parametrize(
    ("seed", "size_m", "match"),
    [(-1, 400.0, "seed"), (1, 100.0, "size_m"), (1, float("nan"), "size_m")],
)
def test_generate_city_bad_request_rejected(seed: int, size_m: float, match: str) -> None:
    with pytest.raises(CityError, match=match):
        generate_city(seed, size_m=size_m)


def test_generate_city_params_change_the_city() -> None:
    parks = generate_city(2, size_m=SMALL_M, params=CityParams(park_fraction=0.9, plaza_fraction=0.0))
    default = generate_city(2, size_m=SMALL_M)
    green = [SurfaceClass.GRASS, SurfaceClass.TREE]
    assert np.isin(parks.grid.cls, green).sum() > 1.5 * np.isin(default.grid.cls, green).sum()
    assert np.unique(parks.grid.region).size * 3 < np.unique(default.grid.region).size


def test_city_camera_tiles_give_the_march_s_answer(small_city: World) -> None:
    """The city has what the scenarios lack in numbers: pitched roofs, trees, towers, a highway on
    piers. A camera image cast in proven tiles finds exactly what the march alone finds there, hit
    for hit, from high and low, level and tilted."""
    live = LiveWorld(small_city)
    g, p = live.grid, live.pyramid
    camera = CameraModel(320, 180, 90.0)
    hits = walls = 0
    for n, e, alt, roll, pitch, yaw in [
        (0.0, 0.0, 110.0, 0.0, 0.0, 0.0),
        (40.0, -60.0, 45.0, 6.0, -8.0, 37.0),
        (-70.0, 80.0, 160.0, 15.0, 10.0, 200.0),
    ]:
        q = euler_to_quat(math.radians(roll), math.radians(pitch), math.radians(yaw))
        origin = np.array([[n, e, alt]])
        dirs = body_to_neu(camera.unit_rays_body(), q)
        march = cast_rays(g.height, p.maps, p.h_max, g.res, g.n0, g.e0, origin, dirs, 600.0)
        tiles = cast_rays(
            g.height, p.maps, p.h_max, g.res, g.n0, g.e0, origin, dirs, 600.0, camera.width_px, 8
        )
        for a, b in zip(march, tiles, strict=True):
            np.testing.assert_array_equal(a, b)
        hits += int((march[3] != HIT_MISS).sum())
        walls += int((march[3] > HIT_TOP).sum())
    assert hits > 150_000  # not vacuous: roofs, streets and facades all seen
    assert walls > 5_000
