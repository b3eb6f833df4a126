"""Replay of a flight record (``companion --record DIR``) through the live page.

:func:`load_record` reads one session's ``events.jsonl`` and turns its events into the feed messages
the companion would have published (companion/ground.py), on the record's own clock:

==================================  ==========================================================
record event                        feed message
==================================  ==========================================================
``alarm``                           ``alarm`` (recorded alarms are the accepted ones)
``state``, ``outcome``              ``state`` (``kind`` says which); ``state`` carries the
                                    vehicle's ``pos_ned_m`` (the replay's trajectory)
``rank``                            ``decision`` with ``thumbnail_jpeg_b64``: the round's
                                    ``roundNN-acquire.jpg`` with the candidates boxed
``confirm``                         ``decision`` (stage ``confirm``, the LiDAR check)
``sensor_fault``, ``defect``,       ``fault``
``link_lost``
``extend``, ``fallback_site``,      ``state`` with ``kind`` ``note``: a line in the timeline
``link_restored``
``search_leg``, ``search_instead``, ``state`` with ``kind`` ``note``: the event's own ``note``,
``search_end``                      as the live feed sends it
==================================  ==========================================================

A line that is not a JSON object, or an event whose fields have the wrong shape, is counted as
malformed (and shown), never fatal. A directory that holds no record is a :class:`NotARecord` error.

:class:`Replay` plays the messages into a :class:`~landfall_ground.station.Station` at ``speed`` times
the recorded pace; the page's slider seeks (the station is rebuilt up to that instant and every
page gets the whole picture again), its buttons pause, resume and step one event back or forward.
"""

from __future__ import annotations

import asyncio
import base64
import bisect
import json
import logging
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2

from companion.ground import annotated_thumbnail
from companion.record import EVENTS_FILE
from landfall_ground.messages import FeedMessage, MalformedPayload, parse_body
from landfall_ground.station import Station

__all__ = ["NotARecord", "RecordedFlight", "Replay", "find_session", "load_record"]

THUMBNAIL_WIDTH_PX = 320  # as the companion's feed sends them
CLOCK_PERIOD_S = 0.25  # wall seconds between the slider's updates while playing
SEEK_TOLERANCE_S = 1e-5  # ten times the rounding of a unix time in a double


class NotARecord(ValueError):
    """A ``--replay`` path that holds no flight record; the message says what was looked for."""


@dataclass
class RecordedFlight:
    """A session's feed messages in time order, and what could not be read."""

    session: str
    messages: list[FeedMessage]
    rejected: list[MalformedPayload] = field(default_factory=list)

    @property
    def t0(self) -> float:
        return self.messages[0].t if self.messages else 0.0

    @property
    def t1(self) -> float:
        return self.messages[-1].t if self.messages else 0.0


def find_session(path: Path) -> Path:
    """The session directory of ``path``: itself when it holds ``events.jsonl``, else its newest session
    (names start with their UTC start time) that does."""
    if not path.exists():
        raise NotARecord(f"{path}: no such file or directory")
    if not path.is_dir():
        raise NotARecord(f"{path} is not a directory (expected a flight record: companion --record DIR)")
    if (path / EVENTS_FILE).is_file():
        return path
    sessions = sorted(p for p in path.iterdir() if p.is_dir() and (p / EVENTS_FILE).is_file())
    if not sessions:
        raise NotARecord(
            f"{path} is not a flight record: no {EVENTS_FILE} in it or in any directory under it "
            "(expected the DIR of companion --record DIR, or one of its session directories)"
        )
    return sessions[-1]


