"""Declarative scenario files: the curated scenarios and the loader's validation and determinism."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from simbridge.world.model import Material, SurfaceClass, WorldGrid
from simbridge.world.scenario_file import (
    BUILTIN_SCENARIO_DIR,
    ScenarioFileError,
    ScenarioSpec,
    builtin_scenario_names,
    builtin_scenario_path,
    load_scenario_file,
    parse_scenario_file,
)
from simbridge.world.world import World

BUILTINS = ("scenario1", "scenario2")
CAMERA_HFOV_DEG, CAMERA_ASPECT = 90.0, 540 / 960


@pytest.fixture(scope="module")
def builtin_worlds() -> dict[str, tuple[ScenarioSpec, World]]:
    out = {}
    for name in BUILTINS:
        path = builtin_scenario_path(name)
        out[name] = (parse_scenario_file(path), load_scenario_file(path, seed=0))
    return out


def _region_of(spec: ScenarioSpec, building_id: str) -> int:
    """Buildings get region ids 1, 2, ... in file order."""
    return next(k + 1 for k, b in enumerate(spec.buildings) if b.id == building_id)


def _zone_cells(grid: WorldGrid, centre: tuple[float, float], size: tuple[float, float], yaw: float) -> tuple:
    got = grid.rect_mask(centre, size[0], size[1], yaw)
    assert got is not None
    (i0, i1, j0, j1), mask, _, _ = got
    return (
        grid.cls[i0:i1, j0:j1][mask],
        grid.height[i0:i1, j0:j1][mask],
        grid.region[i0:i1, j0:j1][mask],
        grid.mat[i0:i1, j0:j1][mask],
    )


# ------------------------------------------------------------------------------------------ built-ins
def test_builtin_scenario_names_lists_both_curated_scenarios() -> None:
    assert set(BUILTINS) <= set(builtin_scenario_names())
    assert all((BUILTIN_SCENARIO_DIR / f"{n}.toml").is_file() for n in BUILTINS)


def test_builtin_scenario_path_unknown_name_lists_known() -> None:
    with pytest.raises(ScenarioFileError, match=r"known: .*scenario1"):
        builtin_scenario_path("no_such_scenario")


@pytest.mark.parametrize("name", BUILTINS)
def test_load_scenario_file_builtin_builds_full_world(
    name: str, builtin_worlds: dict[str, tuple[ScenarioSpec, World]]
) -> None:
    spec, world = builtin_worlds[name]
    assert world.name == name
    assert world.grid.shape == (2500, 2500)  # 500 m x 500 m at 0.2 m
    assert world.grid.extent_m == pytest.approx((-250.0, 250.0, -250.0, 250.0))
    assert len(world.safe_zones) == 1
    assert len(world.lanes) >= 8
    assert len(world.walkways) >= 4
    assert all(5.0 <= lane.speed_m_s[0] <= lane.speed_m_s[1] <= 25.0 for lane in world.lanes)
    classes = set(np.unique(world.grid.cls).tolist())
    for cls in (SurfaceClass.ROOF_FLAT, SurfaceClass.ROAD, SurfaceClass.SIDEWALK, SurfaceClass.CROSSWALK,
                SurfaceClass.PARAPET, SurfaceClass.ROOF_CLUTTER, SurfaceClass.TREE):  # fmt: skip
        assert int(cls) in classes, cls.name
    # every building has its own region id
    assert int(world.grid.region.max()) == len(spec.buildings)


@pytest.mark.parametrize("name", BUILTINS)
def test_launch_builtin_is_above_origin_between_roofs(
    name: str, builtin_worlds: dict[str, tuple[ScenarioSpec, World]]
) -> None:
    spec, world = builtin_worlds[name]
    assert world.launch_ne_m == (0.0, 0.0)
    assert 100.0 <= world.launch_height_m <= 120.0
    grid = world.grid
    clear, cluttered = _region_of(spec, "clear_roof"), _region_of(spec, "cluttered_roof")
    ij = grid.index(0.0, 0.0)
    assert ij is not None
    assert int(grid.region[ij]) not in (clear, cluttered)
    assert grid.class_at(0.0, 0.0) is SurfaceClass.ROAD
    # the two roofs lie on either side of the origin (one west, one east)
    east_of = {}
    for rid in (clear, cluttered):
        cols = np.nonzero((grid.region == rid).any(axis=0))[0]
        east_of[rid] = (grid.e0 + cols.min() * grid.res, grid.e0 + (cols.max() + 1) * grid.res)
    assert east_of[clear][1] < 0.0 < east_of[cluttered][0]
    # and both are wholly in the launch camera's view (90 deg, 16:9, looking straight down)
    half_e = world.launch_height_m * math.tan(math.radians(CAMERA_HFOV_DEG / 2))
    half_n = half_e * CAMERA_ASPECT
    for rid in (clear, cluttered):
        rows, cols = np.nonzero(grid.region == rid)
        assert np.abs(grid.n0 + rows * grid.res).max() < half_n
        assert np.abs(grid.e0 + cols * grid.res).max() < half_e


@pytest.mark.parametrize("name", BUILTINS)
def test_safe_zone_builtin_is_clear_flat_roof(
    name: str, builtin_worlds: dict[str, tuple[ScenarioSpec, World]]
) -> None:
    spec, world = builtin_worlds[name]
    clear = _region_of(spec, "clear_roof")
    roof_h = spec.buildings[clear - 1].height_m
    zone = world.safe_zones[0]
    cls, height, region, mat = _zone_cells(
        world.grid, zone.centre_ne, (zone.length_m, zone.width_m), zone.yaw_rad
    )
    assert cls.size > 0.9 * zone.length_m * zone.width_m / world.grid.res**2
    assert np.all(cls == SurfaceClass.ROOF_FLAT)
    assert np.all(height == np.float32(roof_h))
    assert np.all(region == clear)
    assert not np.isin(mat, [Material.PAINT_TEXT, Material.METAL, Material.RUBBLE]).any()
    # the zone is the roof inset by ~2 m: parapet just outside it, nothing else on the roof
    roof = world.grid.region == clear
    roof_classes = set(np.unique(world.grid.cls[roof]).tolist())
    assert roof_classes == {int(SurfaceClass.ROOF_FLAT), int(SurfaceClass.PARAPET)}
    b = spec.buildings[clear - 1]
    assert zone.length_m == pytest.approx(b.size[0] - 4.0)
    assert zone.width_m == pytest.approx(b.size[1] - 4.0)


@pytest.mark.parametrize("name", BUILTINS)
def test_cluttered_roof_builtin_holds_clutter_above_roof(
    name: str, builtin_worlds: dict[str, tuple[ScenarioSpec, World]]
) -> None:
    spec, world = builtin_worlds[name]
    grid = world.grid
    rid = _region_of(spec, "cluttered_roof")
    roof_h = spec.buildings[rid - 1].height_m
    on_roof = grid.region == rid
    clutter = on_roof & (grid.cls == SurfaceClass.ROOF_CLUTTER)
    assert clutter.sum() * grid.res**2 > 40.0  # m^2 of HVAC, vents, pipes, ...
    assert np.all(grid.height[clutter] > roof_h)
    # no clear 10 m disc anywhere on it
    flat = on_roof & (grid.cls == SurfaceClass.ROOF_FLAT)
    assert flat.any()
    rows, cols = np.nonzero(on_roof)
    sub = flat[rows.min() : rows.max() + 1, cols.min() : cols.max() + 1]
    assert _largest_clear_radius_m(sub, grid.res) < 5.0


def _largest_clear_radius_m(free: np.ndarray, res: float) -> float:
    """Radius of the largest disc of ``free`` cells (brute-force distance to the nearest blocked cell)."""
    blocked = np.argwhere(~np.pad(free, 1))
    best = 0.0
    for i, j in np.argwhere(free)[::7]:
        d = np.min((blocked[:, 0] - (i + 1)) ** 2 + (blocked[:, 1] - (j + 1)) ** 2)
        best = max(best, math.sqrt(float(d)) * res)
    return best


def test_scenario1_features_sit_at_their_heights(
    builtin_worlds: dict[str, tuple[ScenarioSpec, World]],
) -> None:
    _, world = builtin_worlds["scenario1"]
    grid = world.grid
    assert grid.class_at(0.0, -80.0) is SurfaceClass.HIGHWAY
    assert grid.height_at(0.0, -80.0) == pytest.approx(9.0)
    rail = grid.cls == SurfaceClass.GUARD_RAIL
    assert rail.any()
    assert np.isclose(grid.height[rail], 9.9).mean() > 0.5  # deck rails; the rest ride the ramp
    assert any(lane.deck_height_m == 9.0 for lane in world.lanes)
    assert grid.class_at(0.0, 150.0) is SurfaceClass.WATER
    assert grid.height_at(0.0, 150.0) == pytest.approx(-0.8)
    assert grid.class_at(-10.0, 100.0) is SurfaceClass.PIER
    assert grid.height_at(-10.0, 100.0) == pytest.approx(0.6)
    assert (grid.mat == Material.PAINT_TEXT).sum() > 100  # "LAND HERE"
    # the parapet of the clear roof: 1 m above the 22 m roof at its edge
    assert grid.class_at(19.9, -27.0) is SurfaceClass.PARAPET
    assert grid.height_at(19.9, -27.0) == pytest.approx(23.0)
    # the ramp descends from the deck to the ground
    assert 3.0 < grid.height_at(40.0, -68.5) < 8.0


def test_scenario2_has_parked_cars_and_domes(builtin_worlds: dict[str, tuple[ScenarioSpec, World]]) -> None:
    spec, world = builtin_worlds["scenario2"]
    grid = world.grid
    lot = grid.cls == SurfaceClass.PARKING_LOT
    cars = grid.cls == SurfaceClass.VEHICLE
    assert lot.any()
    assert cars.sum() * grid.res**2 > 50 * 4.5 * 1.9 * 0.8  # dozens of parked cars
    assert np.all(grid.height[cars & (grid.region < 0)] > 0)
    rid = _region_of(spec, "cluttered_roof")
    dome_top = grid.height_at(12.0, 44.0)
    assert dome_top == pytest.approx(spec.buildings[rid - 1].height_m + 3.0, abs=0.05)
    assert (grid.mat[grid.region == rid] == Material.SOLAR).sum() > 1000


# ------------------------------------------------------------------------------------------ validation
BASE = """\
name = "tiny"
extent = { north = [-50.0, 50.0], east = [-50.0, 50.0] }
resolution_m = 0.5

