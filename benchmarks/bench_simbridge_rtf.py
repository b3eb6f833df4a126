"""Real-time factor of simbridge: physics + control + autopilot + MAVLink, on one core.

Prints medians over several runs of:
  1. bare JSBSim F450 stepping (baseline, in this process),
  2. JSBSim + our multicopter controller (in this process),
  3. the full simbridge process (--speed very high) pinned to one core, streaming all telemetry to a
     live pymavlink client that decodes every frame and sends GUIDED position targets at 20 Hz.
Ratios are against the baseline measured in the same run.

With ``--autopilot ardupilot-sitl`` the process is simbridge with real ArduCopter SITL as its child (both
pinned to the one core), ``--start air``: the firmware initialises, arms, climbs to the launch pose and
holds, in lock step with JSBSim at SITL's 600 Hz; the baseline is then bare JSBSim stepped at 600 Hz.
``--autopilot px4-sitl`` does the same with real PX4 (HIL at 250 Hz; baseline bare JSBSim at 250 Hz).
With firmware it also reads the CPU time the firmware process and simbridge's own process took (from
/proc while they run): the firmware's CPU seconds per simulated second are its own floor, the real-time
factor it could reach on a core of its own with a simulator that cost nothing.

Usage: python benchmarks/bench_simbridge_rtf.py [--runs 5] [--sim-seconds 120]
       [--autopilot ardupilot|ardupilot-sitl|px4-sitl]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

os.environ.setdefault("MAVLINK20", "1")

from pymavlink import mavutil

from simbridge.control import Setpoint
from simbridge.geo import GeoOrigin
from simbridge.physics import F450Physics
from simbridge.px4_sitl import SENSOR_HZ as PX4_HIL_HZ
from simbridge.telemetry import DEFAULT_INTERVALS_S
from simbridge.terrain import FlatTerrain
from simbridge.vehicle import Vehicle

SIM_CORE, CLIENT_CORE = 0, 1
FIRMWARE = {"ardupilot-sitl": ("real ArduCopter SITL", 600), "px4-sitl": ("real PX4 SITL", PX4_HIL_HZ)}  # Hz


def _pin(core: int) -> None:
    if hasattr(os, "sched_setaffinity") and core < (os.cpu_count() or 1):
        os.sched_setaffinity(0, {core})


def bench_physics(sim_s: float, dt_s: float = F450Physics.DT_S) -> float:
    p = F450Physics(GeoOrigin(), FlatTerrain())
    p.set_dt(dt_s)
    p.reset((0.0, 0.0, -100.0), 0.0)
    steps = round(sim_s / dt_s)
    t0 = time.perf_counter()
    for _ in range(steps):
        p.step((0.42, 0.42, 0.42, 0.42))
        p.state()
    return sim_s / (time.perf_counter() - t0)


def bench_control(sim_s: float) -> float:
    v = Vehicle(GeoOrigin(), FlatTerrain())
    v.reset((0.0, 0.0, -100.0), 0.0)
    targets = [Setpoint.hold((30.0, 0.0, -100.0)), Setpoint.hold((0.0, 0.0, -100.0))]
    steps = round(sim_s / v.DT_S)
    t0 = time.perf_counter()
    for i in range(steps):
        v.step(targets[(i // 2400) % 2])  # a new target every 20 s simulated
    return sim_s / (time.perf_counter() - t0)


def _free_port() -> int:
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _cpu_s(pid: int) -> float:
    """User + system CPU seconds of a live process (/proc), 0 when it is gone."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return 0.0
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _children(pid: int) -> list[int]:
    out: list[int] = []
    for task in Path(f"/proc/{pid}/task").glob("*"):
        try:
            out += [int(c) for c in (task / "children").read_text().split()]
        except OSError:
            continue
    return out


