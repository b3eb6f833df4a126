"""Kinds of place (simbridge/world/places.py): ``--place`` for simbridge, its renderer and companion-bench
city; the kind travels with the city seed into every simbridge a campaign starts, the episode ids, the
results and the episode log, and an unknown kind is refused with the known ones named."""

from __future__ import annotations

from pathlib import Path

import pytest

from landfall_eval.cli import build_parser, episode_specs
from landfall_eval.episode import EpisodeSpec, simbridge_command
from simbridge.cli import build_parser as simbridge_parser
from simbridge.render_cli import build_parser as render_parser
from simbridge.scenarios import load_scenario
from simbridge.sim import SimConfig
from simbridge.world.places import DEFAULT_PLACE, PLACES, generate_place

KNOWN = "downtown, suburb, industrial, farmland, waterfront, hillside, town"


def test_the_kinds_of_place_and_the_default() -> None:
    assert PLACES[0] == DEFAULT_PLACE == "downtown"
    # every kind DESIGN.md section 4 names, in its order
    assert PLACES == ("downtown", "suburb", "industrial", "farmland", "waterfront", "hillside", "town")
    with pytest.raises(ValueError, match=rf"unknown place 'moon'; known places: {KNOWN}"):
        generate_place("moon", 0)
    with pytest.raises(ValueError, match="unknown place 'moon'"):
        load_scenario("city", 0, city_seed=0, place="moon")


def test_simbridge_and_its_renderer_take_a_place_and_refuse_an_unknown_one(
    capsys: pytest.CaptureFixture[str],
) -> None:
    args = simbridge_parser().parse_args(["--scenario", "city", "--place", "suburb"])
    assert args.place == "suburb"
    assert simbridge_parser().parse_args(["--scenario", "city"]).place == "downtown"
    with pytest.raises(SystemExit):
        simbridge_parser().parse_args(["--scenario", "city", "--place", "moon"])
    assert "invalid choice: 'moon'" in capsys.readouterr().err
    pose = ["--scenario", "city", "--pose", "0,0,100,0", "--out", "x.png"]
    assert render_parser().parse_args([*pose, "--place", "suburb"]).place == "suburb"
    with pytest.raises(ValueError, match=rf"--place must be one of {KNOWN}, got 'moon'"):
        SimConfig(scenario="city", place="moon")


def test_a_city_campaign_flies_its_place_in_every_simbridge_and_names_its_episodes_by_it(
    tmp_path: Path,
) -> None:
    def specs(*extra: str) -> list[EpisodeSpec]:
        return episode_specs(
            build_parser().parse_args(["city", "--seeds", "2", "--out", str(tmp_path), *extra])
        )

    suburb = specs("--place", "suburb", "--city-seed", "3")
    assert [s.id for s in suburb] == [
        "suburb3-i0-onboard-crop-clear-px4",
        "suburb3-i1-onboard-crop-clear-px4",
    ]
    downtown = specs()
    assert downtown[0].id == "city0-i0-onboard-crop-clear-px4"  # the ids runs already hold
    for spec, place in ((suburb[0], "suburb"), (downtown[0], "downtown")):
        cmd = simbridge_command(spec, udp_port=1, sensors_port=2, episode_log=tmp_path / "e.jsonl", speed=4.0)
        assert cmd[cmd.index("--place") + 1] == place
        assert cmd[cmd.index("--city-seed") + 1] == str(spec.city_seed)


def test_the_nearest_person_is_measured_without_moving_anyone() -> None:
    """LiveWorld.nearest_person_m: the straight-line distance to the nearest pedestrian's feet; asking
    leaves the actors as the sensors will find them (the traffic stays the episode's)."""
    import numpy as np

    from simbridge.world.live import LiveWorld
    from simbridge.world.suburb import generate_suburb

    live = LiveWorld(generate_suburb(1, 400.0), actor_seed=0)
    people = live.actors.people_at(5.0)
    assert people.shape[1] == 3
    assert len(people) > 0
    n, e, base = (float(v) for v in people[0])
    assert live.nearest_person_m((n, e, -(base + 10.0)), 5.0) <= 10.0 + 1e-6  # 10 m above that one
    before = live.actors.poses()
    far = live.nearest_person_m((n + 1000.0, e, -base), 5.0)
    assert far is not None
    assert far > 500.0
    assert live.actors.poses() == before  # nobody moved
    live.sync(5.0)
    after = np.array(
        [[p.centre_ne[0], p.centre_ne[1]] for p in live.actors.poses() if p.kind.name == "PEDESTRIAN"]
    )
    assert np.allclose(after, people[:, :2], atol=1e-6)  # where people_at said they would be
