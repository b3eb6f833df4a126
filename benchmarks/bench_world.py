"""Sensor rendering cost on one core: camera frame, LiDAR sweep, rangefinder; memory of each kind of place.

Prints medians over several repetitions at several poses per world, with an empty flat grid of the
same size as the baseline measured in the same run (the cost floor of ray setup and shading).

Every kind of procedural place (simbridge ``--place``: downtown, suburb, industrial ...) is timed at
three poses of its seed 0, after the curated scenarios.

Usage: python benchmarks/bench_world.py [--reps 5] [--skip-city] [--places downtown,suburb,...]
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import sys
import time

import numpy as np

from simbridge.geo import euler_to_quat
from simbridge.world.live import LiveWorld
from simbridge.world.model import WorldGrid
from simbridge.world.places import PLACES, generate_place
from simbridge.world.world import World


def _pin() -> None:
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {0})


def _time(fn: object, reps: int) -> float:
    samples = []
    for _ in range(reps):
        t0 = time.perf_counter()
        fn()  # type: ignore[operator]
        samples.append(time.perf_counter() - t0)
    return statistics.median(samples) * 1e3


def bench(
    live: LiveWorld, poses: list[tuple[float, float, float, float]], reps: int
) -> tuple[float, float, float, float]:
    """Medians: camera frame, LiDAR sweep (ms) and rangefinder (us) at one instant; and a camera
    frame at a new instant each time (the actors in reach moved and stamped again, as in flight)."""
    rng = np.random.default_rng(0)
    cam, lid, rf, moving = [], [], [], []
    clock = [0.0]

    def later() -> float:
        clock[0] += 0.25
        return clock[0]

    for n, e, alt, yaw in poses:
        q = euler_to_quat(0.0, 0.0, math.radians(yaw))
        pos = (n, e, -alt)
        live.camera_frame(pos, q, 0.0, "clear", rng)  # warm: compile, shadow tiles
        cam.append(_time(lambda: live.camera_frame(pos, q, 0.0, "clear", rng), reps))  # noqa: B023
        lid.append(_time(lambda: live.lidar_sweep(pos, q, 0.0, rng), reps))  # noqa: B023
        rf.append(_time(lambda: live.rangefinder_m(pos, q), reps) * 1e3)  # noqa: B023
        moving.append(_time(lambda: live.camera_frame(pos, q, later(), "clear", rng), reps))  # noqa: B023
        live.sync(0.0)  # back to the instant the others are timed at (actors never run backwards)
    return statistics.median(cam), statistics.median(lid), statistics.median(rf), statistics.median(moving)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--skip-city", action="store_true", help="no procedural place")
    ap.add_argument("--places", default=",".join(PLACES), help="the kinds of place to time (default all)")
    args = ap.parse_args()
    unknown = set(args.places.split(",")) - set(PLACES)
    if unknown:
        ap.error(f"--places: unknown {', '.join(sorted(unknown))}; known: {', '.join(PLACES)}")
    _pin()
    from simbridge.world.scenario_file import BUILTIN_SCENARIO_DIR, load_scenario_file

    rows = []
    flat = LiveWorld(World(name="empty", seed=0, grid=WorldGrid.empty((-250.0, 250.0), (-250.0, 250.0))))
    poses = [(0.0, 0.0, 110.0, 0.0), (20.0, -30.0, 60.0, 30.0), (-40.0, 40.0, 100.0, 90.0)]
    base = bench(flat, poses, args.reps)
    rows.append(("empty 500 m grid (baseline)", base, flat.grid.memory_bytes(), 0))
    print(f"{rows[-1][0]}: done", flush=True)
    for name in ("scenario1", "scenario2"):
        live = LiveWorld(load_scenario_file(BUILTIN_SCENARIO_DIR / f"{name}.toml", 0))
        rows.append((name, bench(live, poses, args.reps), live.grid.memory_bytes(), len(live.actors.poses())))
        print(f"{name}: done", flush=True)
    for place in [] if args.skip_city else args.places.split(","):
        t0 = time.perf_counter()
        world = generate_place(place, 0)
        gen_s = time.perf_counter() - t0
        live = LiveWorld(world)
        city_poses = [(0.0, 0.0, 110.0, 0.0), (150.0, -200.0, 100.0, 45.0), (-300.0, 250.0, 120.0, 180.0)]
        rows.append(
            (
                f"{place} 1.2 km (seed 0)",
                bench(live, city_poses, args.reps),
                live.grid.memory_bytes(),
                len(live.actors.poses()),
            )
        )
        print(f"{place}: generated in {gen_s:.1f} s", flush=True)
    print(f"\nmedians of {args.reps} repetitions x 3 poses, one core; 960x540 camera, 100x512 LiDAR rays")
    print(
        f"{'world':<30} {'camera ms':>10} {'ratio':>6} {'LiDAR ms':>9} {'ratio':>6} "
        f"{'range us':>9} {'grid MiB':>9} {'moving ms':>10} {'actors':>7}"
    )
    for label, (cam, lid, rf, moving), mem, actors in rows:
        print(
            f"{label:<30} {cam:10.1f} {cam / base[0]:6.2f} {lid:9.1f} {lid / base[1]:6.2f} {rf:9.1f} "
            f"{mem / 2**20:9.0f} {moving:10.1f} {actors:7d}"
        )
    print("moving: a camera frame at a new instant each time (actors in reach moved and stamped again)")
    try:
        import resource

        print(f"peak RSS {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MiB")
    except ImportError:
        pass
    return 0


if __name__ == "__main__":
    sys.exit(main())
