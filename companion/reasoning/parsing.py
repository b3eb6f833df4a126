"""Reading a model's answer: the JSON the schema asks for, or the free-text fallback.

Models answer in many shapes even when asked for a schema: bare JSON, JSON in a Markdown fence, JSON
after a preamble, or prose that ends with ``Final Ranking: [2, 0, 1]`` / ``Final Decision: 1``. All of
these are read. Everything else is a typed error (:mod:`companion.reasoning.base`): nothing at all
(:class:`EmptyAnswer`), JSON that stops early (:class:`TruncatedAnswer`), no readable answer
(:class:`MalformedAnswer`), indices out of range or repeated (:class:`InvalidIndices`).

A ranking may list fewer candidates than were shown (a model may leave out a site it judges unlandable),
never none, never one twice, never one that does not exist.
"""

from __future__ import annotations

import json
import re
from typing import Any

from companion.reasoning.base import (
    EmptyAnswer,
    InvalidIndices,
    MalformedAnswer,
    ReasonerError,
    Refusal,
    TruncatedAnswer,
)

__all__ = ["parse_confirm", "parse_rank"]

_FENCE = re.compile(r"```(?:json|JSON)?\s*(.*?)```", re.DOTALL)
_FINAL_RANKING = re.compile(r"final\s+ranking\s*[:=]?\s*\[([^\]]*)\]", re.IGNORECASE)
_FINAL_DECISION = re.compile(r"final\s+decision\s*[:=]?\s*\**\s*(1|0|yes|no|safe|unsafe)\b", re.IGNORECASE)
_RANKING_KEY = re.compile(r'"ranking"\s*:\s*\[([^\]]*)\]')
_DECISION_KEY = re.compile(r'"decision"\s*:\s*"?(1|0|true|false)"?', re.IGNORECASE)
# a refusal written as the content instead of in message.refusal
_REFUSAL = re.compile(
    r"\b(I'?m sorry|I am sorry|I (?:cannot|can'?t|won'?t|am unable to|'m unable to) "
    r"(?:help|assist|comply|provide|make|choose|decide))",
    re.IGNORECASE,
)


def _json_object(text: str) -> dict[str, Any] | None:
    """The first JSON object in ``text`` (bare, fenced or after a preamble); ``None`` when there is none.

    Raises :class:`TruncatedAnswer` when an object starts but never closes.
    """
    candidates = [m.group(1) for m in _FENCE.finditer(text)] + [text]
    decoder = json.JSONDecoder()
    started = False
    for chunk in candidates:
        for start in (i for i, ch in enumerate(chunk) if ch == "{"):
            started = True
            try:
                obj, _end = decoder.raw_decode(chunk, start)
            except json.JSONDecodeError:
                continue
            if isinstance(obj, dict):
                return obj
    if started and text.count("{") > text.count("}"):
        raise TruncatedAnswer(f"the JSON answer stops before it closes: ...{text[-60:]!r}")
    return None


def _index(value: Any) -> int:
    if isinstance(value, bool):
        raise InvalidIndices(f"ranking holds {value!r}, not a candidate index")
    if isinstance(value, int):
        return value
    if isinstance(value, float) and value.is_integer():
        return int(value)
    if isinstance(value, str) and value.strip().lstrip("-").isdigit():
        return int(value.strip())
    raise InvalidIndices(f"ranking holds {value!r}, not a candidate index")


def _check_order(raw: Any, n: int) -> tuple[int, ...]:
    if not isinstance(raw, list):
        raise MalformedAnswer(f"'ranking' must be a list of indices, got {type(raw).__name__}")
    order = tuple(_index(v) for v in raw)
    if not order:
        raise InvalidIndices("the ranking is empty")
    bad = [k for k in order if not 0 <= k < n]
    if bad:
        raise InvalidIndices(f"ranking {list(order)} has indices outside 0..{n - 1}: {bad}")
    if len(set(order)) != len(order):
        repeated = sorted({k for k in order if order.count(k) > 1})
        raise InvalidIndices(f"ranking {list(order)} repeats {repeated}")
    return order


def _numbers(text: str) -> list[Any]:
    items = [t.strip().strip("\"'") for t in text.split(",") if t.strip()]
    return [int(t) if t.lstrip("-").isdigit() else t for t in items]


def _no_answer(body: str, what: str) -> ReasonerError:
    if _REFUSAL.search(body):
        return Refusal(f"the model declined: {body[:120]!r}")
    return MalformedAnswer(f"no {what} in the answer: {body[:80]!r}")


def _require_text(text: str | None) -> str:
    if text is None or not text.strip():
        raise EmptyAnswer("the model's answer is empty")
    return text.strip()


def parse_rank(text: str | None, n: int) -> tuple[tuple[int, ...], str]:
    """``(order, explanation)`` from a ranking answer over ``n`` candidates."""
    body = _require_text(text)
    try:
        obj = _json_object(body)
    except TruncatedAnswer:
        # a truncated object may still have finished its ranking before the cut
        m = _RANKING_KEY.search(body) or _FINAL_RANKING.search(body)
        if m is None:
            raise
        return _check_order(_numbers(m.group(1)), n), body
    if obj is not None and "ranking" in obj:
        explanation = obj.get("explanation", "")
        return _check_order(obj["ranking"], n), str(explanation) if explanation else ""
    m = _FINAL_RANKING.search(body)
    if m is None:
        raise _no_answer(body, "ranking")
    return _check_order(_numbers(m.group(1)), n), body[: m.start()].strip() or body


def _decision(value: Any) -> bool:
    if isinstance(value, bool):
        return value
    if isinstance(value, int | float) and value in (0, 1):
        return bool(value)
    if isinstance(value, str) and value.strip().lower() in ("1", "0", "true", "false", "yes", "no"):
        return value.strip().lower() in ("1", "true", "yes")
    raise MalformedAnswer(f"'decision' must be 1 or 0, got {value!r}")


def parse_confirm(text: str | None) -> tuple[bool, str]:
    """``(accept, explanation)`` from a confirmation answer."""
    body = _require_text(text)
    try:
        obj = _json_object(body)
    except TruncatedAnswer:
        m = _DECISION_KEY.search(body)
        if m is None:
            raise
        return _decision(m.group(1)), body
    if obj is not None and "decision" in obj:
        explanation = obj.get("explanation", "")
        return _decision(obj["decision"]), str(explanation) if explanation else ""
    m = _FINAL_DECISION.search(body)
    if m is None:
        raise _no_answer(body, "decision")
    word = m.group(1).lower()
    return word in ("1", "yes", "safe"), body[: m.start()].strip() or body
