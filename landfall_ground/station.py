"""What the ground station knows, and who is watching: vehicles' feed histories, the broker link, the
malformed-payload count, and the pages to tell of each change.

Every change becomes one event, a JSON object with a ``type``, serialised once and queued to every
watching page (a WebSocket each):

=============  ================================================================================
type           fields
=============  ================================================================================
``hello``      the whole picture, sent first to each page and after a replay seek: ``source``
               (``live``/``replay``), ``link``, ``malformed``, ``recent``, ``alarms``,
               ``basemap``, ``clock``, ``vehicles`` (id -> the messages kept, oldest first)
``msg``        one checked feed message: ``vehicle``, ``leaf``, ``body``, ``t``
``link``       the broker link: ``state`` (``connecting``, ``connected``, ``down``), ``detail``
``malformed``  the count so far (``malformed``) and the newest few (``recent``: ``topic``,
               ``problem``, ``t``)
``clock``      a replay's position: ``t``, ``t0``, ``t1``, ``playing``, ``speed``
=============  ================================================================================

A page too slow to take its events (its queue is full) is dropped; it reconnects and starts again
from a ``hello``. Histories are bounded: the newest ``TELEMETRY_KEPT`` telemetry samples and
``EVENTS_KEPT`` other messages per vehicle.
"""

from __future__ import annotations

import asyncio
import collections
import itertools
import json
import logging
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

from landfall_ground.messages import FeedMessage, MalformedPayload, parse

__all__ = ["EVENTS_KEPT", "TELEMETRY_KEPT", "Station", "Watcher"]

TELEMETRY_KEPT = 3600  # an hour at the companion's default 1 Hz
EVENTS_KEPT = 1000
MALFORMED_SHOWN = 10
QUEUE_SIZE = 2000  # events waiting for one page before it is dropped


@dataclass
class _Vehicle:
    telemetry: collections.deque[tuple[int, FeedMessage]] = field(
        default_factory=lambda: collections.deque(maxlen=TELEMETRY_KEPT)
    )
    events: collections.deque[tuple[int, FeedMessage]] = field(
        default_factory=lambda: collections.deque(maxlen=EVENTS_KEPT)
    )
    status: FeedMessage | None = None  # the newest, kept even when its turn in ``events`` is over

    def messages(self) -> list[FeedMessage]:
        merged = sorted(itertools.chain(self.telemetry, self.events), key=lambda pair: pair[0])
        out = [m for _, m in merged]
        if self.status is not None and all(m is not self.status for m in out):
            out.insert(0, self.status)
        return out


class Watcher:
    """One page's queue of serialised events; ``dropped`` once it fell too far behind."""

    def __init__(self) -> None:
        self.queue: asyncio.Queue[str] = asyncio.Queue(QUEUE_SIZE)
        self.dropped = False

    def put(self, text: str) -> None:
        if self.dropped:
            return
        try:
            self.queue.put_nowait(text)
        except asyncio.QueueFull:
            self.dropped = True


class Station:
    """The ground station's state. ``source`` is ``live`` (an MQTT feed) or ``replay`` (a record);
    ``alarms`` is what the page's alarm form may do (``enabled``, ``why`` when not); ``prefix`` the
    feed's topic prefix."""

    def __init__(
        self,
        source: str,
        *,
        prefix: str = "landfall",
        alarms: dict[str, Any] | None = None,
        basemap: dict[str, Any] | None = None,
        logger: logging.Logger | None = None,
    ) -> None:
        self.source = source
        self.prefix = prefix
        self.alarms = alarms or {"enabled": False, "why": "alarms are not offered"}
        self.basemap = basemap
        self.log = logger or logging.getLogger("landfall_ground")
        self.vehicles: dict[str, _Vehicle] = {}
        self.malformed = 0
        self.malformed_recent: collections.deque[dict[str, Any]] = collections.deque(maxlen=MALFORMED_SHOWN)
        self.link: dict[str, Any] = {"state": "connecting", "detail": "", "since": time.time()}
        self.clock: dict[str, Any] | None = None
        self._seq = itertools.count()
        self._watchers: set[Watcher] = set()

    # ------------------------------------------------------------------ input
    def ingest(self, topic: str, payload: bytes | bytearray | str, now: float | None = None) -> None:
        """One MQTT message: kept and told when it is the feed's, counted when malformed."""
        now = time.time() if now is None else now
        try:
            msg = parse(topic, payload, self.prefix, now)
        except MalformedPayload as exc:
            self.reject(exc, now)
            return
        if msg is not None:
            self.add(msg)

    def add(self, msg: FeedMessage, tell: bool = True) -> None:
        """Keep a checked message; ``tell=False`` keeps it quietly (a replay's seek resyncs after)."""
        v = self.vehicles.setdefault(msg.vehicle, _Vehicle())
        entry = (next(self._seq), msg)
        if msg.leaf == "telemetry":
            v.telemetry.append(entry)
        else:
            v.events.append(entry)
        if msg.leaf == "status":
            v.status = msg
        if tell:
            self._tell({"type": "msg", **msg.to_json()})

    def reject(self, exc: MalformedPayload, now: float) -> None:
        self.malformed += 1
        self.malformed_recent.append({"topic": exc.topic, "problem": exc.problem, "t": now})
        self.log.warning("malformed feed message on %s: %s", exc.topic, exc.problem)
        self._tell(self._malformed_event())

    def set_link(self, state: str, detail: str = "") -> None:
        if (state, detail) == (self.link["state"], self.link["detail"]):
            return
        self.link = {"state": state, "detail": detail, "since": time.time()}
        self._tell({"type": "link", **self.link})

    def set_clock(self, clock: dict[str, Any]) -> None:
        self.clock = clock
        self._tell({"type": "clock", **clock})

    def reset(self) -> None:
        """Forget every vehicle's history (a replay's seek rebuilds it); pages hear on :meth:`resync`."""
        self.vehicles.clear()

    def resync(self) -> None:
        """Send every page the whole picture again."""
        self._tell(self.snapshot())

    # ------------------------------------------------------------------ output
    def snapshot(self) -> dict[str, Any]:
        malformed = self._malformed_event()
        return {
            "type": "hello",
            "source": self.source,
            "link": self.link,
            "alarms": self.alarms,
            "basemap": self.basemap,
            "clock": self.clock,
            "malformed": malformed["malformed"],
            "recent": malformed["recent"],
            "vehicles": {
                vid: [m.to_json() for m in v.messages()] for vid, v in sorted(self.vehicles.items())
            },
        }

    def _malformed_event(self) -> dict[str, Any]:
        return {"type": "malformed", "malformed": self.malformed, "recent": list(self.malformed_recent)}

    @contextmanager
    def watch(self) -> Iterator[Watcher]:
        """A queue of this station's events for one page, starting with the whole picture."""
        w = Watcher()
        w.put(_dump(self.snapshot()))
        self._watchers.add(w)
        try:
            yield w
        finally:
            self._watchers.discard(w)

    def _tell(self, event: dict[str, Any]) -> None:
        if not self._watchers:
            return
        text = _dump(event)
        for w in self._watchers:
            w.put(text)


def _dump(event: dict[str, Any]) -> str:
    return json.dumps(event, allow_nan=False, separators=(",", ":"))
