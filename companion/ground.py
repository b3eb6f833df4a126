"""The ground-station feed over MQTT (aiomqtt): what the daemon does, for people watching from the ground.

Topics, under ``<topic_prefix>/<vehicle_id>/``:

=================  ==========================================================================  =======
topic              payload (JSON)                                                              retained
=================  ==========================================================================  =======
``status``         ``{"state": "online"|"offline", "t": unix time, "alarm_intake": bool}``;    yes
                   ``offline`` is also the broker's last will, sent when the daemon vanishes
                   without saying goodbye
``alarm``          every alarm: reason, code, criticality, source, ``result`` (what the
                   daemon did with it: accepted, in_progress, denied, temporarily_rejected)    no
``state``          each recovery state change (``state``, ``round``, the vehicle's             no
                   ``pos_ned_m``), and ``outcome``
``decision``       each round's ranking (candidates with boxes and geometry, ``chosen``,       no
                   ``rationale``, ``tier``, ``latency_s``, ``thumbnail_jpeg_b64``: the frame
                   with the candidates boxed and the chosen one in green, ``frame_px``: the
                   frame's [width, height], the boxes' pixels) and each
                   confirmation (``accept``, ``rationale``, the LiDAR check)
``state``          also the search's plan (``kind`` ``note``, ``state`` the line to show): each   no
                   search leg and why (``search_leg``: target, aim, reason), a site struck
                   off from afar (``search_instead``), and why the search ended
                   (``search_end``: battery, need, window)
``fault``          sensor faults the recovery met (``sensor_fault``)                           no
``telemetry``      position NED, velocity, altitude above ground, mode (``custom_mode`` and    no
                   its name), armed, battery, GPS fix, seconds since the autopilot's last
                   heartbeat (``link_age_s``), at ``telemetry_hz``
``alarm/in``       (subscribed, only with ``alarm_intake = true``) ``{"reason": text,
                   "criticality": "low"|"high"|"critical", "code": optional int}``; the
                   answer goes to ``alarm/result``
=================  ==========================================================================  =======

Flying never waits on the broker: ``publish`` only appends to a bounded queue (the oldest message is
dropped when it is full, and counted); one task connects, with exponential backoff between tries,
and drains the queue. Alarm intake trusts whoever may publish to ``alarm/in``: give it to the ground
station only, with broker authentication and an ACL.
"""

from __future__ import annotations

import asyncio
import base64
import collections
import contextlib
import json
import logging
import math
import ssl
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np

from companion.alarms import Alarm, Criticality, ReasonCode

__all__ = ["GroundFeed", "GroundParams", "TeeRecord", "annotated_thumbnail"]

SEARCH_EVENTS = ("search_leg", "search_instead", "search_end")  # record events carrying a ``note``
RESULT_NAMES = {0: "accepted", 1: "temporarily_rejected", 2: "denied", 3: "unsupported", 5: "in_progress"}
BACKOFF_S = (1.0, 2.0, 4.0, 8.0, 15.0, 30.0)
Payload = dict[str, Any] | Callable[[], dict[str, Any]]  # a callable is built in a worker thread


@dataclass(frozen=True, slots=True)
class GroundParams:
    host: str = "127.0.0.1"
    port: int = 1883
    username: str | None = None
    password: str | None = field(default=None, repr=False)  # never in a log line
    tls: bool = False
    topic_prefix: str = "landfall"
    vehicle_id: str = "drone1"
    telemetry_hz: float = 1.0
    queue_size: int = 256
    alarm_intake: bool = False
    keepalive_s: int = 30
    thumbnail_width_px: int = 320


