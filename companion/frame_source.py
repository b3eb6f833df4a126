"""What the companion sees to land by: frames from the sensor stream, or from a video camera with the
LiDAR sweep (if any) from the sensor stream, each placed with the autopilot's pose at its own capture time
(never with a pose the sensor side claims: :mod:`companion.telemetry`). The daemon connects the sensor
stream (:attr:`FrameSource.client`) and hands :meth:`FrameSource.frame` to a recovery.
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import math
from typing import Any

import numpy as np

from companion.camera import stream_capture_time
from companion.guidance.frames import quat_to_matrix
from companion.recovery import FrameUnavailable, Record
from companion.telemetry import TelemetryCache

__all__ = ["POSE_WAIT_UPDATES", "FrameSource"]

POSE_WAIT_UPDATES = 3  # position updates a frame newer than the telemetry waits for


class FrameSource:
    """Frames for a recovery from the sensor stream (``client``, once connected) or a video ``camera``
    (companion.camera.CameraStream), placed with the autopilot's estimate (``telemetry``); a frame older
    than ``max_frame_age_s`` of the autopilot's clock is none. ``camera_latency_s`` (this computer's
    seconds from capture to decoding) and ``camera_offset_frd_m`` (the camera's centre from the body
    origin) apply to the camera; the camera's frames go into ``record`` (``camera_frame`` events), a sweep
    that did not come into ``logger``."""

    def __init__(
        self,
        telemetry: TelemetryCache,
        *,
        max_frame_age_s: float,
        camera: Any = None,
        camera_latency_s: float = 0.0,
        camera_offset_frd_m: tuple[float, float, float] = (0.0, 0.0, 0.0),
        record: Record | None = None,
        logger: logging.Logger | None = None,
    ) -> None:
        self.tm = telemetry
        self.client: Any = None  # the sensor stream's client (landfall_link.sensorstream), once connected
        self._max_frame_age_s = max_frame_age_s
        self._camera = camera
        self._camera_latency_s = camera_latency_s
        self._camera_offset = np.asarray(camera_offset_frd_m, dtype=np.float64)
        self._record = record
        self._log = logger or logging.getLogger("companion")

    def sees(self) -> bool:
        """A view to land by: a video frame from the camera, else a connected sensor stream."""
        if self._camera is not None:
            return self._camera.latest() is not None
        return self.client is not None

    async def frame(self) -> Any:
        """A fresh frame for the recovery, or ``FrameUnavailable`` saying why there is none."""
        from landfall_link.sensorstream import SensorStreamError

        if self._camera is not None:
            return await self._camera_frame()
        if self.client is None:
            raise FrameUnavailable("sensor stream not connected")
        try:
            frame = await self.client.frame(want=("image", "lidar"), image_encoding="raw")
        except SensorStreamError as exc:
            raise FrameUnavailable(str(exc)) from exc
        age_s = self.tm.state.t_boot_s - frame.time_boot_ms / 1000.0
        if age_s > self._max_frame_age_s:
            raise FrameUnavailable(
                f"frame captured {age_s:.1f} s ago (sensors.max_frame_age_s {self._max_frame_age_s:g})"
            )
        return await self.posed(frame)

    async def _camera_frame(self) -> Any:
        """The newest video frame, its capture time on the autopilot's clock (the moment it was decoded,
        on the autopilot's clock fitted from telemetry, less the stream's latency), the LiDAR sweep from
        the sensor stream when there is one (re-expressed in the body frame at the image's capture), the
        downward rangefinder from the autopilot's DISTANCE_SENSOR (or the sweep's); placed with the
        autopilot's pose at the capture time, the camera's offset from the body origin applied."""
        from landfall_link.sensorstream import SensorFrame, SensorStreamError

        cam = self._camera
        video = cam.latest()
        if video is None:
            why = f" ({cam.last_error})" if cam.last_error else ""
            raise FrameUnavailable(f"no camera frame yet from {cam.spec.url}{why}")
        boot = self.tm.clock.boot_at(video.decoded_s)
        rate = self.tm.clock.rate
        if boot is None or rate is None:
            raise FrameUnavailable("the autopilot's clock is not known yet (too little telemetry)")
        # the configured latency is this computer's seconds; the decoder's hold is the stream's own
        # (its presentation clock runs with the autopilot's: real time, or the simulator's)
        hold = cam.decode_delay_s
        if hold is None:
            raise FrameUnavailable("the camera's frame interval is not known yet (fewer than two frames)")
        late = 0.0
        if video.pts_s is not None and cam.spec.kind in ("rtp", "rtsp"):
            # dated by its presentation time: a decoder that fell behind does not make it look newer
            dated = stream_capture_time(video.pts_s, video.decoded_s, cam.arrivals(), self.tm.clock.boot_at)
            if dated is not None:
                boot, late = dated
        t_cap = boot - self._camera_latency_s * rate - hold
        age_s = self.tm.state.t_boot_s - t_cap
        if age_s > self._max_frame_age_s:
            raise FrameUnavailable(
                f"newest camera frame captured {age_s:.1f} s ago (sensors.max_frame_age_s "
                f"{self._max_frame_age_s:g}){f'; {cam.last_error}' if cam.last_error else ''}"
            )
        lidar, sweep_range = None, math.nan
        if self.client is not None:
            try:
                sweep = await self.client.frame(want=("lidar",))
            except SensorStreamError as exc:
                self._log.warning("camera frame without LiDAR: %s", exc)
            else:
                lidar = self._lidar_at(sweep, t_cap)
                sweep_range = sweep.rangefinder_m
        fresh = self.tm.age_s("rangefinder") < 1.0 and math.isfinite(self.tm.state.rangefinder_m)
        rangefinder = self.tm.state.rangefinder_m if fresh else sweep_range
        if not math.isfinite(rangefinder):
            raise FrameUnavailable(
                "no distance to the ground for the camera frame: no downward DISTANCE_SENSOR from the "
                "autopilot and no LiDAR sweep"
            )
        u = cam.intrinsics
        frame = SensorFrame(
            t_s=t_cap, time_boot_ms=max(0, round(t_cap * 1000)), pos_ned_m=(0.0, 0.0, 0.0),
            quat_wxyz=(1.0, 0.0, 0.0, 0.0), rangefinder_m=rangefinder, image_rgb=video.image_rgb,
            depth_m=None, lidar_frd=lidar, fx=u.fx, fy=u.fy, cx=u.cx, cy=u.cy, width=u.width,
            height=u.height, weather="clear",  # the simulator's field: nothing in the companion reads it
        )  # fmt: skip
        posed = await self.posed(frame)
        if self._camera_offset.any():  # the camera's centre, not the body origin, is where the view is from
            r = quat_to_matrix(posed.quat_wxyz)
            pos = tuple(float(v) for v in np.asarray(posed.pos_ned_m) + r @ self._camera_offset)
            pts = posed.lidar_frd
            if pts is not None:
                pts = pts.copy()
                pts[:, :3] -= self._camera_offset.astype(pts.dtype)
            posed = dataclasses.replace(posed, pos_ned_m=pos, lidar_frd=pts)
        if self._record is not None:
            self._record.record_event("camera_frame", {
                "frame_seq": video.seq, "pts_s": video.pts_s, "decoded_s": round(video.decoded_s, 4),
                "capture_boot_s": round(t_cap, 4),
                "clock_rate": round(rate, 5), "latency_s": self._camera_latency_s,
                "decode_delay_s": round(hold, 4), "late_s": round(late, 4),
                "age_s": round(age_s, 3), "lidar": lidar is not None,
            })  # fmt: skip
        return posed

    def _lidar_at(self, sweep: Any, t_cap: float) -> Any:
        """The sweep's points (body FRD at the sweep's capture) in the body frame at ``t_cap``, by the
        autopilot's poses at both times; as they are when either pose is unknown."""
        pts = sweep.lidar_frd
        if pts is None:
            return None
        then, now = self.tm.poses.at(sweep.time_boot_ms / 1000.0), self.tm.poses.at(t_cap)
        if then is None or now is None:
            return pts
        r_then, r_now = quat_to_matrix(then.quat_wxyz), quat_to_matrix(now.quat_wxyz)
        shift = np.asarray(then.pos_ned_m) - np.asarray(now.pos_ned_m)
        out = np.array(pts, dtype=np.float32, copy=True)
        world = pts[:, :3].astype(np.float64) @ r_then.T + shift
        out[:, :3] = world @ r_now
        return out

    async def posed(self, frame: Any) -> Any:
        """The frame placed with the autopilot's estimate at its capture time (module telemetry):
        whatever pose the sensor side sent is replaced here, before anything reads it. A frame newer
        than the telemetry waits for up to ``POSE_WAIT_UPDATES`` position updates."""
        t = frame.time_boot_ms / 1000.0
        pose = self.tm.poses.at(t)
        for _ in range(POSE_WAIT_UPDATES):
            span = self.tm.poses.span()
            if pose is not None or span is None or t <= span[1]:
                break
            with contextlib.suppress(TimeoutError):
                await self.tm.wait_update(0.5)
            pose = self.tm.poses.at(t)
        if pose is None:
            span = self.tm.poses.span()
            covers = f"{span[0]:.2f}..{span[1]:.2f} s" if span else "nothing yet"
            raise FrameUnavailable(
                f"no autopilot pose at the frame's capture time ({t:.2f} s of its boot clock; "
                f"the pose history covers {covers})"
            )
        return dataclasses.replace(frame, pos_ned_m=pose.pos_ned_m, quat_wxyz=pose.quat_wxyz)