def load_record(path: Path) -> RecordedFlight:
    """The feed messages of the flight record at ``path`` (see :func:`find_session`)."""
    session_dir = find_session(path)
    vehicle = session_dir.name
    flight = RecordedFlight(vehicle, [])
    try:
        lines = (session_dir / EVENTS_FILE).read_bytes().splitlines()
    except OSError as exc:
        raise NotARecord(f"{session_dir / EVENTS_FILE}: {exc.strerror or exc}") from exc
    for n, line in enumerate(lines, 1):
        where = f"{EVENTS_FILE} line {n}"
        if not line.strip():
            continue
        try:
            try:
                row = json.loads(line, parse_constant=_refuse_constant)
            except ValueError as exc:  # JSONDecodeError and UnicodeDecodeError among them
                raise ValueError(f"not JSON ({exc})") from None
            except RecursionError:
                raise ValueError("not JSON this ground station reads: nested too deep") from None
            if not isinstance(row, dict):
                raise ValueError(f"expected a JSON object, got {type(row).__name__}")
            t = row.get("time_unix_s")
            if not isinstance(t, int | float) or isinstance(t, bool):
                raise ValueError(f"time_unix_s must be a number, got {t!r:.40}")
            converted = _convert(row, session_dir)
        except ValueError as exc:
            flight.rejected.append(MalformedPayload(where, str(exc)))
            continue
        if converted is None:
            continue
        leaf, body = converted
        try:
            flight.messages.append(parse_body(where, vehicle, leaf, {**body, "t": float(t)}, float(t)))
        except MalformedPayload as exc:
            flight.rejected.append(exc)
    flight.messages.sort(key=lambda m: m.t)
    if not flight.messages and not flight.rejected:
        raise NotARecord(f"{session_dir / EVENTS_FILE} holds no events")
    return flight


def _refuse_constant(name: str) -> float:
    raise ValueError(f"{name} is not JSON")


def _fields(row: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in row.items() if k not in ("time_unix_s", "time_mono_s", "seq", "kind")}


def _convert(row: dict[str, Any], session_dir: Path) -> tuple[str, dict[str, Any]] | None:
    """(leaf, body) of one record event, or None for an event the page does not show."""
    kind, body = row.get("kind"), _fields(row)
    if kind == "alarm":
        return "alarm", {"result": "accepted", **body}
    if kind in ("state", "outcome"):
        return "state", {"kind": kind, **body}
    if kind == "rank":
        return "decision", {"stage": "rank", **body, **_thumbnail(body, session_dir)}
    if kind == "confirm":
        return "decision", {"stage": "confirm", **body}
    if kind in ("sensor_fault", "defect", "link_lost"):
        return "fault", {"kind": kind, **body}
    if kind in ("extend", "fallback_site", "link_restored"):
        return "state", {"kind": "note", "state": _note(kind, body), **_without(body, "state")}
    if kind in ("search_leg", "search_instead", "search_end"):  # as the live feed sends them
        return "state", {**body, "kind": "note", "state": str(body.get("note", kind))}
    return None


def _without(body: dict[str, Any], key: str) -> dict[str, Any]:
    return {k: v for k, v in body.items() if k != key}


def _note(kind: str, body: dict[str, Any]) -> str:
    if kind == "extend":
        return f"budget spent: {body.get('action', 'more rounds')}"
    if kind == "fallback_site":
        instead = body.get("instead_of")
        if isinstance(instead, dict):  # a site seen from afar proved worse from overhead
            chosen = body.get("chosen")
            if not isinstance(chosen, dict):
                chosen = {}
            return (
                f"{instead.get('label', 'the site')} from overhead: {instead.get('hazard', '?')}; "
                f"landing at {chosen.get('label', 'the next site')} instead"
            )
        return f"landing at the best site seen: {body.get('reason', '')}".rstrip(": ")
    return f"link back after {body.get('silent_s', '?')} s"


def _thumbnail(body: dict[str, Any], session_dir: Path) -> dict[str, Any]:
    """The round's frame with its candidates boxed, as the live feed sends it; nothing when the record
    kept no frame for the round (pruned, or no camera)."""
    rnd, candidates = body.get("round"), body.get("candidates")
    if not isinstance(rnd, int) or not isinstance(candidates, list) or not candidates:
        return {}
    bgr = cv2.imread(str(session_dir / f"round{rnd:02d}-acquire.jpg"), cv2.IMREAD_COLOR)
    if bgr is None:
        return {}
    try:
        boxes = [[int(v) for v in c["box"]] for c in candidates]
    except (TypeError, KeyError, ValueError):
        return {}  # the shape check of the decision says what is wrong with them
    chosen = body.get("chosen") if isinstance(body.get("chosen"), int) else None
    jpeg = annotated_thumbnail(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), boxes, chosen, THUMBNAIL_WIDTH_PX)
    return {
        "thumbnail_jpeg_b64": base64.b64encode(jpeg).decode("ascii"),
        "frame_px": [int(bgr.shape[1]), int(bgr.shape[0])],
    }


