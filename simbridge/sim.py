"""The simulator process: vehicle, autopilot, MAVLink link and episode log, paced in real time
times ``speed`` (lockstep with the 120 Hz JSBSim step).

One module over 600 lines: the process's start, its lock-step loop and its stop share the vehicle,
the autopilot, the link and the sensors, and are read together; what each of those is lives in its
own module (:mod:`simbridge.physics`, :mod:`simbridge.autopilot`, :mod:`simbridge.world`)."""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import signal
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from landfall_link.mavlink import MavlinkUdpLink
from simbridge.autopilot.core import Autopilot
from simbridge.autopilot.flavours import flavour_named
from simbridge.autopilot.server import AutopilotServer
from simbridge.battery import BatteryConfig
from simbridge.episode_log import EpisodeLog
from simbridge.estimate import TRUTH, EstimateError, GpsFault, GpsFaultConfig, estimate_preset
from simbridge.geo import GeoOrigin
from simbridge.home import home_on_land
from simbridge.pacing import Pacer
from simbridge.physics import GEAR_HEIGHT_M
from simbridge.scenarios import Scenario, load_scenario
from simbridge.telemetry import Telemetry
from simbridge.terrain import TouchdownGrade
from simbridge.vehicle import Vehicle
from simbridge.wind import WindConfig, WindModel
from simbridge.world.places import PLACES

NEAR_GROUND_M = 10.0  # the last metres of a descent, where a person nearby matters most
PEOPLE_EVERY_S = 0.25  # simulated seconds between two looks for the nearest person there
_MAX_BATCH_STEPS = 6  # physics steps between two looks at the socket (50 ms simulated)
SITL_AUTOPILOT = "ardupilot-sitl"  # real ArduCopter firmware (simbridge.sitl_bridge)
PX4_SITL_AUTOPILOT = "px4-sitl"  # real PX4 firmware (simbridge.px4_bridge)
FIRMWARE_AUTOPILOTS = (SITL_AUTOPILOT, PX4_SITL_AUTOPILOT)
AUTOPILOTS = ("px4", "ardupilot", SITL_AUTOPILOT, PX4_SITL_AUTOPILOT)


