"""The companion's MQTT feed as the ground station reads it: topic and payload checks.

A message is ``<prefix>/<vehicle_id>/<leaf>`` with a JSON object as payload (companion/ground.py lists
the leaves and their keys). :func:`parse` turns one into a :class:`FeedMessage` or raises
:class:`MalformedPayload` saying what was wrong; the page only ever sees checked messages, so a
payload with the wrong shape is counted and shown, never drawn half. Keys the page does not use pass
through unchecked: a newer companion may add keys without breaking an older ground station.
"""

from __future__ import annotations

import base64
import binascii
import json
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

__all__ = ["LEAVES", "FeedMessage", "MalformedPayload", "parse", "parse_body"]

# what the page draws; anything else under a vehicle (alarm/in: alarms on their way to it) is not feed
LEAVES = ("status", "alarm", "state", "decision", "fault", "telemetry", "alarm/result")


class MalformedPayload(ValueError):
    """A feed message the ground station cannot use; ``topic`` names it, the message says why."""

    def __init__(self, topic: str, problem: str) -> None:
        super().__init__(f"{topic}: {problem}")
        self.topic = topic
        self.problem = problem


@dataclass(frozen=True, slots=True)
class FeedMessage:
    """One checked feed message: ``t`` unix seconds (the payload's own ``t`` when it has one)."""

    vehicle: str
    leaf: str
    body: dict[str, Any]
    t: float

    def to_json(self) -> dict[str, Any]:
        return {"vehicle": self.vehicle, "leaf": self.leaf, "body": self.body, "t": self.t}


def split_topic(topic: str, prefix: str) -> tuple[str, str] | None:
    """(vehicle, leaf) of a feed topic, or None when the topic is not one of the feed's."""
    head = prefix.rstrip("/") + "/"
    if not topic.startswith(head):
        return None
    vehicle, _, leaf = topic[len(head) :].partition("/")
    if not vehicle or leaf not in LEAVES:
        return None
    return vehicle, leaf


def _no_constants(name: str) -> float:
    raise ValueError(f"{name} is not JSON")


def parse(topic: str, payload: bytes | bytearray | str, prefix: str, now: float) -> FeedMessage | None:
    """The checked message of an MQTT message; None for a topic outside the feed (nothing to count).

    Raises:
        MalformedPayload: the payload is not a JSON object of the leaf's shape.
    """
    where = split_topic(topic, prefix)
    if where is None:
        return None
    vehicle, leaf = where
    try:
        body = json.loads(payload, parse_constant=_no_constants)
    except (UnicodeDecodeError, ValueError) as exc:  # JSONDecodeError is a ValueError
        raise MalformedPayload(topic, f"not JSON ({exc})") from None
    except RecursionError:
        raise MalformedPayload(topic, "not JSON this ground station reads: nested too deep") from None
    return parse_body(topic, vehicle, leaf, body, now)


def parse_body(topic: str, vehicle: str, leaf: str, body: Any, now: float) -> FeedMessage:
    """A decoded payload checked against its leaf's shape (see :func:`parse`)."""
    if not isinstance(body, dict):
        raise MalformedPayload(topic, f"expected a JSON object, got {type(body).__name__}")
    try:
        _CHECKS[leaf](body)
        t = _opt(body, "t", _number)
    except (TypeError, ValueError) as exc:
        raise MalformedPayload(topic, str(exc)) from None
    return FeedMessage(vehicle, leaf, body, now if t is None else float(t))


# --------------------------------------------------------------------------- shapes
def _number(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)


def _text(v: Any) -> bool:
    return isinstance(v, str)


def _opt(body: dict[str, Any], key: str, ok: Callable[[Any], bool], what: str = "a number") -> Any:
    """``body[key]`` when present and not null, checked; ValueError naming the key otherwise."""
    v = body.get(key)
    if v is not None and not ok(v):
        raise ValueError(f"{key} must be {what} or null, got {v!r:.60}")
    return v


def _need(body: dict[str, Any], key: str, ok: Callable[[Any], bool], what: str) -> Any:
    v = body.get(key)
    if not ok(v):
        raise ValueError(f"{key} must be {what}, got {v!r:.60}")
    return v


def _vector(n: int) -> Callable[[Any], bool]:
    return lambda v: isinstance(v, list) and len(v) == n and all(x is None or _number(x) for x in v)


def _status(body: dict[str, Any]) -> None:
    _need(body, "state", lambda v: v in ("online", "offline"), '"online" or "offline"')
    _opt(body, "alarm_intake", lambda v: isinstance(v, bool), "true or false")


def _alarm(body: dict[str, Any]) -> None:
    _need(body, "reason", _text, "text")
    _opt(body, "result", _text, "text")
    _opt(body, "criticality", _text, "text")


def _state(body: dict[str, Any]) -> None:
    _need(body, "state", _text, "text")
    _opt(body, "kind", _text, "text")
    _opt(body, "round", _number)
    _opt(body, "pos_ned_m", _vector(3), "[north, east, down] metres")


def _candidate(c: Any) -> bool:
    return isinstance(c, dict) and _vector(4)(c.get("box")) and None not in c["box"]


def _decision(body: dict[str, Any]) -> None:
    stage = _need(body, "stage", lambda v: v in ("rank", "confirm"), '"rank" or "confirm"')
    _opt(body, "rationale", _text, "text")
    _opt(body, "tier", _text, "text")
    _opt(body, "latency_s", _number)
    _opt(body, "round", _number)
    if stage == "rank":
        _opt(body, "candidates", lambda v: isinstance(v, list) and all(map(_candidate, v)), "a list of boxes")
        _opt(body, "chosen", lambda v: isinstance(v, int) and not isinstance(v, bool), "an index")
        _opt(body, "frame_px", lambda v: _vector(2)(v) and None not in v and min(v) > 0, "[width, height]")
        thumb = _opt(body, "thumbnail_jpeg_b64", _text, "base64 text")
        if thumb is not None:
            try:
                jpeg = base64.b64decode(thumb, validate=True)
            except binascii.Error as exc:
                raise ValueError(f"thumbnail_jpeg_b64 is not base64 ({exc})") from None
            if not jpeg.startswith(b"\xff\xd8"):
                raise ValueError("thumbnail_jpeg_b64 is not a JPEG image")
    else:
        _opt(body, "accept", lambda v: isinstance(v, bool), "true or false")
        _opt(body, "check", lambda v: isinstance(v, dict), "an object")
        _opt(body, "site_ned_m", _vector(3), "[north, east, down] metres")


def _telemetry(body: dict[str, Any]) -> None:
    _opt(body, "pos_ned_m", _vector(3), "[north, east, down] metres")
    for key in ("agl_m", "battery_pct", "link_age_s"):
        _opt(body, key, _number)
    _opt(body, "mode", _text, "text")
    _opt(body, "armed", lambda v: isinstance(v, bool), "true or false")


def _anything(body: dict[str, Any]) -> None:
    return None


def _alarm_result(body: dict[str, Any]) -> None:
    _need(body, "result", _text, "text")


_CHECKS: dict[str, Callable[[dict[str, Any]], None]] = {
    "status": _status,
    "alarm": _alarm,
    "state": _state,
    "decision": _decision,
    "fault": _anything,
    "telemetry": _telemetry,
    "alarm/result": _alarm_result,
}
