"""simbridge.world.cache: a built place kept on disk is the place built, is never written through, and a
broken or unwritable cache costs only the time."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import pytest

import simbridge.world.places as places
from landfall_eval.cli import build_parser, world_cache
from landfall_eval.episode import EpisodeSpec, simbridge_command
from simbridge.cli import build_parser as simbridge_parser
from simbridge.cli import config_from_args as make_config
from simbridge.scenarios import load_scenario
from simbridge.world.cache import cached_place, entry_dir
from simbridge.world.live import LiveWorld
from simbridge.world.model import Material, SurfaceClass, WorldGrid
from simbridge.world.raycast import Pyramid
from simbridge.world.world import World


def _small_world(seed: int) -> World:
    grid = WorldGrid.empty((-20.0, 20.0), (-30.0, 30.0), 0.5)
    grid.height[10:30, 40:70] = 12.0 + seed
    grid.cls[10:30, 40:70] = int(SurfaceClass.ROOF_FLAT)
    grid.mat[10:30, 40:70] = int(Material.GRAVEL)
    grid.region[10:30, 40:70] = 7
    return World(name=f"small{seed}", seed=seed, grid=grid, launch_ne_m=(1.0, -2.0), description="a roof")


@pytest.fixture
def builds(monkeypatch: pytest.MonkeyPatch) -> list[tuple[str, int]]:
    """generate_place replaced by a small world; the list records every build."""
    seen: list[tuple[str, int]] = []

    def build(place: str, seed: int) -> World:
        seen.append((place, seed))
        return _small_world(seed)

    monkeypatch.setattr(places, "generate_place", build)
    return seen


def test_cached_place_builds_once_and_maps_the_same_world_after(
    tmp_path: Path, builds: list[tuple[str, int]]
) -> None:
    first = cached_place("suburb", 3, tmp_path)
    again = cached_place("suburb", 3, tmp_path)
    other = cached_place("suburb", 4, tmp_path)
    assert builds == [("suburb", 3), ("suburb", 4)]
    assert again.digest() == first.digest() != other.digest()
    kept = (again.name, again.seed, again.launch_ne_m, again.description)
    assert kept == ("small3", 3, (1.0, -2.0), "a roof")
    for name in ("height", "cls", "mat", "region"):
        got = getattr(again.grid, name)
        assert type(got) is np.ndarray  # not the memmap subclass: numba's kernels take it
        np.testing.assert_array_equal(got, getattr(first.grid, name))
    assert entry_dir(tmp_path, "suburb", 3).is_dir()
    assert cached_place("suburb", 3, None).digest() == first.digest()  # no cache: built again
    assert len(builds) == 3


def test_writing_into_a_cached_world_never_reaches_the_cache(
    tmp_path: Path, builds: list[tuple[str, int]]
) -> None:
    pristine = cached_place("town", 1, tmp_path)
    grid_digest, maps = pristine.grid.digest(), np.array(pristine.pyramid_maps)
    mapped = cached_place("town", 1, tmp_path)
    mapped.grid.height[:] = 99.0  # as actors are stamped into the grid while an episode runs
    mapped.grid.cls[0, 0] = int(SurfaceClass.WATER)
    mapped.pyramid_maps[:] = 99.0  # ... and raise the ray caster's max maps
    again = cached_place("town", 1, tmp_path)
    assert again.grid.digest() == grid_digest  # hashed from the arrays read again
    np.testing.assert_array_equal(again.pyramid_maps, maps)
    assert len(builds) == 1


def test_a_cached_world_brings_its_digest_and_max_maps_as_computed_from_its_rasters(
    tmp_path: Path, builds: list[tuple[str, int]]
) -> None:
    """What a process would compute again from the rasters comes from the entry: the same digest
    and the same max maps, mapped copy-on-write (a plain ndarray for numba's kernels); an entry whose
    maps are missing or of another shape is built again."""
    built = cached_place("industrial", 6, tmp_path)
    mapped = cached_place("industrial", 6, tmp_path)
    fresh = _small_world(6)
    assert built.known_digest == mapped.known_digest == mapped.digest() == fresh.digest()
    assert type(mapped.pyramid_maps) is np.ndarray
    np.testing.assert_array_equal(mapped.pyramid_maps, Pyramid(fresh.grid.height).maps)
    live = LiveWorld(mapped)
    assert live.world_digest == fresh.digest()
    assert live.pyramid.h_max == Pyramid(fresh.grid.height).h_max
    assert len(builds) == 1
    entry = entry_dir(tmp_path, "industrial", 6)
    np.save(entry / "pyramid.npy", np.zeros((8, 2, 2), np.float32))
    assert cached_place("industrial", 6, tmp_path).digest() == fresh.digest()
    assert len(builds) == 2
    (entry_dir(tmp_path, "industrial", 6) / "pyramid.npy").unlink()
    assert cached_place("industrial", 6, tmp_path).digest() == fresh.digest()
    assert len(builds) == 3


def test_a_broken_entry_is_built_again_with_a_warning(
    tmp_path: Path, builds: list[tuple[str, int]], caplog: pytest.LogCaptureFixture
) -> None:
    good = cached_place("farmland", 2, tmp_path).digest()
    (entry_dir(tmp_path, "farmland", 2) / "height.npy").write_bytes(b"half a file")
    with caplog.at_level(logging.WARNING, logger="simbridge.world.cache"):
        again = cached_place("farmland", 2, tmp_path)
    assert again.digest() == good
    assert len(builds) == 2
    assert "unreadable" in caplog.text
    assert cached_place("farmland", 2, tmp_path).digest() == good  # and stored again
    assert len(builds) == 2


def test_an_unwritable_cache_costs_only_the_time(
    tmp_path: Path, builds: list[tuple[str, int]], caplog: pytest.LogCaptureFixture
) -> None:
    blocked = tmp_path / "a-file"
    blocked.write_text("not a folder")
    with caplog.at_level(logging.WARNING, logger="simbridge.world.cache"):
        world = cached_place("hillside", 5, blocked / "cache")
    assert world.name == "small5"
    assert "not written" in caplog.text


def test_a_real_city_mapped_from_the_cache_is_the_city_built(tmp_path: Path) -> None:
    """Downtown city 0 through load_scenario, as simbridge and the grading load it: the same world
    digest built or mapped (the digest is what an episode's grading checks against the flown world)."""
    built = load_scenario("city", 1, city_seed=0).world_digest
    assert load_scenario("city", 1, city_seed=0, world_cache=tmp_path).world_digest == built  # stored
    assert load_scenario("city", 2, city_seed=0, world_cache=tmp_path).world_digest == built  # mapped


def test_simbridge_and_companion_bench_pass_the_cache_on(tmp_path: Path) -> None:
    args = simbridge_parser().parse_args(["--scenario", "city", "--world-cache", str(tmp_path)])
    assert make_config(args).world_cache == tmp_path
    assert make_config(simbridge_parser().parse_args(["--scenario", "city"])).world_cache is None

    def bench(*extra: str) -> Path | None:
        return world_cache(build_parser().parse_args(["city", "--out", str(tmp_path / "run"), *extra]))

    assert bench() == (tmp_path / "run" / "world-cache").resolve()
    assert bench("--world-cache", "none") is None
    assert bench("--world-cache", str(tmp_path / "shared")) == tmp_path / "shared"
    spec = EpisodeSpec(kind="city", scenario="city", seed=1, city_seed=0)
    cmd = simbridge_command(
        spec, udp_port=1, sensors_port=2, episode_log=tmp_path / "e.jsonl", speed=4.0, world_cache=tmp_path
    )
    assert cmd[cmd.index("--world-cache") + 1] == str(tmp_path)
    plain = simbridge_command(spec, udp_port=1, sensors_port=2, episode_log=tmp_path / "e.jsonl", speed=4.0)
    assert "--world-cache" not in plain
