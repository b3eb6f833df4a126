"""Campaigns: several cities and weathers in one run, the local and Ray executors, retries
for infrastructure failures only, failure classes, and resumption after a campaign killed outright."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

from landfall_eval import campaign
from landfall_eval.campaign import EpisodeJob, LocalExecutor, fly, is_infrastructure_failure
from landfall_eval.cli import build_parser, episode_specs
from landfall_eval.episode import EpisodeSpec, EpisodeTimes
from landfall_eval.grading import failure_class, summarise

ROOT = Path(__file__).resolve().parent.parent


def _parse(*argv: str) -> Any:
    return build_parser().parse_args(list(argv))


# ------------------------------------------------------------------------------------------ the plan
def test_several_cities_and_weathers_fly_every_launch_in_each(tmp_path: Path) -> None:
    args = _parse(
        "city", "--seeds", "2", "--city-seeds", "0-2", "--weather", "clear,fog,rain", "--out", str(tmp_path)
    )  # fmt: skip
    specs = episode_specs(args)
    assert len(specs) == 2 * 3 * 3
    assert len({s.id for s in specs}) == len(specs)
    # launch by launch: a campaign cut short still has every city and weather
    first = specs[:9]
    assert {s.launch_index for s in first} == {0}
    assert {(s.city_seed, s.weather) for s in first} == {
        (c, w) for c in (0, 1, 2) for w in ("clear", "fog", "rain")
    }
    assert specs[0].id == "city0-i0-onboard-crop-clear-px4"  # a one-city, one-weather id is unchanged


def test_one_city_and_one_weather_are_the_defaults(tmp_path: Path) -> None:
    specs = episode_specs(_parse("city", "--seeds", "2", "--out", str(tmp_path)))
    assert [(s.city_seed, s.weather) for s in specs] == [(0, "clear"), (0, "clear")]
    specs = episode_specs(_parse("city", "--seeds", "1", "--city-seed", "5", "--out", str(tmp_path)))
    assert specs[0].city_seed == 5


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--city-seeds", "1,1"], "a seed twice"),
        (["--city-seeds", "x"], "--city-seeds"),
        (["--weather", "snow"], "choose from clear, fog, rain"),
        (["--weather", "fog,fog"], "names one twice"),
        (["--city-seeds", "1", "--city-seed", "2"], "not allowed with argument"),
        (["--cpus-per-episode", "0"], "must be > 0"),
        (["--executor", "slurm"], "invalid choice"),
    ],
)
def test_bad_campaign_arguments_are_refused_saying_why(
    argv: list[str], message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as exc:
        _parse("city", "--seeds", "1", "--out", str(tmp_path), *argv)
    assert exc.value.code == 2
    assert message in capsys.readouterr().err


def test_a_ray_address_without_the_ray_executor_is_refused() -> None:
    with pytest.raises(ValueError, match="--ray-address goes with --executor ray"):
        campaign.make_executor("local", workers=1, address="auto", cpus_per_episode=1.0)


def test_without_ray_the_ray_executor_says_how_to_install_it(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray -> ImportError
    with pytest.raises(campaign.RayUnavailable, match=r"landfall\[campaign\]"):
        campaign.make_executor("ray", workers=1, address=None, cpus_per_episode=1.0)


# ------------------------------------------------------------------------------------------ grading
def test_failure_classes() -> None:
    assert failure_class({"safe": True, "outcome": "landed", "surface": "rooftop_clear"}) is None
    assert failure_class({"outcome": "error", "error_kind": "infrastructure"}) == "error (infrastructure)"
    assert failure_class({"outcome": "error", "error_kind": None}) == "error"
    assert failure_class({"outcome": "timeout", "surface": "no_landing"}) == "no touchdown"
    assert failure_class({"outcome": "landed", "surface": "water", "safe": False}) == "unsafe: water"
    edge = {"outcome": "landed", "surface": "rooftop_clear", "safe": False, "reasons": ["0.6 m from an edge"]}
    assert failure_class(edge) == "unsafe: rooftop_clear (edge)"
    steep = {"outcome": "landed", "surface": "ground", "safe": False, "reasons": ["slope 19 deg"]}
    assert failure_class(steep) == "unsafe: ground (slope)"
    near = {
        "outcome": "landed",
        "surface": "park",
        "safe": False,
        "reasons": ["person 5.8 m away (at least 10 m)"],
    }
    assert failure_class(near) == "unsafe: park (person)"
    wire = {"outcome": "landed", "surface": "ground", "safe": False,
            "reasons": ["4.0 m from the line under an overhead wire (at least 5 m)"]}  # fmt: skip
    assert failure_class(wire) == "unsafe: ground (wire)"
    assert failure_class({"outcome": "landed", "surface": "crops", "safe": False}) == "unsafe: crops"


def test_the_summary_groups_by_city_and_weather_and_lists_failures_by_class() -> None:
    def ep(i: int, city: int, weather: str, safe: bool, surface: str, defects: int = 0) -> dict[str, Any]:
        return {
            "id": f"e{i}", "safe": safe, "outcome": "landed", "surface": surface, "rounds": 1,
            "reasoner": "onboard", "context": "crop", "weather": weather, "city_seed": city,
            "defects": defects,
        }  # fmt: skip

    eps = [
        ep(1, 0, "clear", True, "rooftop_clear"),
        ep(2, 0, "fog", False, "water"),
        ep(3, 1, "clear", True, "rooftop_clear", defects=1),
        ep(4, 1, "clear", False, "road"),
        ep(5, 1, "clear", False, "water"),
    ]
    s = summarise(eps)
    assert s["failures"] == {"unsafe: road": ["e4"], "unsafe: water": ["e2", "e5"]}
    assert s["recoveries_with_defect"] == 1
    groups = {(g["city_seed"], g["weather"]): (g["episodes"], g["safe"]) for g in s["groups"]}
    assert groups == {(0, "clear"): (1, 1), (0, "fog"): (1, 0), (1, "clear"): (3, 1)}
    assert (s["nearest_person_min_m"], s["touchdowns_within_10m_of_a_person"]) == (None, 0)
    eps[0]["nearest_person_m"], eps[3]["nearest_person_m"], eps[4]["nearest_person_m"] = 42.0, 5.8, 10.0
    s = summarise(eps)
    assert (s["nearest_person_min_m"], s["touchdowns_within_10m_of_a_person"]) == (5.8, 2)


# ------------------------------------------------------------------------------------------ retries
def _job(tmp_path: Path, tries: int = 3) -> EpisodeJob:
    return EpisodeJob(
        EpisodeSpec("curated", "scenario1", 0, run=0), tmp_path / "ep", EpisodeTimes(), tries=tries
    )


def _scripted(monkeypatch: pytest.MonkeyPatch, answers: list[dict[str, Any] | Exception]) -> list[int]:
    """``run_episode`` replaced by a script of answers (the harness's own process boundary is what
    the slow tests below cross for real); returns the list its calls are counted in."""
    calls: list[int] = []

    def run(spec: EpisodeSpec, workdir: Path, **_: Any) -> dict[str, Any]:
        calls.append(1)
        answer = answers[len(calls) - 1]
        if isinstance(answer, Exception):
            raise answer
        return {"id": spec.id, **answer}

    monkeypatch.setattr(campaign, "run_episode", run)
    return calls


def test_an_infrastructure_failure_is_tried_again(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    calls = _scripted(
        monkeypatch,
        [
            {"outcome": "error", "error_kind": "infrastructure", "error": "simbridge exited before ready"},
            OSError("Address already in use"),
            {"outcome": "landed", "safe": True},
        ],
    )
    entry = fly(_job(tmp_path))
    assert len(calls) == 3
    assert entry["outcome"] == "landed"
    assert entry["attempts"] == 3


def test_an_outcome_is_never_tried_again(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    for outcome in (
        {"outcome": "error", "error_kind": None, "error": "the companion exited during the episode"},
        {"outcome": "timeout", "error_kind": None},
        {"outcome": "landed", "safe": False, "surface": "water"},
    ):
        calls = _scripted(monkeypatch, [outcome, {"outcome": "landed", "safe": True}])
        entry = fly(_job(tmp_path))
        assert len(calls) == 1
        assert entry["attempts"] == 1
        assert entry["outcome"] == outcome["outcome"]


def test_the_last_infrastructure_failure_is_entered_when_the_tries_run_out(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    _scripted(monkeypatch, [OSError("no port"), OSError("no port")])
    entry = fly(_job(tmp_path, tries=2))
    assert is_infrastructure_failure(entry)
    assert entry["error"] == "harness: OSError: no port"
    assert entry["attempts"] == 2
    assert failure_class(entry) == "error (infrastructure)"


def test_the_local_executor_hands_back_every_entry(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    _scripted(monkeypatch, [{"outcome": "landed", "safe": True}] * 3)
    jobs = [
        EpisodeJob(EpisodeSpec("curated", "scenario1", k, run=k), tmp_path / str(k), EpisodeTimes())
        for k in range(3)
    ]
    ex = LocalExecutor(workers=2)
    try:
        got = sorted(e["id"] for e in ex.run(jobs))
    finally:
        ex.close()
    assert got == sorted(j.spec.id for j in jobs)


# ------------------------------------------------------------------------------------------ real runs
def bench(*args: str, timeout: float = 600) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "landfall_eval.cli", *args], capture_output=True, text=True, timeout=timeout,
        cwd=ROOT,
    )  # fmt: skip


def _ours(pid: int) -> list[int]:
    """Processes whose parent is ``pid`` (from /proc)."""
    kids = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            kids.append(int(stat.parent.name))
    return kids


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


@pytest.mark.slow
@pytest.mark.timeout(600)
@pytest.mark.skipif(not Path("/proc").is_dir(), reason="reads child processes from /proc (Linux)")
def test_a_campaign_killed_outright_loses_nothing_and_resumes(tmp_path: Path) -> None:
    """``kill -9`` once the first of two episodes is in results.json: the file holds it whole, the
    episode in flight dies with the campaign (no simbridge or companion left behind), and the same
    command with --resume flies the other one only."""
    out = tmp_path / "campaign"
    argv = (
        "curated",
        "--scenario",
        "scenario1",
        "--runs",
        "2",
        "--workers",
        "1",
        "--speed",
        "8",  # what is checked is the results file and the processes, not the flights
        "--quiet",
        "--out",
        str(out),
    )
    log = tmp_path / "killed.log"
    with log.open("wb") as fh:
        proc = subprocess.Popen(
            [sys.executable, "-m", "landfall_eval.cli", *argv], cwd=ROOT, stdout=fh, stderr=subprocess.STDOUT
        )
    results = out / "results.json"
    deadline = time.monotonic() + 400
    while not (results.exists() and json.loads(results.read_text())["episodes"]):
        assert proc.poll() is None, log.read_text()
        assert time.monotonic() < deadline, "no episode finished in 400 s"
        time.sleep(0.5)
    deadline = time.monotonic() + 60
    while not _ours(proc.pid) and time.monotonic() < deadline:  # the second episode's processes
        time.sleep(0.2)
    children = _ours(proc.pid)
    assert children, "the second episode did not start"
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait(timeout=30)
    deadline = time.monotonic() + 30
    while any(_alive(p) for p in children) and time.monotonic() < deadline:
        time.sleep(0.2)
    assert not any(_alive(p) for p in children), "an episode's processes outlived the campaign"
    first = json.loads(results.read_text())["episodes"]
    assert len(first) == 1

    again = bench(*argv, "--resume")
    assert again.returncode == 0, again.stderr[-3000:]
    assert "resuming: 1 of 2 episodes" in again.stderr
    episodes = json.loads(results.read_text())["episodes"]
    assert [e["id"] for e in episodes] == [f"scenario1-r{k}-onboard-crop-clear-px4" for k in range(2)]
    assert [e for e in episodes if e["id"] == first[0]["id"]] == first  # kept as it was
    assert all(e["safe"] for e in episodes), [e["reasons"] for e in episodes]
    # each run kept what it cost as its episodes ended, the killed one too; the campaign sums them
    saved = json.loads(results.read_text())
    assert [r["usage"]["episodes"] for r in saved["runs"]] == [1, 1]
    assert all(r["usage"]["cpu_s"] > 0 and r["usage"]["episodes_per_core_hour"] > 0 for r in saved["runs"])
    assert saved["usage"]["runs"] == 2
    assert saved["usage"]["episodes"] == 2
    assert "episodes per core-hour (2 episodes" in again.stderr


@pytest.mark.slow
@pytest.mark.timeout(300)
@pytest.mark.skipif(not Path("/proc").is_dir(), reason="reads child processes from /proc (Linux)")
def test_a_stopped_campaign_stops_its_episodes_and_says_how_to_go_on(tmp_path: Path) -> None:
    """SIGTERM (a scheduler's stop; Ctrl-C is handled the same) while the first episode flies: the
    campaign terminates that episode's processes, records nothing half-done, says how to go on and
    exits 130."""
    out = tmp_path / "campaign"
    proc = subprocess.Popen(
        [sys.executable, "-m", "landfall_eval.cli", "curated", "--scenario", "scenario1", "--runs", "2",
         "--workers", "1", "--quiet", "--out", str(out)],
        cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    deadline = time.monotonic() + 120
    while len(_ours(proc.pid)) < 2:  # simbridge and the companion of episode 0
        assert proc.poll() is None, "the campaign ended before its first episode started"
        assert time.monotonic() < deadline, "the first episode did not start"
        time.sleep(0.2)
    children = _ours(proc.pid)
    proc.terminate()
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err[-2000:]
    assert "interrupted: 0 of 2 episodes" in err
    assert "--resume goes on" in err
    assert not any(_alive(p) for p in children)
    log = out / "episodes" / "scenario1-r0-onboard-crop-clear-px4" / "companion.log"
    assert "recovery ended" not in log.read_text()  # stopped in flight, not waited for
    results = out / "results.json"
    assert not results.exists() or json.loads(results.read_text())["episodes"] == []
