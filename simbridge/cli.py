"""``simbridge``: the simulator bridge command line (DESIGN.md section 4)."""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import importlib.util
import logging
import sys
from collections.abc import Sequence
from pathlib import Path

from landfall_link.mavlink import UDP_MODES, LinkUrl, LinkUrlError, parse_signing_key
from simbridge.args import non_negative_seed
from simbridge.estimate import PRESETS, GpsFaultConfig
from simbridge.geo import GeoOrigin
from simbridge.px4_sitl import ENV_BINARY as PX4_ENV_BINARY
from simbridge.scenarios import scenario_names
from simbridge.sim import AUTOPILOTS, PX4_SITL_AUTOPILOT, SITL_AUTOPILOT, SimBridge, SimConfig
from simbridge.sitl import ENV_BINARY, SitlError
from simbridge.wind import WindConfig
from simbridge.world.places import DEFAULT_PLACE, PLACES


def _floats(text: str, n: int, what: str) -> tuple[float, ...]:
    parts = text.split(",")
    try:
        values = tuple(float(p) for p in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"{what}: expected {n} comma-separated numbers, got {text!r}"
        ) from None
    if len(values) != n:
        raise argparse.ArgumentTypeError(f"{what}: expected {n} comma-separated numbers, got {len(values)}")
    return values


