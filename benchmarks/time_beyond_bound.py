"""Where a campaign's time beyond the kinematic bound goes, episode by episode.

Reads a ``companion-bench city`` run (its results.json, and each episode's flight record and episode
log) and splits each safe landing's alarm-to-touchdown time beyond its kinematic lower bound into:

- looks: the companion's states that wait on a frame or think (acquire, Surface ID, rank, confirm),
  from the flight record's wall-clock state changes times the run's ``--speed``;
- final approach: the autopilot's land mode (the ``land`` state) beyond what the same height would
  take at the bound's own limits (the height above ground when the land mode was asked for);
- the rest: transit and descent steps not flown at the limits (stops between steps, arrivals, searches).

Prints one line per episode and the median of each part. Looks are wall seconds times the speed: at
``--speed 4`` a second of thinking costs four simulated seconds, at ``--speed 1`` one.

Usage: python benchmarks/time_beyond_bound.py RUN_DIR [--json]
"""

from __future__ import annotations

import argparse
import json
import statistics
from collections import Counter
from pathlib import Path
from typing import Any

from landfall_eval.episode_grade import record_events
from landfall_eval.grading import trapezoid_time_s
from landfall_eval.processes import JsonlTail
from simbridge.control import ControlLimits

LOOK_STATES = ("acquire", "surface_id", "rank", "confirm")
PARTS = ("excess_s", "looks_s", "final_approach_s", "rest_s")


def _log_rows(path: Path) -> list[dict[str, Any]]:
    """simbridge's episode log, read as the harness reads it."""
    tail = JsonlTail(path)
    try:
        return tail.lines()
    finally:
        tail.close()


def split_episode(episode: dict[str, Any], folder: Path, speed: float) -> dict[str, Any] | None:
    """One safe landing's excess over its bound in parts; None when its record or log is missing."""
    log_path = folder / "episode.jsonl"
    if not log_path.exists() or not episode.get("safe"):
        return None
    events = record_events(folder / "record")
    states = [(float(r["time_mono_s"]), str(r["state"])) for r in events if r.get("kind") == "state"]
    ends = [float(r["time_mono_s"]) for r in events if r.get("kind") == "outcome"]
    if not states or not ends:
        return None
    sim_s: Counter[str] = Counter()
    for (t, state), t_next in zip(states, [t for t, _ in states[1:]] + ends[:1], strict=True):
        sim_s[state] += (t_next - t) * speed
    log = _log_rows(log_path)
    switched = next((r["t_s"] for r in log if r["event"] == "mode" and "LAND" in str(r["mode"])), None)
    if switched is None:
        return None
    height = min((abs(r["t_s"] - switched), r["agl_m"]) for r in log if r["event"] == "state")[1]
    lim = ControlLimits()
    final = sim_s["land"] - trapezoid_time_s(
        max(float(height), 0.0), lim.max_speed_down_m_s, lim.max_accel_z_m_s2
    )
    excess = float(episode["time_to_touchdown_s"]) - float(episode["kinematic_lower_bound_s"])
    looks = sum(sim_s[s] for s in LOOK_STATES)
    return {
        "id": episode["id"],
        "rounds": episode.get("rounds"),
        "kinematic_ratio": episode["kinematic_ratio"],
        "bound_s": round(float(episode["kinematic_lower_bound_s"]), 2),
        "excess_s": round(excess, 2),
        "looks_s": round(looks, 2),
        "land_height_m": round(float(height), 2),
        "final_approach_s": round(final, 2),
        "rest_s": round(excess - looks - final, 2),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path, help="a companion-bench city --out folder")
    ap.add_argument("--json", action="store_true", help="the per-episode table and medians as JSON")
    args = ap.parse_args()
    results = json.loads((args.run / "results.json").read_text(encoding="utf-8"))
    speed = float(results["config"]["speed"])
    rows = [
        row
        for e in results["episodes"]
        if (row := split_episode(e, args.run / "episodes" / str(e["id"]), speed)) is not None
    ]
    if not rows:
        raise SystemExit(f"{args.run}: no safe landing with a flight record and an episode log")
    medians = {k: round(statistics.median(float(r[k]) for r in rows), 2) for k in ("kinematic_ratio", *PARTS)}
    if args.json:
        print(json.dumps({"speed": speed, "episodes": rows, "median": medians}, indent=1))
        return
    print(f"{args.run}: --speed {speed:g}, {len(rows)} safe landings with records")
    print(f"{'episode':40} {'ratio':>6} {'bound':>6} {'excess':>7} {'looks':>6} {'final':>6} {'rest':>6}")
    for r in rows:
        print(
            f"{r['id']:40} {r['kinematic_ratio']:6.2f} {r['bound_s']:6.1f} {r['excess_s']:7.1f} "
            f"{r['looks_s']:6.1f} {r['final_approach_s']:6.1f} {r['rest_s']:6.1f}"
        )
    print("median: " + ", ".join(f"{k} {v:g}" for k, v in medians.items()))


if __name__ == "__main__":
    main()
