"""The procedural suburb: determinism, what it holds, how steep its roofs are, who walks where, that the
sensors render it and that the grader reads it as a suburb (roofs unsafe, the sports field safe)."""

from __future__ import annotations

import itertools
import math
import re

import numpy as np
import pytest

from simbridge.world.city_parts import CityError
from simbridge.world.grader import grade
from simbridge.world.live import LiveWorld
from simbridge.world.model import Material, SurfaceClass
from simbridge.world.suburb import generate_suburb
from simbridge.world.world import World

SMALL_M = 400.0


@pytest.fixture(scope="module")
def suburb() -> World:
    return generate_suburb(0, size_m=SMALL_M)


def _shares(world: World) -> np.ndarray:
    return np.bincount(world.grid.cls.ravel(), minlength=len(SurfaceClass)) / world.grid.cls.size


def _samples(points: tuple[tuple[float, float], ...], step_m: float = 1.0) -> np.ndarray:
    """(k, 2) points every ``step_m`` metres along a polyline."""
    out = []
    for (n1, e1), (n2, e2) in itertools.pairwise(points):
        f = np.linspace(0.0, 1.0, max(2, math.ceil(math.hypot(n2 - n1, e2 - e1) / step_m) + 1))
        out.append(np.stack([n1 + f * (n2 - n1), e1 + f * (e2 - e1)], axis=1))
    return np.concatenate(out)


def test_suburb_is_deterministic(suburb: World) -> None:
    again = generate_suburb(0, size_m=SMALL_M)
    assert again.grid.digest() == suburb.grid.digest()
    assert again.lanes == suburb.lanes
    assert again.walkways == suburb.walkways
    assert again.sun == suburb.sun
    other = generate_suburb(1, size_m=SMALL_M)
    assert other.grid.digest() != suburb.grid.digest()


@pytest.mark.parametrize(
    ("seed", "size_m"), [(-1, 400.0), (1.5, 400.0), (True, 400.0), ("3", 400.0), (0, 299.0)]
)
def test_suburb_rejects_bad_requests(seed: object, size_m: float) -> None:
    with pytest.raises(CityError):
        generate_suburb(seed, size_m=size_m)  # type: ignore[arg-type]


def test_suburb_world_fields(suburb: World) -> None:
    assert suburb.name == "suburb"
    assert suburb.seed == 0
    assert suburb.launch_ne_m == (0.0, 0.0)
    assert suburb.launch_height_m == 100.0
    assert suburb.grid.extent_m == pytest.approx((-200.0, 200.0, -200.0, 200.0))
    assert 90.0 <= suburb.sun.azimuth_deg <= 270.0
    assert 35.0 <= suburb.sun.elevation_deg <= 65.0
    assert "suburb" in suburb.description


def test_suburb_composition(suburb: World) -> None:
    s = _shares(suburb)
    g = suburb.grid
    assert s[SurfaceClass.GRASS] > 0.4
    assert 0.01 < s[SurfaceClass.ROOF_PITCHED] < 0.2
    assert 0.02 < s[SurfaceClass.ROAD] < 0.2
    assert s[SurfaceClass.TREE] > 0.005
    assert s[SurfaceClass.VEHICLE] > 0.001
    assert s[SurfaceClass.SIDEWALK] > 0.002
    assert s[SurfaceClass.UNKNOWN] == 0
    assert s[SurfaceClass.PEDESTRIAN] == 0
    assert s[SurfaceClass.HIGHWAY] == 0
    assert s[SurfaceClass.PARKING_ROOF] == 0
    # flat roofs: garden sheds (a few square metres each) and the school alone
    flat = g.cls == SurfaceClass.ROOF_FLAT
    areas = np.bincount(g.region[flat]) * g.res**2
    assert int((areas > 12.0).sum()) <= 1
    assert s[SurfaceClass.ROOF_FLAT] < 0.02
    # pools: sunk 0.3-1 m, water class
    pool = g.mat == Material.POOL
    assert pool.sum() * g.res**2 > 20.0
    assert (g.cls[pool] == SurfaceClass.WATER).all()
    assert g.height[pool].min() >= -1.0 - 1e-6
    assert g.height[pool].max() <= -0.3 + 1e-6
    roof_mats = set(np.unique(g.mat[g.cls == SurfaceClass.ROOF_PITCHED]).tolist())
    assert len(roof_mats & {int(m) for m in (Material.TILES, Material.SHINGLE, Material.SLATE)}) >= 2
    assert Material.LANE_MARKING in set(np.unique(g.mat[g.cls == SurfaceClass.ROAD]).tolist())
    # near the launch point: lawns, roofs and streets
    i, j = np.ogrid[: g.shape[0], : g.shape[1]]
    n, e = g.n0 + (i + 0.5) * g.res, g.e0 + (j + 0.5) * g.res
    near = g.cls[n**2 + e**2 <= 150.0**2]
    for cls in (SurfaceClass.GRASS, SurfaceClass.ROOF_PITCHED, SurfaceClass.ROAD):
        assert (near == cls).mean() > 0.01, cls.name


