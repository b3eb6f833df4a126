"""A world in motion: the static grid plus actors at simulated time t, with everything the sensors
and the grader need (max-height pyramid, shadow map). Implements simbridge's Terrain protocol."""

from __future__ import annotations

import threading
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from simbridge.geo import Quat
from simbridge.terrain import TouchdownGrade
from simbridge.world.actors import Actors
from simbridge.world.camera import CameraModel, Frame, ShadowMap, render
from simbridge.world.grader import GraderConfig, grade
from simbridge.world.lidar import LidarModel, rangefinder_m, sweep
from simbridge.world.raycast import Pyramid
from simbridge.world.stamping import raise_pyramid, shadows
from simbridge.world.world import World

DYNAMIC_LEVELS = 5  # max maps raised per actor per frame (radii to 12.8 m); the rest hold an envelope
SEEN_MARGIN_M = 60.0  # actors stamped this far beyond what a sensor's pose says it can see


class LiveWorld:
    """``sync(t)`` moves the actors; sensors and grading call it themselves with their time.

    ``actor_seed`` seeds the traffic and the pedestrians (the episode's seed); by default the world's
    own seed. ``world_digest`` fingerprints the static world (:meth:`World.digest`), taken before the
    first actor is stamped into the grid.

    Thread-safe for its sensors: a camera frame, a LiDAR sweep and a touchdown grade each move the actors
    and stamp them into the grid before they read it, so one lock runs them one at a time (simbridge
    renders the sensor stream's frames and the RTP camera's in worker threads: unlocked, two threads
    moving the traffic at once broke its arrays). The rangefinder reads without it: a read that meets a
    car being moved sees it at one place or the other.
    """

    def __init__(
        self,
        world: World,
        *,
        camera: CameraModel | None = None,
        lidar: LidarModel | None = None,
        grader: GraderConfig | None = None,
        actor_seed: int | None = None,
    ) -> None:
        self.world = world
        self.grid = world.grid
        self.actor_seed = world.seed if actor_seed is None else actor_seed
        self.camera = camera or CameraModel()
        self.lidar = lidar or LidarModel()
        self.grader = grader or GraderConfig()
        self.sun_neu = world.sun.direction_neu()
        # the digest (0.2 s for a city) is hashed alongside the pyramid: hashlib lets go of the GIL, and
        # nothing here writes to the grid until the first sync stamps the actors
        with ThreadPoolExecutor(max_workers=1, thread_name_prefix="world-digest") as pool:
            digest = pool.submit(world.digest)
            self.pyramid = Pyramid(self.grid.height, world.pyramid_maps)
            self.shadow = ShadowMap(self.grid, self.pyramid, self.sun_neu)
            self.actors = Actors(world.lanes, world.walkways, self.actor_seed)
            self.pyramid.raise_envelope(self.actors.envelope(self.grid), DYNAMIC_LEVELS)
            self.world_digest = digest.result()
        self.t_s = -1.0
        self._near: tuple[float, float, float] | None = None
        self._lock = threading.RLock()
        self.sync(0.0)

    # ------------------------------------------------------------------ time
    def sync(self, t_s: float, near: tuple[float, float, float] | None = None) -> None:
        """Advance the actors to ``t_s`` and stamp them (and their shadows) into the grid: all of
        them, or (``near``: north, east, radius in metres) those within that distance, which is
        all a sensor there can see. Every actor moves either way."""
        with self._lock:
            self._sync(t_s, near)

    def _sync(self, t_s: float, near: tuple[float, float, float] | None) -> None:
        if t_s == self.t_s and (near == self._near or self._near is None):
            return
        self.shadow.unstamp()
        self.actors.advance(max(t_s, 0.0))
        boxes, windows = self.actors.stamp(self.grid, near)
        raise_pyramid(self.pyramid, windows, boxes.top, DYNAMIC_LEVELS)
        for window, mask in shadows(self.grid, boxes, self.sun_neu):
            self.shadow.stamp(window, mask)
        self.t_s = t_s
        self._near = near

    def _seen_from(self, pos_ned_m: tuple[float, float, float]) -> tuple[float, float, float]:
        """The ground a sensor at ``pos_ned_m`` can see actors on: a nadir camera's rays out to 63
        degrees from straight down (its 90-degree field of view, tilted), and the LiDAR's range."""
        up = max(-pos_ned_m[2], 0.0)
        return (pos_ned_m[0], pos_ned_m[1], SEEN_MARGIN_M + max(2.0 * up, self.lidar.range_m))

    # ------------------------------------------------------------------ Terrain protocol
    def height_m(self, north_m: float, east_m: float) -> float:
        return self.grid.height_at(north_m, east_m)

    def nearest_person_m(self, pos_ned_m: tuple[float, float, float], t_s: float) -> float | None:
        """The straight-line distance from ``pos_ned_m`` to the nearest pedestrian at ``t_s`` (their
        feet, on the surface they walk), metres; None when the world has none."""
        with self._lock:
            people = self.actors.people_at(t_s)
        if not len(people):
            return None
        n, e, d = pos_ned_m
        gaps = np.hypot(np.hypot(people[:, 0] - n, people[:, 1] - e), people[:, 2] + d)
        return float(gaps.min())

    def grade_touchdown(self, north_m: float, east_m: float, t_s: float) -> TouchdownGrade:
        with self._lock:
            self._sync(t_s, (north_m, east_m, SEEN_MARGIN_M))
            people = self.actors.people_at(t_s)
            return grade(self.grid, north_m, east_m, self.grader, people=people, wires=self.world.wires)

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
        with self._lock:
            self._sync(t_s, self._seen_from(pos_ned_m))
            return render(
                self.grid,
                self.pyramid,
                self.shadow,
                self.camera,
                pos_ned_m,
                quat,
                self.sun_neu,
                weather,
                rng,
                wires=self.world.wires,
            )

    def lidar_sweep(
        self, pos_ned_m: tuple[float, float, float], quat: Quat, t_s: float, rng: np.random.Generator
    ) -> np.ndarray:
        with self._lock:
            self._sync(t_s, self._seen_from(pos_ned_m))
            return sweep(self.grid, self.pyramid, self.lidar, pos_ned_m, quat, rng, self.world.wires)