[[buildings]]
id = "b"
centre = [0.0, 10.0]
size = [20.0, 16.0]
height_m = 12.0
roof = "gravel"
parapet = { height_m = 1.0, width_m = 0.5 }

[[clutter]]
kind = "rubble"
centre = [0.0, 10.0]
size = [6.0, 4.0]

[[parks]]
centre = [0.0, -30.0]
size = [30.0, 30.0]
trees = 10

[[lanes]]
points = [[-50.0, -5.0], [50.0, -5.0]]

[[safe_zones]]
centre = [6.0, 10.0]
size = [4.0, 12.0]
"""


def _write(tmp_path: Path, text: str, name: str = "bad.toml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def test_load_scenario_file_base_fixture_is_valid(tmp_path: Path) -> None:
    world = load_scenario_file(_write(tmp_path, BASE, "tiny.toml"))
    assert world.grid.shape == (200, 200)
    assert world.launch_height_m == 110.0  # the default
    assert world.grid.class_at(0.0, 10.0) is SurfaceClass.ROOF_CLUTTER
    assert world.grid.class_at(6.0, 10.0) is SurfaceClass.ROOF_FLAT
    assert world.grid.height_at(6.0, 10.0) == pytest.approx(12.0)


@pytest.mark.parametrize(
    ("old", "new", "field", "problem"),
    [
        ("height_m = 12.0", "height_m = -3", "buildings[0].height_m", "must be greater than 0 (got -3)"),
        ("height_m = 12.0", "heigth_m = 12.0", "buildings[0].heigth_m",
         "unknown key (did you mean 'height_m'?)"),
        ('roof = "gravel"', 'roof = "slate"', "buildings[0].roof",
         "must be 'gravel', 'concrete', 'tar', 'membrane' or 'tiles' (got 'slate')"),
        ("centre = [0.0, 10.0]\nsize = [6.0, 4.0]", "centre = [0.0, -10.0]\nsize = [6.0, 4.0]",
         "clutter[0].centre", "not on a building roof"),
        ("[[buildings]]", "[[bulidings]]", "bulidings", "did you mean 'buildings'?"),
        ('resolution_m = 0.5', 'resolution_m = 0.5\nlaunch = { height_m = 300.0 }', "launch.height_m",
         "must be less than or equal to 200 (got 300.0)"),
        ("north = [-50.0, 50.0]", "north = [50.0, -50.0]", "extent.north", "min must be less than max"),
        ("centre = [0.0, 10.0]\nsize = [20.0, 16.0]", "centre = [45.0, 10.0]\nsize = [20.0, 16.0]",
         "buildings[0].centre", "lies outside the extent (north -50..50, east -50..50)"),
        ("[[lanes]]\npoints = [[-50.0, -5.0], [50.0, -5.0]]", "[[lanes]]\npoints = [[-50.0, -5.0]]",
         "lanes[0].points", "at least 2 items"),
        ("[[lanes]]\npoints = [[-50.0, -5.0], [50.0, -5.0]]",
         "[[lanes]]\npoints = [[-50.0, -5.0], [50.0, -5.0]]\nspeed_m_s = [3.0, 10.0]",
         "lanes[0].speed_m_s[0]", "must be greater than or equal to 5 (got 3.0)"),
        ('roof = "gravel"', 'roof = "gravel"\npitched = { ridge_m = 10.0 }', "buildings[0].parapet",
         "a pitched roof has no parapet"),
        ("centre = [6.0, 10.0]\nsize = [4.0, 12.0]", "centre = [0.0, 10.0]\nsize = [10.0, 10.0]",
         "safe_zones[0]", "roof_clutter; a safe zone must be clear"),
        ('kind = "rubble"', 'kind = "vent"', "clutter[0].size", "not used by kind 'vent'"),
    ],
)  # fmt: skip
def test_load_scenario_file_invalid_names_file_field_and_problem(
    tmp_path: Path, old: str, new: str, field: str, problem: str
) -> None:
    assert old in BASE
    path = _write(tmp_path, BASE.replace(old, new, 1))
    with pytest.raises(ScenarioFileError) as err:
        load_scenario_file(path)
    message = str(err.value)
    assert f"bad.toml: {field}: " in message, message
    assert problem in message, message
    assert isinstance(err.value, ValueError)
    assert err.value.path == path
    assert any(f == field and problem in p for f, p in err.value.issues)


def test_load_scenario_file_negative_height_message_is_one_clear_line(tmp_path: Path) -> None:
    path = _write(tmp_path, BASE.replace("height_m = 12.0", "height_m = -3"), "scenario1.toml")
    with pytest.raises(ScenarioFileError) as err:
        load_scenario_file(path)
    assert str(err.value) == "scenario1.toml: buildings[0].height_m: must be greater than 0 (got -3)"
    assert err.value.field == "buildings[0].height_m"
    assert err.value.problem == "must be greater than 0 (got -3)"


def test_load_scenario_file_toml_syntax_error_names_file_and_line(tmp_path: Path) -> None:
    text = BASE.replace("size = [20.0, 16.0]", "size = [20.0, 16.0")
    line = text.splitlines().index("size = [20.0, 16.0") + 1
    with pytest.raises(ScenarioFileError) as err:
        load_scenario_file(_write(tmp_path, text))
    message = str(err.value)
    assert message.startswith("bad.toml: line ")
    assert "TOML syntax error" in message
    reported = int(message.split("line ")[1].split(":")[0])
    assert line <= reported <= line + 1  # tomllib reports where it noticed: this line or the next


def test_load_scenario_file_duplicate_building_id_is_rejected(tmp_path: Path) -> None:
    twin = '\n[[buildings]]\nid = "b"\ncentre = [-20.0, 30.0]\nsize = [8.0, 8.0]\nheight_m = 5.0\n'
    with pytest.raises(ScenarioFileError, match=r"bad\.toml: buildings\[1\]\.id: duplicate id 'b'"):
        load_scenario_file(_write(tmp_path, BASE + twin))


def test_load_scenario_file_missing_file_names_it(tmp_path: Path) -> None:
    with pytest.raises(ScenarioFileError, match=r"nowhere\.toml: cannot read the file"):
        load_scenario_file(tmp_path / "nowhere.toml")


def test_load_scenario_file_clutter_height_is_above_the_roof(tmp_path: Path) -> None:
    text = BASE + '\n[[clutter]]\nkind = "hvac"\ncentre = [-6.0, 6.0]\nsize = [2.0, 2.0]\nheight_m = 1.5\n'
    world = load_scenario_file(_write(tmp_path, text, "hvac.toml"))
    assert world.grid.class_at(-6.0, 6.0) is SurfaceClass.ROOF_CLUTTER
    assert world.grid.height_at(-6.0, 6.0) == pytest.approx(13.5)
    assert world.grid.class_at(-6.0, 3.0) is SurfaceClass.ROOF_FLAT


# ------------------------------------------------------------------------------------------ determinism
def test_load_scenario_file_same_seed_same_grid(tmp_path: Path) -> None:
    path = _write(tmp_path, BASE, "tiny.toml")
    a, b = load_scenario_file(path, seed=3), load_scenario_file(path, seed=3)
    for name in ("height", "cls", "mat", "region"):
        assert np.array_equal(getattr(a.grid, name), getattr(b.grid, name)), name


def test_load_scenario_file_other_seed_moves_only_random_things(tmp_path: Path) -> None:
    path = _write(tmp_path, BASE, "tiny.toml")
    a, b = load_scenario_file(path, seed=3), load_scenario_file(path, seed=4)
    differs = a.grid.height != b.grid.height
    assert differs.any()
    # only rubble (on the roof) and park trees (on the lawn, canopies overhanging its edge) move
    changed = {SurfaceClass(c) for c in np.unique(np.concatenate([a.grid.cls[differs], b.grid.cls[differs]]))}
    random_things = {SurfaceClass.ROOF_CLUTTER, SurfaceClass.ROOF_FLAT, SurfaceClass.TREE}
    assert changed <= random_things | {SurfaceClass.GRASS, SurfaceClass.GROUND}
    assert differs[a.grid.region == 1].any()  # the rubble
    assert differs[(a.grid.cls == SurfaceClass.TREE) | (b.grid.cls == SurfaceClass.TREE)].any()  # the trees


def test_load_scenario_file_builtin_same_seed_same_grid(
    builtin_worlds: dict[str, tuple[ScenarioSpec, World]],
) -> None:
    _, first = builtin_worlds["scenario1"]
    again = load_scenario_file(builtin_scenario_path("scenario1"), seed=0)
    other = load_scenario_file(builtin_scenario_path("scenario1"), seed=1)
    for name in ("height", "cls", "mat", "region"):
        assert np.array_equal(getattr(first.grid, name), getattr(again.grid, name)), name
    assert not np.array_equal(first.grid.height, other.grid.height)


def test_scenario_format_doc_example_loads(tmp_path: Path) -> None:
    doc = (Path(__file__).resolve().parents[1] / "docs" / "scenario-format.md").read_text()
    example = doc.split("```toml\n", 1)[1].split("```", 1)[0]
    world = load_scenario_file(_write(tmp_path, example, "example.toml"))
    assert world.name == "two_roofs"
    assert len(world.safe_zones) == 1
    assert world.grid.class_at(-12.0, 25.0) is SurfaceClass.ROOF_FLAT  # under the painted text
