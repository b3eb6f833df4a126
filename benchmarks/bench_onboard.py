"""Onboard reasoning tier cost on one core: rank of 5 crops, confirm of one close-up.

Frames: simbridge renders of scenario1 (clear weather). Rank: the launch frame (110 m above Quay
Street) and its LiDAR sweep through Surface ID (``propose``), whose candidates' boxes are the crops
(5 of them, a clear roof and slivers of the cluttered one), ranked with their geometry and from the
images alone. Confirm: a 960 x 540 close-up 30 m above the clear roof with the LiDAR site check.
Timed: ``OnboardReasoner.rank_sync`` and ``confirm_sync`` (image cues included), medians of ``--reps``.
Single-threaded: this process is pinned to one CPU, OpenCV runs one thread, BLAS/OpenMP one.

Baseline, measured in the same run: with the cues, the same analysis without the working-size reduction
(every crop and the close-up's window analysed at full resolution: ``CueParams.work_area_px`` unbounded); with
``--judge landnet`` (LandNet-S, companion/reasoning/landnet.py, reading every crop and the close-up), the
same net reading each image once instead of with its mirror images (sidecar ``input.views`` for the
confirmation, ``input.rank_views`` for the crops of a rank).
Printed as the ratio baseline / ours, with whether the baseline picks the same site and makes the same
decision.

Goals: rank of 5 crops <= 50 ms, confirm <= 20 ms (medians).

Usage: python benchmarks/bench_onboard.py [--reps 30] [--judge cues|landnet] [--model X.onnx]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")  # before numpy loads its BLAS

import argparse  # noqa: E402
import sys  # noqa: E402
from typing import Any  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from companion.guidance.frames import PinholeCamera  # noqa: E402
from companion.perception.depth import LidarDepth  # noqa: E402
from companion.perception.site_check import check_site  # noqa: E402
from companion.perception.surface_id import propose  # noqa: E402
from companion.reasoning.base import ConfirmRequest, RankRequest  # noqa: E402
from companion.reasoning.image_cues import CueParams  # noqa: E402
from companion.reasoning.landnet import LandNet  # noqa: E402
from companion.reasoning.onboard import JUDGES, OnboardReasoner  # noqa: E402
from landfall_eval.timing import median_ms, pin_one_core  # noqa: E402
from simbridge.geo import euler_to_quat  # noqa: E402
from simbridge.scenarios import load_scenario  # noqa: E402
from simbridge.world.live import LiveWorld  # noqa: E402

RANK_GOAL_MS = 50.0
CONFIRM_GOAL_MS = 20.0
LEVEL = euler_to_quat(0.0, 0.0, 0.0)
LAUNCH = (0.0, 0.0, -110.0)
CLOSE_UP = (0.0, -27.0, -52.0)  # 30 m above the clear roof (22 m)


def _pin() -> None:
    pin_one_core()
    cv2.setNumThreads(1)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--reps", type=int, default=30)
    ap.add_argument("--judge", choices=JUDGES, default="cues", help="what reads the images (default cues)")
    ap.add_argument(
        "--model", default=None, help="--judge landnet: this ONNX model (default: the packaged one)"
    )
    args = ap.parse_args(argv)
    if args.reps < 1:
        ap.error("--reps must be at least 1")
    _pin()
    world = load_scenario("scenario1", 0).terrain
    if not isinstance(world, LiveWorld):
        print("scenario1 has no rendered world", file=sys.stderr)
        return 1
    rng = np.random.default_rng(0)
    frame = world.camera_frame(LAUNCH, LEVEL, 0.0, "clear", rng)
    lidar = world.lidar_sweep(LAUNCH, LEVEL, 0.0, rng)
    cm = world.camera
    camera = PinholeCamera.from_hfov(cm.width_px, cm.height_px, cm.hfov_deg)
    cands, _ = propose(
        LidarDepth(), camera, lidar_frd=lidar, quat_wxyz=LEVEL, pos_ned_m=LAUNCH, ground_up_m=LAUNCH[2]
    )
    crops = tuple(
        np.ascontiguousarray(frame.rgb[y0:y1, x0:x1]) for x0, y0, x1, y1 in (c.box_px for c in cands)
    )
    close = world.camera_frame(CLOSE_UP, LEVEL, 0.0, "clear", rng)
    check = check_site(world.lidar_sweep(CLOSE_UP, LEVEL, 0.0, rng), CLOSE_UP, LEVEL, CLOSE_UP[:2])

    onboard = OnboardReasoner(judge=args.judge, landnet=LandNet.load(args.model) if args.model else None)
    with_geometry = RankRequest(crops, tuple(cands))
    images_only = RankRequest(crops)
    confirm = ConfirmRequest(close.rgb, check)

    def measure(onboard: OnboardReasoner) -> dict[str, Any]:
        return {
            "rank": median_ms(lambda: onboard.rank_sync(with_geometry), args.reps),
            "rank_images": median_ms(lambda: onboard.rank_sync(images_only), args.reps),
            "confirm": median_ms(lambda: onboard.confirm_sync(confirm), args.reps),
            "order": onboard.rank_sync(with_geometry).order,
            "order_images": onboard.rank_sync(images_only).order,
            "accept": onboard.confirm_sync(confirm).accept,
        }

    ours = measure(onboard)
    if onboard.landnet is not None:  # baseline: one reading of each image
        single = LandNet.load(args.model)
        single.views = single.rank_views = 1
        base = measure(OnboardReasoner(judge="landnet", landnet=single))
        views = f"{onboard.landnet.rank_views} to rank, {onboard.landnet.views} to confirm"
        baseline = f"baseline: one view (shipped: {views})"
    else:
        full_size = CueParams(work_area_px=10**9)  # baseline: analyse at full resolution
        base = measure(OnboardReasoner(judge=args.judge, cues=full_size))
        baseline = "baseline: full resolution"

    sizes = ", ".join(f"{c.shape[1]}x{c.shape[0]}" for c in crops)
    print(
        f"Onboard tier ({args.judge}), one core, median of {args.reps}; crops {sizes}; "
        f"close-up 960x540 (site window); {baseline}"
    )
    print(f"{'stage':<26}{'ours ms':>9}{'baseline ms':>13}{'ratio':>8}{'same answer':>13}")
    rows = [
        ("rank, 5 crops + geometry", "rank", ours["order"][0] == base["order"][0]),
        ("rank, 5 crops, images only", "rank_images", ours["order_images"][0] == base["order_images"][0]),
        ("confirm, close-up + LiDAR", "confirm", ours["accept"] == base["accept"]),
    ]
    for label, key, same in rows:
        print(f"{label:<26}{ours[key]:>9.1f}{base[key]:>13.1f}{base[key] / ours[key]:>7.1f}x{same!s:>13}")
    print(f"best site {ours['order'][0]} (images only: {ours['order_images'][0]}); confirm: "
          f"{'accept' if ours['accept'] else 'reject'}")  # fmt: skip
    rank_ok = max(ours["rank"], ours["rank_images"]) <= RANK_GOAL_MS
    confirm_ok = ours["confirm"] <= CONFIRM_GOAL_MS
    print(f"rank goal <= {RANK_GOAL_MS:.0f} ms {'met' if rank_ok else 'NOT met'}; "
          f"confirm goal <= {CONFIRM_GOAL_MS:.0f} ms {'met' if confirm_ok else 'NOT met'}")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
