"""``simbridge render``: one sensor frame of a scenario at a pose, written to files."""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np

from simbridge.args import non_negative_seed
from simbridge.geo import euler_to_quat
from simbridge.world.places import DEFAULT_PLACE, PLACES


def _pose(text: str) -> tuple[float, float, float, float]:
    parts = text.split(",")
    if len(parts) != 4:
        raise argparse.ArgumentTypeError(f"--pose: expected N,E,ALT,YAW (m, m, m up, deg), got {text!r}")
    try:
        n, e, alt, yaw = (float(p) for p in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--pose: expected numbers, got {text!r}") from None
    if not all(math.isfinite(v) for v in (n, e, alt, yaw)):
        raise argparse.ArgumentTypeError("--pose: values must be finite")
    return n, e, alt, yaw


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="simbridge render", description=__doc__)
    p.add_argument(
        "--scenario", required=True, help="flat is blind; scenario1, scenario2, city or a .toml path"
    )
    p.add_argument("--seed", type=int, default=0, help="the episode's seed: traffic and sensor noise")
    p.add_argument(
        "--city-seed", type=non_negative_seed, default=0, metavar="N", help="seed of the procedural city"
    )
    p.add_argument(
        "--place", choices=PLACES, default=DEFAULT_PLACE, help="the kind of place --scenario city builds"
    )
    p.add_argument("--weather", choices=("clear", "fog", "rain"), default="clear")
    p.add_argument(
        "--pose",
        type=_pose,
        required=True,
        metavar="N,E,ALT,YAW",
        help="camera position (north, east, metres up from the origin's ground) and heading (deg)",
    )
    p.add_argument("--time", type=float, default=0.0, help="simulated time (moves traffic and pedestrians)")
    p.add_argument("--out", type=Path, required=True, help="RGB image (.png or .jpg)")
    p.add_argument("--depth-out", type=Path, help="z-depth map, metres, 540 x 960 float32 .npy")
    p.add_argument(
        "--lidar-out", type=Path, help="LiDAR points, N x 4 float32 .npy: body FRD x, y, z, intensity"
    )
    return p


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    from simbridge.scenarios import load_scenario
    from simbridge.world.live import LiveWorld

    try:
        scenario = load_scenario(args.scenario, args.seed, city_seed=args.city_seed, place=args.place)
    except ValueError as exc:
        parser.error(str(exc))
    world = scenario.terrain
    if not isinstance(world, LiveWorld):
        parser.error(f"scenario {args.scenario!r} has no world to render (try scenario1, scenario2 or city)")
    n, e, alt, yaw = args.pose
    pos = (n, e, -alt)
    quat = euler_to_quat(0.0, 0.0, math.radians(yaw))
    rng = np.random.default_rng(args.seed)
    t0 = time.perf_counter()
    frame = world.camera_frame(pos, quat, args.time, args.weather, rng)
    render_ms = (time.perf_counter() - t0) * 1e3
    args.out.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(args.out), cv2.cvtColor(frame.rgb, cv2.COLOR_RGB2BGR)):
        parser.error(f"--out: cannot write an image to {args.out} (use .png or .jpg)")
    summary: dict[str, object] = {"image": str(args.out), "render_ms": round(render_ms, 1)}
    if args.depth_out:
        np.save(args.depth_out, frame.depth_m)
        summary["depth"] = str(args.depth_out)
    if args.lidar_out:
        points = world.lidar_sweep(pos, quat, args.time, rng)
        np.save(args.lidar_out, points)
        summary["lidar"] = str(args.lidar_out)
        summary["lidar_points"] = int(points.shape[0])
    summary["rangefinder_m"] = round(world.rangefinder_m(pos, quat), 3)
    print(json.dumps(summary))
    return 0


if __name__ == "__main__":
    sys.exit(main())
