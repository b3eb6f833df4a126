"""``companion``: the emergency-landing daemon (DESIGN.md section 4)."""

from __future__ import annotations

import argparse
import asyncio
import gc
import logging
import os
import signal
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from companion.alarms import Alarm
from companion.config import ConfigError, load_config
from companion.config_schema import DEFAULTS, CompanionConfig
from companion.daemon import Companion
from companion.ground import GroundFeed, GroundParams
from companion.memory import limit_malloc_arenas, trim_malloc
from companion.operator import InhibitSwitch
from companion.perception.depth import DepthError
from companion.reasoning.tiers import BUILTIN_PROFILES, ONBOARD, build_cascade, secrets
from companion.recovery import RecoveryParams
from companion.redact import redact_logs
from landfall_link.mavlink import URL_FORMS


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="companion", description="Landfall: land the drone safely when an alarm fires."
    )
    p.add_argument(
        "--mavlink",
        help="MAVLink endpoint, e.g. udp:14550, tcp:127.0.0.1:5760 or serial:/dev/ttyAMA0:921600 "
        f"(default from the config: {DEFAULTS.mavlink.url}); forms: {URL_FORMS}",
    )
    p.add_argument("--config", type=Path, help="TOML configuration file (deploy/companion.toml documents it)")
    p.add_argument(
        "--reasoner",
        help=f"first reasoning tier: {ONBOARD} (default), {', '.join(BUILTIN_PROFILES)} or a profile of the "
        "config; the onboard tier always answers when the others cannot",
    )
    p.add_argument(
        "--sensors",
        metavar="HOST:PORT",
        help="sensor stream endpoint (simbridge --sensors, a LiDAR driver; default from the config: "
        f"{DEFAULTS.sensors.endpoint}); 'none' with --camera: no LiDAR",
    )
    p.add_argument(
        "--camera",
        metavar="URL",
        help="video camera for the image: udp://[HOST]:PORT (RTP/H.264, e.g. udp://:5600), rtsp://..., "
        "/dev/videoN or a video file (camera.url; needs --camera-info)",
    )
    p.add_argument(
        "--camera-info",
        metavar="FILE",
        help="the camera's calibration: ROS camera_info or OpenCV calibration YAML (camera.info)",
    )
    p.add_argument("--record", type=Path, metavar="DIR", help="keep a flight record of every round here")
    p.add_argument("--log-level", choices=("DEBUG", "INFO", "WARNING", "ERROR"))
    return p


def params_from(cfg: CompanionConfig) -> RecoveryParams:
    """The recovery's parameters of ``cfg`` (:meth:`RecoveryParams.from_config`); a depth source that
    cannot be built is a configuration error of ``perception.depth``."""
    try:
        return RecoveryParams.from_config(cfg)
    except DepthError as exc:
        raise ConfigError(f"perception.depth = {cfg.perception.depth!r}", str(exc)) from exc


def _interrupted(record: Any) -> Alarm | None:
    """The alarm whose recovery the previous session never finished (see Companion._resume)."""
    pending = record.interrupted_alarm() if record is not None else None
    return Alarm.from_json(pending) if pending is not None else None


def _ground_feed(cfg: CompanionConfig) -> GroundFeed | None:
    m = cfg.mqtt
    if not m.enabled:
        return None
    return GroundFeed(
        GroundParams(
            host=m.host,
            port=m.port,
            username=m.username or None,
            password=cfg.mqtt_password(os.environ),
            tls=m.tls,
            topic_prefix=m.topic_prefix,
            vehicle_id=m.vehicle_id,
            telemetry_hz=m.telemetry_hz,
            queue_size=m.queue_size,
            alarm_intake=m.alarm_intake,
            keepalive_s=m.keepalive_s,
            thumbnail_width_px=m.thumbnail_width_px,
        )
    )


