"""Compile simbridge's numba kernels ahead of a flight: ``python -m simbridge.warmup``.

The ray caster, the shading and the LiDAR sweep are numba kernels cached in the package's
``__pycache__`` (``cache=True``). On a fresh install the first simbridge to render compiles them before
its sensor server opens: 1.5-2.5 minutes on one core (137 s on 2026-12-06), more on a loaded machine,
while the companion waits for a sensor stream. A frame rendered and a sweep cast over scenario1 here
compiles them once; with the cache filled it takes a few seconds (building scenario1, one frame). The
demo runs it first and says so; ``make test`` runs it beside the linters (tests/warmup.py).
"""

from __future__ import annotations

import argparse
import time


def warm_up(scenario: str = "scenario1") -> float:
    """Render one frame and cast one sweep over ``scenario`` from 110 m up; the seconds it took."""
    import numpy as np

    from simbridge.geo import euler_to_quat
    from simbridge.scenarios import load_scenario
    from simbridge.world.live import LiveWorld

    t0 = time.perf_counter()
    world = load_scenario(scenario, 0).terrain
    if not isinstance(world, LiveWorld):
        raise ValueError(f"{scenario}: not a rendered world")
    pose, level = (0.0, 0.0, -110.0), euler_to_quat(0.0, 0.0, 0.0)
    world.camera_frame(pose, level, 0.0, "clear", np.random.default_rng(7))
    world.lidar_sweep(pose, level, 0.0, np.random.default_rng(0))
    return time.perf_counter() - t0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="scenario1", help="the world rendered (default: scenario1)")
    args = ap.parse_args(argv)
    print(f"simbridge's kernels ready in {warm_up(args.scenario):.1f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