def bench_process(sim_s: float, autopilot: str = "ardupilot") -> tuple[float, int, dict[str, float]]:
    """Returns (real-time factor, frames the client decoded, CPU seconds of simbridge and of its
    firmware child as last seen while they ran)."""
    port = _free_port()
    sitl = autopilot in FIRMWARE
    with tempfile.TemporaryDirectory() as tmp:
        log = Path(tmp) / "episode.jsonl"
        conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=255, source_component=190)
        cmd = [
            sys.executable, "-m", "simbridge", "--autopilot", autopilot,
            "--speed", "1000" if sitl else "100000",
            "--duration", str(sim_s), "--mavlink", f"udpout:127.0.0.1:{port}", "--episode-log", str(log),
            "--log-level", "WARNING",
        ]  # fmt: skip
        proc = subprocess.Popen(cmd, preexec_fn=lambda: _pin(SIM_CORE))
        decoded = 0
        stop = threading.Event()

        def drive() -> None:
            nonlocal decoded
            conn.wait_heartbeat(timeout=30)
            for msg_id, interval_s in DEFAULT_INTERVALS_S.items():  # every stream at the PX4 defaults
                conn.mav.command_long_send(1, 1, 511, 0, msg_id, interval_s * 1e6, 0, 0, 0, 0, 0)
            if sitl:  # simbridge's own link flies the firmware to the launch pose: just listen
                while not stop.is_set():
                    if conn.recv_match(blocking=True, timeout=0.05) is not None:
                        decoded += 1
                return
            conn.mav.command_long_send(1, 1, 176, 0, 1, 4, 0, 0, 0, 0, 0)  # GUIDED
            last, k = 0.0, 0
            while not stop.is_set():
                if conn.recv_match(blocking=True, timeout=0.01) is not None:
                    decoded += 1
                if time.monotonic() - last > 0.05:
                    last, k = time.monotonic(), k + 1
                    n = 30.0 if (k // 40) % 2 else 0.0
                    conn.mav.set_position_target_local_ned_send(
                        0, 1, 1, 1, 3576, n, 0, -100, 0, 0, 0, 0, 0, 0, 0, 0
                    )

        cpu = {"simbridge": 0.0, "firmware": 0.0}

        def sample() -> None:
            while proc.poll() is None:
                cpu["simbridge"] = max(cpu["simbridge"], _cpu_s(proc.pid))
                kids = _children(proc.pid)
                if kids:
                    cpu["firmware"] = max(cpu["firmware"], sum(_cpu_s(k) for k in kids))
                time.sleep(0.1)

        _pin(CLIENT_CORE)
        t = threading.Thread(target=drive, daemon=True)
        t.start()
        sampler = threading.Thread(target=sample, daemon=True)
        sampler.start()
        proc.wait(timeout=600)
        stop.set()
        t.join(timeout=5)
        sampler.join(timeout=5)
        conn.close()
        stop_event = next(json.loads(x) for x in log.read_text().splitlines() if '"event": "stop"' in x)
        sim_done = float(stop_event["t_s"])
        if stop_event.get("lockstep_wall_s"):  # PX4: the lock step's own pace, from its first answer
            cpu["lockstep_rtf"] = float(stop_event["lockstep_sim_s"]) / float(stop_event["lockstep_wall_s"])
        return sim_done / float(stop_event["wall_s"]), decoded, {**cpu, "sim_s": sim_done}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--sim-seconds", type=float, default=120.0)
    ap.add_argument("--autopilot", choices=("ardupilot", *FIRMWARE), default="ardupilot")
    args = ap.parse_args()
    sitl = args.autopilot in FIRMWARE
    dt = 1.0 / FIRMWARE[args.autopilot][1] if sitl else F450Physics.DT_S
    results: dict[str, list[float]] = {"physics": [], "control": [], "process": []}
    frames = []
    floors: list[float] = []
    shares: list[float] = []
    paces: list[float] = []  # the lock step from the firmware's first answer (PX4)
    for i in range(args.runs):
        _pin(SIM_CORE)
        results["physics"].append(bench_physics(args.sim_seconds, dt))
        results["control"].append(bench_control(args.sim_seconds))
        rtf, n, cpu = bench_process(args.sim_seconds, args.autopilot)
        results["process"].append(rtf)
        frames.append(n)
        extra = ""
        if sitl and cpu["firmware"] > 0:
            floors.append(cpu["sim_s"] / cpu["firmware"])
            shares.append(cpu["firmware"] / (cpu["firmware"] + cpu["simbridge"]))
            extra = (
                f"  CPU: firmware {cpu['firmware']:.1f} s, simbridge {cpu['simbridge']:.1f} s "
                f"for {cpu['sim_s']:.0f} s simulated"
            )
        if "lockstep_rtf" in cpu:
            paces.append(cpu["lockstep_rtf"])
            extra += f"  in lock step {cpu['lockstep_rtf']:.1f}x"
        print(
            f"run {i + 1}/{args.runs}: physics {results['physics'][-1]:7.1f}x  "
            f"+control {results['control'][-1]:6.1f}x  full process {rtf:6.1f}x  ({n} frames decoded){extra}",
            flush=True,
        )
    med = {k: statistics.median(v) for k, v in results.items()}
    base = med["physics"]
    print(f"\nmedian of {args.runs} runs, {args.sim_seconds:.0f} s simulated each, one core:")
    rows = (
        (f"bare JSBSim F450 at {1 / dt:.0f} Hz (baseline)", med["physics"]),
        ("JSBSim + controller (120 Hz)", med["control"]),
        (
            f"simbridge + {FIRMWARE[args.autopilot][0]} (lock step)"
            if sitl
            else "simbridge process (+autopilot, MAVLink)",
            med["process"],
        ),
    )
    for label, value in rows:
        print(f"  {label:<46} {value:7.1f}x real time  ratio {value / base:.2f}")
    if paces:
        pace = statistics.median(paces)
        label = "the same from the firmware first answering"
        print(f"  {label:<46} {pace:7.1f}x real time  ratio {pace / base:.2f}")
    if sitl:
        print("  (the firmware initialises, arms and climbs to the launch pose in this time)")
        if paces:
            verdict = "met" if statistics.median(paces) >= 10 else "NOT met"
            print(f"  goal >= 10x in lock step on one core: {verdict}")
        if floors:
            floor, share = statistics.median(floors), 100 * statistics.median(shares)
            print(
                f"  the firmware's own floor: {floor:.1f}x real time on a core of its own (simulated s per "
                f"CPU s of the firmware process); it took {share:.0f} % of the CPU both processes used"
            )
    else:
        print(f"  goal >= 50x for the full process: {'met' if med['process'] >= 50 else 'NOT met'}")
    print(f"  client decoded a median of {statistics.median(frames):.0f} MAVLink frames per run")
    return 0


if __name__ == "__main__":
    sys.exit(main())