def _camera(cfg: CompanionConfig) -> Any:
    """The video camera of ``[camera]``, its calibration read and its undistortion maps built now: a bad
    file is an error at start, never a wrong geometry in flight."""
    c = cfg.camera
    if c.url is None:
        return None
    from companion.camera import CameraStream, mount_rotation, parse_camera_url
    from landfall_link.camera_info import load_camera_info

    assert c.info is not None  # CameraConfig requires it with a url
    info = load_camera_info(c.info)
    return CameraStream(parse_camera_url(c.url), info.undistorter(mount_rotation(*c.mount_rpy_deg)))


def build_companion(cfg: CompanionConfig) -> Companion:
    from landfall_link.sensorstream import parse_endpoint

    record: Any = None
    if cfg.record.dir is not None:
        from companion.record import FlightRecord

        record = FlightRecord(cfg.record.dir, cfg.record.max_mb)
    reasoner = build_cascade(cfg.reasoner, record=record.record_event if record is not None else None)
    # what loading the onboard net freed (ONNX Runtime's graph optimisation: some 30 MB) goes back now:
    # the warm-up's reads that follow at once no longer stack on it (the daemon's peak began there)
    trim_malloc()
    a = cfg.alarms
    return Companion(
        mavlink_url=cfg.mavlink.url,
        component_id=cfg.mavlink.component_id,
        vehicle_system_id=cfg.mavlink.vehicle_system_id,
        signing_key=cfg.signing_key(),
        sensors=None if cfg.sensors.endpoint == "none" else parse_endpoint(cfg.sensors.endpoint),
        frame_timeout_s=cfg.sensors.frame_timeout_s,
        max_frame_age_s=cfg.sensors.max_frame_age_s,
        camera=_camera(cfg),
        camera_latency_s=cfg.camera.latency_ms / 1000.0,
        camera_offset_frd_m=cfg.camera.offset_frd_m,
        reasoner=reasoner,
        params=params_from(cfg),
        record=record,
        ground=_ground_feed(cfg),
        resume=_interrupted(record),
        watch_battery_pct=a.battery_critical_pct if a.watch_battery else None,
        watch_failsafe_text=a.watch_failsafe_text,
        watch_gps=a.watch_gps,
        accept_from=tuple(a.accept_from_system_ids),
        cancel_to=a.cancel_mode,
        inhibit=InhibitSwitch(a.inhibit_rc_channel, (a.inhibit_pwm_us[0], a.inhibit_pwm_us[1]))
        if a.inhibit_rc_channel
        else None,
        params_file=Path(cfg.mavlink.params_file) if cfg.mavlink.params_file else None,
        heartbeat_hz=cfg.mavlink.heartbeat_hz,
    )


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    limit_malloc_arenas()
    overrides = {
        key: value
        for key, value in (
            ("mavlink.url", args.mavlink),
            ("sensors.endpoint", args.sensors),
            ("camera.url", args.camera),
            ("camera.info", args.camera_info),
            ("reasoner.name", args.reasoner),
            ("record.dir", args.record),
            ("log.level", args.log_level),
        )
        if value is not None
    }
    try:
        cfg = load_config(args.config, os.environ, overrides)
        companion = build_companion(cfg)
    except (ConfigError, ValueError) as exc:
        print(f"companion: configuration error: {exc}", file=sys.stderr)
        return 2
    logging.basicConfig(level=cfg.log.level, stream=sys.stderr, format="%(levelname)s %(name)s: %(message)s")
    redact_logs(secrets(cfg, os.environ))

    # What the start-up imported (numpy, scipy, cv2, pydantic, pymavlink: some 70,000 objects) lives as
    # long as the daemon: frozen out of the collector, a full collection no longer walks it and stalls
    # the event loop (and with it the setpoint stream) for 30-100 ms on a busy two-core computer.
    gc.freeze()

    async def run() -> None:
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(sig, companion.stop)
        await companion.run()

    asyncio.run(run())
    return 0


if __name__ == "__main__":
    sys.exit(main())