class Replay:
    """Plays a :class:`RecordedFlight` into ``station``: :meth:`run` until cancelled; :meth:`seek`,
    :meth:`play`, :meth:`pause`, :meth:`step` and :meth:`set_speed` steer it (the page's controls)."""

    def __init__(
        self,
        flight: RecordedFlight,
        station: Station,
        speed: float = 1.0,
        logger: logging.Logger | None = None,
    ) -> None:
        if not speed > 0:
            raise ValueError(f"speed must be > 0, got {speed}")
        self.flight = flight
        self.station = station
        self.speed = speed
        self.log = logger or logging.getLogger("landfall_ground.replay")
        self.playing = True
        self._times = [m.t for m in flight.messages]
        self._next = 0  # index of the next message to play
        self._pos_t = flight.t0  # record time now shown
        self._changed = asyncio.Event()
        for exc in flight.rejected:
            station.reject(exc, time.time())
        station.set_link("connected", f"replay of {flight.session}")

    # ------------------------------------------------------------------ controls
    def seek(self, t: float) -> None:
        """Show the flight as it was at record time ``t`` (clamped to the record)."""
        if not math.isfinite(t):
            raise ValueError(f"seek time must be a finite number, got {t}")
        t = min(max(t, self.flight.t0), self.flight.t1)
        self.station.reset()
        # the page's slider counts seconds from the start: t0 + (t1 - t0) may miss t1 by a rounding
        self._next = bisect.bisect_right(self._times, t + SEEK_TOLERANCE_S)
        for m in self.flight.messages[: self._next]:
            self.station.add(m, tell=False)
        self._pos_t = t
        self._tell_clock(resync=True)

    def play(self) -> None:
        if self._next >= len(self._times):
            self.seek(self.flight.t0)  # from the start again
        self.playing = True
        self._tell_clock()

    def pause(self) -> None:
        self.playing = False
        self._tell_clock()

    def step(self, by: int) -> None:
        """Pause and show ``by`` more messages (fewer when negative): event by event review."""
        self.playing = False
        shown = min(max(self._next + by, 1), len(self._times))
        self.seek(self._times[shown - 1] if self._times else self.flight.t0)

    def set_speed(self, speed: float) -> None:
        if not speed > 0:
            raise ValueError(f"speed must be > 0, got {speed}")
        self.speed = speed
        self._tell_clock()

    def clock(self) -> dict[str, Any]:
        return {
            "t": self._pos_t,
            "t0": self.flight.t0,
            "t1": self.flight.t1,
            "playing": self.playing,
            "speed": self.speed,
        }

    def _tell_clock(self, resync: bool = False) -> None:
        self.station.clock = self.clock()
        if resync:
            self.station.resync()
        else:
            self.station.set_clock(self.clock())
        self._changed.set()

    # ------------------------------------------------------------------ the player
    async def run(self) -> None:
        self._tell_clock()
        while True:
            self._changed.clear()
            if not self.playing:
                await self._changed.wait()
                continue
            if self._next >= len(self._times):
                self._pos_t = self.flight.t1
                self.playing = False
                self._tell_clock()
                continue
            due = self._times[self._next]
            wait_s = min((due - self._pos_t) / self.speed, CLOCK_PERIOD_S)
            started = time.monotonic()
            if wait_s > 0:
                try:
                    async with asyncio.timeout(wait_s):
                        await self._changed.wait()
                    continue  # a control changed the position or the pace: start over from there
                except TimeoutError:
                    pass
            self._pos_t = min(due, self._pos_t + (time.monotonic() - started) * self.speed)
            while self._next < len(self._times) and self._times[self._next] <= self._pos_t:
                self.station.add(self.flight.messages[self._next])
                self._next += 1
            self.station.set_clock(self.clock())
