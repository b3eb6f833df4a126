"""Reading model answers: JSON in its usual wrappings, the free-text fallback, and typed errors."""

from __future__ import annotations

import json

import pytest
from hypothesis import given
from hypothesis import strategies as st

from companion.reasoning.base import (
    EmptyAnswer,
    InvalidIndices,
    MalformedAnswer,
    Refusal,
    TruncatedAnswer,
)
from companion.reasoning.parsing import parse_confirm, parse_rank
from companion.reasoning.prompts import (
    CONFIRM_SCHEMA,
    RANK_SCHEMA,
    confirm_prompt,
    rank_prompt,
    response_format,
)


@given(st.permutations(range(5)), st.sampled_from(["bare", "fenced", "preamble", "free"]))
def test_any_ranking_reads_back_in_any_wrapping(order: list[int], wrapping: str) -> None:
    obj = json.dumps({"explanation": "site analysis", "ranking": order})
    text = {
        "bare": obj,
        "fenced": f"Here you go:\n```json\n{obj}\n```",
        "preamble": f"Let me think. {{not json}} Answer: {obj} done",
        "free": f"Site 3 is best.\nFinal Ranking: {order}",
    }[wrapping]
    parsed, explanation = parse_rank(text, 5)
    assert list(parsed) == order
    assert explanation


def test_partial_ranking_is_kept_and_indices_may_be_numeric_strings() -> None:
    assert parse_rank('{"explanation": "x", "ranking": ["2", 0]}', 3)[0] == (2, 0)
    assert parse_rank('{"explanation": "x", "ranking": [2.0, 1]}', 3)[0] == (2, 1)


@pytest.mark.parametrize(
    ("text", "error"),
    [
        (None, EmptyAnswer),
        ("   ", EmptyAnswer),
        ('{"explanation": "x", "ranking": [0, 3]}', InvalidIndices),
        ('{"explanation": "x", "ranking": [-1, 0]}', InvalidIndices),
        ('{"explanation": "x", "ranking": [1, 1]}', InvalidIndices),
        ('{"explanation": "x", "ranking": [true, 0]}', InvalidIndices),
        ('{"explanation": "x", "ranking": []}', InvalidIndices),
        ('{"explanation": "x", "ranking": {"a": 1}}', MalformedAnswer),
        ('{"explanation": "the roof is', TruncatedAnswer),
        ("Final Ranking: [0, 7]", InvalidIndices),
        ("I prefer the roof.", MalformedAnswer),
        ("I'm sorry, but I can't help with choosing a landing site.", Refusal),
    ],
)
def test_bad_rankings(text: str | None, error: type[Exception]) -> None:
    with pytest.raises(error):
        parse_rank(text, 3)


def test_truncated_after_a_complete_ranking_still_reads() -> None:
    # the ranking closed before the cut: the answer is usable
    assert parse_rank('{"ranking": [2, 0, 1], "explanation": "2 is a clear ro', 3)[0] == (2, 0, 1)


@pytest.mark.parametrize(
    ("text", "accept"),
    [
        ('{"explanation": "clear", "decision": 1}', True),
        ('{"explanation": "a person", "decision": 0}', False),
        ('{"explanation": "clear", "decision": "1"}', True),
        ('```json\n{"explanation": "x", "decision": true}\n```', True),
        ("The site is clear gravel.\nFinal Decision: 1", True),
        ("Vents near the centre.\nFinal Decision: **0**", False),
    ],
)
def test_confirm_answers(text: str, accept: bool) -> None:
    assert parse_confirm(text)[0] is accept


@pytest.mark.parametrize(
    ("text", "error"),
    [
        ('{"explanation": "x", "decision": 2}', MalformedAnswer),
        ('{"explanation": "x", "decision": "maybe"}', MalformedAnswer),
        ('{"explanation": "the site', TruncatedAnswer),
        ("", EmptyAnswer),
        ("It looks fine to me.", MalformedAnswer),
        ("I cannot make that decision.", Refusal),
    ],
)
def test_bad_confirmations(text: str, error: type[Exception]) -> None:
    with pytest.raises(error):
        parse_confirm(text)


def test_prompts_state_the_rules_and_the_format() -> None:
    text = rank_prompt(4, with_context=True)
    assert "0 to 3" in text
    assert "context only" in text
    assert '"ranking"' in text
    assert "Final Ranking" in text
    assert '"decision"' in confirm_prompt()
    with pytest.raises(ValueError, match="at least one"):
        rank_prompt(0)


def test_schema_variants() -> None:
    strict = response_format("rank", "strict")
    assert strict is not None
    assert strict["json_schema"]["strict"] is True
    assert strict["json_schema"]["schema"] == RANK_SCHEMA
    relaxed = response_format("confirm", "relaxed")
    assert relaxed is not None
    assert "additionalProperties" not in json.dumps(relaxed)
    assert relaxed["json_schema"]["schema"]["properties"] == CONFIRM_SCHEMA["properties"]
    assert response_format("rank", "none") is None
    # strict schemas need every property required and no extra ones
    for schema in (RANK_SCHEMA, CONFIRM_SCHEMA):
        assert set(schema["required"]) == set(schema["properties"])
        assert schema["additionalProperties"] is False