@dataclass(frozen=True, slots=True)
class SimConfig:
    mavlink: str = "udpout:127.0.0.1:14550"
    autopilot: str = "px4"
    scenario: str = "flat"
    seed: int = 0  # the episode: traffic, sensor noise, wind (and a scenario file's furniture)
    city_seed: int = 0  # the procedural city (scenario "city"): one campaign, one city
    place: str = "downtown"  # the kind of place the scenario "city" builds (simbridge.world.places)
    world_cache: Path | None = None  # where built places are kept (simbridge.world.cache); None: none
    speed: float = 1.0
    start: str = "air"
    episode_log: Path | None = None
    signing_key: bytes | None = None
    system_id: int = 1
    origin: GeoOrigin = field(default_factory=GeoOrigin)
    wind: WindConfig = field(default_factory=WindConfig)
    duration_s: float | None = None  # stop after this much simulated time
    weather: str = "clear"
    sensors: tuple[str, int] | None = None  # serve sensor frames on this TCP endpoint
    launch: tuple[float, ...] | None = None  # (north, east[, height above ground]) override
    sitl: str | None = None  # ArduCopter SITL binary (autopilot "ardupilot-sitl"; default: find_arducopter)
    px4: str | None = None  # PX4 SITL binary (autopilot "px4-sitl"; default: simbridge.px4_sitl.find_px4)
    ekf_error: str = "off"  # the emulation's estimator errors (simbridge.estimate.PRESETS)
    gps_fault: GpsFaultConfig | None = None  # the GPS lies during the descent (simbridge.estimate)
    battery_pct: float = 100.0  # the pack's charge at the start (a low-battery alarm's flight)
    # send the camera as H.264 to (host, port, framing: rtp, raw-udp, raw-tcp; simbridge.camera_stream)
    camera_stream: tuple[str, int, str] | None = None
    camera_fps: float = 5.0  # the stream's frames per simulated second
    camera_info_out: Path | None = None  # write the camera's calibration (ROS camera_info YAML) here
    wait_for_go: bool = False  # the clock starts once standard input has a line or ends (--wait-for-go)
    fence: str = "off"  # "map": the emulated autopilot's circular fence reaches the map's nearest edge

    def __post_init__(self) -> None:
        if not 0.0 < self.battery_pct <= 100.0:
            raise ValueError(f"--battery must be in (0, 100] percent, got {self.battery_pct}")
        if self.autopilot not in AUTOPILOTS:
            raise ValueError(f"--autopilot must be one of {', '.join(AUTOPILOTS)}, got {self.autopilot!r}")
        estimate_preset(self.ekf_error)  # raises ValueError naming the flag
        if self.fence not in ("off", "map"):
            raise ValueError(f"--fence must be off or map, got {self.fence!r}")
        if self.fence == "map" and self.autopilot in FIRMWARE_AUTOPILOTS:
            raise ValueError(
                f"--fence map sets the emulated autopilot's fence; with --autopilot {self.autopilot} set "
                "the firmware's own (FENCE_ENABLE, FENCE_RADIUS; GF_MAX_HOR_DIST) instead"
            )
        if self.autopilot in FIRMWARE_AUTOPILOTS:
            name = self.autopilot
            if self.battery_pct != 100.0:
                raise ValueError("--battery: real firmware simulates its own battery (leave it at 100)")
            if self.camera_stream is not None:
                raise ValueError(
                    f"--camera-stream: with the emulated autopilots (px4, ardupilot) only, not {name} yet"
                )
            if self.ekf_error != "off":
                raise ValueError("--ekf-error: real firmware has its own estimator (leave it off)")
            if self.signing_key is not None:
                raise ValueError(
                    f"--signing-key: not with {name} (real firmware takes its key over MAVLink, "
                    "SETUP_SIGNING; simbridge does not set it up yet)"
                )
            if not self.mavlink.startswith("udpout:"):
                raise ValueError(
                    f"--mavlink {self.mavlink}: {name} sends to a companion (udpout:HOST:PORT: "
                    "the firmware's own MAVLink port sends there); it cannot listen"
                )
        if not 0.2 <= self.camera_fps <= 30.0:
            raise ValueError(
                f"--camera-fps must be in [0.2, 30] frames per simulated second, got {self.camera_fps}"
            )
        if not self.speed > 0:
            raise ValueError(f"--speed must be > 0, got {self.speed}")
        if self.start not in ("air", "ground"):
            raise ValueError(f"--start must be 'air' or 'ground', got {self.start!r}")
        if self.city_seed < 0:
            raise ValueError(f"--city-seed must be >= 0, got {self.city_seed}")
        if self.place not in PLACES:
            raise ValueError(f"--place must be one of {', '.join(PLACES)}, got {self.place!r}")
        if not 1 <= self.system_id <= 255:
            raise ValueError(f"system id must be 1..255, got {self.system_id}")
        if self.weather not in ("clear", "fog", "rain"):
            raise ValueError(f"--weather must be clear, fog or rain, got {self.weather!r}")


