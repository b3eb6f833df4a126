"""Generation time and grid memory of the procedural city.

Prints the median wall-clock time of several generations of the default 1.2 km city at 0.2 m, the
grid's memory (MiB) and a census of what it holds. The grid must stay within 1.5 GB.

Usage: python benchmarks/bench_city.py [--runs 3] [--size-m 1200] [--res 0.2] [--seed 1]
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from simbridge.world.city import generate_city
from simbridge.world.model import SurfaceClass

MEMORY_LIMIT_BYTES = 1.5e9


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--size-m", type=float, default=1200.0)
    ap.add_argument("--res", type=float, default=0.2)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()

    times = []
    for _ in range(max(args.runs, 1)):
        t0 = time.perf_counter()
        world = generate_city(args.seed, args.size_m, args.res)
        times.append(time.perf_counter() - t0)
        if len(times) < args.runs:
            del world  # free the grid before building the next one
    grid = world.grid
    mem = grid.memory_bytes()
    rows, cols = grid.shape
    print(f"city {args.size_m:.0f} m at {args.res} m/cell: {rows} x {cols} cells")
    runs = ", ".join(f"{t:.2f}" for t in times)
    print(f"generation time: median {statistics.median(times):.2f} s over {len(times)} runs ({runs})")
    print(f"grid memory: {mem / 2**20:.1f} MiB ({mem / 1e9:.3f} GB, limit {MEMORY_LIMIT_BYTES / 1e9:.1f} GB)")
    print(f"last city: {world.description}; {len(world.lanes)} lanes, {len(world.walkways)} walkways")
    counts = np.bincount(grid.cls.ravel(), minlength=len(SurfaceClass))
    for c in SurfaceClass:
        if counts[c]:
            print(f"  {c.name:<13} {100.0 * counts[c] / grid.cls.size:6.2f} %")
    if mem > MEMORY_LIMIT_BYTES:
        raise SystemExit(
            f"grid memory {mem / 1e9:.3f} GB exceeds the {MEMORY_LIMIT_BYTES / 1e9:.1f} GB limit"
        )


if __name__ == "__main__":
    main()
