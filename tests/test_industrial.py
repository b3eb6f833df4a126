"""The industrial estate (simbridge/world/industrial.py, ``--place industrial``): deterministic per seed,
its own plan (spines and staggered access roads, a railway), what stands in it, how the grader reads
its new surfaces, and that the sensors render it."""

from __future__ import annotations

import numpy as np
import pytest

from simbridge.world.city_parts import CityError
from simbridge.world.grader import grade
from simbridge.world.industrial import generate_industrial
from simbridge.world.live import LiveWorld
from simbridge.world.model import Material, SurfaceClass
from simbridge.world.places import generate_place
from simbridge.world.world import World

SIZE_M = 400.0


@pytest.fixture(scope="module")
def estate() -> World:
    return generate_industrial(3, SIZE_M)


def _share(w: World, cls: SurfaceClass) -> float:
    return float((w.grid.cls == int(cls)).mean())


def _cell_of(w: World, cls: SurfaceClass, pick: int = 0, around_m: float = 5.0) -> tuple[float, float]:
    """The centre (north, east) of a cell of ``cls`` with ``around_m`` of ``cls`` on every side."""
    g = w.grid
    mask = g.cls == int(cls)
    k = int(around_m / g.res)
    inner = (
        mask[k:-k, k:-k]
        & mask[2 * k :, k:-k]
        & mask[: -2 * k, k:-k]
        & mask[k:-k, 2 * k :]
        & mask[k:-k, : -2 * k]
    )
    rows, cols = np.nonzero(inner)
    assert rows.size, f"no {cls.name} cell with {around_m} m of the same around it"
    i, j = rows[pick % rows.size] + k, cols[pick % rows.size] + k
    n, e = g.cell_centres(i, i + 1, j, j + 1)
    return float(n.ravel()[0]), float(e.ravel()[0])


def test_a_seed_is_one_estate_and_bad_requests_are_refused(estate: World) -> None:
    again = generate_industrial(3, SIZE_M)
    assert again.grid.digest() == estate.grid.digest()
    assert again.lanes == estate.lanes
    assert again.walkways == estate.walkways
    assert generate_industrial(4, SIZE_M).grid.digest() != estate.grid.digest()
    assert estate.name == "industrial"
    with pytest.raises(CityError, match="non-negative"):
        generate_industrial(-1)
    with pytest.raises(CityError, match="at least 300 m"):
        generate_industrial(0, 200.0)


def test_big_flat_roofs_yards_car_parks_and_a_railway(estate: World) -> None:
    assert _share(estate, SurfaceClass.ROOF_FLAT) > 0.12  # the sheds' roofs
    assert _share(estate, SurfaceClass.ROOF_PITCHED) == 0.0
    assert _share(estate, SurfaceClass.ROOF_CLUTTER) > 0.005  # skylights, HVAC, solar arrays
    assert _share(estate, SurfaceClass.PARKING_LOT) > 0.03
    assert _share(estate, SurfaceClass.GROUND) > 0.1  # the yards' concrete
    assert _share(estate, SurfaceClass.MACHINERY) > 0.0  # containers, stacked material
    assert _share(estate, SurfaceClass.VEHICLE) > 0.0  # lorries and parked cars
    rail = estate.grid.cls == int(SurfaceClass.RAIL)
    cols = np.nonzero(rail.any(axis=0))[0]
    assert rail.any(axis=1).all()  # the railway crosses the estate from north to south
    assert cols.size * estate.grid.res < 15.0  # on its own corridor
    assert (estate.grid.mat[rail] == int(Material.METAL)).any()  # rails on the ballast
    assert "clear roofs" in estate.description
    half = SIZE_M / 2
    for path in [*(lane.points_ne for lane in estate.lanes), *(w.points_ne for w in estate.walkways)]:
        assert all(abs(n) < half and abs(e) < half for n, e in path)
    # workers cross yards and car parks, not only footpaths
    assert any(w.surface_height_m == 0.0 for w in estate.walkways)


def test_the_access_roads_end_at_the_spines_instead_of_crossing_the_estate(estate: World) -> None:
    """Downtown's streets cross the whole city; here only the north-south spines do."""
    road = estate.grid.cls == int(SurfaceClass.ROAD)
    full_rows = int(road.all(axis=1).sum())
    full_cols = int(road.all(axis=0).sum())
    assert full_cols > 0  # the spines (interrupted only by the level crossings' rails... or not at all)
    assert full_rows == 0  # no east-west road runs from edge to edge


def test_the_grader_refuses_rail_and_machinery_and_passes_a_bare_roof(estate: World) -> None:
    g = grade(estate.grid, *_cell_of(estate, SurfaceClass.RAIL, around_m=0.4))
    assert not g.safe
    assert g.surface == "rail"
    machinery = estate.grid.cls == int(SurfaceClass.MACHINERY)
    i, j = (int(v[0]) for v in np.nonzero(machinery))
    n, e = estate.grid.cell_centres(i, i + 1, j, j + 1)
    g = grade(estate.grid, float(n.ravel()[0]), float(e.ravel()[0]))
    assert not g.safe
    assert g.surface == "machinery"
    roofs = generate_industrial(0, 1200.0)  # clear roofs are a quarter of them: the full estate has some
    flat = roofs.grid.cls == int(SurfaceClass.ROOF_FLAT)
    assert flat.any()
    safe = [grade(roofs.grid, *_cell_of(roofs, SurfaceClass.ROOF_FLAT, k)) for k in range(0, 40_000, 4_000)]
    assert any(s.safe and s.surface == "rooftop_clear" for s in safe)


def test_it_renders_and_the_lidar_sees_it(estate: World) -> None:
    live = LiveWorld(estate, actor_seed=0)
    rng = np.random.default_rng(0)
    frame = live.camera_frame((0.0, 0.0, -100.0), (1.0, 0.0, 0.0, 0.0), 0.0, "clear", rng)
    assert frame.rgb.shape == (540, 960, 3)
    assert frame.rgb.std() > 10.0
    points = live.lidar_sweep((0.0, 0.0, -100.0), (1.0, 0.0, 0.0, 0.0), 0.0, rng)
    assert len(points) > 1000


def test_places_builds_it_by_name() -> None:
    assert generate_place("industrial", 0).name == "industrial"