class SimBridge:
    """Build with a config, then ``await run()``; ``stop()`` ends it cleanly."""

    def __init__(self, config: SimConfig, logger: logging.Logger | None = None) -> None:
        self.config = config
        self.log = logger or logging.getLogger("simbridge")
        self.scenario: Scenario = load_scenario(
            config.scenario,
            config.seed,
            config.launch,
            city_seed=config.city_seed,
            place=config.place,
            world_cache=config.world_cache,
        )
        rng = np.random.default_rng(config.seed)
        wind = WindModel(config.wind, rng) if config.wind != WindConfig() else None
        self.vehicle = Vehicle(
            config.origin,
            self.scenario.terrain,
            wind=wind,
            battery=BatteryConfig(initial_fraction=config.battery_pct / 100.0),
        )
        sc = self.scenario
        n, e = sc.launch_ne_m
        ground = sc.terrain.height_m(n, e)
        hn, he = home_on_land(sc.terrain, n, e)
        self.home_ned_m = (hn, he, -sc.terrain.height_m(hn, he))
        if config.start == "air":
            self.vehicle.reset((n, e, -(ground + sc.launch_height_m)), sc.launch_yaw_rad)
        else:
            self.vehicle.reset((n, e, -(ground + GEAR_HEIGHT_M)), sc.launch_yaw_rad)
        self.episode = EpisodeLog(config.episode_log)
        self._stop = asyncio.Event()
        self._sensor_rng = np.random.default_rng(config.seed + 1)
        self.wall_elapsed_s = 0.0
        # the nearest person during the last NEAR_GROUND_M of a descent (a regulator's question)
        self._people = getattr(self.scenario.terrain, "nearest_person_m", None)
        self._nearest_low_m: float | None = None
        self._next_person_t_s = 0.0
        # a collision (the vehicle flew into a wall) is seen and said once: its touchdown ends the episode
        self._crash_seen = self._crash_said = False
        self.episode.event(
            0.0,
            "start",
            {
                "scenario": "city" if config.scenario == "city" else sc.name,  # what load_scenario takes
                "autopilot": config.autopilot,
                "seed": config.seed,
                "city_seed": config.city_seed if config.scenario == "city" else None,
                "place": config.place if config.scenario == "city" else None,
                "world_digest": sc.world_digest,
                "start": config.start,
                "home_ned_m": list(self.home_ned_m),
                "ekf_error": config.ekf_error,
                "gps_fault": _fault_fields(config.gps_fault),
            },
        )
        self._init_autopilot()

    def _init_autopilot(self) -> None:
        """The emulated autopilot, its telemetry, link and server; ready at once."""
        config = self.config
        preset = estimate_preset(config.ekf_error)
        fault = self._gps_fault()
        if fault is not None and preset is None:
            preset = TRUTH  # the fault's lie on an estimate that is otherwise the truth
        rng = np.random.default_rng([config.seed, 7])
        estimate = EstimateError(preset, rng, fault) if preset else None
        self.autopilot = Autopilot(
            flavour_named(config.autopilot),
            self.vehicle,
            self.home_ned_m,
            self._on_event,
            self._on_text,
            estimate=estimate,
        )
        self.telemetry = Telemetry(self.autopilot, config.origin)
        self.link = MavlinkUdpLink(
            config.mavlink,
            config.system_id,
            1,
            self._on_message,
            signing_key=config.signing_key,
            logger=self.log,
        )
        self.server = AutopilotServer(
            self.autopilot, self.telemetry, self.link.send, config.system_id, 1, self.log
        )
        if config.fence == "map":
            self._fence_to_map()
        if config.start == "air":
            self.autopilot.spawn_in_air(self.vehicle.state)
        self.episode.event(0.0, "ready", self.ready_fields())

    def _fence_to_map(self) -> None:
        """``--fence map``: the emulated autopilot's circular fence around home, out to the modelled
        area's nearest edge (what an operator sets around the area a flight may use), enabled."""
        n0, n1, e0, e1 = self._live_world("--fence map").grid.extent_m
        n, e, _d = self.home_ned_m
        radius = float(max(30.0, min(n - n0, n1 - n, e - e0, e1 - e)))  # ArduPilot's least FENCE_RADIUS
        names = ("GF_MAX_HOR_DIST",) if "GF_MAX_HOR_DIST" in self.autopilot.params else ("FENCE_RADIUS",)
        for name, value in ((names[0], radius), ("FENCE_ENABLE", 1.0)):
            if name in self.autopilot.params and not self.autopilot.set_param(name, value):
                raise ValueError(f"--fence map: the emulated autopilot refused {name} {value:g}")
        self.log.info("fence: %g m around home, to the map's nearest edge (%s)", radius, names[0])
        self.episode.event(0.0, "fence", {"radius_m": round(radius, 1), "param": names[0]})

    def _gps_fault(self) -> GpsFault | None:
        """The configured GPS fault, its start written to the episode log and said in simbridge's log."""
        cfg = self.config.gps_fault
        if cfg is None:
            return None

        def started(t_s: float, height_m: float) -> None:
            fields = {
                "offset_ne_m": [round(v, 3) for v in cfg.offset_ne_m],
                "ramp_s": cfg.ramp_s,
                "height_agl_m": round(height_m, 2),
            }
            self.episode.event(t_s, "gps_fault", fields)
            self.log.info("t=%.2f GPS fault starts at %.1f m above the ground: %s", t_s, height_m, fields)

        return GpsFault(cfg, started)

    def ready_fields(self) -> dict[str, Any]:
        """The ``ready`` event's fields: the vehicle holds at its launch pose (air) or can arm (ground)."""
        s = self.vehicle.state
        return {
            "pos_ned_m": [round(v, 3) for v in s.pos_ned_m],
            "autopilot": self.config.autopilot,
            "start": self.config.start,
            "time_boot_ms": self.time_boot_ms(s.t_s),  # ties the autopilot's clock to the log's t_s
        }

    def _watch_people(self, pos_ned_m: tuple[float, float, float], t_s: float, armed: bool) -> None:
        """Every ``PEOPLE_EVERY_S`` of simulated time: within ``NEAR_GROUND_M`` of the ground under
        the vehicle, armed, the nearest person's distance, the least kept for the touchdown event."""
        assert self._people is not None
        self._next_person_t_s = t_s + PEOPLE_EVERY_S
        above_m = -pos_ned_m[2] - self.scenario.terrain.height_m(pos_ned_m[0], pos_ned_m[1])
        if not armed or above_m > NEAR_GROUND_M:
            return
        d = self._people(pos_ned_m, t_s)
        if d is not None and (self._nearest_low_m is None or d < self._nearest_low_m):
            self._nearest_low_m = d

    # ------------------------------------------------------------------ callbacks
    def _on_message(self, msg: Any, addr: tuple[str, int]) -> None:
        self.server.handle(msg, addr)

    def _on_event(self, name: str, fields: dict[str, Any]) -> None:
        s = self.vehicle.state
        collision = self.vehicle.physics.collision
        if name == "touchdown":
            if collision is not None:
                if self._crash_said:
                    return  # the wreck's touchdown was the collision's, said once
                self._crash_said = True
                grade = TouchdownGrade("collision", False, (collision.said(),))
            else:
                grade = self.scenario.terrain.grade_touchdown(s.pos_ned_m[0], s.pos_ned_m[1], s.t_s)
            fields = {**fields, "surface": grade.surface, "safe": grade.safe, "reasons": list(grade.reasons)}
            if collision is None and self._people is not None:
                now = self._people(s.pos_ned_m, s.t_s)
                low = now if self._nearest_low_m is None else min(self._nearest_low_m, now or math.inf)
                fields["nearest_person_m"] = None if now is None else round(now, 2)
                fields["nearest_person_last_10m_m"] = None if low is None else round(low, 2)
        self.episode.event(s.t_s, name, fields)
        self.log.info("t=%.2f %s %s", s.t_s, name, fields)

    def _crashed(self, s: Any) -> None:
        """The vehicle flew into a wall (:class:`simbridge.physics.Collision`): a ``collision`` event
        with where, how fast and what it struck, then the wreck's touchdown, graded unsafe with the
        surface ``collision``; the episode ends there as any touchdown ends it."""
        c = self.vehicle.physics.collision
        assert c is not None
        self._on_event(
            "collision",
            {
                "pos_ned_m": [round(v, 3) for v in c.pos_ned_m],
                "speed_m_s": round(c.speed_m_s, 2),
                "struck_up_m": round(c.struck_up_m, 2),
                "ground_up_m": round(c.ground_before_m, 2),
            },
        )
        self._on_event("touchdown", {"pos_ned_m": [round(v, 3) for v in s.pos_ned_m], "collision": True})

    def _on_text(self, severity: int, text: str) -> None:
        self.log.info("STATUSTEXT[%d] %s", severity, text)
        self.link.send_statustext(severity, text)

    # ------------------------------------------------------------------ running
    def step(self) -> None:
        """One physics step with the autopilot's decision and the streams that fall due."""
        ap = self.autopilot
        sp = ap.tick(self.vehicle.state)
        s = self.vehicle.step(sp, ap.armed)
        if self.vehicle.physics.collision is not None and not self._crash_seen:
            self._crash_seen = True
            self._crashed(s)
            ap.crash()
        if self._people is not None and s.t_s >= self._next_person_t_s:
            self._watch_people(s.pos_ned_m, s.t_s, ap.armed)
        for msg in self.telemetry.due(s.t_s):
            self.link.send(msg)
        est = ap.estimated_state.pos_ned_m if ap.estimate is not None else None
        self.episode.state(
            s, ap.mode.name, ap.armed, ap.landed_state, 100 * self.vehicle.battery.remaining_fraction, est
        )

    def stop(self) -> None:
        self._stop.set()

    async def run(self) -> None:
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            with contextlib.suppress(NotImplementedError, RuntimeError):  # not the main thread
                loop.add_signal_handler(sig, self._stop.set)
        cfg = self.config
        if cfg.camera_info_out is not None:
            self.write_camera_info(cfg.camera_info_out)
        if cfg.sensors is not None or cfg.camera_stream is not None:
            self._warm_up_sensors()
        if not await self._go():
            return
        async with contextlib.AsyncExitStack() as stack:
            await stack.enter_async_context(self.link)
            if cfg.sensors is not None:
                await stack.enter_async_context(self._sensor_server(*cfg.sensors))
            if cfg.camera_stream is not None:
                task = asyncio.create_task(self._stream_camera(*cfg.camera_stream), name="camera-stream")
                task.add_done_callback(self._camera_stream_ended)
                stack.push_async_callback(_cancelled, task)
            await self._loop(loop)

    async def _go(self) -> bool:
        """With ``wait_for_go``, all that is heavy done (the world built, the sensors warmed): wait for
        a line on standard input, or its end, before the clock starts, nothing sent or listened to
        meanwhile. False when stopped (SIGINT, SIGTERM) while waiting."""
        if not self.config.wait_for_go:
            return True
        loop = asyncio.get_running_loop()
        go = asyncio.Event()
        fd = sys.stdin.fileno()
        loop.add_reader(fd, go.set)  # readable: a line, or the end of the input
        self.log.info("built and warmed: waiting for the go on standard input")
        try:
            waits = [asyncio.ensure_future(go.wait()), asyncio.ensure_future(self._stop.wait())]
            await asyncio.wait(waits, return_when=asyncio.FIRST_COMPLETED)
            for w in waits:
                w.cancel()
        finally:
            loop.remove_reader(fd)
        return go.is_set()

    def _camera_stream_ended(self, task: asyncio.Task[None]) -> None:
        """A camera stream that fails is said at once (the flight goes on without it), not at exit."""
        if not task.cancelled() and task.exception() is not None:
            self.log.error("camera stream stopped: %s", task.exception())

    def _live_world(self, flag: str) -> Any:
        from simbridge.world.live import LiveWorld

        terrain = self.scenario.terrain
        if not isinstance(terrain, LiveWorld):
            raise ValueError(f"{flag} needs a world with a camera; scenario {self.scenario.name!r} has none")
        return terrain

    def write_camera_info(self, path: Path) -> None:
        """The camera's calibration as a ROS camera_info YAML (an ideal pinhole: no distortion)."""
        from landfall_link.camera_info import CameraInfo

        cam = self._live_world("--camera-info-out").camera
        cx, cy = cam.principal_px
        info = CameraInfo.pinhole(
            cam.width_px, cam.height_px, cam.focal_px, cam.focal_px, cx, cy, "simbridge"
        )
        part = path.with_name(path.name + ".part")
        part.write_text(info.to_ros_yaml())
        part.replace(path)  # whole or not at all: a companion may be waiting for the file to appear
        self.log.info("camera calibration written to %s", path)

    async def _stream_camera(self, host: str, port: int, framing: str = "rtp") -> None:
        """Render the camera every 1 / camera_fps simulated seconds at the vehicle's pose then and send it
        (simbridge.camera_stream); a frame that would fall behind is skipped, not queued."""
        from simbridge.camera_stream import CameraStreamer

        world = self._live_world("--camera-stream")
        cam = world.camera
        fps = self.config.camera_fps
        loop = asyncio.get_running_loop()
        streamer = await loop.run_in_executor(
            None, CameraStreamer, host, port, cam.width_px, cam.height_px, fps, framing
        )
        self.log.info("camera: H.264 (%s) to %s, %g frames per simulated second", framing, streamer.url, fps)
        rng = np.random.default_rng(
            self.config.seed + 2
        )  # its own: the sensor stream's noise stays as seeded
        weather = self.config.weather
        period = 1.0 / fps
        index, next_t = 0, self.vehicle.state.t_s
        t0 = next_t  # presentation times are simulated time since the first frame: a skipped frame
        # (the renderer behind) leaves a gap in them, as a real camera's clock does
        try:
            while not self._stop.is_set():
                wait = (next_t - self.vehicle.state.t_s) / self.config.speed
                if wait > 0:
                    await asyncio.sleep(wait)
                    continue
                s = self.vehicle.state
                stamp = self.time_boot_ms(s.t_s)
                posed = time.monotonic()  # the moment of the pose: the frame's "glass" time

                pts = round(s.t_s - t0, 4)

                def render_and_send(s: Any = s, pts: float = pts) -> float:
                    frame = world.camera_frame(s.pos_ned_m, s.quat, s.t_s, weather, rng)
                    streamer.send(frame.rgb, pts)
                    return time.monotonic()

                sent = await loop.run_in_executor(None, render_and_send)
                self.episode.event(s.t_s, "camera_frame", {
                    "index": index, "pts_s": pts, "time_boot_ms": stamp,
                    "pos_ned_m": [round(v, 4) for v in s.pos_ned_m],
                    "quat_wxyz": [round(v, 6) for v in s.quat], "posed_monotonic_s": round(posed, 4),
                    "sent_monotonic_s": round(sent, 4),
                })  # fmt: skip
                index += 1
                next_t = max(next_t + period, self.vehicle.state.t_s)
        finally:
            await loop.run_in_executor(None, streamer.close)

    def _launch_pose_ned(self) -> tuple[float, float, float]:
        """Where the vehicle holds when an episode's alarm comes: the scenario's launch point, its launch
        height above the ground there."""
        sc = self.scenario
        n, e = sc.launch_ne_m
        return (n, e, -(sc.terrain.height_m(n, e) + sc.launch_height_m))

    def _warm_up_sensors(self) -> None:
        """Render one camera frame and one sweep before the link opens. The ray caster and the shader
        are compiled on first use (numba; about 10 s on one core with no cache, seconds more on a busy
        computer), and that compilation holds the interpreter: done mid-flight, it would stall the
        physics, the telemetry and the first frame a companion asks for. Afterwards they load from
        numba's cache. A vehicle that starts on the ground (real firmware always does) is rendered at
        the launch pose too: the shadows of what a frame sees are computed tile by tile on first sight,
        and the first frame 110 m up over scenario1 took 213 ms after a warm-up on the ground against
        57 ms after one at the launch pose, time a lock step spends paused. Its own random generator:
        the sensor noise stream stays as seeded."""
        from simbridge.world.live import LiveWorld

        world = self.scenario.terrain
        if not isinstance(world, LiveWorld):
            return
        t0 = time.perf_counter()
        s = self.vehicle.state
        rng = np.random.default_rng(0)
        launch = self._launch_pose_ned()
        poses = [s.pos_ned_m]
        if math.dist(s.pos_ned_m, launch) > 1.0:
            poses.append(launch)
        for pos in poses:
            world.camera_frame(pos, s.quat, s.t_s, self.config.weather, rng)
            world.lidar_sweep(pos, s.quat, s.t_s, rng)
            world.rangefinder_m(pos, s.quat)
        self.log.info("sensors ready (%.1f s to warm up the renderer)", time.perf_counter() - t0)

    def _sensor_server(self, host: str, port: int) -> contextlib.AbstractAsyncContextManager[object]:
        from landfall_link.sensorstream import SensorStreamServer

        terrain = self._live_world("--sensors")
        cam, lidar = terrain.camera, terrain.lidar
        info = {
            "simulator": "simbridge", "scenario": self.scenario.name, "weather": self.config.weather,
            "camera": {"width": cam.width_px, "height": cam.height_px, "hfov_deg": cam.hfov_deg,
                       "to_body": "x_cam=+y_body, y_cam=-x_body, z_cam=+z_body"},
            "lidar": {
                "channels": lidar.channels,
                "points_per_ring": lidar.points_per_ring,
                "range_m": lidar.range_m,
            },
        }  # fmt: skip
        return SensorStreamServer(host, port, self._capture, info)

    def time_boot_ms(self, t_s: float) -> int:
        """The autopilot's boot clock at simulated time ``t_s`` (the emulation's starts with the world's)."""
        return int(t_s * 1000)

    async def _capture(self, want: set[str]) -> Any:
        """Render what ``want`` asks for at the vehicle's pose now (in a worker thread)."""
        from landfall_link.sensorstream import SensorFrame
        from simbridge.world.live import LiveWorld

        world = self.scenario.terrain
        assert isinstance(world, LiveWorld)
        s = self.vehicle.state
        rng = self._sensor_rng
        weather = self.config.weather
        stamp = self.time_boot_ms(s.t_s)  # once: real firmware's clock offset may move meanwhile
        # the true pose each frame is rendered from, for evaluation only (the frame carries it too;
        # the companion replaces it with the autopilot's estimate): harnesses place a chosen pixel with it
        self.episode.event(
            s.t_s,
            "frame",
            {
                "time_boot_ms": stamp,
                "pos_ned_m": [round(v, 4) for v in s.pos_ned_m],
                "quat_wxyz": [round(v, 6) for v in s.quat],
                "parts": sorted(want),
            },
        )

        def render() -> Any:
            frame = (
                world.camera_frame(s.pos_ned_m, s.quat, s.t_s, weather, rng)
                if {"image", "depth"} & want
                else None
            )
            points = world.lidar_sweep(s.pos_ned_m, s.quat, s.t_s, rng) if "lidar" in want else None
            cam = world.camera
            cx, cy = cam.principal_px
            return SensorFrame(
                t_s=s.t_s, time_boot_ms=stamp, pos_ned_m=s.pos_ned_m, quat_wxyz=s.quat,
                rangefinder_m=world.rangefinder_m(s.pos_ned_m, s.quat),
                image_rgb=frame.rgb if frame is not None and "image" in want else None,
                depth_m=frame.depth_m if frame is not None and "depth" in want else None,
                lidar_frd=points, fx=cam.focal_px, fy=cam.focal_px, cx=cx, cy=cy,
                width=cam.width_px, height=cam.height_px, weather=weather,
            )  # fmt: skip

        return await asyncio.get_running_loop().run_in_executor(None, render)

    async def _loop(self, loop: asyncio.AbstractEventLoop) -> None:
        cfg = self.config
        dt = Vehicle.DT_S
        self.log.info(
            "simbridge %s on %s (local UDP port %d): scenario %s%s, seed %d, speed %.1fx, start %s",
            cfg.autopilot,
            cfg.mavlink,
            self.link.local_port,
            cfg.scenario,
            f" ({cfg.place}, city seed {cfg.city_seed})" if cfg.scenario == "city" else "",
            cfg.seed,
            cfg.speed,
            cfg.start,
        )
        wall0 = loop.time()
        pacer = Pacer(cfg.speed)
        pacer.start(wall0, self.vehicle.state.t_s)
        try:
            while not self._stop.is_set():
                target = pacer.target(loop.time(), self.vehicle.state.t_s)
                steps = 0
                while self.vehicle.state.t_s + dt <= target + 1e-9 and steps < _MAX_BATCH_STEPS:
                    self.step()
                    steps += 1
                if cfg.duration_s is not None and self.vehicle.state.t_s >= cfg.duration_s:
                    break
                if steps == _MAX_BATCH_STEPS:
                    await asyncio.sleep(0)
                else:
                    await asyncio.sleep(max(self.vehicle.state.t_s + dt - target, 0.0) / cfg.speed)
        finally:
            self.wall_elapsed_s = loop.time() - wall0
            st = self.link.stats
            self.episode.event(
                self.vehicle.state.t_s,
                "stop",
                {
                    "wall_s": round(self.wall_elapsed_s, 3),
                    "received": st.received,
                    "sent": st.sent,
                    "bad_frames": st.bad_frames,
                    "rejected_unsigned": st.rejected_unsigned,
                    "rejected_bad_signature": st.rejected_bad_signature,
                    "ignored_foreign": self.server.ignored_foreign,
                    "clock_slipped_s": round(pacer.slipped_s, 3),
                },
            )
            self.episode.close()
            self.log.info(
                "simbridge stopped at t=%.1f s after %.1f s wall (%.1fx); link %s",
                self.vehicle.state.t_s,
                self.wall_elapsed_s,
                self.vehicle.state.t_s / max(self.wall_elapsed_s, 1e-9),
                st,
            )


def _fault_fields(cfg: GpsFaultConfig | None) -> dict[str, Any] | None:
    if cfg is None:
        return None
    return {"offset_ne_m": list(cfg.offset_ne_m), "below_m": cfg.below_m, "ramp_s": cfg.ramp_s}


async def _cancelled(task: asyncio.Task[Any]) -> None:
    task.cancel()
    with contextlib.suppress(asyncio.CancelledError):
        await task
