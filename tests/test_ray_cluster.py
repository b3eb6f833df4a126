"""companion-bench on a Ray cluster of several nodes: a head and two worker nodes, each a raylet with
its own object store and CPUs, started as separate processes on this machine (ray.cluster_utils, as
``ray start --head`` and ``ray start --address`` start them on several machines). A worker node dies
while an episode flies on it, then the driver is killed outright: no episode is lost or counted twice,
and ``--resume`` finishes the campaign, with the verdicts a local campaign gives these episodes."""

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

from tests.test_campaign import ROOT, _alive, bench

IDS = [f"scenario1-r{k}-onboard-crop-clear-px4" for k in range(3)]


def _descendants(pid: int) -> set[int]:
    """Every process below ``pid`` (from /proc)."""
    children: dict[int, list[int]] = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            parent = int(stat.read_text().rsplit(")", 1)[1].split()[1])
        except (OSError, IndexError, ValueError):
            continue
        children.setdefault(parent, []).append(int(stat.parent.name))
    found: set[int] = set()
    todo = [pid]
    while todo:
        for kid in children.get(todo.pop(), []):
            if kid not in found:
                found.add(kid)
                todo.append(kid)
    return found


def _flying_under(pid: int) -> dict[str, int]:
    """The episodes whose simbridge runs below ``pid``: episode id -> simbridge's pid."""
    out: dict[str, int] = {}
    for p in _descendants(pid):
        try:
            argv = Path(f"/proc/{p}/cmdline").read_bytes().split(b"\0")
        except OSError:
            continue
        if b"simbridge" in argv and b"--episode-log" in argv:
            log = Path(argv[argv.index(b"--episode-log") + 1].decode())
            out[log.parent.name] = p
    return out


def _episodes(results: Path) -> list[dict[str, Any]]:
    if not results.exists():
        return []
    episodes: list[dict[str, Any]] = json.loads(results.read_text())["episodes"]
    return episodes


@pytest.mark.slow
@pytest.mark.timeout(600)
@pytest.mark.skipif(not Path("/proc").is_dir(), reason="reads the nodes' processes from /proc (Linux)")
def test_a_node_and_then_the_driver_killed_lose_no_episode_and_count_none_twice(tmp_path: Path) -> None:
    pytest.importorskip("ray", reason="the campaign extra: pip install 'landfall[campaign]'")
    from ray.cluster_utils import Cluster

    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 0})
    try:
        nodes = [cluster.add_node(num_cpus=1) for _ in range(2)]
        out = tmp_path / "campaign"
        results = out / "results.json"
        argv = ("curated", "--scenario", "scenario1", "--runs", "3", "--speed", "8", "--quiet",
                "--executor", "ray", "--ray-address", cluster.address, "--out", str(out))  # fmt: skip
        log = tmp_path / "driver.log"
        with log.open("wb") as fh:
            driver = subprocess.Popen(
                [sys.executable, "-m", "landfall_eval.cli", *argv],
                cwd=ROOT,
                stdout=fh,
                stderr=subprocess.STDOUT,
            )
        raylets = [n.all_processes["raylet"][0].process.pid for n in nodes]

        # both worker nodes fly an episode: the first node dies with its episode in the air
        deadline = time.monotonic() + 180
        while not all(_flying_under(r) for r in raylets):
            assert driver.poll() is None, log.read_text()[-3000:]
            assert time.monotonic() < deadline, "the two nodes never flew an episode each"
            time.sleep(0.5)
        time.sleep(3.0)  # well into the flight
        doomed = _flying_under(raylets[0])
        (doomed_id, doomed_sim), *_ = doomed.items()
        cluster.remove_node(nodes[0], allow_graceful=False)
        deadline = time.monotonic() + 30
        while _alive(doomed_sim) and time.monotonic() < deadline:
            time.sleep(0.2)
        assert not _alive(doomed_sim), "the killed node's episode outlived it"

        # once an episode is in results.json, the driver is killed outright
        deadline = time.monotonic() + 300
        while not _episodes(results):
            assert driver.poll() is None, log.read_text()[-3000:]
            assert time.monotonic() < deadline, "no episode finished in 300 s"
            time.sleep(0.5)
        os.kill(driver.pid, signal.SIGKILL)
        driver.wait(timeout=30)
        first = _episodes(results)
        assert 1 <= len(first) < 3
        assert len({e["id"] for e in first}) == len(first)

        again = bench(*argv, "--resume")
        assert again.returncode == 0, again.stderr[-3000:]
        assert f"resuming: {len(first)} of 3 episodes" in again.stderr
        episodes = _episodes(results)
        assert sorted(e["id"] for e in episodes) == IDS  # each once: none lost, none twice
        for e in first:  # kept as they were
            assert [x for x in episodes if x["id"] == e["id"]] == [e]
        for e in episodes:  # the verdicts the local executor gives these episodes (tests/test_bench.py)
            assert e["outcome"] == "landed", (e["id"], e["error"])
            assert e["safe"], (e["id"], e["reasons"])
            assert e["surface"] == "rooftop_clear", e["id"]
            assert (out / "episodes" / e["id"] / "episode.jsonl").exists()
        assert json.loads(results.read_text())["config"]["executor"] == "ray"
        assert doomed_id in IDS
    finally:
        cluster.shutdown()
