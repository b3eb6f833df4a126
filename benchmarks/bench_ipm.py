"""Inverse perspective mapping cost on one core: index build + one nearest query + pixel_to_ned.

The cloud is one synthetic 100 x 512 sweep (51,200 returns) of the simbridge LiDAR pattern: a
downward hemisphere over flat ground 100 m below the vehicle with a 20 x 20 x 30 m box under it. The
camera is the default 960 x 540, 90 deg one; the vehicle is yawed 37 deg and tilted (roll 8, pitch -5).

Baseline, measured in the same run: numpy brute force over the same cloud (project every return,
keep those in the image, argmin of the squared pixel distance to one pixel, rotate to NED). Also
printed: the cost of each further query on a built index against a further brute-force query.

Goal: <= 10 ms for build + query + pixel_to_ned (median of the repetitions).

Usage: python benchmarks/bench_ipm.py [--reps 20]
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import sys
import time
from collections.abc import Callable

import numpy as np

from companion.guidance import LidarPixelIndex, PinholeCamera, pixel_to_ned, quat_to_matrix
from simbridge.geo import euler_to_quat

GOAL_MS = 10.0
CHANNELS, POINTS_PER_RING = 100, 512
GROUND_BELOW_M = 100.0
BOX_HALF_M, BOX_TOP_BELOW_M = 10.0, 70.0  # a 30 m tall box whose roof is 70 m below the vehicle


def _pin() -> None:
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {0})


def synthetic_sweep() -> np.ndarray:
    """(51200, 4) float32 body FRD x, y, z, intensity of a level sweep over ground plus a box."""
    el = np.radians(np.linspace(0.5, 90.0, CHANNELS))
    az = np.linspace(0.0, 2 * math.pi, POINTS_PER_RING, endpoint=False)
    e, a = np.meshgrid(el, az, indexing="ij")
    dirs = np.stack([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)], axis=-1).reshape(-1, 3)
    t = GROUND_BELOW_M / dirs[:, 2]
    # slab test against the box [-h, h] x [-h, h] x [top, ground]
    lo = np.array([-BOX_HALF_M, -BOX_HALF_M, BOX_TOP_BELOW_M])
    hi = np.array([BOX_HALF_M, BOX_HALF_M, GROUND_BELOW_M])
    with np.errstate(divide="ignore", invalid="ignore"):
        t0, t1 = lo / dirs, hi / dirs
    t_near = np.nanmax(np.minimum(t0, t1), axis=1)
    t_far = np.nanmin(np.maximum(t0, t1), axis=1)
    on_box = (t_near <= t_far) & (t_near > 0)
    t = np.where(on_box, t_near, t)
    pts = dirs * t[:, None]
    intensity = np.where(on_box, 0.35, 0.3)
    return np.column_stack([pts, intensity]).astype(np.float32)


def brute_force(
    lidar: np.ndarray, camera: PinholeCamera, u: float, v: float, pos: np.ndarray, rot: np.ndarray
) -> np.ndarray:
    """Baseline: plain numpy over every return, no index."""
    x, y, z = (lidar[:, i].astype(np.float64) for i in range(3))
    front = z > 1e-3
    x, y, z = x[front], y[front], z[front]
    pu = camera.fx * y / z + camera.cx  # camera x = body y
    pv = camera.fy * -x / z + camera.cy  # camera y = -body x
    inside = (pu >= 0) & (pu < camera.width) & (pv >= 0) & (pv < camera.height)
    pu, pv = pu[inside], pv[inside]
    i = int(np.argmin((pu - u) ** 2 + (pv - v) ** 2))
    point = np.array([x[inside][i], y[inside][i], z[inside][i]])
    out: np.ndarray = pos + rot @ point
    return out


def _median_ms(fn: Callable[[], object], reps: int) -> float:
    fn()  # warm
    samples = []
    for _ in range(reps):
        t0 = time.perf_counter()
        fn()
        samples.append(time.perf_counter() - t0)
    return statistics.median(samples) * 1e3


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    ap.add_argument("--reps", type=int, default=20)
    args = ap.parse_args()
    _pin()
    lidar = synthetic_sweep()
    camera = PinholeCamera.from_hfov(960, 540, 90.0)
    pos = np.array([0.0, 0.0, -100.0])
    quat = euler_to_quat(math.radians(8.0), math.radians(-5.0), math.radians(37.0))
    rot = quat_to_matrix(quat)
    u, v = 500.3, 260.7

    def ours() -> np.ndarray:
        index = LidarPixelIndex(lidar, camera)
        return pixel_to_ned(u, v, index, pos, quat)

    def baseline() -> np.ndarray:
        return brute_force(lidar, camera, u, v, pos, rot)

    if not np.allclose(ours(), baseline()):
        print(f"MISMATCH: index gives {ours()}, brute force gives {baseline()}", file=sys.stderr)
        return 1
    index = LidarPixelIndex(lidar, camera)
    ours_ms = _median_ms(ours, args.reps)
    base_ms = _median_ms(baseline, args.reps)
    build_ms = _median_ms(lambda: LidarPixelIndex(lidar, camera), args.reps)
    query_ms = _median_ms(lambda: pixel_to_ned(u, v, index, pos, quat), args.reps)
    affinity = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else "n/a"
    print(f"cloud: {lidar.shape[0]} returns, {len(index)} inside the 960x540 image; cores {affinity}")
    print(f"median of {args.reps} runs, one core:")
    verdict = "meets" if ours_ms <= GOAL_MS else "MISSES"
    print(f"  build + nearest + pixel_to_ned : {ours_ms:8.3f} ms  ({verdict} the {GOAL_MS:g} ms goal)")
    print(f"    of which index build         : {build_ms:8.3f} ms")
    print(f"    of which query + pixel_to_ned: {query_ms:8.3f} ms")
    print(f"  baseline, numpy brute force    : {base_ms:8.3f} ms")
    print(f"  ratio ours / baseline, 1 query : {ours_ms / base_ms:8.2f}")
    # k queries on one frame: ours = build + k * query; brute force = k * baseline
    for k in (5, 10):
        ratio = (build_ms + k * query_ms) / (k * base_ms)
        print(f"  ratio ours / baseline, {k:2d} queries: {ratio:7.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
