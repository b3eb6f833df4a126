"""Figures of the search over a companion-bench campaign: what the launch point was, where it
landed, how long it searched and what it cost.

    python benchmarks/search_campaign.py runs/campaign [--min-legs 1]

Reads DIR/results.json and each episode's files (episode.jsonl: simbridge's ground truth; record/: the
companion's flight record) and prints: safe landings; landings on water or a road or highway, and of
those the ones made while the battery was above its reserve (no ``search_end`` for the battery before
them); episodes without a touchdown; rounds (mean, median, max); search legs; time from taking control
to touchdown (median, max); battery used (at control to touchdown, median, max); per launch surface
(what lies under the launch point: ``simbridge``'s world, for launches over water, highways and roads);
and each episode that searched (legs > 0).
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
from pathlib import Path
from typing import Any

ENGAGED = ("OFFBOARD", "GUIDED")
BAD = ("water", "road", "highway")


def _jsonl(path: Path) -> list[dict[str, Any]]:
    if not path.is_file():
        return []
    out = []
    for line in path.read_text().splitlines():
        try:
            out.append(json.loads(line))
        except json.JSONDecodeError:
            continue
    return out


def _record(episode_dir: Path) -> list[dict[str, Any]]:
    events: list[dict[str, Any]] = []
    for path in sorted(episode_dir.glob("record/*/events.jsonl")):
        events += _jsonl(path)
    return events


def _launch_surface(entry: dict[str, Any], worlds: dict[int, Any]) -> str:
    """The ground truth's class under the launch point (a city episode), e.g. ``water``."""
    seed, ned = entry.get("city_seed"), entry.get("launch_ned_m")
    if seed is None or not ned:
        return "?"
    from simbridge.world.city import generate_city
    from simbridge.world.model import SurfaceClass

    if seed not in worlds:
        worlds[seed] = generate_city(int(seed))
    cls = worlds[seed].grid.class_at(float(ned[0]), float(ned[1]))
    return str(SurfaceClass(cls).name.lower())


def episode_figures(entry: dict[str, Any], episode_dir: Path, worlds: dict[int, Any]) -> dict[str, Any]:
    log = _jsonl(episode_dir / "episode.jsonl")
    engaged = next((e for e in log if e.get("event") == "mode" and e.get("mode") in ENGAGED), None)
    touchdown = next((e for e in log if e.get("event") == "touchdown"), None)
    states = [e for e in log if e.get("event") == "state" and isinstance(e.get("battery_pct"), int | float)]
    t0 = float(engaged["t_s"]) if engaged else None
    t1 = float(touchdown["t_s"]) if touchdown else None

    def battery_at(t: float | None) -> float | None:
        if t is None or not states:
            return None
        return float(min(states, key=lambda e: abs(float(e["t_s"]) - t))["battery_pct"])

    b0, b1 = battery_at(t0), battery_at(t1)
    record = _record(episode_dir)
    ends = [e for e in record if e.get("kind") == "search_end"]
    return {
        "id": entry["id"],
        "launch_surface": _launch_surface(entry, worlds),
        "surface": entry.get("surface"),
        "safe": bool(entry.get("safe")),
        "touchdown": touchdown is not None,
        "rounds": entry.get("rounds"),
        "legs": sum(1 for e in record if e.get("kind") == "search_leg"),
        "instead": sum(1 for e in record if e.get("kind") == "search_instead"),
        "search_end": ends[0].get("reason") if ends else None,
        "battery_end": bool(ends) and str(ends[0].get("reason", "")).startswith("battery"),
        "control_to_touchdown_s": None if t0 is None or t1 is None else t1 - t0,
        "battery_used_pct": None if b0 is None or b1 is None else b0 - b1,
        "battery_at_touchdown_pct": b1,
    }


def _stats(values: list[float]) -> str:
    if not values:
        return "-"
    return (
        f"mean {statistics.fmean(values):.2f}, median {statistics.median(values):.1f}, max {max(values):.1f}"
    )


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("dir", type=Path, help="a companion-bench output folder (results.json, episodes/)")
    args = p.parse_args(argv)
    results = json.loads((args.dir / "results.json").read_text())
    worlds: dict[int, Any] = {}
    rows = [episode_figures(e, args.dir / "episodes" / e["id"], worlds) for e in results["episodes"]]
    n = len(rows)
    safe = sum(r["safe"] for r in rows)
    bad = [r for r in rows if r["surface"] in BAD]
    bad_above_reserve = [r for r in bad if not r["battery_end"]]
    print(f"episodes {n}: safe {safe} ({100 * safe / max(n, 1):.1f} %)")
    print(
        f"landings on water, roads or highways: {len(bad)}; of those with the battery above its reserve: "
        f"{len(bad_above_reserve)} {[r['id'] for r in bad_above_reserve]}"
    )
    print(f"without touchdown: {sum(not r['touchdown'] for r in rows)}")
    print(f"rounds: {_stats([float(r['rounds']) for r in rows if r['rounds'] is not None])}")
    print(
        f"search legs: {_stats([float(r['legs']) for r in rows])}; episodes with a leg: "
        f"{sum(r['legs'] > 0 for r in rows)}; sites struck off from afar: {sum(r['instead'] for r in rows)}"
    )
    ends: dict[str, int] = {}
    for r in rows:
        if r["search_end"]:
            key = r["search_end"].split(":")[0] if r["battery_end"] else r["search_end"]
            ends[key] = ends.get(key, 0) + 1
    print(f"searches ended by the battery or the window: {ends or 'none'}")
    times = [r["control_to_touchdown_s"] for r in rows if r["control_to_touchdown_s"] is not None]
    print(f"control to touchdown, s: {_stats(times)}")
    used = [r["battery_used_pct"] for r in rows if r["battery_used_pct"] is not None]
    left = [r["battery_at_touchdown_pct"] for r in rows if r["battery_at_touchdown_pct"] is not None]
    print(f"battery used, %: {_stats(used)}; lowest at touchdown {min(left, default=None)}")
    by_launch: dict[str, list[dict[str, Any]]] = {}
    for r in rows:
        by_launch.setdefault(r["launch_surface"], []).append(r)
    print("by the surface under the launch point:")
    for surface, group in sorted(by_launch.items()):
        s = sum(r["safe"] for r in group)
        rounds = _stats([float(r["rounds"]) for r in group if r["rounds"] is not None])
        landed = sorted({str(r["surface"]) for r in group})
        legs = sum(r["legs"] for r in group)
        print(
            f"  {surface:14s} {len(group):3d} episodes, safe {s}, rounds {rounds}, legs {legs}, "
            f"landed on {landed}"
        )
    print("episodes that searched:")
    for r in rows:
        if r["legs"]:
            t = r["control_to_touchdown_s"]
            print(
                f"  {r['id']}: over {r['launch_surface']}, {r['legs']} legs, {r['rounds']} rounds, "
                f"{t:.0f} s, battery used {r['battery_used_pct']:.1f} %, landed on {r['surface']}"
                f" ({'safe' if r['safe'] else 'UNSAFE'})"
                if t is not None and r["battery_used_pct"] is not None
                else f"  {r['id']}: {r['legs']} legs, landed on {r['surface']}"
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
