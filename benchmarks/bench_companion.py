"""Companion latency and memory through real landings (simbridge + companion processes).

A UDP relay sits between simbridge and the companion and timestamps every frame: the benchmark sends
the alarm itself and measures the time until the companion's first SET_POSITION_TARGET_LOCAL_NED
toward the chosen site passes the relay (the first target more than ``TOWARD_M`` from the companion's
first setpoint, the hold where the alarm found the vehicle); the hold setpoint's time is printed too.
The baseline in the same run is the companion's answer time to the alarm command (its COMMAND_ACK).
The companion's RSS is sampled every 0.2 s through the whole landing. The companion runs as deploy/'s
service runs it, keeping a flight record (``--record``); its record's ``sensors`` event says when its
sensor stream is up, and its first round's events say where the time went: the frame (``acquire`` to
``surface_id``), Surface ID and the record's saved frame (to ``rank``), the ranking (to the rank's
exchange), and IPM with the move's start (to ``move``), each in the companion's own monotonic clock.

``--autopilot px4-sitl`` (or ``ardupilot-sitl``) flies real firmware: the alarm goes out once simbridge's
episode log says ``ready`` (the firmware holds at the launch pose).

``--config FILE`` runs the companion with that configuration (e.g. another onboard model).

Goals: alarm -> first setpoint toward the site <= 250 ms on the emulation, <= 350 ms on real firmware;
companion peak RSS <= 250 MB.

Usage: python benchmarks/bench_companion.py [--runs 3] [--speed 4] [--autopilot px4|px4-sitl|...]
       [--config FILE]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import os
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import common as mavlink2

from landfall_eval.episode import SENSORS_UP
from landfall_eval.episode_grade import recorded
from landfall_eval.processes import ProcessSample

ROOT = Path(__file__).resolve().parent.parent
TOWARD_M = 1.0
GOAL_MS = {"emulation": 250.0, "firmware": 350.0}  # alarm -> first setpoint toward the site
STAGES = ("frame", "surface_id", "rank", "to_move")  # the first round, from the record (docstring)


def first_round_ms(record: Path) -> dict[str, float]:
    """The first round's stages in ms (``STAGES``) from a flight record's events.jsonl; those it lacks
    are left out."""
    marks: dict[str, float] = {}
    for path in sorted(record.glob("*/events.jsonl")):
        for line in path.read_text().splitlines():
            ev = json.loads(line)
            key = ev.get("state") if ev.get("kind") == "state" else None
            if ev.get("kind") == "exchange" and ev.get("stage") == "rank":
                key = "ranked"
            if key in ("acquire", "surface_id", "rank", "ranked", "move") and key not in marks:
                marks[key] = float(ev["time_mono_s"])
        break
    order = ("acquire", "surface_id", "rank", "ranked", "move")
    return {
        name: (marks[b] - marks[a]) * 1e3
        for name, a, b in zip(STAGES, order[:-1], order[1:], strict=True)
        if a in marks and b in marks
    }


def _port(kind: int) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Relay(asyncio.DatagramProtocol):
    """simbridge <-> relay <-> companion; notes when the first setpoint leaves the companion."""

    def __init__(self, companion_addr: tuple[str, int]) -> None:
        self.companion_addr = companion_addr
        self.sim_addr: tuple[str, int] | None = None
        self.transport: Any = None
        self.parser = mavlink2.MAVLink(None)
        self.parser.robust_parsing = True
        self.first_setpoint: float | None = None  # any: the hold where the alarm found the vehicle
        self.first_toward: float | None = None  # the first one away from that hold: toward the site
        self._hold: tuple[float, float] | None = None

    def connection_made(self, transport: Any) -> None:
        self.transport = transport

    def datagram_received(self, data: bytes, addr: tuple[str, int]) -> None:
        if addr == self.companion_addr:
            if self.first_toward is None:
                for m in self.parser.parse_buffer(data) or []:
                    if m.get_type() != "SET_POSITION_TARGET_LOCAL_NED":
                        continue
                    if self._hold is None:
                        self.first_setpoint = time.perf_counter()
                        self._hold = (m.x, m.y)
                    elif math.dist(self._hold, (m.x, m.y)) > TOWARD_M:
                        self.first_toward = time.perf_counter()
            if self.sim_addr is not None:
                self.transport.sendto(data, self.sim_addr)
        else:
            self.sim_addr = addr
            self.transport.sendto(data, self.companion_addr)


async def one_run(
    speed: float, autopilot: str = "px4", config: Path | None = None
) -> tuple[float, float, float, float, str, dict[str, float]]:
    comp_port, relay_port, sensors = (
        _port(socket.SOCK_DGRAM),
        _port(socket.SOCK_DGRAM),
        _port(socket.SOCK_STREAM),
    )
    loop = asyncio.get_running_loop()
    relay = Relay(("127.0.0.1", comp_port))
    transport, _ = await loop.create_datagram_endpoint(lambda: relay, local_addr=("127.0.0.1", relay_port))
    with tempfile.TemporaryDirectory() as tmp:
        episode = Path(tmp) / "ep.jsonl"
        sim = await asyncio.create_subprocess_exec(
            sys.executable, "-m", "simbridge", "--scenario", "scenario1", "--speed", str(speed),
            "--autopilot", autopilot,
            "--mavlink", f"udpout:127.0.0.1:{relay_port}", "--sensors", f"127.0.0.1:{sensors}",
            "--episode-log", str(episode), "--log-level", "WARNING", cwd=ROOT,
        )  # fmt: skip
        log = Path(tmp) / "companion.log"
        record = Path(tmp) / "record"
        with log.open("wb") as fh:
            comp = await asyncio.create_subprocess_exec(
                sys.executable, "-m", "companion", "--mavlink", f"udp:{comp_port}",
                "--sensors", f"127.0.0.1:{sensors}", "--record", str(record),
                *(["--config", str(config)] if config else []), stdout=fh, stderr=subprocess.STDOUT,
                cwd=ROOT,
            )  # fmt: skip
        try:
            # the companion's flight record says when its sensor stream is up
            while not recorded(record, SENSORS_UP):
                if comp.returncode is not None:
                    raise RuntimeError(f"the companion exited: {log.read_text()[-2000:]}")
                await asyncio.sleep(0.1)
            while not (episode.exists() and '"ready"' in episode.read_text()):  # noqa: ASYNC110
                await asyncio.sleep(0.2)  # real firmware takes off to the launch pose first
            await asyncio.sleep(2.0)  # a couple of seconds of telemetry, as a vehicle in flight has
            alarm = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            alarm.bind(("127.0.0.1", 0))
            alarm.settimeout(5.0)
            mav = mavlink2.MAVLink(None, 255, 25)
            t_sent = time.perf_counter()
            alarm.sendto(mav.command_long_encode(1, 191, 31010, 0, 1, 1, 0, 0, 0, 0, 0).pack(mav),
                         ("127.0.0.1", comp_port))  # fmt: skip
            await loop.run_in_executor(None, alarm.recvfrom, 4096)
            t_ack = time.perf_counter()
            alarm.close()
            usage = ProcessSample(comp.pid)  # the kernel's high-water mark of resident memory
            deadline = time.monotonic() + 300
            while time.monotonic() < deadline:
                usage.sample()
                if episode.exists() and '"touchdown"' in episode.read_text():
                    break
                await asyncio.sleep(0.2)
            td = next(json.loads(x) for x in episode.read_text().splitlines() if '"touchdown"' in x)
            hold, toward = relay.first_setpoint, relay.first_toward
            if hold is None or toward is None:
                raise RuntimeError("no setpoint toward a site seen")
            verdict = f"{td['surface']} safe={td['safe']}"
            stages = first_round_ms(record)
            return toward - t_sent, hold - t_sent, t_ack - t_sent, usage.peak_rss_mb, verdict, stages
        finally:
            for p in (comp, sim):
                p.terminate()
                await asyncio.wait_for(p.wait(), 10)
            transport.close()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--speed", type=float, default=4.0)
    ap.add_argument("--autopilot", choices=("px4", "ardupilot", "px4-sitl", "ardupilot-sitl"), default="px4")
    ap.add_argument("--config", type=Path, default=None, help="the companion's TOML configuration")
    args = ap.parse_args()
    rows = []
    stage_rows: list[dict[str, float]] = []
    for k in range(args.runs):
        first, hold, ack, rss, verdict, stages = asyncio.run(one_run(args.speed, args.autopilot, args.config))
        rows.append((first, ack, rss, hold))
        stage_rows.append(stages)
        print(
            f"run {k + 1}/{args.runs}: alarm->first setpoint toward the site {first * 1e3:.1f} ms "
            f"(hold setpoint {hold * 1e3:.1f} ms), alarm->ack {ack * 1e3:.1f} ms, "
            f"companion peak RSS {rss:.0f} MB, touchdown {verdict}",
            flush=True,
        )
        print("  first round: " + ", ".join(f"{k} {v:.0f} ms" for k, v in stages.items()), flush=True)
    first = statistics.median(r[0] for r in rows)
    ack = statistics.median(r[1] for r in rows)
    rss = max(r[2] for r in rows)
    hold = statistics.median(r[3] for r in rows)
    goal = GOAL_MS["firmware" if args.autopilot.endswith("-sitl") else "emulation"]
    print(
        f"\nmedian of {args.runs} landings ({args.autopilot}): alarm -> hold setpoint {hold * 1e3:.1f} ms, "
        f"-> first setpoint toward the site {first * 1e3:.1f} ms "
        f"(goal <= {goal:.0f} ms; {first / ack:.1f}x the alarm acknowledgement, {ack * 1e3:.1f} ms)"
    )
    medians = {
        k: statistics.median(r[k] for r in stage_rows) for k in STAGES if all(k in r for r in stage_rows)
    }
    print("first round, medians (record): " + ", ".join(f"{k} {v:.0f} ms" for k, v in medians.items()))
    print(f"companion peak RSS over all landings: {rss:.0f} MB (goal <= 250 MB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