def annotated_thumbnail(
    rgb: np.ndarray, boxes: list[list[int]], chosen: int | None, width_px: int, quality: int = 70
) -> bytes:
    """The frame scaled to ``width_px`` wide with each candidate box drawn (the chosen one green and
    thicker, the others amber) and numbered; JPEG bytes."""
    h, w = rgb.shape[:2]
    scale = width_px / w
    small = cv2.resize(rgb, (width_px, max(1, round(h * scale))), interpolation=cv2.INTER_AREA)
    bgr = cv2.cvtColor(small, cv2.COLOR_RGB2BGR)
    for k, box in enumerate(boxes):
        x0, y0, x1, y1 = (round(v * scale) for v in box)
        mine = k == chosen
        colour = (60, 200, 40) if mine else (0, 170, 255)
        cv2.rectangle(bgr, (x0, y0), (x1, y1), colour, 2 if mine else 1)
        cv2.putText(bgr, str(k), (x0 + 2, y0 + 12), cv2.FONT_HERSHEY_SIMPLEX, 0.4, colour, 1, cv2.LINE_AA)
    ok, buf = cv2.imencode(".jpg", bgr, [int(cv2.IMWRITE_JPEG_QUALITY), quality])
    if not ok:
        raise ValueError(f"thumbnail JPEG encoding failed for shape {small.shape}")
    return bytes(buf)


