"""The soak script's mechanism on a short run: one companion daemon through several simbridge
lifetimes (a reset per episode), every landing safe, no file descriptor or thread left behind.
The 50-episode figures are in the README (benchmarks/soak.py)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow
ROOT = Path(__file__).resolve().parent.parent


def test_one_daemon_lands_every_episode_across_simulator_resets_and_keeps_its_fds(tmp_path: Path) -> None:
    out = tmp_path / "soak"
    res = subprocess.run(
        # 8 x: what is checked (landings, file descriptors, threads, the exit) does not depend on the speed
        [
            sys.executable,
            str(ROOT / "benchmarks" / "soak.py"),
            "--episodes",
            "3",
            "--speed",
            "8",
            "--out",
            str(out),
        ],
        capture_output=True,
        text=True,
        timeout=900,
        cwd=ROOT,
    )
    summary = json.loads((out / "soak.json").read_text())
    log = (out / "companion.log").read_text()
    assert summary["episodes"] == 3, res.stdout + res.stderr + log[-3000:]
    assert [s["outcome"] for s in summary["samples"]] == ["landed"] * 3, res.stdout
    assert summary["safe_landings"] == 3, res.stdout
    assert {s["autopilot"] for s in summary["samples"]} == {"px4", "ardupilot"}
    assert log.count("recovery ended: landed") == 3  # one daemon, three recoveries
    assert summary["fds"]["after_last"] <= summary["fds"]["after_first"], res.stdout  # sockets closed
    # threads: the asyncio worker pool grows on demand up to cpu_count + 4, and no further
    assert summary["threads"]["max"] <= summary["threads"]["start"] + (os.cpu_count() or 1) + 4
    assert summary["companion_exit_status"] == 0
    assert "safe landings in one daemon lifetime" in res.stdout
    assert res.returncode == (0 if summary["goals_met"] else 1)
