"""The waterfront (simbridge/world/waterfront*.py, ``--place waterfront``): deterministic per seed, its
own plan (a curving shore, water over a third of the square, a beach, piers with boats, the shore road
and a town), who is where, how the grader reads it and that the camera over the launch point sees both
water and land."""

from __future__ import annotations

import numpy as np
import pytest

from simbridge.world.city_parts import CityError
from simbridge.world.grader import grade
from simbridge.world.live import LiveWorld
from simbridge.world.model import Material, SurfaceClass
from simbridge.world.places import PLACES, generate_place
from simbridge.world.waterfront import generate_waterfront
from simbridge.world.world import World

SMALL_M = 400.0


@pytest.fixture(scope="module")
def shore() -> World:
    return generate_waterfront(0)


@pytest.fixture(scope="module")
def live(shore: World) -> LiveWorld:
    return LiveWorld(shore, actor_seed=0)


def _centre(w: World, i: int, j: int) -> tuple[float, float]:
    n, e = w.grid.cell_centres(i, i + 1, j, j + 1)
    return float(n.ravel()[0]), float(e.ravel()[0])


def _cells(w: World, cls: SurfaceClass, around_m: float) -> np.ndarray:
    """(k, 2) indices of the cells of ``cls`` with ``around_m`` of ``cls`` on every side."""
    mask = w.grid.cls == int(cls)
    k = round(around_m / w.grid.res)
    inner = (
        mask[k:-k, k:-k]
        & mask[2 * k :, k:-k]
        & mask[: -2 * k, k:-k]
        & mask[k:-k, 2 * k :]
        & mask[k:-k, : -2 * k]
    )
    return np.argwhere(inner) + k


def _turned(w: World, a: np.ndarray) -> np.ndarray:
    """``a`` (rows x cols over the grid) turned so that the water lies at growing column index (the
    water side is a whole side of the square)."""
    water = w.grid.cls == int(SurfaceClass.WATER)
    side = int(np.argmax([water[:, -1].mean(), water[:, 0].mean(), water[-1, :].mean(), water[0, :].mean()]))
    return (a, a[:, ::-1], a.T, a.T[:, ::-1])[side]


def _shoreline(w: World) -> np.ndarray:
    """Per line across the shore, the column of the first cell of land met coming from the water
    (pontoons and boats are not land), in the turned grid."""
    afloat = np.isin(w.grid.cls, [int(SurfaceClass.WATER), int(SurfaceClass.PIER), int(SurfaceClass.VEHICLE)])
    turned = _turned(w, afloat)[:, ::-1]
    return np.asarray(turned.shape[1] - 1 - np.argmin(turned, axis=1))


def test_a_seed_is_one_waterfront_and_bad_requests_are_refused() -> None:
    a, b = generate_waterfront(3, SMALL_M), generate_waterfront(3, SMALL_M)
    assert a.grid.digest() == b.grid.digest()
    assert a.lanes == b.lanes
    assert a.walkways == b.walkways
    assert a.sun == b.sun
    assert generate_waterfront(4, SMALL_M).grid.digest() != a.grid.digest()
    assert a.name == "waterfront"
    with pytest.raises(CityError, match="non-negative"):
        generate_waterfront(-1)
    with pytest.raises(CityError, match="at least 300 m"):
        generate_waterfront(0, 200.0)


def test_the_water_covers_a_third_of_the_square_behind_a_curving_shore(shore: World) -> None:
    share = float((shore.grid.cls == int(SurfaceClass.WATER)).mean())
    assert 0.30 <= share <= 0.45
    # the shoreline: per line across the shore, the first water cell from the land side
    first = _shoreline(shore).astype(float) * shore.grid.res
    rows = np.arange(len(first)) * shore.grid.res
    fit = np.polyval(np.polyfit(rows, first, 1), rows)
    assert float(np.abs(first - fit).max()) > 20.0  # not a straight line
    assert float(np.abs(np.diff(first)).max()) < 4.0  # but a smooth one (the piers start 3 m into the quay)
    # the launch point is on land within 50 m of the water
    assert shore.grid.class_at(0.0, 0.0) != SurfaceClass.WATER
    i, j = shore.grid.index(0.0, 0.0) or (0, 0)
    k = round(50.0 / shore.grid.res)
    assert (shore.grid.cls[i - k : i + k, j - k : j + k] == int(SurfaceClass.WATER)).any()


def test_a_sand_beach_lies_along_the_water_with_people_on_it(shore: World) -> None:
    g = shore.grid
    sand = (g.cls == int(SurfaceClass.GROUND)) & (g.mat == int(Material.SAND))
    assert sand.mean() > 0.005
    water = g.cls == int(SurfaceClass.WATER)
    touching = (sand[:, :-1] & water[:, 1:]).sum() + (sand[:, 1:] & water[:, :-1]).sum()
    touching += (sand[:-1] & water[1:]).sum() + (sand[1:] & water[:-1]).sum()
    assert touching * g.res > 200.0  # over 200 m of shoreline is beach
    on_sand = 0
    for w in shore.walkways:
        ij = g.index(*w.points_ne[0])
        if ij is not None and sand[ij]:
            on_sand += w.count
    assert on_sand > 150  # a crowded beach
    assert any(len(w.points_ne) == 1 for w in shore.walkways)  # people lying or standing still
    starts = [(w, g.index(*w.points_ne[0])) for w in shore.walkways]
    assert any(len(w.points_ne) > 2 and ij is not None and sand[ij] for w, ij in starts)  # waterline walks


