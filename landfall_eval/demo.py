"""``python -m landfall_eval.demo``: a simulated emergency landing, end to end, with the onboard reasoner.

Starts simbridge (PX4 flavour, scenario1, airborne 110 m above the street between two roofs) and
the companion as separate processes wired over loopback UDP and the sensor socket, sends an alarm
with trigger_alarm.py, follows the companion's decisions, and ends with simbridge's ground-truth
verdict. Everything it wrote (episode log, companion log, flight record) stays in ``--out``. The
processes are run by :func:`landfall_eval.episode.run_episode`, as companion-bench runs its episodes.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from landfall_eval.episode import EpisodeSpec, EpisodeTimes, run_episode
from simbridge.warmup import warm_up


def _show(source: str, text: str) -> None:
    if source == "alarm":
        print(f"[demo] trigger_alarm.py: {text}", flush=True)
        return
    if "Landfall" not in text and "companion: " not in text:
        return
    text = text.split("companion: ", 1)[-1]
    if not text.startswith(("companion up", "sensor stream", "recovery ended")):
        print(f"[companion] {text}", flush=True)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    ap.add_argument("--scenario", default="scenario1")
    ap.add_argument("--autopilot", default="px4", choices=("px4", "ardupilot"))
    ap.add_argument("--weather", default="clear", choices=("clear", "fog", "rain"))
    ap.add_argument("--speed", type=float, default=4.0, help="simulation speed (simulated s per wall s)")
    ap.add_argument("--reason", default="GPS spoofing detected")
    ap.add_argument("--criticality", default="high", choices=("low", "high", "critical"))
    ap.add_argument("--out", type=Path, default=Path("runs/demo"))
    ap.add_argument(
        "--time-limit",
        type=float,
        default=600.0,
        help="simulated seconds after the alarm to wait for touchdown",
    )
    args = ap.parse_args(argv)
    if args.speed <= 0 or args.time_limit <= 0:
        ap.error("--speed and --time-limit must be > 0")
    out: Path = args.out
    print(
        f"[demo] simbridge: {args.scenario}, {args.autopilot}, {args.weather}, {args.speed:g}x real time",
        flush=True,
    )
    # a fresh install compiles simbridge's renderer first: done here, said, and out of the episode's
    # start-up budget (on a loaded machine it outlasted the wait for the sensor stream)
    print("[demo] warming up simbridge's renderer (a fresh install compiles it first: 1.5-2.5 min)")
    print(f"[demo] simbridge's renderer ready in {warm_up():.0f} s", flush=True)
    spec = EpisodeSpec(
        "curated", args.scenario, 0, weather=args.weather, autopilot=args.autopilot,
        criticality=args.criticality, reason=args.reason, run=0,
    )  # fmt: skip
    e = run_episode(spec, out, times=EpisodeTimes(speed=args.speed, sim_s=args.time_limit), on_line=_show)
    if e["touchdown_ned_m"] is None:
        print(f"[demo] FAILED: {e['error'] or 'no touchdown'}", file=sys.stderr)
        return 1
    n, east, d = e["touchdown_ned_m"]
    print("\n=== Landfall demo summary ===")
    print(f"alarm        '{args.reason}' ({args.criticality})")
    print(f"touchdown    N {n:.1f} m, E {east:.1f} m, {-d - 0.15:.1f} m up")
    print(f"surface      {e['surface']}")
    print(f"safe         {e['safe']} {e['reasons'] or ''}")
    print(f"rounds       {e['rounds']}")
    if e["time_to_touchdown_s"] is not None:
        print(
            f"sim time     {e['time_to_touchdown_s']:.0f} s from taking control to touchdown "
            f"({e['kinematic_ratio']:.2f}x the vehicle's kinematic limit)"
        )
    print(f"wall time    {e['wall_s']:.0f} s")
    print(f"files        {out}/episode.jsonl, {out}/companion.log, {out}/record/")
    try:
        from landfall_eval.report import ReportError, write_episode_report

        report = write_episode_report(e, out, out / "record")
        print(f"report       {report} (each round's frame, the chosen site, the trajectory)")
    except (ImportError, ReportError, OSError) as exc:
        print(f"report       not written: {exc}")
    return 0 if e["safe"] else 1


if __name__ == "__main__":
    sys.exit(main())
