"""The procedural hillside village: determinism, its relief (span, steep slopes and flat benches),
roads cut level across, houses on platforms, actors standing on the sloped ground, the grader's slope
rule on it, and actors on flat worlds placed exactly as before relief came."""

from __future__ import annotations

import hashlib
import math

import cv2
import numpy as np
import pytest

from simbridge.world.actors import Actors
from simbridge.world.city_parts import CityError
from simbridge.world.grader import grade
from simbridge.world.hillside import build_hillside, generate_hillside
from simbridge.world.model import SurfaceClass, WorldError, WorldGrid
from simbridge.world.relief import ReliefParams, make_relief
from simbridge.world.world import Lane, Walkway, World

SIZE_M = 600.0


@pytest.fixture(scope="module")
def built() -> tuple[World, np.ndarray]:
    return build_hillside(0, size_m=SIZE_M)


def _ground_at(world: World, ground: np.ndarray, n: np.ndarray, e: np.ndarray) -> np.ndarray:
    g = world.grid
    i = np.floor((n - g.n0) / g.res).astype(int)
    j = np.floor((e - g.e0) / g.res).astype(int)
    return np.asarray(ground[i, j], np.float64)


def _slope_deg(ground: np.ndarray, res: float, every: int = 10) -> np.ndarray:
    """Slopes over ``every`` cells (2 m at 0.2 m a cell), degrees."""
    z = ground[::every, ::every].astype(np.float64)
    gn, ge = np.gradient(z, res * every)
    return np.asarray(np.degrees(np.arctan(np.hypot(gn, ge))))


def test_hillside_is_deterministic(built: tuple[World, np.ndarray]) -> None:
    world, _ = built
    again = generate_hillside(0, size_m=SIZE_M)
    assert again.digest() == world.digest()
    assert again.lanes == world.lanes
    assert again.walkways == world.walkways
    assert again.sun == world.sun
    assert generate_hillside(1, size_m=300.0).digest() != generate_hillside(0, size_m=300.0).digest()


@pytest.mark.parametrize(("seed", "size_m"), [(-1, 400.0), (1.5, 400.0), (True, 400.0), (0, 299.0)])
def test_hillside_rejects_bad_requests(seed: object, size_m: float) -> None:
    with pytest.raises(CityError):
        generate_hillside(seed, size_m=size_m)  # type: ignore[arg-type]


def test_hillside_world_fields(built: tuple[World, np.ndarray]) -> None:
    world, _ = built
    assert world.name == "hillside"
    assert world.launch_ne_m == (0.0, 0.0)
    assert world.launch_height_m == 100.0  # above the ground at (0, 0), wherever that lies
    assert world.grid.extent_m == pytest.approx((-300.0, 300.0, -300.0, 300.0))
    shares = np.bincount(world.grid.cls.ravel(), minlength=len(SurfaceClass)) / world.grid.cls.size
    for cls in (SurfaceClass.ROAD, SurfaceClass.ROOF_PITCHED, SurfaceClass.TREE, SurfaceClass.WATER):
        assert shares[cls] > 0.002, cls.name
    assert shares[SurfaceClass.PEDESTRIAN] == 0  # actors are not in the static world


def test_hillside_relief_spans_slopes_and_benches(built: tuple[World, np.ndarray]) -> None:
    world, ground = built
    assert float(ground.max() - ground.min()) >= 30.0
    slope = _slope_deg(ground, world.grid.res)
    assert (slope > 15.0).mean() > 0.02
    assert (slope < 5.0).mean() > 0.1
    # the ground is in the grid: where nothing stands on it, the grid's height is the ground's
    bare = world.grid.cls == SurfaceClass.GRASS
    diff = np.abs(world.grid.height[bare] - ground[bare])
    assert float(np.percentile(diff, 50)) < 0.01


def test_hillside_roads_are_level_across(built: tuple[World, np.ndarray]) -> None:
    world, ground = built
    worst = []
    for lane in world.lanes:
        p = np.asarray(lane.points_ne)[8:-8]  # away from the junctions at the ends
        d = np.gradient(p, axis=0)
        d /= np.hypot(d[:, 0], d[:, 1])[:, None]
        across = np.stack([-d[:, 1], d[:, 0]], axis=1)
        inside = (np.abs(p) < SIZE_M / 2 - 5.0).all(axis=1)
        p, across = p[inside], across[inside]
        left = _ground_at(world, ground, p[:, 0] + across[:, 0], p[:, 1] + across[:, 1])
        right = _ground_at(world, ground, p[:, 0] - across[:, 0], p[:, 1] - across[:, 1])
        worst.append(np.abs(left - right))
    gaps = np.concatenate(worst)
    assert len(gaps) > 100
    assert float(np.percentile(gaps, 99)) < 0.1  # 2 m across a lane: level (a hairpin's joint aside)
    heights = np.concatenate([np.asarray(ln.heights_m) for ln in world.lanes if ln.heights_m is not None])
    assert float(heights.max() - heights.min()) > 10.0  # and they climb


