"""Surface ID against ground truth: the Jaccard index of the best candidate's box and the safe zone.

A scenario's safe zone (a rectangle on a roof, in its file) is projected into the camera image at the
height of the surface under it; its ground-truth box is the axis-aligned bounding box of the projected
corners. The Jaccard index (intersection over union) of two boxes is the study's Surface ID figure.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from companion.guidance.frames import PinholeCamera, quat_to_matrix
from companion.perception.depth import ArrayDepth, DepthMap, DepthSource, LidarDepth
from companion.perception.surface_id import Candidate, SurfaceParams, propose
from landfall_link.sensorstream import SensorFrame
from simbridge.geo import euler_to_quat
from simbridge.scenarios import load_scenario
from simbridge.terrain import Terrain
from simbridge.world.live import LiveWorld
from simbridge.world.world import SafeZone

Box = tuple[float, float, float, float]


def box_iou(a: Sequence[float], b: Sequence[float]) -> float:
    """Jaccard index of two (x0, y0, x1, y1) boxes; 0 when either is empty."""
    iw = min(a[2], b[2]) - max(a[0], b[0])
    ih = min(a[3], b[3]) - max(a[1], b[1])
    inter = max(iw, 0.0) * max(ih, 0.0)
    area_a = max(a[2] - a[0], 0.0) * max(a[3] - a[1], 0.0)
    area_b = max(b[2] - b[0], 0.0) * max(b[3] - b[1], 0.0)
    union = area_a + area_b - inter
    return inter / union if union > 0 else 0.0


def zone_box(
    zone: SafeZone,
    surface_up_m: float,
    camera: PinholeCamera,
    pos_ned_m: tuple[float, float, float],
    quat_wxyz: tuple[float, float, float, float],
) -> Box:
    """The safe zone's bounding box in the image (pixels), clipped to the image."""
    corners = zone.corners_ne()
    ned = np.column_stack([corners, np.full(len(corners), -surface_up_m)])
    uv, _front = camera.project_frd((ned - np.asarray(pos_ned_m)) @ quat_to_matrix(quat_wxyz))
    u, v = uv[:, 0], uv[:, 1]
    return (
        float(np.clip(u.min(), 0, camera.width)),
        float(np.clip(v.min(), 0, camera.height)),
        float(np.clip(u.max(), 0, camera.width)),
        float(np.clip(v.max(), 0, camera.height)),
    )


@dataclass(frozen=True, slots=True)
class LaunchFrame:
    """One rendered sensor frame at a scenario's launch pose, with its ground-truth boxes."""

    scenario: str
    seed: int
    image: np.ndarray
    lidar_frd: np.ndarray
    depth_m: np.ndarray
    pos_ned_m: tuple[float, float, float]
    quat_wxyz: tuple[float, float, float, float]
    camera: PinholeCamera
    truth_boxes: tuple[Box, ...]


HOVER_SIGMA_M = 0.5  # hover position scatter about the launch point, per axis
HOVER_TILT_SIGMA_DEG = 1.5  # roll and pitch scatter while holding position in light wind
HOVER_YAW_SIGMA_DEG = 3.0


def hover_pose(
    rng: np.random.Generator,
    ne_m: tuple[float, float],
    down_m: float,
    yaw_rad: float,
    *,
    scatter: bool = True,
) -> tuple[tuple[float, float, float], tuple[float, float, float, float]]:
    """A hovering drone's pose about (north, east, down) and heading: position, roll, pitch and yaw
    drawn about it (six normal draws from ``rng``, made even without ``scatter``, so the stream that
    follows is the same either way)."""
    dn, de, dd, roll, pitch, yaw = (
        np.array([HOVER_SIGMA_M] * 3 + [HOVER_TILT_SIGMA_DEG] * 2 + [HOVER_YAW_SIGMA_DEG])
        * rng.standard_normal(6)
        * scatter
    ).tolist()
    pos = (ne_m[0] + dn, ne_m[1] + de, down_m + dd)
    return pos, euler_to_quat(math.radians(roll), math.radians(pitch), yaw_rad + math.radians(yaw))


def launch_frame(
    scenario: str, seed: int, weather: str = "clear", t_s: float = 0.0, hover: bool = True
) -> LaunchFrame:
    """A frame at the scenario's launch pose; with ``hover`` the pose scatters as a hovering drone's
    does (seeded): position, roll, pitch and yaw drawn about the launch pose."""
    sc = load_scenario(scenario, seed)
    world = sc.terrain
    if not isinstance(world, LiveWorld):
        raise ValueError(f"scenario {scenario!r} has no rendered world")
    if not world.world.safe_zones:
        raise ValueError(f"scenario {scenario!r} has no ground-truth safe zone")
    n, e = sc.launch_ne_m
    rng = np.random.default_rng(seed)
    pos, quat = hover_pose(
        rng, (n, e), -(world.height_m(n, e) + sc.launch_height_m), sc.launch_yaw_rad, scatter=hover
    )
    frame = world.camera_frame(pos, quat, t_s, weather, rng)
    lidar = world.lidar_sweep(pos, quat, t_s, rng)
    cm = world.camera
    camera = PinholeCamera.from_hfov(cm.width_px, cm.height_px, cm.hfov_deg)
    boxes = tuple(
        zone_box(z, world.height_m(*z.centre_ne), camera, pos, quat) for z in world.world.safe_zones
    )
    return LaunchFrame(scenario, seed, frame.rgb, lidar, frame.depth_m, pos, quat, camera, boxes)


def sensor_frame(
    world: Terrain,
    camera: PinholeCamera,
    pos_ned_m: tuple[float, float, float],
    quat_wxyz: tuple[float, float, float, float],
    image: np.ndarray,
    lidar_frd: np.ndarray,
    weather: str = "clear",
) -> SensorFrame:
    """What the sensor stream brings from this pose (the frame the companion's recovery reads): the
    image, the LiDAR sweep and the rangefinder's reading of ``world``."""
    return SensorFrame(
        t_s=0.0,
        time_boot_ms=0,
        pos_ned_m=pos_ned_m,
        quat_wxyz=quat_wxyz,
        rangefinder_m=world.rangefinder_m(pos_ned_m, quat_wxyz),
        fx=camera.fx,
        fy=camera.fy,
        cx=camera.cx,
        cy=camera.cy,
        width=camera.width,
        height=camera.height,
        weather=weather,
        image_rgb=image,
        lidar_frd=lidar_frd,
    )


def propose_on(
    lf: LaunchFrame, source: DepthSource, params: SurfaceParams | None = None
) -> tuple[list[Candidate], DepthMap]:
    """Surface ID on a launch frame, with everything the frame knows (image, LiDAR, pose)."""
    return propose(
        source,
        lf.camera,
        image=lf.image,
        lidar_frd=lf.lidar_frd,
        quat_wxyz=lf.quat_wxyz,
        pos_ned_m=lf.pos_ned_m,
        ground_up_m=lf.pos_ned_m[2],
        params=params,
    )


def best_jaccard(
    lf: LaunchFrame, source: str = "lidar", params: SurfaceParams | None = None
) -> tuple[float, list[float]]:
    """Jaccard index of the best candidate against the best-matching safe zone, and the box."""
    src: DepthSource = LidarDepth() if source == "lidar" else ArrayDepth(lf.depth_m)
    best = propose_on(lf, src, params)[0][0]
    return max(box_iou(best.box_px, b) for b in lf.truth_boxes), [float(v) for v in best.box_px]