def test_piers_reach_into_the_water_with_boats_moored_beside_them(shore: World) -> None:
    g = shore.grid
    pier = g.cls == int(SurfaceClass.PIER)
    water = g.cls == int(SurfaceClass.WATER)
    assert pier.sum() * g.res**2 > 500.0
    t_pier = _turned(shore, pier)
    shoreline = _shoreline(shore)
    # pier cells 30 m beyond the shoreline of their own line: out in the water
    cols = np.arange(t_pier.shape[1])[None, :]
    assert (t_pier & (cols > shoreline[:, None] + round(30.0 / g.res))).any()
    boats = (g.cls == int(SurfaceClass.VEHICLE)) & (g.height < 1.5)
    near_water = np.zeros_like(water)
    near_water[:, 1:] |= water[:, :-1]
    near_water[:, :-1] |= water[:, 1:]
    assert (boats & near_water).sum() > 100  # hulls afloat, beside the pontoons
    assert "piers" in shore.description


def test_the_shore_road_has_traffic_and_the_town_has_clear_flat_roofs(shore: World) -> None:
    assert len(shore.lanes) >= 4
    long_lanes = [ln for ln in shore.lanes if len(ln.points_ne) > 100]
    assert long_lanes  # the shore road runs across the square
    g = shore.grid
    on_road = [g.class_at(*p) for ln in long_lanes for p in ln.points_ne[::10]]
    assert sum(c == SurfaceClass.ROAD for c in on_road) > 0.9 * len(on_road)
    assert (g.cls == int(SurfaceClass.ROOF_PITCHED)).mean() > 0.01
    assert (g.cls == int(SurfaceClass.ROOF_CLUTTER)).mean() > 0.003
    assert "clear roofs" in shore.description


def test_the_grader_refuses_water_and_a_crowded_beach_and_passes_a_clear_roof(
    shore: World, live: LiveWorld
) -> None:
    g = shore.grid
    i, j = _cells(shore, SurfaceClass.WATER, 5.0)[0]
    wet = grade(g, *_centre(shore, int(i), int(j)))
    assert not wet.safe
    assert wet.surface == "water"
    people = live.actors.people_at(0.0)
    k = round(1.5 / g.res)

    def on_sand(n: float, e: float) -> bool:  # the ground around them: they are stamped into the grid
        ij = g.index(n, e)
        return (
            ij is not None
            and float((g.mat[ij[0] - k : ij[0] + k, ij[1] - k : ij[1] + k] == int(Material.SAND)).mean())
            > 0.5
        )

    sand = [p for p in people if on_sand(float(p[0]), float(p[1]))]
    assert sand
    pn, pe, _ = sand[0]
    near = live.grade_touchdown(float(pn) + 3.0, float(pe), 0.0)
    assert not near.safe
    assert any("person" in r for r in near.reasons)
    roofs = _cells(shore, SurfaceClass.ROOF_FLAT, 5.0)
    tried = [
        live.grade_touchdown(*_centre(shore, int(i), int(j)), 0.0)
        for i, j in roofs[:: max(1, len(roofs) // 30)]
    ]
    assert any(t.safe and t.surface == "rooftop_clear" for t in tried)


def test_the_camera_over_the_launch_point_sees_water_and_land(live: LiveWorld) -> None:
    rng = np.random.default_rng(0)
    frame = live.camera_frame((0.0, 0.0, -100.0), (1.0, 0.0, 0.0, 0.0), 0.0, "clear", rng)
    water = float((frame.hit_class == int(SurfaceClass.WATER)).mean())
    assert 0.05 < water < 0.95
    assert (frame.hit_class == int(SurfaceClass.GROUND)).mean() > 0.02  # the beach
    points = live.lidar_sweep((0.0, 0.0, -100.0), (1.0, 0.0, 0.0, 0.0), 0.0, rng)
    assert len(points) > 1000


def test_places_names_it() -> None:
    assert "waterfront" in PLACES
    assert generate_place("waterfront", 1).name == "waterfront"


def test_a_launch_over_the_water_took_off_from_the_shore(live: LiveWorld) -> None:
    """Home is where the vehicle took off: over the water, the nearest point on land where a touchdown
    grades safe (simbridge.home.home_on_land); over land, the ground under the launch point."""
    from simbridge.home import HOME_STEP_M, home_on_land

    g = live.grid
    wet = _cells(live.world, SurfaceClass.WATER, 30.0)
    i, j = wet[np.argmin(np.hypot(*(wet - np.array(g.shape) / 2).T))]  # the water nearest the middle
    n, e = _centre(live.world, int(i), int(j))
    hn, he = home_on_land(live, n, e)
    assert g.class_at(hn, he) in (
        SurfaceClass.GROUND,
        SurfaceClass.GRASS,
        SurfaceClass.PARKING_LOT,
        SurfaceClass.PIER,
    )
    assert live.grade_touchdown(hn, he, 0.0).safe
    far = float(np.hypot(hn - n, he - e))
    assert far >= 30.0  # off the water, which reaches 30 m every way
    n0, n1, e0, e1 = g.extent_m
    assert min(hn - n0, n1 - hn, he - e0, e1 - he) >= far + 20.0  # --fence map's circle holds the launch
    # nearest: no ring nearer than the one it came from holds such a point on the 8 compass points
    for r in np.arange(HOME_STEP_M, far - HOME_STEP_M, HOME_STEP_M):
        for a in np.linspace(0.0, 2 * np.pi, 8, endpoint=False):
            p = (n + r * np.cos(a), e + r * np.sin(a))
            room = min(p[0] - n0, n1 - p[0], p[1] - e0, e1 - p[1]) - r
            grass = g.class_at(*p) == SurfaceClass.GRASS and live.grade_touchdown(*p, 0.0).safe
            assert not (grass and room >= 20.0)
    i, j = _cells(live.world, SurfaceClass.ROOF_FLAT, 5.0)[0]
    assert home_on_land(live, *_centre(live.world, int(i), int(j))) == _centre(live.world, int(i), int(j))
