"""``landfall-ground``: the operator's view in a browser, of a live MQTT feed or of a flight record.

    landfall-ground --mqtt HOST[:PORT] [--vehicle ID] [--http 127.0.0.1:8080]
    landfall-ground --replay RECORD_DIR [--speed X] [--http 127.0.0.1:8080]

Exit status 2 for bad arguments (a record directory that is not one, a bad address, a base map that
cannot be drawn), with one line saying what was wrong; 0 after Ctrl-C.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import logging
import os
import sys
from pathlib import Path

__all__ = ["main", "parse_hostport"]

PASSWORD_ENV = "LANDFALL_GROUND_MQTT_PASSWORD"
BASEMAP_MAX_PX = 1200


def parse_hostport(text: str, default_port: int) -> tuple[str, int]:
    """``HOST[:PORT]`` (``[v6]:PORT`` for IPv6) as (host, port); ValueError saying what was wrong."""
    host, port = text, default_port
    if text.startswith("["):
        host, _, rest = text[1:].partition("]")
        if rest:
            if not rest.startswith(":"):
                raise ValueError(f"{text!r}: expected [HOST]:PORT")
            port = _port(rest[1:], text)
    elif text.count(":") == 1:
        host, _, p = text.partition(":")
        port = _port(p, text)
    if not host:
        raise ValueError(f"{text!r}: no host")
    return host, port


def _port(text: str, whole: str) -> int:
    if not text.isdigit() or not 0 <= int(text) <= 65535:
        raise ValueError(f"{whole!r}: the port must be a number from 0 to 65535")
    return int(text)


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog="landfall-ground",
        description="The operator's view in a browser: a companion's MQTT feed live, or a flight record.",
    )
    src = ap.add_mutually_exclusive_group(required=True)
    src.add_argument("--mqtt", metavar="HOST[:PORT]", help="the broker the companions publish to (port 1883)")
    src.add_argument(
        "--replay", metavar="RECORD_DIR", type=Path, help="a flight record (companion --record DIR)"
    )
    ap.add_argument("--vehicle", metavar="ID", help="watch this vehicle only (default: every vehicle)")
    ap.add_argument(
        "--prefix", default="landfall", help="the feed's topic prefix (companion mqtt.topic_prefix)"
    )
    ap.add_argument("--http", metavar="HOST:PORT", default="127.0.0.1:8080", help="where to serve the page")
    ap.add_argument(
        "--speed", type=float, default=1.0, help="replay pace, times the recorded one (default 1)"
    )
    ap.add_argument(
        "--mqtt-user",
        metavar="USER",
        help=f"broker user name; with the password in ${PASSWORD_ENV}, the page may send alarms",
    )
    ap.add_argument("--mqtt-tls", action="store_true", help="connect to the broker over TLS")
    ap.add_argument(
        "--basemap",
        metavar="SCENARIO[:SEED]",
        help="draw the trajectory over this simbridge world (needs the sim extra; seed 0 by default)",
    )
    ap.add_argument("--log-level", default="INFO", help="DEBUG, INFO, WARNING (default INFO)")
    return ap


def _alarm_policy(args: argparse.Namespace, password: str | None) -> dict[str, object]:
    if args.replay is not None:
        return {"enabled": False, "why": "a replay: alarms go to live vehicles only"}
    if not args.mqtt_user or not password:
        return {
            "enabled": False,
            "why": f"alarms are off: this ground station has no broker credentials "
            f"(start it with --mqtt-user USER and the password in ${PASSWORD_ENV})",
        }
    return {"enabled": True, "why": ""}


def _basemap(spec: str) -> tuple[bytes, dict[str, object]]:
    """The PNG and its extent for ``--basemap SCENARIO[:SEED]``; ValueError saying what was wrong."""
    scenario, _, seed_text = spec.partition(":")
    if seed_text and not seed_text.lstrip("-").isdigit():
        raise ValueError(f"--basemap {spec!r}: the seed must be an integer")
    try:
        import cv2

        from landfall_eval.basemap import basemap
    except ImportError as exc:
        raise ValueError(
            f"--basemap needs the simulator's packages ({exc.name}): pip install 'landfall[sim]'"
        ) from exc
    bm = basemap(scenario, int(seed_text or 0), None, max_px=BASEMAP_MAX_PX)
    ok, png = cv2.imencode(".png", cv2.cvtColor(bm.rgb, cv2.COLOR_RGB2BGR))
    if not ok:
        raise ValueError(f"--basemap {spec!r}: PNG encoding failed")
    n_min, n_max, e_min, e_max = bm.extent_ne_m
    return bytes(png), {
        "url": "basemap.png",
        "north_m": [n_min, n_max],
        "east_m": [e_min, e_max],
        "name": spec,
    }


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    logging.basicConfig(
        level=args.log_level.upper(), format="%(asctime)s %(levelname)s %(name)s: %(message)s"
    )
    try:
        import uvicorn

        from landfall_ground.live import BrokerParams, LiveFeed
        from landfall_ground.replay import Replay, load_record
        from landfall_ground.server import create_app
        from landfall_ground.station import Station
    except ImportError as exc:
        print(
            f"landfall-ground: {exc.name} is not installed: pip install 'landfall[ground]'", file=sys.stderr
        )
        return 2
    password = os.environ.get(PASSWORD_ENV) or None
    try:
        http_host, http_port = parse_hostport(args.http, 8080)
        if not args.speed > 0:
            raise ValueError(f"--speed must be > 0, got {args.speed}")
        png, extent = _basemap(args.basemap) if args.basemap else (None, None)
        station = Station(
            "replay" if args.replay is not None else "live",
            prefix=args.prefix,
            alarms=_alarm_policy(args, password),
            basemap=extent,
        )
        source: LiveFeed | Replay
        if args.replay is not None:
            source = Replay(load_record(args.replay), station, args.speed)
            what = f"replay of {source.flight.session} ({len(source.flight.messages)} messages)"
        else:
            host, port = parse_hostport(args.mqtt, 1883)
            params = BrokerParams(
                host, port, args.mqtt_user, password, args.mqtt_tls, args.prefix, args.vehicle
            )
            source = LiveFeed(params, station)
            what = f"live feed from {host}:{port} ({params.topic_filter})"
    except ValueError as exc:  # NotARecord and bad addresses among them
        print(f"landfall-ground: {exc}", file=sys.stderr)
        return 2
    app = create_app(station, source, png)
    config = uvicorn.Config(app, host=http_host, port=http_port, log_level="warning", lifespan="on")
    server = uvicorn.Server(config)
    logging.getLogger("landfall_ground").info("serving http://%s:%d/ : %s", http_host, http_port, what)
    with contextlib.suppress(KeyboardInterrupt):
        asyncio.run(server.serve())
    return 0 if server.started else 1
