"""The landing distance to the intended target, from ground truth (DESIGN.md section 9).

The intended target is what the pixel the companion chose truly shows: the centre pixel of the
candidate it ranked first, cast into simbridge's world from the vehicle's *true* pose when that
frame was captured. The companion places the pixel with the autopilot's estimate and IPM; this
measures everything that puts the touchdown somewhere else (IPM, the estimator's error, the
autopilot's flight). Both harnesses use it: ``companion-bench modules`` on its rendered launch frame
(:func:`pixel_truth_ned`), and ``curated``/``city`` episodes on their flight record and episode log
(:func:`landing_target_ned`). Evaluation only: the companion never sees any of it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from companion.guidance.frames import PinholeCamera, quat_to_matrix

__all__ = [
    "ChosenPixel",
    "TruePose",
    "chosen_pixel",
    "landing_distance_m",
    "landing_target_ned",
    "pixel_truth_ned",
]


def pixel_truth_ned(
    depth_m: np.ndarray,
    camera: PinholeCamera,
    pos_ned_m: Sequence[float],
    quat_wxyz: Sequence[float],
    u: float,
    v: float,
) -> np.ndarray | None:
    """World NED point (3,) that pixel (u, v) truly shows, from a depth image rendered at the true pose
    (z-depth along the optical axis, which is body +z); ``None`` for sky or outside the image."""
    col, row = int(u), int(v)
    h, w = depth_m.shape
    if not (0 <= col < w and 0 <= row < h):
        return None
    z = float(depth_m[row, col])
    if not math.isfinite(z):
        return None
    ray = camera.pixel_ray_frd(u, v)
    point: np.ndarray = np.asarray(pos_ned_m, dtype=float) + quat_to_matrix(quat_wxyz) @ (ray * (z / ray[2]))
    return point


@dataclass(frozen=True, slots=True)
class ChosenPixel:
    """The pixel the companion chose for the site it last confirmed, and its frame's capture time."""

    u: float
    v: float
    time_boot_ms: int  # the autopilot's boot clock when the frame was captured
    round: int


@dataclass(frozen=True, slots=True)
class TruePose:
    """The simulator's true pose when a frame was rendered (the episode log's ``frame`` event)."""

    t_s: float
    pos_ned_m: tuple[float, float, float]
    quat_wxyz: tuple[float, float, float, float]


def chosen_pixel(events: Sequence[Mapping[str, Any]]) -> ChosenPixel | None:
    """From a flight record's events: the last site confirmed for descent (the one it descended on),
    its candidate's centre pixel, and the time of the frame that candidate was found in.

    The confirm event names its candidate (``candidate``: the candidate's record); the pixel's frame
    is that of the latest rank event up to the confirm's round that lists the same candidate (a site
    looked at again later, after its round, keeps its first frame). A record without ``candidate`` (an
    older one) falls back to the chosen candidate of the confirm's own round. None when nothing was
    confirmed or no rank event says which frame (no ``frame_time_boot_ms``)."""
    confirm = next((e for e in reversed(events) if e.get("kind") == "confirm" and e.get("accept")), None)
    if confirm is None:
        return None
    rnd = confirm.get("round")
    rnd = rnd if isinstance(rnd, int) else 0
    ranks = [e for e in events if e.get("kind") == "rank" and isinstance(e.get("round"), int)]
    wanted = confirm.get("candidate")
    for rank in reversed(ranks):
        candidates = rank.get("candidates")
        if not isinstance(candidates, list):
            continue
        if wanted is not None:
            if rank["round"] > rnd or wanted not in candidates:
                continue
            cand = wanted
        else:
            chosen = rank.get("chosen")
            if rank["round"] != rnd or not isinstance(chosen, int) or not 0 <= chosen < len(candidates):
                continue
            cand = candidates[chosen]
        stamp = rank.get("frame_time_boot_ms")
        if not isinstance(stamp, int):
            return None
        u, v = cand["centre_px"]
        return ChosenPixel(float(u), float(v), stamp, int(rank["round"]))
    return None


def true_pose(frames: Mapping[int, Mapping[str, Any]], time_boot_ms: int) -> TruePose | None:
    """The pose of the frame simbridge served at ``time_boot_ms`` (its ``frame`` events by that clock)."""
    row = frames.get(time_boot_ms)
    if row is None:
        return None
    p, q = row["pos_ned_m"], row["quat_wxyz"]
    return TruePose(float(row["t_s"]), (p[0], p[1], p[2]), (q[0], q[1], q[2], q[3]))


def landing_target_ned(
    header: Mapping[str, Any],
    pose: TruePose,
    u: float,
    v: float,
    *,
    launch: tuple[float, ...] | None = None,
    world_cache: Path | None = None,
) -> np.ndarray | None:
    """The world point pixel (u, v) truly showed from ``pose``: simbridge's world of the episode
    (``header``: the episode log's ``start`` line; ``launch`` as simbridge was given it), its actors
    at the frame's time, and a depth image rendered at the true pose. None for sky or off the image.

    Raises:
        ValueError: the world built here is not the one flown (``world_digest`` differs), or the
            scenario has no rendered world.
    """
    from simbridge.scenarios import load_scenario
    from simbridge.world.live import LiveWorld

    city_seed = header.get("city_seed")
    sc = load_scenario(
        str(header["scenario"]),
        int(header["seed"]),
        launch,
        city_seed=int(city_seed) if isinstance(city_seed, int) else 0,
        place=str(header.get("place") or "downtown"),
        world_cache=world_cache,
    )
    world = sc.terrain
    if not isinstance(world, LiveWorld):
        raise ValueError(f"scenario {header['scenario']!r} has no rendered world")
    flown = header.get("world_digest")
    if flown is not None and flown != world.world_digest:
        raise ValueError(f"world digest {world.world_digest} is not the flown world's {flown}")
    frame = world.camera_frame(pose.pos_ned_m, pose.quat_wxyz, pose.t_s, "clear", np.random.default_rng(0))
    cm = world.camera
    cx, cy = cm.principal_px
    camera = PinholeCamera(cm.width_px, cm.height_px, cm.focal_px, cm.focal_px, cx, cy)
    return pixel_truth_ned(frame.depth_m, camera, pose.pos_ned_m, pose.quat_wxyz, u, v)


def landing_distance_m(
    touchdown: Mapping[str, Any] | None,
    header: Mapping[str, Any] | None,
    frames: Mapping[int, Mapping[str, Any]],
    events: Sequence[Mapping[str, Any]],
    *,
    launch: tuple[float, ...] | None = None,
    world_cache: Path | None = None,
) -> tuple[float, list[float]] | None:
    """Horizontal distance (m) from the true touchdown to what the chosen pixel of the last confirmed
    site truly shows, and that point (NED, the scenario frame). None without a touchdown, a confirmed
    site with its pixel and frame time, the frame's true pose, or a surface under the pixel."""
    pick = chosen_pixel(events)
    if touchdown is None or header is None or pick is None:
        return None
    pose = true_pose(frames, pick.time_boot_ms)
    if pose is None:
        return None
    target = landing_target_ned(header, pose, pick.u, pick.v, launch=launch, world_cache=world_cache)
    if target is None:
        return None
    td = touchdown["pos_ned_m"]
    distance = math.hypot(float(td[0]) - float(target[0]), float(td[1]) - float(target[1]))
    return round(distance, 2), [round(float(x), 2) for x in target]
