"""A world in motion: the static grid plus actors at simulated time t, with everything the sensors
and the grader need (max-height pyramid, shadow map). Implements simbridge's Terrain protocol."""

from __future__ import annotations

import math

import numpy as np

from simbridge.geo import Quat
from simbridge.terrain import TouchdownGrade
from simbridge.world.actors import (
    CAR_HEIGHT_M,
    CAR_LENGTH_M,
    CAR_WIDTH_M,
    PERSON_HEIGHT_M,
    PERSON_SIZE_M,
    Actors,
)
from simbridge.world.camera import CameraModel, Frame, ShadowMap, render
from simbridge.world.grader import GraderConfig, grade
from simbridge.world.lidar import LidarModel, rangefinder_m, sweep
from simbridge.world.model import SurfaceClass
from simbridge.world.raycast import Pyramid
from simbridge.world.world import World


class LiveWorld:
    """``sync(t)`` moves the actors; sensors and grading call it themselves with their time."""

    def __init__(
        self,
        world: World,
        *,
        camera: CameraModel | None = None,
        lidar: LidarModel | None = None,
        grader: GraderConfig | None = None,
    ) -> None:
        self.world = world
        self.grid = world.grid
        self.camera = camera or CameraModel()
        self.lidar = lidar or LidarModel()
        self.grader = grader or GraderConfig()
        self.sun_neu = world.sun.direction_neu()
        self.pyramid = Pyramid(self.grid.height)
        self.shadow = ShadowMap(self.grid, self.pyramid, self.sun_neu)
        self.actors = Actors(world.lanes, world.walkways, world.seed)
        self.t_s = -1.0
        self.sync(0.0)

    # ------------------------------------------------------------------ time
    def sync(self, t_s: float) -> None:
        """Advance the actors to ``t_s`` and stamp them (and their shadows) into the grid."""
        if t_s == self.t_s:
            return
        self.shadow.unstamp()
        self.actors.advance(max(t_s, 0.0))
        poses = self.actors.stamp(self.grid)
        sn, se, su = self.sun_neu
        shadow_len = 1.0 / max(math.tan(math.asin(min(su, 1.0))), 0.05)
        horiz = math.hypot(sn, se) or 1.0
        for a in poses:
            if a.kind is SurfaceClass.VEHICLE:
                length, width, height = CAR_LENGTH_M, CAR_WIDTH_M, CAR_HEIGHT_M
            else:
                length, width, height = PERSON_SIZE_M, PERSON_SIZE_M, PERSON_HEIGHT_M
            top = a.base_height_m + height
            got = self.grid.rect_mask(a.centre_ne, length, width, a.yaw_rad)
            if got is not None:
                i0, i1, j0, j1 = got[0]
                self.pyramid.raise_window(i0, i1, j0, j1, top)
            off = height * shadow_len
            centre = (a.centre_ne[0] - sn / horiz * off / 2, a.centre_ne[1] - se / horiz * off / 2)
            shade = self.grid.rect_mask(
                centre, length + off * abs(sn / horiz), width + off * abs(se / horiz), 0.0
            )
            if shade is not None:
                win, mask, _, _ = shade
                i0, i1, j0, j1 = win
                under = mask & (self.grid.height[i0:i1, j0:j1] < top - 0.5)  # not the actor's own top
                self.shadow.stamp(win, under)
        self.t_s = t_s

    # ------------------------------------------------------------------ Terrain protocol
    def height_m(self, north_m: float, east_m: float) -> float:
        return self.grid.height_at(north_m, east_m)

    def grade_touchdown(self, north_m: float, east_m: float, t_s: float) -> TouchdownGrade:
        self.sync(t_s)
        return grade(self.grid, north_m, east_m, self.grader)

    def rangefinder_m(self, pos_ned_m: tuple[float, float, float], quat: Quat, max_m: float = 200.0) -> float:
        return rangefinder_m(self.grid, self.pyramid, pos_ned_m, quat, max_m)

    # ------------------------------------------------------------------ sensors
    def camera_frame(
        self,
        pos_ned_m: tuple[float, float, float],
        quat: Quat,
        t_s: float,
        weather: str,
        rng: np.random.Generator,
    ) -> Frame:
        self.sync(t_s)
        return render(
            self.grid, self.pyramid, self.shadow, self.camera, pos_ned_m, quat, self.sun_neu, weather, rng
        )

    def lidar_sweep(
        self, pos_ned_m: tuple[float, float, float], quat: Quat, t_s: float, rng: np.random.Generator
    ) -> np.ndarray:
        self.sync(t_s)
        return sweep(self.grid, self.pyramid, self.lidar, pos_ned_m, quat, rng)
