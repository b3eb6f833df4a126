"""Surface ID cost per 960 x 540 frame on one core, with LiDAR depth (the default source).

Frames: simbridge renders of scenario1 and scenario2 at their launch poses (camera
image + one LiDAR sweep each). Timed: the whole of ``propose`` (LiDAR projection and densification,
plane-fit flatness, components, geometry, boxes); also each stage. Medians of ``--reps`` repetitions.

Baseline, measured in the same run: the same plane fits done directly, one least-squares solve per
window over its measured points (numpy, batched with ``sliding_window_view``), instead of the running
sums of point moments that Surface ID uses. Printed as the ratio baseline / ours for the flatness
stage, after checking both give the same slopes.

Goal: <= 30 ms per frame (median) for the whole of ``propose``.

Usage: python benchmarks/bench_surface_id.py [--reps 30]
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

import numpy as np

from companion.perception.depth import LidarDepth
from companion.perception.flatness import cell_points, flatness
from companion.perception.surface_id import SurfaceParams
from landfall_eval.surfaces import LaunchFrame, launch_frame, propose_on
from landfall_eval.timing import median_ms, pin_one_core

GOAL_MS = 30.0


def direct_slopes(lf: LaunchFrame, window: int) -> np.ndarray:
    """Baseline: one explicit least-squares plane per window over its measured cells."""
    dm = LidarDepth().depth_map(lf.camera, lidar_frd=lf.lidar_frd)
    ned = cell_points(dm, lf.camera, lf.quat_wxyz)
    fit = dm.measured & dm.valid
    pad = window // 2
    p = np.pad(np.where(fit[..., None], ned, 0.0), ((pad, pad), (pad, pad), (0, 0)))
    w = np.pad(fit, pad).astype(np.float64)
    win_p = np.lib.stride_tricks.sliding_window_view(p, (window, window), axis=(0, 1))  # r, c, 3, k, k
    win_w = np.lib.stride_tricks.sliding_window_view(w, (window, window))  # r, c, k, k
    rows, cols = dm.shape
    a = np.stack([win_p[:, :, 0] * win_w, win_p[:, :, 1] * win_w, win_w], axis=-1).reshape(
        rows, cols, window * window, 3
    )
    b = (win_p[:, :, 2] * win_w).reshape(rows, cols, window * window)
    ata = np.einsum("rcki,rckj->rcij", a, a) + np.eye(3) * 1e-9
    atb = np.einsum("rcki,rck->rci", a, b)
    coef = np.linalg.solve(ata, atb[..., None])[..., 0]
    return np.degrees(np.arctan(np.hypot(coef[..., 0], coef[..., 1])))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=30)
    args = ap.parse_args(argv)
    pin_one_core()
    params = SurfaceParams()
    frames = [launch_frame("scenario1", 0), launch_frame("scenario2", 0)]
    print(f"Surface ID per frame, LiDAR depth, one core, median of {args.reps}")
    print(f"{'frame':<11}{'returns':>8}{'depth ms':>10}{'flatness ms':>13}{'propose ms':>12}"
          f"{'direct fit ms':>15}{'ratio':>7}{'candidates':>12}")  # fmt: skip
    totals = []
    for lf in frames:
        src = LidarDepth(cell_px=params.cell_px)
        dm = src.depth_map(lf.camera, lidar_frd=lf.lidar_frd)
        t_depth = median_ms(
            lambda lf=lf, src=src: src.depth_map(lf.camera, lidar_frd=lf.lidar_frd), args.reps
        )
        t_flat = median_ms(lambda lf=lf, dm=dm: flatness(dm, lf.camera, lf.quat_wxyz), args.reps)

        def whole(lf: LaunchFrame = lf, src: LidarDepth = src) -> Any:
            return propose_on(lf, src, params)

        t_all = median_ms(whole, args.reps)
        t_direct = median_ms(lambda lf=lf: direct_slopes(lf, params.window_cells), max(3, args.reps // 5))
        ours = flatness(dm, lf.camera, lf.quat_wxyz).slope_deg
        ref = direct_slopes(lf, params.window_cells)
        both = np.isfinite(ours)
        agree = float(np.nanmax(np.abs(ours[both] - ref[both])))
        if agree > 0.05:
            print(f"slopes disagree with the direct fit by {agree:.3f} deg", file=sys.stderr)
            return 1
        cands, _ = whole()
        totals.append(t_all)
        print(f"{lf.scenario:<11}{len(lf.lidar_frd):>8}{t_depth:>10.1f}{t_flat:>13.1f}{t_all:>12.1f}"
              f"{t_direct:>15.1f}{t_direct / t_flat:>6.1f}x{len(cands):>12}")  # fmt: skip
    worst = max(totals)
    verdict = "met" if worst <= GOAL_MS else "NOT met"
    print(f"slowest frame {worst:.1f} ms per frame: goal <= {GOAL_MS:.0f} ms {verdict}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