def test_hillside_houses_sit_on_platforms(built: tuple[World, np.ndarray]) -> None:
    world, ground = built
    g = world.grid
    roofs = g.cls == SurfaceClass.ROOF_PITCHED
    regions = np.unique(g.region[roofs])
    assert len(regions) >= 10
    for rid in regions[:: max(1, len(regions) // 25)].tolist():
        cells = roofs & (g.region == rid)
        under = ground[cells]
        assert float(under.max() - under.min()) < 0.05, rid  # a level platform under the house
        i, j = np.nonzero(cells)
        ring = ground[max(i.min() - 10, 0) : i.max() + 11, max(j.min() - 10, 0) : j.max() + 11]
        assert (
            float(g.height[cells].max()) > float(np.median(ring)) + 2.0
        )  # the roof (a shed's, 2.2-2.5 m) stands above


def test_hillside_actors_stand_on_the_ground(built: tuple[World, np.ndarray]) -> None:
    world, _ = built
    grid = world.grid
    actors = Actors(world.lanes, world.walkways, 3)
    spans = []
    for t in (0.0, 17.0, 61.0):
        actors.advance(t)
        people = actors.people_at(t)
        assert len(people) > 10
        under = np.asarray([grid.height_at(n, e) for n, e, _ in people])
        assert np.abs(people[:, 2] - under).max() < 0.3
        spans.append(float(np.ptp(people[:, 2])))
        cars = [p for p in actors.poses() if p.kind == SurfaceClass.VEHICLE]
        assert cars
        for car in cars:
            assert abs(car.base_height_m - grid.height_at(*car.centre_ne)) < 0.3
    assert max(spans) > 5.0  # people stand at many heights: on the slopes, not one ground level


def test_hillside_grading_steep_unsafe_bench_safe(built: tuple[World, np.ndarray]) -> None:
    world, ground = built
    g = world.grid
    rng = np.random.default_rng(0)
    slope = _slope_deg(ground, g.res, every=1)
    steep = np.argwhere((slope > 18.0) & (g.cls == SurfaceClass.GRASS))
    kernel = np.ones((11, 11), np.uint8)  # 2 m square: level ground all round, not a wall's top
    flat = cv2.dilate(ground, kernel) - cv2.erode(ground, kernel) < 0.02
    level = np.argwhere(flat & (g.cls == SurfaceClass.GRASS))
    assert len(steep) > 0
    assert len(level) > 0

    def centre(ij: np.ndarray) -> tuple[float, float]:
        return (g.n0 + (ij[0] + 0.5) * g.res, g.e0 + (ij[1] + 0.5) * g.res)

    for ij in steep[rng.choice(len(steep), 5)]:
        result = grade(g, *centre(ij))
        assert not result.safe
        assert any(r.startswith("slope ") for r in result.reasons), result.reasons
    safe = [grade(g, *centre(ij)) for ij in level[rng.choice(len(level), 40)]]
    assert any(r.safe and r.surface == "park" for r in safe)
    sloped = [r for r in safe if any(x.startswith("slope ") for x in r.reasons)]
    assert len(sloped) <= 4  # a few next to a roof or a wall, whose cells the plane fit takes in


def test_relief_is_seeded_and_checks_its_extent() -> None:
    a = make_relief(np.random.default_rng(5), (-100.0, 100.0), (-100.0, 100.0))
    b = make_relief(np.random.default_rng(5), (-100.0, 100.0), (-100.0, 100.0))
    assert a.z.tobytes() == b.z.tobytes()
    assert a.sample(0.0, 0.0) == pytest.approx(b.sample(0.0, 0.0))
    with pytest.raises(WorldError):
        make_relief(np.random.default_rng(5), (-100.0, 100.5), (-100.0, 100.0))
    with pytest.raises(WorldError):
        ReliefParams(bench_strength=1.0)
    with pytest.raises(WorldError):
        Walkway(((0.0, 0.0), (1.0, 1.0)), heights_m=(0.0,))


def _fingerprint(lanes: tuple[Lane, ...], walks: tuple[Walkway, ...]) -> str:
    grid = WorldGrid.empty((-60.0, 60.0), (-60.0, 60.0), 0.5)
    actors = Actors(lanes, walks, 11)
    h = hashlib.blake2b(digest_size=8)
    for t in (0.0, 2.5, 13.0, 47.0):
        actors.advance(t)
        h.update(
            repr(
                [(p.kind, p.centre_ne, p.yaw_rad, p.base_height_m, p.colour) for p in actors.poses()]
            ).encode()
        )
        h.update(actors.people_at(t + 1.5).tobytes())
        actors.stamp(grid)
        h.update(grid.digest().encode())
        actors.unstamp(grid)
    h.update(actors.envelope(grid).tobytes())
    return h.hexdigest()


def test_flat_actors_are_placed_as_before_relief() -> None:
    lanes = (
        Lane(((-50.0, -40.0), (0.0, 0.0), (30.0, 45.0)), (6.0, 11.0), 8.0, 0.0),
        Lane(((40.0, -50.0), (40.0, 50.0)), (9.0, 14.0), 5.0, 9.5),
    )
    walks = (
        Walkway(((-20.0, 5.0), (-5.0, 20.0), (10.0, 22.0)), 6, 0.15, 2.5),
        Walkway(((12.0, -30.0),), 2, 30.0, 2.0),
    )
    # poses, people, stamped grids and envelope from the code before lanes and walkways had heights_m
    assert _fingerprint(lanes, walks) == "18e1ed4d0b31f063"
    # a sloped path whose heights are all one value places its actors on that value, like a level one
    same = tuple(
        Lane(ln.points_ne, ln.speed_m_s, ln.arrivals_per_min, 0.0, (ln.deck_height_m,) * len(ln.points_ne))
        for ln in lanes
    )
    a, b = Actors(lanes, walks, 2), Actors(same, walks, 2)
    a.advance(9.0)
    b.advance(9.0)
    assert [p.base_height_m for p in a.poses()] == [p.base_height_m for p in b.poses()]
    assert math.isclose(sum(p.centre_ne[0] for p in a.poses()), sum(p.centre_ne[0] for p in b.poses()))
