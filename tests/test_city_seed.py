"""One city per campaign (DESIGN.md section 7): ``--city-seed`` draws the procedural city, ``--seed``
the episode (traffic, sensor noise, wind). The episode log names the world it flew (``city_seed``,
``world_digest``), companion-bench passes the campaign's city seed to every simbridge, and the report
draws that city and says so when an episode flew another."""

from __future__ import annotations

import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from landfall_eval.basemap import basemap
from landfall_eval.cli import build_parser, episode_specs
from landfall_eval.episode import EpisodeSpec, simbridge_command
from landfall_eval.launches import halton_launches
from landfall_eval.report import write_report
from simbridge import render_cli
from simbridge.cli import main as simbridge_main
from simbridge.scenarios import load_scenario
from simbridge.sim import SimConfig
from simbridge.world.live import LiveWorld
from simbridge.world.scenario_file import BUILTIN_SCENARIO_DIR, load_scenario_file
from tests.conftest import SimProcess

HEX16 = re.compile(r"[0-9a-f]{16}")


def _flown(sim: SimProcess, timeout_s: float = 180.0) -> dict[str, object]:
    """The start line of a simbridge run with ``--duration``, once the process has ended by itself."""
    assert sim.proc.wait(timeout=timeout_s) == 0, sim.stderr_path.read_text()[-2000:]
    (start,) = sim.events("start")
    assert sim.events("stop"), "the run did not end cleanly"
    return start


def _live(name: str, seed: int, city_seed: int = 0) -> LiveWorld:
    world = load_scenario(name, seed, city_seed=city_seed).terrain
    assert isinstance(world, LiveWorld)
    return world


# ------------------------------------------------------------------------------------ simbridge
@pytest.mark.slow
def test_simbridge_city_seed_picks_the_city_and_seed_does_not(
    start_sim: Callable[..., SimProcess],
) -> None:
    short = ("--scenario", "city", "--duration", "0.3", "--speed", "10")
    a = start_sim(*short, "--city-seed", "4", "--seed", "1")
    b = start_sim(*short, "--city-seed", "4", "--seed", "2")
    first, second = _flown(a), _flown(b)
    other = _flown(start_sim(*short, "--city-seed", "5", "--seed", "1"))
    assert (first["seed"], second["seed"], other["seed"]) == (1, 2, 1)
    assert (first["city_seed"], second["city_seed"], other["city_seed"]) == (4, 4, 5)
    assert HEX16.fullmatch(str(first["world_digest"]))
    assert first["world_digest"] == second["world_digest"]  # other episode seed, same city
    assert other["world_digest"] != first["world_digest"]  # other city seed, other city


@pytest.mark.slow
def test_simbridge_episode_log_names_a_curated_world_without_a_city_seed(
    start_sim: Callable[..., SimProcess],
) -> None:
    start = _flown(start_sim("--scenario", "scenario1", "--seed", "3", "--duration", "0.3", "--speed", "10"))
    assert start["city_seed"] is None
    assert start["world_digest"] == load_scenario_file(BUILTIN_SCENARIO_DIR / "scenario1.toml", 3).digest()
    flat = _flown(start_sim("--scenario", "flat", "--duration", "0.3", "--speed", "10"))
    assert flat["world_digest"] is None
    assert flat["city_seed"] is None


