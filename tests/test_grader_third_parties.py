"""The grader's rules for third parties (simbridge/world/grader.py): no person within 10 m of a touchdown
(from the actors' own positions), no vehicle or machinery within 5 m, never on a swimming pool or
standing crops, never within 5 m of the line under an overhead wire; a roof high above the street is
not "near" the cars and people down there."""

from __future__ import annotations

import numpy as np
import pytest

from simbridge.world.grader import GraderConfig, grade
from simbridge.world.model import Material, SurfaceClass, WorldGrid
from simbridge.world.world import Wire, World


def _field() -> WorldGrid:
    """A 60 m square lawn; a car 1.5 m tall whose nearest side is 4 m east of the origin (its nearest
    cell's centre 4.05 m); a pool and a crop field to the north; a 20 m tall building to the south-west."""
    g = WorldGrid.empty((-30.0, 30.0), (-30.0, 30.0), 0.1, SurfaceClass.GRASS, Material.GRASS)
    g.fill_rect((0.0, 5.0), 4.0, 2.0, height_m=1.5, cls=SurfaceClass.VEHICLE, mat=Material.CAR_PAINT)
    g.fill_rect((20.0, -10.0), 6.0, 4.0, height_m=-1.5, cls=SurfaceClass.WATER, mat=Material.POOL)
    g.fill_rect((20.0, 15.0), 10.0, 10.0, height_m=0.0, cls=SurfaceClass.CROP, mat=Material.CROP)
    g.fill_rect((-20.0, -20.0), 16.0, 16.0, height_m=20.0, cls=SurfaceClass.ROOF_FLAT, mat=Material.GRAVEL)
    return g


@pytest.mark.parametrize(
    ("point", "safe", "surface", "reason"),
    [
        ((0.0, 0.0), False, "park", "vehicle within 4.1 m"),
        ((0.0, -2.0), True, "park", None),  # 6 m from the car's side
        ((20.0, -10.0), False, "pool", "landed on a swimming pool"),
        ((20.0, 15.0), False, "crops", "landed on crop"),
        # 20 m above the lawn, 3 m in from the roof's edge and 9 m across from the car's corner
        ((-15.0, -15.0), True, "rooftop_clear", None),
    ],
)
def test_vehicles_pools_and_crops(
    point: tuple[float, float], safe: bool, surface: str, reason: str | None
) -> None:
    verdict = grade(_field(), *point)
    assert (verdict.safe, verdict.surface) == (safe, surface), verdict.reasons
    if reason is None:
        assert verdict.reasons == ()
    else:
        assert any(reason in r for r in verdict.reasons), verdict.reasons


def test_a_person_within_ten_metres_makes_a_touchdown_unsafe() -> None:
    g = _field()
    at = (0.0, -10.0)
    for feet, safe in (((9.0, -10.0, 0.0), False), ((0.0, -20.5, 0.0), True), ((6.0, -18.5, 0.0), True)):
        verdict = grade(g, *at, people=np.array([feet]))
        assert verdict.safe is safe, (feet, verdict.reasons)
    near = grade(g, *at, people=np.array([[9.0, -10.0, 0.0], [0.0, -20.5, 0.0]]))
    assert any("person 9.0 m away (at least 10 m)" in r for r in near.reasons), near.reasons
    assert grade(g, *at, people=np.zeros((0, 3))).safe
    # on the roof, 20 m up: a person on the lawn 6 m across from the touchdown point is 21 m away
    assert grade(g, -15.0, -15.0, people=np.array([[-15.0, -9.0, 0.0]])).safe
    # a rule of 2 m instead of 10 (the config says how far)
    assert grade(g, *at, GraderConfig(person_m=2.0), people=np.array([[9.0, -10.0, 0.0]])).safe


def test_the_line_under_an_overhead_wire_is_kept_five_metres_away() -> None:
    g = _field()
    wire = Wire(((-30.0, -25.0, 9.0), (0.0, -25.0, 10.0), (30.0, -25.0, 9.0)))
    assert wire.ground_gap_m(0.0, -21.0) == pytest.approx(4.0)
    assert wire.ground_gap_m(40.0, -25.0) == pytest.approx(10.0)  # beyond the last pole
    under = grade(g, 0.0, -21.0, wires=(wire,))
    assert not under.safe
    assert any("4.0 m from the line under an overhead wire" in r for r in under.reasons), under.reasons
    assert grade(g, 0.0, -19.0, wires=(wire,)).safe


def test_wires_change_the_world_digest_and_none_leave_it_as_the_grid_says() -> None:
    g = _field()
    bare = World(name="w", seed=0, grid=g)
    wired = World(name="w", seed=0, grid=g, wires=(Wire(((0.0, 0.0, 9.0), (10.0, 0.0, 9.0))),))
    assert bare.digest() == g.digest()
    assert wired.digest() != bare.digest()
    assert len(wired.digest()) == len(bare.digest())
