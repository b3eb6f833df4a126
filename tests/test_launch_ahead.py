"""Launching the next episode while one flies: simbridge's ``--wait-for-go`` (built, then nothing sent
and no clock until a line on standard input) and the local executor that uses it (each job flown
once, every job but a worker's first launched ahead, nothing left running when stopped)."""

from __future__ import annotations

import json
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import pytest

from landfall_eval import campaign
from landfall_eval.campaign import EpisodeJob, LocalExecutor
from landfall_eval.episode import EpisodeSpec, EpisodeTimes


def _wait_for(what: str, check: Any, timeout_s: float = 30.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not check():
        assert time.monotonic() < deadline, f"never: {what}"
        time.sleep(0.05)


def _events(log: Path, name: str) -> list[dict[str, Any]]:
    text = log.read_text() if log.exists() else ""
    rows = [json.loads(line) for line in text[: text.rfind("\n") + 1].splitlines() if line.strip()]
    return [r for r in rows if r.get("event") == name]


def test_a_held_simbridge_sends_nothing_and_keeps_its_clock_until_the_go(tmp_path: Path) -> None:
    """Held, simbridge builds its world and says so, then stays silent: no datagram on its MAVLink
    port and no step of the simulation in its episode log, however long the wait. A line on
    standard input starts it: heartbeats, and the simulation's steps from simulated time zero (the
    wait cost none). Stopped while held, it exits at once and cleanly."""
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    rx.settimeout(0.5)
    log, err = tmp_path / "episode.jsonl", tmp_path / "simbridge.stderr"
    cmd = [
        sys.executable, "-m", "simbridge", "--scenario", "flat", "--speed", "4", "--wait-for-go",
        "--mavlink", f"udpout:127.0.0.1:{rx.getsockname()[1]}", "--episode-log", str(log),
        "--log-level", "INFO",
    ]  # fmt: skip
    with err.open("wb") as fh:
        sim = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=fh)
    try:
        _wait_for("simbridge built and held", lambda: "waiting for the go" in err.read_text())
        time.sleep(1.5)  # 6 simulated seconds at 4x, had the clock run
        with pytest.raises(TimeoutError):
            rx.recv(2048)
        assert _events(log, "state") == []  # no step of the simulation yet
        assert sim.stdin is not None
        sim.stdin.write(b"go\n")
        sim.stdin.flush()
        assert rx.recv(2048)  # MAVLink now
        _wait_for("the simulation's steps", lambda: _events(log, "state"))
        assert float(_events(log, "state")[0]["t_s"]) < 1.0  # its clock started at the go
    finally:
        sim.terminate()
        sim.wait(10)
        if sim.stdin is not None:
            sim.stdin.close()
        rx.close()

    with err.open("wb") as fh:
        held = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=fh)
    _wait_for("simbridge built and held", lambda: "waiting for the go" in err.read_text())
    held.terminate()
    assert held.wait(10) == 0
    if held.stdin is not None:
        held.stdin.close()


class _Launched:
    """What ``launch_episode`` gives, as the executor sees it."""

    def __init__(self, spec: EpisodeSpec) -> None:
        self.spec = spec
        self.discarded = False
        self.went = False

    def go(self) -> None:
        self.went = True

    def discard(self) -> None:
        self.discarded = True


def _jobs(tmp_path: Path, n: int) -> list[EpisodeJob]:
    return [
        EpisodeJob(EpisodeSpec("curated", "scenario1", k, run=k), tmp_path / str(k), EpisodeTimes())
        for k in range(n)
    ]


def test_each_worker_launches_its_next_job_while_it_flies_and_flies_each_job_once(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """Two workers, seven jobs: every job is flown once; a worker's first job is started by its
    flight, every other one was launched during the flight before it, told to go once that flight's
    processes stopped, and handed to its flight; without ``ahead`` nothing is launched ahead."""
    launched: list[str] = []
    flown: list[tuple[str, str | None]] = []

    def launch_episode(spec: EpisodeSpec, workdir: Path, **kw: Any) -> _Launched:
        assert kw["held"] is True
        launched.append(spec.id)
        return _Launched(spec)

    both = threading.Barrier(2)

    def run_episode(spec: EpisodeSpec, workdir: Path, **kw: Any) -> dict[str, Any]:
        got = kw["launched"]
        if got is None:
            both.wait(10.0)  # each worker's first flight: both workers are at work
        else:
            assert got.went  # its clock started when the flight before it stopped
        flown.append((spec.id, got.spec.id if got is not None else None))
        for _ in range(3):  # the flight's looks: the next job is launched once
            kw["in_flight"]()
        kw["on_stopped"]()
        return {"id": spec.id, "outcome": "landed", "safe": True}

    monkeypatch.setattr(campaign, "launch_episode", launch_episode)
    monkeypatch.setattr(campaign, "run_episode", run_episode)
    jobs = _jobs(tmp_path, 7)
    ex = LocalExecutor(workers=2)
    try:
        got = sorted(e["id"] for e in ex.run(jobs))
    finally:
        ex.close()
    ids = sorted(j.spec.id for j in jobs)
    assert got == ids
    assert sorted(i for i, _ in flown) == ids
    assert sorted(launched) == sorted(i for i, given in flown if given is not None)
    assert all(given in (None, i) for i, given in flown)
    assert sum(given is None for _, given in flown) == 2  # each worker's first
    assert len(set(launched)) == len(launched) == 5

    launched.clear()
    flown.clear()
    ex = LocalExecutor(workers=2, ahead=False)
    try:
        assert len(list(ex.run(_jobs(tmp_path, 4)))) == 4
    finally:
        ex.close()
    assert launched == []
    assert all(given is None for _, given in flown)


def test_a_launch_that_fails_leaves_the_job_to_its_flight_and_a_failed_flight_frees_its_launch(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """Launching ahead fails (no port, say): the job is still flown, started by its flight. A
    launched job whose flight raises before it starts (the harness's own error) has its processes
    discarded, and the try after it starts afresh."""
    tries: list[tuple[int, bool]] = []
    made: list[_Launched] = []

    def launch_episode(spec: EpisodeSpec, workdir: Path, **kw: Any) -> _Launched:
        if spec.seed == 1:
            raise OSError("no port")
        made.append(_Launched(spec))
        return made[-1]

    def run_episode(spec: EpisodeSpec, workdir: Path, **kw: Any) -> dict[str, Any]:
        tries.append((spec.seed, kw["launched"] is not None))
        kw["in_flight"]()
        if spec.seed == 2 and kw["launched"] is not None:
            raise OSError("address in use")
        return {"id": spec.id, "outcome": "landed", "safe": True}

    monkeypatch.setattr(campaign, "launch_episode", launch_episode)
    monkeypatch.setattr(campaign, "run_episode", run_episode)
    ex = LocalExecutor(workers=1)
    try:
        entries = list(ex.run(_jobs(tmp_path, 3)))
    finally:
        ex.close()
    assert [e["outcome"] for e in entries] == ["landed"] * 3
    assert tries == [(0, False), (1, False), (2, True), (2, False)]
    assert [m.spec.seed for m in made] == [2]
    assert made[0].discarded
