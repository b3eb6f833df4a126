"""``python -m companion.demo``: a simulated emergency landing, end to end, with the onboard reasoner.

Starts simbridge (PX4 flavour, scenario1, airborne 110 m above the street between two roofs) and
the companion as separate processes wired over loopback UDP and the sensor socket, sends an alarm
with trigger_alarm.py, follows the companion's decisions, and ends with simbridge's ground-truth
verdict. Everything it wrote (episode log, companion log, flight record) stays in ``--out``.
"""

from __future__ import annotations

import argparse
import json
import socket
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def _free_port(kind: int) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _events(path: Path) -> list[dict[str, object]]:
    if not path.exists():
        return []
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    ap.add_argument("--scenario", default="scenario1")
    ap.add_argument("--autopilot", default="px4", choices=("px4", "ardupilot"))
    ap.add_argument("--weather", default="clear", choices=("clear", "fog", "rain"))
    ap.add_argument("--speed", type=float, default=4.0, help="simulation speed (simulated s per wall s)")
    ap.add_argument("--reason", default="GPS spoofing detected")
    ap.add_argument("--criticality", default="high", choices=("low", "high", "critical"))
    ap.add_argument("--out", type=Path, default=Path("runs/demo"))
    ap.add_argument("--timeout", type=float, default=300.0, help="wall seconds to wait for the touchdown")
    args = ap.parse_args(argv)
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    episode, comp_log = out / "episode.jsonl", out / "companion.log"
    for stale in (episode, comp_log):
        stale.unlink(missing_ok=True)
    udp, tcp = _free_port(socket.SOCK_DGRAM), _free_port(socket.SOCK_STREAM)
    py = sys.executable
    sim_cmd = [
        py,
        "-m",
        "simbridge",
        "--scenario",
        args.scenario,
        "--autopilot",
        args.autopilot,
        "--weather",
        args.weather,
        "--speed",
        str(args.speed),
        "--mavlink",
        f"udpout:127.0.0.1:{udp}",
        "--sensors",
        f"127.0.0.1:{tcp}",
        "--episode-log",
        str(episode),
        "--log-level",
        "WARNING",
    ]
    comp_cmd = [
        py,
        "-m",
        "companion",
        "--mavlink",
        f"udp:{udp}",
        "--sensors",
        f"127.0.0.1:{tcp}",
        "--record",
        str(out / "record"),
    ]
    print(
        f"[demo] simbridge: {args.scenario}, {args.autopilot}, {args.weather}, {args.speed:g}x real time",
        flush=True,
    )
    sim = subprocess.Popen(sim_cmd, cwd=ROOT)
    with comp_log.open("wb") as fh:
        comp = subprocess.Popen(comp_cmd, stdout=fh, stderr=subprocess.STDOUT, cwd=ROOT)
    t0 = time.monotonic()
    shown = 0
    try:
        while "sensor stream connected" not in comp_log.read_text():
            if time.monotonic() - t0 > 60 or comp.poll() is not None or sim.poll() is not None:
                print(
                    "[demo] FAILED: companion or simbridge did not come up\n" + comp_log.read_text(),
                    file=sys.stderr,
                )
                return 1
            time.sleep(0.2)
        alarm_cmd = [
            py,
            str(ROOT / "trigger_alarm.py"),
            "--mavlink",
            f"udpout:127.0.0.1:{udp}",
            "--reason",
            args.reason,
            "--criticality",
            args.criticality,
        ]
        for _ in range(30):  # the first telemetry may still be on its way: 'refused for now'
            res = subprocess.run(alarm_cmd, capture_output=True, text=True, timeout=30)
            if res.returncode == 0:
                break
            time.sleep(0.5)
        print(f"[demo] trigger_alarm.py: {res.stdout.strip() or res.stderr.strip()}", flush=True)
        if res.returncode != 0:
            return 1
        t_alarm = time.monotonic()
        touchdown: dict[str, object] | None = None
        while time.monotonic() - t_alarm < args.timeout:
            lines = [
                ln for ln in comp_log.read_text().splitlines() if "Landfall" in ln or "companion: " in ln
            ]
            for line in lines[shown:]:
                text = line.split("companion: ", 1)[-1]
                if not text.startswith(("companion up", "sensor stream")):
                    print(f"[companion] {text}", flush=True)
            shown = len(lines)
            found = [e for e in _events(episode) if e.get("event") == "touchdown"]
            if found and "recovery ended" in comp_log.read_text():
                touchdown = found[0]
                break
            time.sleep(0.3)
        if touchdown is None:
            print("[demo] FAILED: no touchdown", file=sys.stderr)
            return 1
        start = next(
            (
                e
                for e in _events(episode)
                if e.get("event") == "mode" and e.get("mode") in ("OFFBOARD", "GUIDED")
            ),
            None,
        )
        log = comp_log.read_text()
        rounds = (
            log.split("recovery ended: ")[-1].split(" after ")[1].split(" ")[0]
            if "recovery ended" in log
            else "?"
        )
        n, e, d = (float(v) for v in touchdown["pos_ned_m"])  # type: ignore[attr-defined]
        print("\n=== Landfall demo summary ===")
        print(f"alarm        '{args.reason}' ({args.criticality})")
        print(f"touchdown    N {n:.1f} m, E {e:.1f} m, {-d - 0.15:.1f} m up")
        print(f"surface      {touchdown['surface']}")
        print(f"safe         {touchdown['safe']} {touchdown['reasons'] or ''}")
        print(f"rounds       {rounds}")
        if start is not None:
            flown = float(str(touchdown["t_s"])) - float(str(start["t_s"]))
            print(f"sim time     {flown:.0f} s from taking control to touchdown")
        print(f"wall time    {time.monotonic() - t_alarm:.0f} s from the alarm")
        print(f"files        {out}/episode.jsonl, {out}/companion.log, {out}/record/")
        return 0 if touchdown["safe"] else 1
    finally:
        for p in (comp, sim):
            if p.poll() is None:
                p.terminate()
                try:
                    p.wait(timeout=10)
                except subprocess.TimeoutExpired:
                    p.kill()


if __name__ == "__main__":
    sys.exit(main())
