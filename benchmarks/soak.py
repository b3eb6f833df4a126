"""Soak: one companion daemon, many alarms and landings; does it leak?

One ``companion`` process runs for the whole soak (with a flight record). Each episode starts a
fresh ``simbridge`` (the simulator's reset: a new autopilot boot with a full battery at the launch
point; scenario1/scenario2 and PX4/ArduPilot in turn, seeded by the episode number) on the same
MAVLink and sensor ports, sends an alarm with ``trigger_alarm.py``, waits for simbridge's touchdown
and the companion's "recovery ended", samples the companion's resident memory, open file descriptors
and threads from /proc, and stops that simbridge. The companion meets each new autopilot as a
vehicle that rebooted: its sensor client reconnects, its routes follow the new peer.

Growth is measured from the end of the first episode (which pays for the first imports, the
onboard reasoner's tables and the allocator's arenas) to the end of the last. Goals: RSS
growth < 10 %, no file-descriptor growth, every landing safe. Exit status 0 when all are met.

Usage: python benchmarks/soak.py [--episodes 50] [--speed 4] [--out runs/soak]
"""

from __future__ import annotations

import argparse
import json
import os
import re
import signal
import socket
import statistics
import subprocess
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from landfall_eval.processes import JsonlTail, free_port, send_alarm, sped_up_env, stop_process  # noqa: E402

RSS_GROWTH_GOAL = 0.10
EPISODE_WALL_S = 300.0  # one landing at 4x takes 20-60 s of wall time


@dataclass
class Sample:
    episode: int
    scenario: str
    autopilot: str
    outcome: str
    surface: str | None
    safe: bool | None
    wall_s: float
    rss_mb: float
    fds: int
    threads: int


HELD_SAMPLES = 8  # file descriptors count when held through this many samples ...
HELD_EVERY_S = 0.25  # ... this far apart


def proc_figures(pid: int, simulator_port: int | None = None) -> tuple[float, int, int]:
    """Resident memory (MB), open file descriptors and threads of ``pid`` (Linux /proc).

    The file descriptors counted are those held through ``HELD_SAMPLES`` looks ``HELD_EVERY_S`` apart,
    less the companion's TCP connection to the simulator's sensor port ``simulator_port``: with its
    simulator stopped, the sensor client holds that connection until it notices, then tries to
    reconnect, each try's socket living for a moment, so a look counts one of them or none by chance (a
    soak's 3 episodes read 7, 8, 8 that way). A leaked descriptor is held throughout and counted (a socket
    by its inode, not its number, which a new socket may reuse)."""
    held: set[tuple[str, str]] | None = None
    for k in range(HELD_SAMPLES):
        if k:
            time.sleep(HELD_EVERY_S)
        now = set(_open_files(pid))
        held = now if held is None else held & now
    to_sim = _sockets_to(simulator_port) if simulator_port is not None else set()
    counted = [f for f in held or () if f[1] not in to_sim]
    status = Path(f"/proc/{pid}/status").read_text()
    rss = int(re.search(r"VmRSS:\s+(\d+)", status).group(1)) / 1024  # type: ignore[union-attr]
    threads = int(re.search(r"Threads:\s+(\d+)", status).group(1))  # type: ignore[union-attr]
    return rss, len(counted), threads


def _open_files(pid: int) -> list[tuple[str, str]]:
    """(descriptor, what it is: a path or socket:[inode]) of ``pid``."""
    out = []
    for fd in os.listdir(f"/proc/{pid}/fd"):
        try:
            out.append((fd, os.readlink(f"/proc/{pid}/fd/{fd}")))
        except FileNotFoundError:  # closed since the listing
            continue
    return out


def _sockets_to(port: int) -> set[str]:
    """``socket:[inode]`` of every TCP socket on this machine whose remote port is ``port``."""
    out = set()
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        try:
            rows = Path(table).read_text().splitlines()[1:]
        except OSError:
            continue
        for row in rows:
            cols = row.split()
            if len(cols) > 9 and int(cols[2].rsplit(":", 1)[1], 16) == port:
                out.add(f"socket:[{cols[9]}]")
    return out


def _slope(ys: list[float]) -> float:
    """Least-squares slope of ``ys`` against their index (0 for fewer than two points)."""
    if len(ys) < 2:
        return 0.0
    return float(statistics.linear_regression(range(len(ys)), ys).slope)


def _log_count(path: Path, text: str) -> int:
    return path.read_text(errors="replace").count(text)