def test_suburb_pitched_roofs_are_steep(suburb: World) -> None:
    """Every pitched roof (houses, wings, sheds): the median slope of its inner cells is over 20 degrees."""
    g = suburb.grid
    dn, de = np.gradient(g.height.astype(np.float64), g.res)
    slope = np.degrees(np.arctan(np.hypot(dn, de)))
    pitched = g.cls == SurfaceClass.ROOF_PITCHED
    inner = pitched.copy()
    for axis, shift in ((0, 1), (0, -1), (1, 1), (1, -1)):  # the cell and its four neighbours on one roof
        inner &= np.roll(pitched, shift, axis) & (np.roll(g.region, shift, axis) == g.region)
    rid, sl = g.region[inner], slope[inner]
    order = np.argsort(rid, kind="stable")
    rid, sl = rid[order], sl[order]
    ids, starts = np.unique(rid, return_index=True)
    assert len(ids) >= 20
    assert (ids > 0).all()
    medians = np.array([np.median(part) for part in np.split(sl, starts[1:])])
    assert medians.min() > 20.0, ids[medians.argmin()]
    assert np.unique(g.region[pitched]).size == len(ids)  # no roof too small to measure


def test_suburb_people_walk_on_open_ground(suburb: World) -> None:
    g = suburb.grid
    on_grass = 0
    for w in suburb.walkways:
        pts = _samples(w.points_ne)
        assert (np.abs(pts) < SMALL_M / 2).all()
        cls = np.array([g.class_at(float(n), float(e)) for n, e in pts])
        on_grass += int((cls == SurfaceClass.GRASS).mean() > 0.5)
    assert on_grass >= 3
    assert any(w.surface_height_m == 0.0 for w in suburb.walkways)
    assert any(w.surface_height_m > 0.1 for w in suburb.walkways)  # and on the sidewalks
    assert suburb.lanes
    for lane in suburb.lanes:
        pts = np.asarray(lane.points_ne)
        assert (np.abs(pts) < SMALL_M / 2).all()
        assert 6.0 <= lane.speed_m_s[0] <= lane.speed_m_s[1] <= 12.0
        cls = np.array([g.class_at(float(n), float(e)) for n, e in pts[::5]])
        assert (cls == SurfaceClass.ROAD).mean() > 0.9


def test_suburb_grader_reads_roofs_and_the_field(suburb: World) -> None:
    g = suburb.grid
    found = re.search(r"sports field at (-?\d+) N (-?\d+) E", suburb.description)
    assert found is not None
    field = grade(g, float(found.group(1)), float(found.group(2)))
    assert field.safe, field.reasons
    assert field.surface == "park"
    rows, cols = np.nonzero(g.cls == SurfaceClass.ROOF_PITCHED)
    pick = np.random.default_rng(0).choice(len(rows), 40, replace=False)
    slopes = 0
    for k in pick:
        gr = grade(g, g.n0 + (rows[k] + 0.5) * g.res, g.e0 + (cols[k] + 0.5) * g.res)
        assert not gr.safe
        slopes += any(r.startswith("slope") for r in gr.reasons)
    assert slopes >= 25


def test_suburb_renders() -> None:
    """The camera sees a varied picture from 100 m over the launch point and the LiDAR gets returns
    (a world of its own: LiveWorld stamps actors into the grid)."""
    world = generate_suburb(2, size_m=SMALL_M)
    live = LiveWorld(world, actor_seed=0)
    pose = ((0.0, 0.0, -100.0), (1.0, 0.0, 0.0, 0.0), 0.0)
    frame = live.camera_frame(*pose, "clear", np.random.default_rng(0))
    rgb = np.asarray(frame.rgb)
    assert rgb.ndim == 3
    assert rgb.shape[2] == 3
    assert rgb.std() > 5.0
    points = np.asarray(live.lidar_sweep(*pose, np.random.default_rng(0)))
    assert points.size > 0