def _launch(text: str) -> tuple[float, ...]:
    parts = text.split(",")
    if len(parts) not in (2, 3):
        raise argparse.ArgumentTypeError(f"--launch: expected N,E or N,E,HEIGHT, got {text!r}")
    try:
        values = tuple(float(p) for p in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--launch: expected numbers, got {text!r}") from None
    if len(values) == 3 and not 5.0 <= values[2] <= 300.0:
        raise argparse.ArgumentTypeError(f"--launch: height must be 5..300 m above ground, got {values[2]}")
    return values


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="simbridge",
        description="JSBSim F450 quadcopter behind a PX4/ArduPilot MAVLink autopilot emulation. "
        "`simbridge render --help` renders one sensor frame to files.",
    )
    p.add_argument(
        "--mavlink",
        default="udpout:127.0.0.1:14550",
        help="MAVLink endpoint: udpout:HOST:PORT (send to), udpin:HOST:PORT or udp:PORT (listen)",
    )
    p.add_argument(
        "--autopilot",
        choices=AUTOPILOTS,
        default="px4",
        help="px4 or ardupilot: the emulation; ardupilot-sitl: real ArduCopter firmware (SITL), px4-sitl: "
        "real PX4 firmware (SITL), each as a child process with simbridge as its physics",
    )
    p.add_argument(
        "--sitl",
        metavar="PATH",
        help=f"ArduCopter SITL binary for --autopilot ardupilot-sitl (default: ${ENV_BINARY}, else "
        "../shared/sitl/ardupilot/arducopter beside the repository)",
    )
    p.add_argument(
        "--px4",
        metavar="PATH",
        help=f"PX4 SITL binary (bin/px4 of a px4_sitl_default build, its ROMFS the etc/ beside bin/) for "
        f"--autopilot px4-sitl (default: ${PX4_ENV_BINARY}, else ../shared/sitl/px4/bin/px4 beside the "
        "repository)",
    )
    p.add_argument(
        "--scenario",
        default="flat",
        help="world and launch pose: flat, scenario1, scenario2, city, or a path to a .toml scenario file",
    )
    p.add_argument("--weather", choices=("clear", "fog", "rain"), default="clear", help="camera weather")
    p.add_argument(
        "--sensors",
        metavar="HOST:PORT",
        help="serve camera/LiDAR/rangefinder frames on this TCP endpoint (docs/sensor-stream.md)",
    )
    p.add_argument(
        "--camera-stream",
        metavar="URL",
        help="also send the camera as H.264: udp://HOST:PORT over RTP, as Gazebo cameras do; "
        "raw+udp://HOST:PORT raw (rpicam-vid -o udp://); raw+tcp://HOST:PORT raw from a TCP server the "
        "receiver connects to (rpicam-vid --listen -o tcp://); companion --camera udp://:PORT or "
        "tcp://HOST:PORT takes each. The emulated autopilots only",
    )
    p.add_argument(
        "--camera-fps",
        type=float,
        default=5.0,
        help="--camera-stream frames per simulated second (default 5)",
    )
    p.add_argument(
        "--camera-info-out",
        type=Path,
        metavar="FILE",
        help="write the camera's calibration as a ROS camera_info YAML (companion --camera-info)",
    )
    p.add_argument(
        "--launch",
        type=_launch,
        metavar="N,E[,HEIGHT]",
        help="launch point (metres from the scenario origin) and height above ground",
    )
    p.add_argument(
        "--seed",
        type=int,
        default=0,
        help="the episode's seed: traffic, sensor noise, wind, a scenario file's furniture "
        "(same seeds, same episode)",
    )
    p.add_argument(
        "--city-seed",
        type=non_negative_seed,
        default=0,
        metavar="N",
        help="seed of the procedural city (--scenario city): one city seed, one city, whatever --seed",
    )
    p.add_argument(
        "--place",
        choices=PLACES,
        default=DEFAULT_PLACE,
        help=f"the kind of place --scenario city builds (default {DEFAULT_PLACE}; docs/simbridge.md)",
    )
    p.add_argument(
        "--world-cache",
        type=Path,
        default=None,
        metavar="DIR",
        help="keep the place --scenario city builds in DIR, and map it from there when built before "
        "(copy-on-write; companion-bench's campaigns share one; default: build it every start)",
    )
    p.add_argument("--speed", type=float, default=1.0, help="simulated seconds per wall second")
    p.add_argument(
        "--wait-for-go",
        action="store_true",
        help="build the world and warm the sensors, then wait for a line (or the end) on standard input "
        "before the simulation starts: a harness starts the next episode while it flies this one",
    )
    p.add_argument(
        "--start",
        choices=("air", "ground"),
        default="air",
        help="air: armed and holding at the launch pose; ground: disarmed on the ground",
    )
    p.add_argument("--episode-log", type=Path, help="write JSON lines of state and events here")
    p.add_argument(
        "--signing-key", help="MAVLink 2 signing key, 64 hex digits; unsigned frames are then rejected"
    )
    p.add_argument("--sysid", type=int, default=1, help="vehicle MAVLink system id")
    p.add_argument(
        "--home",
        type=lambda t: _floats(t, 3, "--home"),
        default=None,
        metavar="LAT,LON,ALT",
        help="geodetic position of the scenario origin (deg, deg, m)",
    )
    p.add_argument(
        "--wind",
        type=lambda t: _floats(t, 2, "--wind"),
        default=(0.0, 0.0),
        metavar="N,E",
        help="steady wind toward north/east, m/s",
    )
    p.add_argument("--gusts", type=float, default=0.0, metavar="SIGMA", help="gust standard deviation, m/s")
    p.add_argument("--duration", type=float, default=None, help="stop after this many simulated seconds")
    p.add_argument(
        "--ekf-error",
        choices=tuple(PRESETS),
        default="off",
        help="the emulated autopilot's estimator errors: off (it knows the truth) or nominal (GPS/EKF bias "
        "drift, noise, lag, attitude error; its telemetry and its position targets are in that frame)",
    )
    p.add_argument(
        "--gps-fault",
        type=lambda t: _floats(t, 2, "--gps-fault"),
        default=None,
        metavar="N,E",
        help="the GPS lies during the descent: its position moves N,E metres (north, east) the first time "
        "the vehicle descends below --gps-fault-below (the emulation's estimate follows at once; real "
        "ArduCopter gets SIM_GPS1_GLTCH_X/Y, PX4 SITL its HIL_GPS moved)",
    )
    p.add_argument(
        "--gps-fault-below",
        type=float,
        default=40.0,
        metavar="M",
        help="height above the ground whose first crossing downward starts --gps-fault (default 40)",
    )
    p.add_argument(
        "--gps-fault-ramp",
        type=float,
        default=0.0,
        metavar="S",
        help="0 (default): --gps-fault jumps at once (a glitch); S > 0: it grows evenly over S "
        "simulated seconds (a drift)",
    )
    p.add_argument(
        "--battery",
        type=float,
        default=100.0,
        metavar="PCT",
        help="the battery's charge at the start, percent (default 100): a low-battery flight",
    )
    p.add_argument(
        "--fence",
        choices=("off", "map"),
        default="off",
        help="off (default): the emulated autopilot's fence as its parameters have it (disabled); map: "
        "its circular fence enabled around home out to the map's nearest edge (FENCE_RADIUS / "
        "GF_MAX_HOR_DIST), which the companion reads and keeps inside",
    )
    p.add_argument("--log-level", default="INFO", choices=("DEBUG", "INFO", "WARNING", "ERROR"))
    return p


