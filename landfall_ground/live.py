"""The live source: the companion's MQTT feed, subscribed through aiomqtt, into a :class:`Station`.

One task holds the broker connection: it subscribes to ``<prefix>/<vehicle or +>/#``, hands every
message to the station (which checks it) and, when the broker is down or goes away, tells the page
(``link``: ``down`` with the reason) and tries again after a capped, jittered backoff. Retained
messages (each vehicle's ``status``) arrive again on every reconnection.

Alarms from the page go to ``<prefix>/<vehicle>/alarm/in`` (QoS 1) on the same connection; the
companion answers on ``alarm/result``, which the page shows like any feed message.
"""

from __future__ import annotations

import asyncio
import json
import logging
import random
import ssl
from dataclasses import dataclass, field
from typing import Any

import aiomqtt

from landfall_ground.station import Station

__all__ = ["AlarmNotSent", "BrokerParams", "LiveFeed"]

BACKOFF_FIRST_S = 0.5
BACKOFF_CAP_S = 5.0  # an operator watching the page wants it back soon after the broker is
CONNECT_TIMEOUT_S = 10.0
PUBLISH_TIMEOUT_S = 5.0


class AlarmNotSent(RuntimeError):
    """An alarm from the page that could not go to the broker (not connected, or it failed)."""


@dataclass(frozen=True, slots=True)
class BrokerParams:
    """Where the feed is: ``vehicle`` None watches every vehicle under ``prefix``."""

    host: str
    port: int = 1883
    username: str | None = None
    password: str | None = field(default=None, repr=False)  # never in a log line
    tls: bool = False
    prefix: str = "landfall"
    vehicle: str | None = None
    identifier: str | None = None

    @property
    def topic_filter(self) -> str:
        return f"{self.prefix}/{self.vehicle or '+'}/#"


class LiveFeed:
    """The broker connection of a live ground station (see the module docstring)."""

    def __init__(self, params: BrokerParams, station: Station, logger: logging.Logger | None = None) -> None:
        self.p = params
        self.station = station
        self.log = logger or logging.getLogger("landfall_ground.live")
        self._client: aiomqtt.Client | None = None
        self.connections = 0

    def _new_client(self) -> aiomqtt.Client:
        tls = ssl.create_default_context() if self.p.tls else None
        return aiomqtt.Client(
            self.p.host,
            self.p.port,
            username=self.p.username,
            password=self.p.password,
            identifier=self.p.identifier,
            tls_context=tls,
            timeout=CONNECT_TIMEOUT_S,
        )

    async def run(self) -> None:
        """Connect, take messages, reconnect; until cancelled."""
        failures = 0
        where = f"{self.p.host}:{self.p.port}"
        while True:
            self.station.set_link("connecting", where)
            try:
                async with self._new_client() as client:
                    await client.subscribe(self.p.topic_filter, qos=1)
                    self._client, failures = client, 0
                    self.connections += 1
                    self.station.set_link("connected", where)
                    self.log.info("MQTT connected to %s, watching %s", where, self.p.topic_filter)
                    async for message in client.messages:
                        payload = message.payload
                        raw = payload if isinstance(payload, bytes | bytearray) else str(payload).encode()
                        self.station.ingest(str(message.topic), raw)
            except aiomqtt.MqttError as exc:
                delay = min(BACKOFF_CAP_S, BACKOFF_FIRST_S * 2**failures) * random.uniform(0.5, 1.0)
                failures += 1
                self.station.set_link("down", f"broker {where}: {exc}; trying again")
                if failures == 1:
                    self.log.warning("MQTT %s: %s; retrying", where, exc)
                await asyncio.sleep(delay)
            finally:
                self._client = None

    async def send_alarm(self, vehicle: str, body: dict[str, Any]) -> None:
        """Publish an alarm for ``vehicle`` (a checked ``alarm/in`` body); AlarmNotSent when it cannot."""
        client = self._client
        if client is None:
            raise AlarmNotSent(f"not connected to the broker {self.p.host}:{self.p.port}")
        topic = f"{self.p.prefix}/{vehicle}/alarm/in"
        try:
            async with asyncio.timeout(PUBLISH_TIMEOUT_S):
                await client.publish(topic, json.dumps(body).encode(), qos=1)
        except (aiomqtt.MqttError, TimeoutError) as exc:
            raise AlarmNotSent(f"publishing to {topic} failed: {exc}") from exc
        self.log.info("alarm %r (%s) sent to %s", body.get("reason"), body.get("criticality"), vehicle)
