"""The ground station's web side: one static page and the WebSocket that keeps it current (Starlette).

=====================  ==================================================================================
route                  what
=====================  ==================================================================================
``GET /``              the page (``landfall_ground/static/``, shipped in the package: no CDN)
``WS /ws``             the station's events (:mod:`landfall_ground.station`), first a ``hello``; a replay
                       also takes ``{"type": "seek", "t"}``, ``play``, ``pause``, ``{"type": "step",
                       "by": N}``, ``{"type": "speed", "speed"}`` from the page
``GET /api/state``     the ``hello`` as JSON (what a page would start from)
``POST /api/alarm``    ``{"vehicle", "reason", "criticality"}``: an alarm to the vehicle's ``alarm/in``;
                       202 once published (the companion answers on ``alarm/result``), 403 when alarms
                       are off (the reason says why) or the request comes from another site's page,
                       415 unless JSON, 400 for a bad form, 503 with the broker away
``GET /basemap.png``   the simulated world's top view under the trajectory (``--basemap``), else 404
=====================  ==================================================================================
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
from collections.abc import AsyncIterator
from typing import Any
from urllib.parse import urlsplit

from starlette.applications import Starlette
from starlette.requests import Request
from starlette.responses import JSONResponse, Response
from starlette.routing import Mount, Route, WebSocketRoute
from starlette.staticfiles import StaticFiles
from starlette.websockets import WebSocket, WebSocketDisconnect

from companion.ground import alarm_from_mqtt
from landfall_ground.live import AlarmNotSent, LiveFeed
from landfall_ground.replay import Replay
from landfall_ground.station import Station, Watcher

__all__ = ["create_app"]

log = logging.getLogger("landfall_ground.server")


def create_app(station: Station, source: LiveFeed | Replay, basemap_png: bytes | None = None) -> Starlette:
    """The ASGI app: ``source`` runs for the app's lifetime (started and cancelled by its lifespan)."""

    @contextlib.asynccontextmanager
    async def lifespan(app: Starlette) -> AsyncIterator[None]:
        task = asyncio.create_task(source.run(), name="ground-source")
        try:
            yield
        finally:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task

    async def state(request: Request) -> Response:
        return JSONResponse(station.snapshot())

    async def basemap(request: Request) -> Response:
        if basemap_png is None:
            return JSONResponse({"error": "no base map: start with --basemap SCENARIO"}, status_code=404)
        return Response(basemap_png, media_type="image/png")

    async def alarm(request: Request) -> Response:
        if not isinstance(source, LiveFeed) or not station.alarms.get("enabled"):
            return _refused(403, str(station.alarms.get("why", "alarms are off")))
        # another site's page in the operator's browser must not start a landing: JSON only (a
        # cross-site JSON POST needs a CORS preflight, which this server never grants) and same origin
        if request.headers.get("content-type", "").split(";")[0].strip() != "application/json":
            return _refused(415, "the form must be sent as application/json")
        origin = request.headers.get("origin")
        if origin is not None and urlsplit(origin).netloc != request.headers.get("host"):
            return _refused(
                403, f"alarms are taken from this ground station's own page only (origin {origin})"
            )
        try:
            form = json.loads(await request.body())
        except (ValueError, RecursionError):
            return _refused(400, "the form must be JSON")
        if not isinstance(form, dict) or not isinstance(form.get("vehicle"), str):
            return _refused(400, "the form must be a JSON object naming the vehicle")
        vehicle = form["vehicle"]
        known = station.vehicles.get(vehicle)
        status = known.status.body if known is not None and known.status is not None else {}
        if status.get("alarm_intake") is not True:
            return _refused(
                403, f"vehicle {vehicle!r} does not take alarms over MQTT (its alarm_intake is off)"
            )
        body = {"reason": form.get("reason"), "criticality": form.get("criticality")}
        try:
            alarm_from_mqtt(json.dumps(body).encode())  # the companion's own check, before it travels
        except ValueError as exc:
            return _refused(400, str(exc))
        try:
            await source.send_alarm(vehicle, body)
        except AlarmNotSent as exc:
            return _refused(503, str(exc))
        return JSONResponse({"sent": True, "vehicle": vehicle, **body}, status_code=202)

    async def ws(websocket: WebSocket) -> None:
        await websocket.accept()
        with station.watch() as watcher:
            sender = asyncio.create_task(_send(websocket, watcher), name="ws-send")
            try:
                while True:
                    text = await websocket.receive_text()
                    reply = _control(text, source)
                    if reply is not None:
                        await websocket.send_text(json.dumps({"type": "error", "detail": reply}))
            except WebSocketDisconnect:
                pass
            finally:
                sender.cancel()
                with contextlib.suppress(asyncio.CancelledError, Exception):
                    await sender

    static = StaticFiles(packages=[("landfall_ground", "static")], html=True)
    routes = [
        Route("/api/state", state),
        Route("/api/alarm", alarm, methods=["POST"]),
        Route("/basemap.png", basemap),
        WebSocketRoute("/ws", ws),
        Mount("/", static, name="static"),
    ]
    return Starlette(routes=routes, lifespan=lifespan)


def _refused(status: int, why: str) -> Response:
    return JSONResponse({"sent": False, "error": why}, status_code=status)


async def _send(websocket: WebSocket, watcher: Watcher) -> None:
    while True:
        text = await watcher.queue.get()
        if watcher.dropped:  # it fell behind: it reconnects and starts again from a hello
            await websocket.close(code=1013, reason="too far behind")
            return
        await websocket.send_text(text)


def _control(text: str, source: LiveFeed | Replay) -> str | None:
    """Apply a page's control message; what was wrong with it, or None."""
    try:
        msg: Any = json.loads(text)
    except (ValueError, RecursionError):
        return "a control message must be JSON"
    kind = msg.get("type") if isinstance(msg, dict) else None
    if not isinstance(source, Replay):
        return f"{kind!r}: only a replay takes controls"
    try:
        if kind == "seek":
            source.seek(float(msg["t"]))
        elif kind == "play":
            source.play()
        elif kind == "pause":
            source.pause()
        elif kind == "step":
            source.step(int(msg["by"]))
        elif kind == "speed":
            source.set_speed(float(msg["speed"]))
        else:
            return f"unknown control {kind!r} (seek, play, pause, step, speed)"
    except (KeyError, TypeError, ValueError) as exc:
        return f"bad {kind} control: {exc}"
    return None