def run_episode(k: int, comp: subprocess.Popen[bytes], comp_log: Path, udp: int, tcp: int,
                speed: float, out: Path) -> Sample:  # fmt: skip
    scenario = ("scenario1", "scenario2")[k % 2]
    autopilot = ("px4", "px4", "ardupilot", "ardupilot")[k % 4]
    episode_log = out / "episodes" / f"ep{k:03d}.jsonl"
    sim_cmd = [
        sys.executable, "-m", "simbridge", "--scenario", scenario, "--seed", str(k), "--autopilot",
        autopilot, "--speed", f"{speed:g}", "--mavlink", f"udpout:127.0.0.1:{udp}", "--sensors",
        f"127.0.0.1:{tcp}", "--episode-log", str(episode_log), "--log-level", "WARNING",
    ]  # fmt: skip
    ended_before = _log_count(comp_log, "recovery ended")
    t0 = time.monotonic()
    with (out / "simbridge.log").open("ab") as err:
        sim = subprocess.Popen(sim_cmd, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=err)
    tail = JsonlTail(episode_log)
    touchdown: dict[str, Any] | None = None
    outcome = "landed"
    try:
        res = send_alarm(udp, f"soak alarm {k}", "high", time.monotonic() + 90)
        if res.returncode != 0:
            outcome = "alarm refused: " + (res.stdout or res.stderr).strip()[:120]
        while outcome == "landed":
            for row in tail.lines():
                if row.get("event") == "touchdown" and touchdown is None:
                    touchdown = row
            if touchdown is not None and _log_count(comp_log, "recovery ended") > ended_before:
                break
            if comp.poll() is not None:
                outcome = "companion exited"
            elif sim.poll() is not None:
                outcome = "simbridge exited"
            elif time.monotonic() - t0 > EPISODE_WALL_S:
                outcome = "timeout"
            time.sleep(0.25)
    finally:
        stop_process(sim)
        tail.close()
    wall = time.monotonic() - t0
    rss, fds, threads = proc_figures(comp.pid, tcp) if comp.poll() is None else (0.0, 0, 0)
    return Sample(
        k, scenario, autopilot, outcome,
        touchdown.get("surface") if touchdown else None,
        touchdown.get("safe") if touchdown else None,
        round(wall, 1), round(rss, 1), fds, threads,
    )  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    ap.add_argument("--episodes", type=int, default=50)
    ap.add_argument("--speed", type=float, default=4.0)
    ap.add_argument("--out", type=Path, default=ROOT / "runs" / "soak")
    args = ap.parse_args(argv)
    if args.episodes < 2:
        ap.error("--episodes must be >= 2 (growth is measured from the end of the first)")
    out: Path = args.out
    (out / "episodes").mkdir(parents=True, exist_ok=True)
    for stale in (out / "companion.log", out / "simbridge.log"):
        stale.unlink(missing_ok=True)
    udp, tcp = free_port(socket.SOCK_DGRAM), free_port(socket.SOCK_STREAM)
    comp_cmd = [sys.executable, "-m", "companion", "--mavlink", f"udp:{udp}", "--sensors",
                f"127.0.0.1:{tcp}", "--record", str(out / "record")]  # fmt: skip
    env = {**os.environ, **sped_up_env(args.speed)}
    comp_log = out / "companion.log"
    t_start = time.monotonic()
    with comp_log.open("wb") as fh:
        comp = subprocess.Popen(comp_cmd, cwd=ROOT, env=env, stdout=fh, stderr=subprocess.STDOUT)
    samples: list[Sample] = []
    try:
        time.sleep(2.0)
        start_rss, start_fds, start_threads = proc_figures(comp.pid, tcp)
        print(f"companion pid {comp.pid}: {start_rss:.1f} MB, {start_fds} fds, {start_threads} threads "
              f"at start; {args.episodes} episodes at {args.speed:g}x", flush=True)  # fmt: skip
        print(" ep  scenario   autopilot  outcome  surface           safe  wall s  RSS MB  fds  threads")
        for k in range(args.episodes):
            s = run_episode(k, comp, comp_log, udp, tcp, args.speed, out)
            samples.append(s)
            safe_word = "yes" if s.safe else "no"
            print(f"{k:3d}  {s.scenario:9s}  {s.autopilot:9s}  {s.outcome[:7]:7s}  {s.surface or '-':16s}  "
                  f"{safe_word:4s}  {s.wall_s:6.1f}  {s.rss_mb:6.1f}  {s.fds:3d}  {s.threads:7d}",
                  flush=True)  # fmt: skip
            if comp.poll() is not None:
                break
    finally:
        comp.send_signal(signal.SIGTERM)
        try:
            comp_rc = comp.wait(timeout=20)
        except subprocess.TimeoutExpired:
            comp.kill()
            comp_rc = comp.wait()
    first, last = samples[0], samples[-1]
    growth = (last.rss_mb - first.rss_mb) / first.rss_mb if first.rss_mb else float("inf")
    safe = sum(1 for s in samples if s.safe)
    summary = {
        "episodes": len(samples),
        "speed": args.speed,
        "safe_landings": safe,
        "rss_mb": {
            "start": round(start_rss, 1),
            "after_first": first.rss_mb,
            "after_last": last.rss_mb,
            "max": max(s.rss_mb for s in samples),
        },
        "rss_growth": round(growth, 4),
        "fds": {
            "start": start_fds,
            "after_first": first.fds,
            "after_last": last.fds,
            "max": max(s.fds for s in samples),
        },
        "threads": {
            "start": start_threads,
            "after_first": first.threads,
            "after_last": last.threads,
            "max": max(s.threads for s in samples),
        },
        "rss_slope_mb_per_episode": round(_slope([s.rss_mb for s in samples[1:]]), 4),
        "median_episode_wall_s": statistics.median(s.wall_s for s in samples),
        "wall_s": round(time.monotonic() - t_start, 1),
        "companion_exit_status": comp_rc,
        "samples": [asdict(s) for s in samples],
    }
    ok = (
        len(samples) == args.episodes
        and safe == args.episodes
        and growth < RSS_GROWTH_GOAL
        and last.fds <= first.fds
        and comp_rc == 0
    )
    summary["goals_met"] = ok
    (out / "soak.json").write_text(json.dumps(summary, indent=1) + "\n")
    print(
        f"\n{safe}/{len(samples)} safe landings in one daemon lifetime ({summary['wall_s'] / 60:.1f} min); "
        f"RSS {first.rss_mb:.1f} MB after the first episode -> {last.rss_mb:.1f} MB after the last "
        f"({growth:+.1%}, goal < {RSS_GROWTH_GOAL:.0%}; trend after the first "
        f"{summary['rss_slope_mb_per_episode']:+.3f} MB per episode); fds {first.fds} -> {last.fds}; threads "
        f"{first.threads} -> {last.threads}; companion exit status {comp_rc}; "
        f"{'goals met' if ok else 'GOALS NOT MET'} ({out / 'soak.json'})"
    )
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