def config_from_args(args: argparse.Namespace) -> SimConfig:
    """Turn parsed flags into a validated config; raises ValueError naming the flag."""
    try:
        LinkUrl.parse(args.mavlink, allowed=UDP_MODES)  # simbridge speaks UDP only
    except LinkUrlError as exc:
        raise ValueError(f"--mavlink: {exc}") from None
    key = None
    if args.signing_key:
        try:
            key = parse_signing_key(args.signing_key)
        except ValueError as exc:
            raise ValueError(f"--signing-key: {exc}") from None
    if args.sitl and args.autopilot != SITL_AUTOPILOT:
        raise ValueError("--sitl: only with --autopilot ardupilot-sitl")
    if args.px4 and args.autopilot != PX4_SITL_AUTOPILOT:
        raise ValueError("--px4: only with --autopilot px4-sitl")
    known = scenario_names()
    if args.scenario not in known and not args.scenario.endswith(".toml"):
        names = ", ".join(known)
        raise ValueError(f"--scenario: unknown scenario {args.scenario!r}; known: {names} or a .toml path")
    sensors = None
    if args.sensors:
        from landfall_link.sensorstream import parse_endpoint

        try:
            sensors = parse_endpoint(args.sensors)
        except ValueError as exc:
            raise ValueError(f"--sensors: {exc}") from None
    camera_stream = None
    if args.camera_stream:
        from simbridge.camera_stream import parse_stream_url

        camera_stream = parse_stream_url(args.camera_stream)
        if importlib.util.find_spec("av") is None:
            raise ValueError("--camera-stream needs PyAV (H.264 over RTP): pip install 'landfall[sim]'")
    origin = GeoOrigin(*args.home) if args.home else GeoOrigin()
    if args.gusts < 0:
        raise ValueError(f"--gusts must be >= 0, got {args.gusts}")
    gps_fault = None
    if args.gps_fault is not None:
        offset = (args.gps_fault[0], args.gps_fault[1])
        gps_fault = GpsFaultConfig(offset, args.gps_fault_below, args.gps_fault_ramp)
    elif args.gps_fault_below != 40.0 or args.gps_fault_ramp != 0.0:
        raise ValueError("--gps-fault-below and --gps-fault-ramp: only with --gps-fault N,E")
    return SimConfig(
        mavlink=args.mavlink,
        autopilot=args.autopilot,
        scenario=args.scenario,
        seed=args.seed,
        city_seed=args.city_seed,
        place=args.place,
        world_cache=args.world_cache,
        speed=args.speed,
        start=args.start,
        episode_log=args.episode_log,
        signing_key=key,
        system_id=args.sysid,
        origin=origin,
        wind=WindConfig(steady_ned_m_s=(args.wind[0], args.wind[1], 0.0), gust_sigma_m_s=args.gusts),
        duration_s=args.duration,
        weather=args.weather,
        sensors=sensors,
        launch=args.launch,
        sitl=args.sitl,
        px4=args.px4,
        ekf_error=args.ekf_error,
        gps_fault=gps_fault,
        battery_pct=args.battery,
        camera_stream=camera_stream,
        fence=args.fence,
        camera_fps=args.camera_fps,
        camera_info_out=args.camera_info_out,
        wait_for_go=args.wait_for_go,
    )


def make_bridge(config: SimConfig, logger: logging.Logger | None = None) -> SimBridge:
    """The bridge for ``config.autopilot``: the emulation, or real ArduCopter or PX4 SITL (which subclass
    it, so it is chosen here, above them)."""
    if config.autopilot == SITL_AUTOPILOT:
        from simbridge.sitl_bridge import SitlBridge

        return SitlBridge(config, logger)
    if config.autopilot == PX4_SITL_AUTOPILOT:
        from simbridge.px4_bridge import Px4SitlBridge

        return Px4SitlBridge(config, logger)
    return SimBridge(config, logger)


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["render"]:
        from simbridge.render_cli import main as render_main

        return render_main(argv[1:])
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(level=args.log_level, stream=sys.stderr, format="%(levelname)s %(name)s: %(message)s")
    try:
        config = config_from_args(args)
    except ValueError as exc:
        parser.error(str(exc))
    try:
        bridge = make_bridge(config)
        with contextlib.suppress(KeyboardInterrupt):
            asyncio.run(bridge.run())
    except SitlError as exc:
        print(f"simbridge: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
