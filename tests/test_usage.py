"""A campaign's cost on this machine (landfall_eval/usage.py): wall time, the CPU of the episodes'
processes once they end, episodes per core-hour, summed over the runs of a resumed campaign."""

from __future__ import annotations

import subprocess
import sys

import pytest

from landfall_eval.usage import RunUsage, campaign_usage, machine_cores


def test_a_run_counts_its_childrens_cpu_once_they_end_and_its_episodes_per_core_hour() -> None:
    usage = RunUsage()
    busy = "import time\nt = time.process_time()\nwhile time.process_time() - t < 0.3: pass"
    subprocess.run([sys.executable, "-c", busy], check=True)
    u = usage.entry(3)
    assert u["episodes"] == 3
    assert u["cores"] == machine_cores() >= 1
    assert u["cpu_s"] >= 0.3  # the child's busy loop, counted once it was waited for
    assert u["wall_s"] >= 0.3
    assert u["episodes_per_core_hour"] == pytest.approx(3 / (u["wall_s"] * u["cores"] / 3600), rel=0.2)


def test_on_ray_neither_the_cpu_nor_the_cores_are_this_machines() -> None:
    u = RunUsage(local=False).entry(5)
    assert u["cores"] is None
    assert u["cpu_s"] is None
    assert u["episodes_per_core_hour"] is None


def test_a_resumed_campaign_adds_up_its_runs() -> None:
    runs = [
        {"speed": 12.0, "usage": {"episodes": 300, "wall_s": 3600.0, "cpu_s": 5000.0, "cores": 2}},
        {"speed": 12.0},  # a run from before the figures were kept: left out
        {"speed": 12.0, "usage": {"episodes": 100, "wall_s": 1800.0, "cpu_s": 2000.0, "cores": 4}},
        {"speed": 12.0, "usage": {"episodes": 7, "wall_s": 60.0, "cpu_s": None, "cores": None}},  # Ray
    ]
    total = campaign_usage(runs)
    assert total == {
        "runs": 2,
        "episodes": 400,
        "wall_s": 5400.0,
        "cpu_s": 7000.0,
        "core_hours": 4.0,  # 1 h on 2 cores, half an hour on 4
        "episodes_per_core_hour": 100.0,
    }
    assert campaign_usage([{"speed": 4.0}]) is None
