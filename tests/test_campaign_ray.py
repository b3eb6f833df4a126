"""Campaigns through Ray (issue 20): the same episodes and verdicts as the local executor. A file of its
own: the slowest test of the campaign's, which the suite's workers (one file each) then share out."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.test_campaign import _verdicts, bench


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_ray_tasks_give_the_verdicts_the_local_executor_gives(tmp_path: Path) -> None:
    """The same two curated episodes through the local executor and through a local Ray instance with
    2 CPUs: the same episodes, outcomes, verdicts and surfaces."""
    pytest.importorskip("ray", reason="the campaign extra: pip install 'landfall[campaign]'")
    common = ("curated", "--scenario", "scenario1", "--runs", "2", "--workers", "2", "--quiet")
    local = bench(*common, "--out", str(tmp_path / "local"))
    assert local.returncode == 0, local.stderr[-3000:]
    ray = bench(*common, "--executor", "ray", "--out", str(tmp_path / "ray"))
    assert ray.returncode == 0, ray.stderr[-3000:]
    assert _verdicts(tmp_path / "ray") == _verdicts(tmp_path / "local")
    assert [v[2] for v in _verdicts(tmp_path / "ray")] == [True, True]
    results = json.loads((tmp_path / "ray" / "results.json").read_text())
    assert results["config"]["executor"] == "ray"
    assert (tmp_path / "ray" / "episodes" / "scenario1-r1-onboard-crop-clear-px4" / "episode.jsonl").exists()