def test_simbridge_refuses_a_negative_city_seed(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        simbridge_main(["--scenario", "city", "--city-seed", "-1"])
    assert exc.value.code == 2
    assert "argument --city-seed: must be >= 0, got -1" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        render_cli.main(["--scenario", "city", "--city-seed", "-3", "--pose", "0,0,100,0", "--out", "x.png"])
    assert exc.value.code == 2
    assert "argument --city-seed: must be >= 0, got -3" in capsys.readouterr().err
    with pytest.raises(ValueError, match="--city-seed must be >= 0, got -2"):
        SimConfig(scenario="city", city_seed=-2)


# ------------------------------------------------------------------------------------ load_scenario
@pytest.mark.slow
def test_load_scenario_same_city_seed_other_episode_seed_same_grid_other_traffic() -> None:
    a, b = _live("city", 1, city_seed=6), _live("city", 2, city_seed=6)
    assert a.world_digest == b.world_digest
    assert (a.actor_seed, b.actor_seed) == (1, 2)
    assert a.world.seed == b.world.seed == 6  # the world is the city's; the actors are the episode's
    for w in (a, b):
        w.sync(30.0)
        w.actors.unstamp(w.grid)  # back to the static world
    assert np.array_equal(a.grid.height, b.grid.height)
    assert np.array_equal(a.grid.cls, b.grid.cls)
    assert a.grid.digest() == a.world_digest  # unstamped: the world as it was built
    pa, pb = a.actors.poses(), b.actors.poses()
    assert len(pa) > 100  # a city has traffic
    moved = {p.centre_ne for p in pa} ^ {p.centre_ne for p in pb}
    assert len(moved) > len(pa) // 2  # most actors stand elsewhere at t = 30 s


def test_load_scenario_file_actors_follow_the_episode_seed_as_before() -> None:
    path = BUILTIN_SCENARIO_DIR / "scenario2.toml"
    now = _live("scenario2", 4, city_seed=9)  # a city seed means nothing to a scenario file
    before = LiveWorld(load_scenario_file(path, 4))  # the old default: actors from the world's seed
    assert now.actor_seed == 4
    for w in (now, before):
        w.sync(20.0)
    assert now.actors.poses() == before.actors.poses()
    assert now.world_digest == before.world_digest == load_scenario_file(path, 4).digest()
    assert now.world_digest != load_scenario_file(path, 5).digest()  # its furniture follows the seed


# ------------------------------------------------------------------------------------ companion-bench
def test_city_campaign_gives_every_simbridge_its_city_seed(tmp_path: Path) -> None:
    args = build_parser().parse_args(
        ["city", "--seeds", "3", "--start-index", "2", "--city-seed", "7", "--out", str(tmp_path)]
    )
    specs = episode_specs(args)
    assert [s.launch_index for s in specs] == [2, 3, 4]
    assert {s.city_seed for s in specs} == {7}
    for spec, launch in zip(specs, halton_launches(3, 2), strict=True):
        cmd = simbridge_command(
            spec, udp_port=14600, sensors_port=14601, episode_log=tmp_path / "e.jsonl", speed=4.0
        )
        assert cmd[cmd.index("--scenario") + 1] == "city"
        assert cmd[cmd.index("--city-seed") + 1] == "7"
        assert cmd[cmd.index("--seed") + 1] == str(launch.index)  # the episode: its launch index
        assert f"--launch={launch.north_m:.2f},{launch.east_m:.2f},{launch.height_m:.2f}" in cmd
        assert cmd[cmd.index("--episode-log") + 1] == str(tmp_path / "e.jsonl")
    curated = simbridge_command(
        EpisodeSpec("curated", "scenario1", 3, run=3),
        udp_port=1, sensors_port=2, episode_log=tmp_path / "c.jsonl", speed=2.0,
    )  # fmt: skip
    assert "--city-seed" not in curated
    assert curated[curated.index("--seed") + 1] == "3"


def test_city_campaign_refuses_a_negative_city_seed(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as exc:
        build_parser().parse_args(["city", "--city-seed", "-1", "--out", str(tmp_path)])
    assert exc.value.code == 2
    assert "argument --city-seed: must be >= 0, got -1" in capsys.readouterr().err


# ------------------------------------------------------------------------------------ report
def _city_results(digest: str, city_seed: int | None, launch_ne: tuple[float, float]) -> dict[str, Any]:
    n, e = launch_ne
    entry = {
        "id": "city3-i0-onboard-crop-clear-px4", "kind": "city", "scenario": "city", "seed": 0,
        "city_seed": 3, "world_digest": digest, "launch_index": 0, "run": None, "reasoner": "onboard",
        "context": "crop", "weather": "clear", "autopilot": "px4", "launch_ned_m": [n, e, -110.0],
        "touchdown_ned_m": None, "surface": "no_landing", "safe": False, "reasons": ["no touchdown"],
        "outcome": "timeout", "error": "no touchdown within 1 simulated seconds", "rounds": 0,
        "trajectory_ne_m": [[n, e], [n + 5.0, e + 5.0]],
        "last_state": {"recovery_state": "rank", "round": 1, "outcome_state": None, "outcome_reason": None,
                       "vehicle_t_s": 20.0, "vehicle_mode": "OFFBOARD", "vehicle_armed": True,
                       "vehicle_pos_ned_m": [n + 5.0, e + 5.0, -108.0], "vehicle_agl_m": 108.0},
    }  # fmt: skip
    config: dict[str, Any] = {"reasoner": "onboard", "context": "crop"}
    if city_seed is not None:
        config["city_seed"] = city_seed
    return {"schema": "landfall-bench/1", "command": "city", "config": config, "episodes": [entry]}


@pytest.mark.slow
def test_report_map_of_a_city_run_is_the_city_its_episodes_flew(
    start_sim: Callable[..., SimProcess], tmp_path: Path
) -> None:
    start = _flown(start_sim("--scenario", "city", "--city-seed", "3", "--seed", "8", "--duration", "0.3"))
    digest = str(start["world_digest"])
    launch = (float(start["home_ned_m"][0]), float(start["home_ned_m"][1]))  # type: ignore[index]
    bounds = (launch[0] - 100.0, launch[0] + 100.0, launch[1] - 100.0, launch[1] + 100.0)
    assert basemap("city", 3, bounds, max_px=200).world_digest == digest

    # the run's city seed, or (no config) the episodes' own: the map is their city, no warning
    for config_seed in (3, None):
        page = write_report(_city_results(digest, config_seed, launch), tmp_path / f"ok{config_seed}")
        html = page.read_text()
        assert 'class="warning"' not in html
        assert "companion in rank, round 1; vehicle OFFBOARD 108 m above ground" in html  # last_state
    # a run that says city 4 while its episode flew city 3: the page says the map is wrong
    html = write_report(_city_results(digest, 4, launch), tmp_path / "wrong").read_text()
    (warning,) = re.findall(r'<p class="warning">([^<]*)</p>', html)
    assert "city of city seed 4" in warning
    assert f"digest {digest}" in warning
    assert "1 of 1 episodes flew another world" in warning
