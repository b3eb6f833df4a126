"""The procedural town (simbridge/world/town.py) and the paste it is built with (simbridge/world/paste.py):
the plan keeps the launch point downtown, every district kind is there, the arterials are unbroken road
bands with nothing cut in half beside them, routes stay on their surfaces and in their districts, and the
camera renders it."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from simbridge.world.city_parts import CityError
from simbridge.world.live import LiveWorld
from simbridge.world.model import SurfaceClass, WorldError, WorldGrid
from simbridge.world.paste import Box, clip_polyline, paste_world
from simbridge.world.places import generate_place
from simbridge.world.town import District, TownPlan, generate_town, plan_town
from simbridge.world.town_roads import CARRIAGEWAY_M, SIDEWALK_M, Seam, seam_band_mask
from simbridge.world.world import Lane, SafeZone, Walkway, Wire, World
from tests.test_suburb import _samples

SMALL_M = 600.0
ON_ROAD = (SurfaceClass.ROAD, SurfaceClass.CROSSWALK)
WALKABLE = (
    SurfaceClass.SIDEWALK, SurfaceClass.CROSSWALK, SurfaceClass.GRASS, SurfaceClass.GROUND,
    SurfaceClass.PARKING_LOT, SurfaceClass.ROOF_FLAT, SurfaceClass.PARKING_ROOF, SurfaceClass.PIER,
    SurfaceClass.VEHICLE, SurfaceClass.TREE,  # between the parked cars of a car park, under a park's trees
)  # fmt: skip


@pytest.fixture(scope="module")
def town() -> World:
    """Seed 0 at full size (1.2 km at 0.2 m), built once: its build time shows in ``--durations``."""
    return generate_place("town", 0)


@pytest.fixture(scope="module")
def plan() -> TownPlan:
    return plan_town(0)


def _classes(world: World, pts: np.ndarray) -> np.ndarray:
    g = world.grid
    i = np.floor((pts[:, 0] - g.n0) / g.res).astype(int)
    j = np.floor((pts[:, 1] - g.e0) / g.res).astype(int)
    cls: np.ndarray = g.cls[i, j]
    return cls


def _inner(d: District, plan: TownPlan) -> tuple[slice, slice]:
    """The cells of a district's area less the arterials' bands."""
    pad = plan.seams[0].band_half_m
    half = plan.size_m / 2

    def edge(x: float, centre: float) -> float:
        return x if abs(abs(x) - half) < 1e-9 else x + math.copysign(pad, centre - x)

    c_n, c_e = d.area.centre_ne
    n_lo, n_hi = sorted((edge(d.area.n_lo, c_n), edge(d.area.n_hi, c_n)))
    e_lo, e_hi = sorted((edge(d.area.e_lo, c_e), edge(d.area.e_hi, c_e)))
    rows = slice(round((n_lo + half) / 0.2), round((n_hi + half) / 0.2))
    cols = slice(round((e_lo + half) / 0.2), round((e_hi + half) / 0.2))
    return rows, cols


# ---------------------------------------------------------------------------------------------- the plan
def test_town_plan_keeps_the_launch_point_in_the_downtown_core() -> None:
    for seed in range(30):
        p = plan_town(seed)
        assert sorted(d.kind for d in p.districts) == ["downtown", "industrial", "suburb", "suburb"]
        assert sum(d.area.size_ne[0] * d.area.size_ne[1] for d in p.districts) == pytest.approx(1200.0**2)
        here = p.district_at(0.0, 0.0)
        assert here is not None
        assert here.kind == "downtown"
        for c in p.crossroads_ne:
            assert 60.0 <= abs(c) <= 150.0  # the launch point is this far from either arterial
        assert all(12.0 <= s.band_half_m <= 15.0 for s in p.seams)
        assert min(min(d.area.size_ne) for d in p.districts) >= 300.0
        assert len({d.seed for d in p.districts}) == 4
    assert plan_town(3) == plan_town(3)
    assert {plan_town(s).districts[0].area for s in range(8)} != {plan_town(0).districts[0].area}


def test_town_is_deterministic() -> None:
    a, b, c = generate_town(0, SMALL_M), generate_town(0, SMALL_M), generate_town(1, SMALL_M)
    assert a.digest() == b.digest()
    assert (a.lanes, a.walkways, a.sun) == (b.lanes, b.walkways, b.sun)
    assert np.array_equal(a.grid.mat, b.grid.mat)
    assert np.array_equal(a.grid.region, b.grid.region)
    assert c.digest() != a.digest()


@pytest.mark.parametrize(("seed", "size_m"), [(-1, 600.0), (1.5, 600.0), (True, 600.0), (0, 599.0)])
def test_town_rejects_bad_requests(seed: object, size_m: float) -> None:
    with pytest.raises(CityError):
        generate_town(seed, size_m)  # type: ignore[arg-type]


# ---------------------------------------------------------------------------------------------- the town
def test_town_world_fields(town: World, plan: TownPlan) -> None:
    assert town.name == "town"
    assert town.seed == 0
    assert town.launch_ne_m == (0.0, 0.0)
    assert town.launch_height_m == 100.0
    assert town.grid.extent_m == pytest.approx((-600.0, 600.0, -600.0, 600.0))
    assert town.grid.shape == (6000, 6000)
    assert "downtown" in town.description
    assert "industrial" in town.description
    assert town.grid.cls.max() < len(SurfaceClass)
    assert (town.grid.cls != SurfaceClass.UNKNOWN).all()


def test_town_holds_each_district_kind(town: World, plan: TownPlan) -> None:
    g = town.grid
    ids: list[set[int]] = []
    for d in plan.districts:
        win = _inner(d, plan)
        cls = g.cls[win]
        share = np.bincount(cls.ravel(), minlength=len(SurfaceClass)) / cls.size
        ids.append(set(np.unique(g.region[win]).tolist()) - {0})
        if d.kind == "downtown":
            assert share[SurfaceClass.ROOF_FLAT] > 0.05, d
            assert share[SurfaceClass.ROOF_CLUTTER] > 0.005, d
            assert share[SurfaceClass.PARAPET] > 0.002, d
            assert share[SurfaceClass.RAIL] == 0.0
        elif d.kind == "suburb":
            assert share[SurfaceClass.ROOF_PITCHED] > 0.01, d
            assert share[SurfaceClass.GRASS] > 0.4, d
            assert share[SurfaceClass.ROOF_FLAT] < 0.02, d
            assert share[SurfaceClass.RAIL] == 0.0
        else:
            assert share[SurfaceClass.RAIL] > 0.001, d
            assert share[SurfaceClass.MACHINERY] > 0.002, d
            assert share[SurfaceClass.ROOF_FLAT] > 0.05, d
            assert share[SurfaceClass.ROOF_PITCHED] == 0.0
    for a, b in itertools.combinations(ids, 2):
        assert not a & b  # every district's buildings keep ids of their own
    # the launch point: downtown, 100 m above its ground
    assert plan.district_at(0.0, 0.0) == plan.districts[0]


def test_town_arterials_are_unbroken_road_bands(town: World, plan: TownPlan) -> None:
    g = town.grid
    band = seam_band_mask(g, plan.seams)
    cw = CARRIAGEWAY_M / 2
    for seam in plan.seams:
        along = np.arange(seam.lo + 0.1, seam.hi, 0.2)
        for across, allowed in (
            (0.1, ON_ROAD), (cw - 0.3, ON_ROAD), (-(cw - 0.3), ON_ROAD), (-2.0, ON_ROAD),
            (cw + SIDEWALK_M / 2, (SurfaceClass.SIDEWALK, SurfaceClass.CROSSWALK)),
            (-(cw + SIDEWALK_M / 2), (SurfaceClass.SIDEWALK, SurfaceClass.CROSSWALK)),
        ):  # fmt: skip
            pts = np.array([seam.point(float(a), across) for a in along])
            cls = _classes(town, pts)
            assert np.isin(cls, allowed).all(), (seam, across, np.unique(cls))
    assert (g.height[band] <= 0.15 + 1e-6).all()  # nothing stands in the band
    assert set(np.unique(g.cls[band]).tolist()) <= {
        int(c) for c in (*ON_ROAD, SurfaceClass.SIDEWALK, SurfaceClass.GRASS)
    }
    assert (g.cls[band] == SurfaceClass.ROAD).mean() > 0.4


def test_town_leaves_nothing_cut_in_half_beside_the_arterials(town: World, plan: TownPlan) -> None:
    g = town.grid
    band = seam_band_mask(g, plan.seams)
    assert np.unique(g.region[band]).tolist() == [0]  # no building reaches into the band...
    edge = seam_band_mask(g, plan.seams, g.res) & ~band
    assert np.unique(g.region[edge]).tolist() == [0]  # ...nor stands flush against it, as if cut
    near = seam_band_mask(g, plan.seams, 6.0) & ~band
    assert not (g.cls[near] == SurfaceClass.TREE).any()


def test_town_streets_meet_the_arterials(town: World, plan: TownPlan) -> None:
    """Where a district's street reaches the band its mouth crosses the verge (road) and the sidewalk (a
    zebra) to the carriageway: a line across the band there is road or crossing all the way."""
    mouths = 0
    for seam in plan.seams:
        outer = seam.band_half_m - 0.5
        for side in (1.0, -1.0):
            along = np.arange(seam.lo + 30.0, seam.hi - 30.0, 0.2)
            pts = np.array([seam.point(float(a), side * outer) for a in along])
            at_road = np.isin(_classes(town, pts), ON_ROAD)
            at_road &= np.abs(along - plan.crossroads_ne[1 if seam.axis == "ew" else 0]) > 40.0
            for k in np.flatnonzero(at_road)[::10]:
                across = np.arange(0.0, seam.band_half_m + 2.0, 0.2) * side
                line = np.array([seam.point(float(along[k]), float(x)) for x in across])
                cls = _classes(town, line)
                assert np.isin(cls[: int(seam.band_half_m / 0.2)], ON_ROAD).all()
            mouths += int(np.count_nonzero(np.diff(at_road.astype(np.int8)) == 1))
    assert mouths >= 8


def test_town_routes_stay_on_their_surfaces_and_in_their_districts(town: World, plan: TownPlan) -> None:
    g = town.grid
    band = seam_band_mask(g, plan.seams)
    assert len(town.lanes) > 50
    assert len(town.walkways) > 50
    rng = np.random.default_rng(0)
    arterial_lanes = 0
    routes: list[Lane | Walkway] = [*town.lanes, *town.walkways]
    for route in routes:
        pts = _samples(route.points_ne)
        assert (np.abs(pts) < 600.0).all()
        i = np.floor((pts[:, 0] - g.n0) / g.res).astype(int)
        j = np.floor((pts[:, 1] - g.e0) / g.res).astype(int)
        in_band = band[i, j]
        if in_band.all():  # an arterial's own
            arterial_lanes += isinstance(route, Lane)
            continue
        assert not in_band.any(), route  # a district's: cut where the band begins
        homes = {plan.district_at(float(n), float(e)) for n, e in pts}
        assert len(homes) == 1, route
    assert arterial_lanes == 4 * len(plan.seams)
    lanes = [town.lanes[k] for k in rng.choice(len(town.lanes), 40, replace=False)]
    for lane in lanes:
        cls = _classes(town, _samples(lane.points_ne, 2.0))
        surface = (SurfaceClass.HIGHWAY,) if lane.deck_height_m > 0 else ON_ROAD
        assert np.isin(cls, surface).mean() > 0.9, lane
    walks = [town.walkways[k] for k in rng.choice(len(town.walkways), 40, replace=False)]
    for walk in walks:
        cls = _classes(town, _samples(walk.points_ne))
        assert np.isin(cls, WALKABLE).mean() > 0.8, (walk, np.unique(cls))


def test_town_renders_from_over_the_launch_point() -> None:
    """A camera frame from 100 m over the launch point (a town of its own: LiveWorld stamps actors)."""
    world = generate_town(2, SMALL_M)
    live = LiveWorld(world, actor_seed=0)
    frame = live.camera_frame(
        (0.0, 0.0, -100.0), (1.0, 0.0, 0.0, 0.0), 0.0, "clear", np.random.default_rng(0)
    )
    rgb = np.asarray(frame.rgb)
    assert rgb.ndim == 3
    assert rgb.shape[2] == 3
    assert rgb.std() > 5.0


# ---------------------------------------------------------------------------------------------- the paste
def _source() -> World:
    g = WorldGrid.empty((-10.0, 10.0), (-10.0, 10.0), 0.2)
    g.fill_rect((0.0, 0.0), 4.0, 4.0, height_m=5.0, cls=SurfaceClass.ROOF_FLAT, region=3)
    lane = Lane(((-9.0, 0.0), (9.0, 0.0)))
    loop = Walkway(((-9.0, -8.0), (9.0, -8.0), (9.0, 8.0), (-9.0, 8.0)))  # leaves the keep box and returns
    wire = Wire(((0.0, -9.0, 8.0), (0.0, 9.0, 10.0)))
    zones = (SafeZone((5.0, 5.0), 2.0, 2.0), SafeZone((-5.0, -5.0), 2.0, 2.0))
    return World("src", 0, g, lanes=(lane,), walkways=(loop,), wires=(wire,), safe_zones=zones)


def test_paste_world_moves_rasters_and_cuts_routes_to_the_box() -> None:
    target = WorldGrid.empty((-50.0, 50.0), (-50.0, 50.0), 0.2)
    keep = Box(20.0, 40.0, -20.0, -5.0)  # the source's east part (east of -5 once moved) is left out
    got = paste_world(target, _source(), (30.0, -10.0), keep, region_base=10)
    assert target.height_at(30.0, -10.0) == 5.0
    assert target.region[target.index(30.0, -10.0)] == 13
    assert got.next_region == 14
    assert target.class_at(30.0, -4.0) == SurfaceClass.GROUND  # beyond the box: untouched
    assert target.height_at(30.0, -4.0) == 0.0
    assert got.window == (350, 450, 150, 225)
    (lane,) = got.lanes
    assert lane.points_ne == ((21.0, -10.0), (39.0, -10.0))
    (walk,) = got.walkways
    assert walk.points_ne == ((21.0, -18.0), (39.0, -18.0), (39.0, -5.0))
    (wire,) = got.wires
    assert wire.points_neh[0] == (30.0, -19.0, 8.0)
    assert wire.points_neh[-1] == pytest.approx((30.0, -5.0, 8.0 + 2.0 * 14.0 / 18.0))
    assert [z.centre_ne for z in got.safe_zones] == [(25.0, -15.0)]


def test_paste_world_refuses_misaligned_or_foreign_grids() -> None:
    target = WorldGrid.empty((-50.0, 50.0), (-50.0, 50.0), 0.2)
    with pytest.raises(WorldError, match="whole number"):
        paste_world(target, _source(), (0.1, 0.0))
    coarse = WorldGrid.empty((-50.0, 50.0), (-50.0, 50.0), 0.5)
    with pytest.raises(WorldError, match="one resolution"):
        paste_world(coarse, _source(), (0.0, 0.0))
    with pytest.raises(WorldError, match="keeps nothing"):
        paste_world(target, _source(), (0.0, 0.0), Box(30.0, 40.0, 30.0, 40.0))


def test_clip_polyline_splits_a_route_that_leaves_and_returns() -> None:
    box = Box(0.0, 10.0, 0.0, 10.0)
    pieces = clip_polyline([(5.0, -5.0), (5.0, 5.0), (15.0, 5.0), (5.0, 8.0)], box)
    assert pieces == [((5.0, 0.0), (5.0, 5.0), (10.0, 5.0)), ((10.0, 6.5), (5.0, 8.0))]
    assert clip_polyline([(20.0, 20.0), (30.0, 30.0)], box) == []
    assert clip_polyline([(1.0, 1.0), (2.0, 1.0)], box, min_length_m=5.0) == []
    ((start, end),) = clip_polyline([(1.0, 1.0, 3.0), (1.0, 20.0, 13.0)], box)  # a wire's height, cut
    assert start == (1.0, 1.0, 3.0)
    assert end == pytest.approx((1.0, 10.0, 3.0 + 10.0 * 9.0 / 19.0))
    assert Seam("ns", 5.0, 0.0, 10.0, 12.0).point(2.0, 1.0) == (2.0, 6.0)