class GroundFeed:
    """Publishes the daemon's story to an MQTT broker; a ``Record`` for the recovery's events."""

    def __init__(self, params: GroundParams, logger: logging.Logger | None = None) -> None:
        self.p = params
        self.log = logger or logging.getLogger("companion.ground")
        self._queue: collections.deque[tuple[str, Payload, bool]] = collections.deque()
        self._pending = asyncio.Event()
        self._last_frame: np.ndarray | None = None
        self.connected = False
        self.published = 0
        self.dropped = 0  # queue full: the oldest message went
        self.failed = 0  # a payload that could not be built or sent

    def topic(self, leaf: str) -> str:
        return f"{self.p.topic_prefix}/{self.p.vehicle_id}/{leaf}"

    # ------------------------------------------------------------------ queue (never blocks)
    def publish(self, leaf: str, payload: Payload, retain: bool = False) -> None:
        if len(self._queue) >= self.p.queue_size:
            self._queue.popleft()
            self.dropped += 1
        self._queue.append((leaf, payload, retain))
        self._pending.set()

    def alarm(self, alarm: Alarm, result: int) -> None:
        self.publish(
            "alarm",
            {"t": time.time(), **alarm.to_json(), "result": RESULT_NAMES.get(result, str(result))},
        )

    # ------------------------------------------------------------------ Record protocol
    def record_event(self, kind: str, fields: dict[str, Any]) -> None:
        body = {"t": time.time(), **fields}
        if kind in ("state", "outcome"):
            self.publish("state", {"kind": kind, **body})
        elif kind == "rank":
            self.publish("decision", self._rank_payload(body))
        elif kind == "confirm":
            self.publish("decision", {"stage": "confirm", **body})
        elif kind == "sensor_fault":
            self.publish("fault", {"kind": kind, **body})
        elif kind in SEARCH_EVENTS:  # the search's plan: a line in the station's timeline
            self.publish("state", {**body, "kind": "note", "state": str(body.get("note", kind))})

    def save_image(self, name: str, rgb: Any) -> None:
        if name.endswith("-acquire") and isinstance(rgb, np.ndarray):
            self._last_frame = rgb  # the frame the next ranking boxes its candidates on
        return None

    def _rank_payload(self, body: dict[str, Any]) -> Payload:
        frame, self._last_frame = self._last_frame, None
        candidates = body.get("candidates") or []
        chosen = body.get("chosen")  # the recovery's pick: the first of the order that is not a fallback
        head = {"stage": "rank", **body}
        if frame is None or not candidates:
            return head
        head["frame_px"] = [int(frame.shape[1]), int(frame.shape[0])]  # what the boxes' pixels are of
        boxes = [c["box"] for c in candidates]
        width = self.p.thumbnail_width_px

        def build() -> dict[str, Any]:
            jpeg = annotated_thumbnail(frame, boxes, chosen, width)
            return {**head, "thumbnail_jpeg_b64": base64.b64encode(jpeg).decode("ascii")}

        return build

    # ------------------------------------------------------------------ the connection
    def _status(self, state: str) -> bytes:
        # alarm_intake: whether a ground station may offer alarms to this vehicle over ``alarm/in``
        return json.dumps({"state": state, "t": time.time(), "alarm_intake": self.p.alarm_intake}).encode()

    def _client(self) -> Any:
        import aiomqtt

        tls = ssl.create_default_context() if self.p.tls else None
        return aiomqtt.Client(
            self.p.host,
            self.p.port,
            username=self.p.username,
            password=self.p.password,
            identifier=f"landfall-{self.p.vehicle_id}",
            keepalive=self.p.keepalive_s,
            tls_context=tls,
            will=aiomqtt.Will(self.topic("status"), self._status("offline"), qos=1, retain=True),
        )

    async def run(
        self,
        telemetry: Callable[[], dict[str, Any]] | None = None,
        on_alarm: Callable[[Alarm], int] | None = None,
    ) -> None:
        """Connect, publish, reconnect after a backoff, until cancelled (then say ``offline``)."""
        import aiomqtt

        tasks = []
        if telemetry is not None:
            tasks.append(asyncio.create_task(self._telemetry(telemetry), name="mqtt-telemetry"))
        failures = 0
        try:
            while True:
                try:
                    async with self._client() as client:
                        self.connected, failures = True, 0
                        self.log.info("MQTT connected to %s:%d", self.p.host, self.p.port)
                        await client.publish(self.topic("status"), self._status("online"), qos=1, retain=True)
                        try:
                            await self._session(client, on_alarm)
                        finally:
                            with contextlib.suppress(aiomqtt.MqttError, asyncio.CancelledError):
                                async with asyncio.timeout(2.0):
                                    await client.publish(
                                        self.topic("status"), self._status("offline"), qos=1, retain=True
                                    )
                except aiomqtt.MqttError as exc:
                    delay = BACKOFF_S[min(failures, len(BACKOFF_S) - 1)]
                    if failures == 0 or self.connected:
                        self.log.warning(
                            "MQTT %s:%d: %s; retrying in %.0f s", self.p.host, self.p.port, exc, delay
                        )
                    self.connected = False
                    failures += 1
                    await asyncio.sleep(delay)
        finally:
            self.connected = False
            for t in tasks:
                t.cancel()

    async def _session(self, client: Any, on_alarm: Callable[[Alarm], int] | None) -> None:
        """Drain (and take alarms) until one of them fails; its error (an ``MqttError``) propagates."""
        jobs = [asyncio.create_task(self._drain(client), name="mqtt-drain")]
        if self.p.alarm_intake and on_alarm is not None:
            await client.subscribe(self.topic("alarm/in"), qos=1)
            jobs.append(asyncio.create_task(self._intake(client, on_alarm), name="mqtt-intake"))
        try:
            done, _ = await asyncio.wait(jobs, return_when=asyncio.FIRST_EXCEPTION)
            for job in done:
                job.result()
        finally:
            for job in jobs:
                job.cancel()
            await asyncio.gather(*jobs, return_exceptions=True)

    async def _drain(self, client: Any) -> None:
        while True:
            await self._pending.wait()
            while self._queue:
                leaf, payload, retain = self._queue[0]
                try:
                    body = await asyncio.to_thread(payload) if callable(payload) else payload
                    data = json.dumps(_finite(body), allow_nan=False, default=_plain).encode()
                except (ValueError, TypeError) as exc:
                    self.failed += 1
                    self.log.warning("MQTT %s payload dropped: %s", leaf, exc)
                    self._queue.popleft()
                    continue
                await client.publish(self.topic(leaf), data, qos=0, retain=retain)
                self._queue.popleft()  # only once sent: a broken connection keeps it for the next one
                self.published += 1
            self._pending.clear()

    async def _intake(self, client: Any, on_alarm: Callable[[Alarm], int]) -> None:
        async for message in client.messages:
            try:
                alarm = alarm_from_mqtt(message.payload)
            except ValueError as exc:
                self.log.warning("MQTT alarm refused: %s", exc)
                self.publish("alarm/result", {"t": time.time(), "result": "malformed", "error": str(exc)})
                continue
            result = on_alarm(alarm)
            self.publish("alarm/result", {"t": time.time(), "reason": alarm.reason,
                                          "result": RESULT_NAMES.get(result, str(result))})  # fmt: skip

    async def _telemetry(self, snapshot: Callable[[], dict[str, Any]]) -> None:
        period = 1.0 / self.p.telemetry_hz
        while True:
            await asyncio.sleep(period)
            self.publish("telemetry", {"t": time.time(), **snapshot()})


def alarm_from_mqtt(payload: Any) -> Alarm:
    """An alarm from an ``alarm/in`` message; ValueError naming the problem."""
    if not isinstance(payload, bytes | bytearray):
        raise ValueError("payload must be JSON bytes")
    try:
        body = json.loads(payload)
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ValueError(f"not JSON: {exc}") from None
    if not isinstance(body, dict):
        raise ValueError("must be a JSON object")
    reason = body.get("reason")
    if not isinstance(reason, str) or not 0 < len(reason.strip()) <= 50:
        raise ValueError("reason must be text of 1 to 50 characters")
    names = {c.name.lower(): c for c in Criticality}
    criticality = body.get("criticality", "high")
    if criticality not in names:
        raise ValueError(f"criticality must be one of {', '.join(names)} (got {criticality!r})")
    code = body.get("code", 0)
    if type(code) is not int:
        raise ValueError(f"code must be an integer (got {code!r})")
    try:
        reason_code = ReasonCode(code)
    except ValueError:
        reason_code = ReasonCode.OTHER
    return Alarm(reason_code, names[criticality], reason.strip(), (0, 0), time.monotonic())


def _finite(value: Any) -> Any:
    """JSON has no NaN or infinity: they become null (an edge distance of inf: no edge in view)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite(v) for v in value]
    return value


def _plain(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"{type(value).__name__} is not JSON")


class TeeRecord:
    """Several records as one: every event to each; an image's path from the first that saves it."""

    def __init__(self, *records: Any) -> None:
        self.records = records

    def record_event(self, kind: str, fields: dict[str, Any]) -> None:
        for r in self.records:
            r.record_event(kind, fields)

    def save_image(self, name: str, rgb: Any) -> Any:
        paths = [r.save_image(name, rgb) for r in self.records]
        return next((p for p in paths if p is not None), None)


def mode_name(autopilot: int, base_mode: int, custom_mode: int) -> str | None:
    """The autopilot's flight mode as its ground stations name it (PX4 ``OFFBOARD``, ArduCopter
    ``GUIDED``), from pymavlink's tables; None before the first heartbeat or for an unknown mode."""
    from pymavlink import mavutil

    if autopilot == mavutil.mavlink.MAV_AUTOPILOT_PX4:
        return str(mavutil.interpret_px4_mode(base_mode, custom_mode))
    if autopilot == mavutil.mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA:
        name = mavutil.mode_mapping_acm.get(custom_mode)
        return None if name is None else str(name)
    return None


def telemetry_snapshot(state: Any) -> dict[str, Any]:
    """The ``telemetry`` payload from a ``VehicleState``."""

    def num(v: float, nd: int = 2) -> float | None:
        return round(v, nd) if math.isfinite(v) else None

    return {
        "pos_ned_m": [num(v) for v in state.pos_ned_m],
        "vel_ned_m_s": [num(v) for v in state.vel_ned_m_s],
        "agl_m": num(state.rangefinder_m),
        "custom_mode": state.custom_mode,
        "mode": mode_name(state.autopilot, state.base_mode, state.custom_mode),
        # seconds since the autopilot's last heartbeat: the companion's link to it (null: never heard)
        "link_age_s": num(time.monotonic() - beat, 1)
        if (beat := state.stamps.get("heartbeat")) is not None
        else None,
        "armed": state.armed,
        "landed": state.landed_state == 1,
        "battery_pct": num(state.battery_pct, 1),
        "gps_fix": state.gps_fix,
    }
