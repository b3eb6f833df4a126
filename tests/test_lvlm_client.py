"""The OpenAI-compatible LVLM client against a scripted local HTTP server: request shape per endpoint
family, and every failure turned into its typed error within the deadline."""

from __future__ import annotations

import base64
import json
import time
from collections.abc import Iterator

import cv2
import numpy as np
import pytest

from companion.reasoning.base import (
    ConfirmRequest,
    DeadlineExceeded,
    EmptyAnswer,
    EndpointError,
    ErrorBody,
    InvalidIndices,
    MalformedAnswer,
    NotConfigured,
    RankRequest,
    RateLimited,
    Refusal,
    TruncatedAnswer,
    Unreachable,
)
from companion.reasoning.lvlm import LvlmProfile, LvlmReasoner, encode_image
from companion.reasoning.prompts import SYSTEM_PROMPT
from tests.lvlm_server import Reply, ScriptedServer, answer, completion

KEY = "sk-test-0123456789abcdef"
ENV = {"TEST_LVLM_KEY": KEY}


@pytest.fixture
def server() -> Iterator[ScriptedServer]:
    s = ScriptedServer()
    yield s
    s.close()


def crops(n: int = 3) -> tuple[np.ndarray, ...]:
    rng = np.random.default_rng(n)
    return tuple(rng.integers(0, 255, (300 + 40 * k, 700, 3), dtype=np.uint8) for k in range(n))


def reasoner(server: ScriptedServer, model: str, **kw: object) -> LvlmReasoner:
    profile = LvlmProfile(
        name=f"test-{model}",
        base_url=server.base_url,
        model=model,
        api_key_env="TEST_LVLM_KEY",
        **kw,  # type: ignore[arg-type]
    )
    return LvlmReasoner(profile, env=ENV)


def rank_request(n: int = 3, deadline_s: float = 5.0, **kw: object) -> RankRequest:
    return RankRequest(crops(n), deadline=time.monotonic() + deadline_s, transcript=[], **kw)  # type: ignore[arg-type]


def decode(url: str) -> np.ndarray:
    assert url.startswith("data:image/jpeg;base64,")
    raw = base64.b64decode(url.split(",", 1)[1])
    img = cv2.imdecode(np.frombuffer(raw, np.uint8), cv2.IMREAD_COLOR)
    assert img is not None
    return img


GOOD_RANK = answer(
    {"explanation": "1 is a clear gravel roof; 0 has vents; 2 is a road", "ranking": [1, 0, 2]}
)


# ------------------------------------------------------------------------------------------ request shape
async def test_rank_sends_images_schema_and_key_and_reads_the_answer(server: ScriptedServer) -> None:
    server.script("m", GOOD_RANK)
    r = reasoner(server, "m", max_side_px=256)
    req = rank_request()
    ranking = await r.rank(req)
    await r.aclose()
    assert ranking.order == (1, 0, 2)
    assert "gravel" in ranking.rationale
    assert ranking.tier == "test-m"
    (seen,) = server.seen("m")
    assert seen.path == "/v1/chat/completions"
    assert seen.headers["authorization"] == f"Bearer {KEY}"
    body = seen.body
    assert body["messages"][0] == {"role": "system", "content": SYSTEM_PROMPT}
    parts = body["messages"][1]["content"]
    assert parts[0]["type"] == "text"
    assert "3 candidate landing sites" in parts[0]["text"]
    urls = [p["image_url"]["url"] for p in parts if p["type"] == "image_url"]
    assert len(urls) == 3
    for url, original in zip(urls, req.crops, strict=True):
        img = decode(url)
        assert max(img.shape[:2]) == 256  # resized to the profile's longest side
        assert img.shape[1] / img.shape[0] == pytest.approx(original.shape[1] / original.shape[0], rel=0.02)
    schema = body["response_format"]["json_schema"]
    assert schema["strict"] is True
    assert schema["schema"]["additionalProperties"] is False
    assert set(schema["schema"]["required"]) == {"explanation", "ranking"}
    assert body["max_tokens"] == 1024
    assert body["temperature"] == 0.0
    # the key never reaches the transcript (it goes to the flight record)
    assert req.transcript is not None
    assert KEY not in json.dumps(req.transcript)
    assert any(e.get("raw") for e in req.transcript)


async def test_context_image_is_sent_last_and_named(server: ScriptedServer) -> None:
    server.script("m", GOOD_RANK)
    r = reasoner(server, "m")
    await r.rank(rank_request(context=np.zeros((540, 960, 3), np.uint8)))
    await r.aclose()
    parts = server.seen("m")[0].body["messages"][1]["content"]
    assert sum(p["type"] == "image_url" for p in parts) == 4
    assert "context only" in parts[0]["text"]
    assert "context only" in parts[-2]["text"]


async def test_gemini_variant_drops_keywords_gemini_rejects(server: ScriptedServer) -> None:
    server.script("g", GOOD_RANK)
    r = reasoner(server, "g", schema="relaxed")
    await r.rank(rank_request())
    await r.aclose()
    fmt = json.dumps(server.seen("g")[0].body["response_format"])
    assert "additionalProperties" not in fmt
    assert "$schema" not in fmt
    assert '"ranking"' in fmt


async def test_no_schema_variant_sends_no_response_format_and_reads_free_text(server: ScriptedServer) -> None:
    server.script("o", Reply(body=completion("Site 2 is a clear roof.\nFinal Ranking: [2, 0, 1]")))
    r = reasoner(server, "o", schema="none")
    ranking = await r.rank(rank_request())
    await r.aclose()
    assert "response_format" not in server.seen("o")[0].body
    assert ranking.order == (2, 0, 1)
    assert "clear roof" in ranking.rationale


async def test_gpt5_parameters(server: ScriptedServer) -> None:
    server.script("gpt-5-mini", GOOD_RANK)
    r = reasoner(
        server,
        "gpt-5-mini",
        max_tokens=None,
        max_completion_tokens=4000,
        reasoning_effort="low",
        temperature=None,
    )
    await r.rank(rank_request())
    await r.aclose()
    body = server.seen("gpt-5-mini")[0].body
    assert body["max_completion_tokens"] == 4000
    assert body["reasoning_effort"] == "low"
    assert "max_tokens" not in body
    assert "temperature" not in body


async def test_openrouter_headers_and_extra_body(server: ScriptedServer) -> None:
    server.script("google/gemini-2.5-flash", GOOD_RANK)
    r = reasoner(
        server,
        "google/gemini-2.5-flash",
        headers={"HTTP-Referer": "https://example.org/landfall", "X-Title": "Landfall"},
        extra_body={"provider": {"require_parameters": True}},
    )
    await r.rank(rank_request())
    await r.aclose()
    seen = server.seen("google/gemini-2.5-flash")[0]
    assert seen.headers["x-title"] == "Landfall"
    assert seen.headers["http-referer"] == "https://example.org/landfall"
    assert seen.body["provider"] == {"require_parameters": True}


async def test_confirm_reads_the_decision(server: ScriptedServer) -> None:
    server.script("m", answer({"explanation": "a person stands at the centre", "decision": 0}))
    r = reasoner(server, "m")
    decision = await r.confirm(ConfirmRequest(crops(1)[0], deadline=time.monotonic() + 5))
    await r.aclose()
    assert decision.accept is False
    assert "person" in decision.rationale
    body = server.seen("m")[0].body
    assert set(body["response_format"]["json_schema"]["schema"]["required"]) == {"explanation", "decision"}


def test_encode_image_rejects_bad_images() -> None:
    with pytest.raises(ValueError, match="H x W x 3 uint8"):
        encode_image(np.zeros((10, 10), np.uint8), 64)
    with pytest.raises(ValueError, match="H x W x 3 uint8"):
        encode_image(np.zeros((10, 10, 3), np.float32), 64)
    with pytest.raises(ValueError, match="empty"):
        encode_image(np.zeros((0, 10, 3), np.uint8), 64)
    _url, size = encode_image(np.zeros((10, 20, 3), np.uint8), 64)
    assert size == (20, 10)  # never enlarged


# ------------------------------------------------------------------------------------------ failures
@pytest.mark.parametrize(
    ("reply", "error", "message"),
    [
        (Reply(body={"error": {"message": "upstream overloaded", "code": 502}}), ErrorBody, "overloaded"),
        (Reply(body=completion("")), EmptyAnswer, "empty"),
        (Reply(body=completion(None, finish="length")), TruncatedAnswer, "max_completion_tokens"),
        (Reply(body=completion(None, refusal="I can't help with that.")), Refusal, "can't help"),
        (Reply(body=completion("The safest is clearly the second one.")), MalformedAnswer, "no ranking"),
        (Reply(body=completion('{"explanation": "site 1 is clear, site')), TruncatedAnswer, "stops"),
        (answer({"explanation": "x", "ranking": [1, 5, 0]}), InvalidIndices, "outside 0..2"),
        (answer({"explanation": "x", "ranking": [1, 1, 0]}), InvalidIndices, "repeats"),
        (answer({"explanation": "x", "ranking": []}), InvalidIndices, "empty"),
        (answer({"explanation": "x", "ranking": "1, 0, 2"}), MalformedAnswer, "list"),
        (Reply(body="<html>gateway</html>"), MalformedAnswer, "not a JSON object"),
        (Reply(body={"object": "chat.completion", "choices": []}), MalformedAnswer, "no choices"),
    ],
)
async def test_bad_answers_become_typed_errors(
    server: ScriptedServer, reply: Reply, error: type[Exception], message: str
) -> None:
    server.script("m", reply)
    r = reasoner(server, "m", max_attempts=1)
    with pytest.raises(error, match=message):
        await r.rank(rank_request())
    await r.aclose()


async def test_confirm_with_a_decision_out_of_range_is_malformed(server: ScriptedServer) -> None:
    server.script("m", answer({"explanation": "x", "decision": 2}))
    r = reasoner(server, "m")
    with pytest.raises(MalformedAnswer, match="1 or 0"):
        await r.confirm(ConfirmRequest(crops(1)[0], deadline=time.monotonic() + 5))
    await r.aclose()


async def test_429_waits_for_retry_after_then_succeeds(server: ScriptedServer) -> None:
    server.script(
        "m", Reply(429, {"error": {"message": "rate limited"}}, headers={"Retry-After": "1"}), GOOD_RANK
    )
    r = reasoner(server, "m")
    req = rank_request(deadline_s=5.0)
    ranking = await r.rank(req)
    await r.aclose()
    assert ranking.order == (1, 0, 2)
    first, second = server.seen("m")
    assert second.t_monotonic - first.t_monotonic >= 0.95  # Retry-After honoured
    assert req.transcript is not None
    statuses = [e.get("status") for e in req.transcript if "attempt" in e]
    assert statuses == [429, 200]


async def test_429_whose_retry_after_outlasts_the_deadline_fails_at_once(server: ScriptedServer) -> None:
    server.script(
        "m", Reply(429, {"error": {"message": "slow down"}}, headers={"Retry-After": "30"}), GOOD_RANK
    )
    r = reasoner(server, "m")
    with pytest.raises(RateLimited, match="429") as info:
        await r.rank(rank_request(deadline_s=3.0))
    await r.aclose()
    assert info.value.retry_after_s == 30.0
    assert len(server.seen("m")) == 1  # no second attempt: it could not have answered in time


async def test_5xx_is_retried_and_the_last_status_reported(server: ScriptedServer) -> None:
    server.script("flaky", Reply(503, {"error": {"message": "overloaded"}}), GOOD_RANK)
    server.script("down", Reply(500, {"error": {"message": "boom"}}))
    r = reasoner(server, "flaky")
    assert (await r.rank(rank_request())).order == (1, 0, 2)
    await r.aclose()
    r = reasoner(server, "down", max_attempts=2)
    with pytest.raises(EndpointError, match="HTTP 500: boom") as info:
        await r.rank(rank_request())
    await r.aclose()
    assert info.value.status == 500
    assert len(server.seen("down")) == 2


async def test_4xx_other_than_408_429_is_not_retried(server: ScriptedServer) -> None:
    server.script("m", Reply(400, {"error": {"message": "image_url not supported"}}))
    r = reasoner(server, "m")
    with pytest.raises(EndpointError, match="400"):
        await r.rank(rank_request())
    await r.aclose()
    assert len(server.seen("m")) == 1


async def test_a_slow_answer_is_cut_at_the_deadline(server: ScriptedServer) -> None:
    server.script("m", Reply(body=GOOD_RANK.body, delay_s=5.0))
    r = reasoner(server, "m")
    t0 = time.monotonic()
    with pytest.raises(DeadlineExceeded):
        await r.rank(rank_request(deadline_s=1.0))
    await r.aclose()
    assert time.monotonic() - t0 < 1.5  # the attempt timeout ends at the deadline, not at 30 s


async def test_missing_key_is_not_configured_and_sends_nothing(server: ScriptedServer) -> None:
    server.script("m", GOOD_RANK)
    r = LvlmReasoner(LvlmProfile("p", server.base_url, "m", api_key_env="NOT_SET_ANYWHERE"), env={})
    with pytest.raises(NotConfigured, match="NOT_SET_ANYWHERE"):
        await r.rank(rank_request())
    await r.aclose()
    assert server.seen("m") == []


async def test_keyless_local_endpoint_sends_no_authorization(server: ScriptedServer) -> None:
    server.script("qwen2.5-vl", GOOD_RANK)
    r = LvlmReasoner(LvlmProfile("local", server.base_url, "qwen2.5-vl", api_key_env=None), env={})
    await r.rank(rank_request())
    await r.aclose()
    assert "authorization" not in server.seen("qwen2.5-vl")[0].headers


async def test_unreachable_endpoint() -> None:
    s = ScriptedServer()
    url = s.base_url
    s.close()  # nothing listens on the port now
    r = LvlmReasoner(LvlmProfile("gone", url, "m", max_attempts=2), env={})
    with pytest.raises(Unreachable):
        await r.rank(rank_request(deadline_s=4.0))
    await r.aclose()


async def test_a_provider_quoting_the_key_back_loses_it_before_the_log_and_the_record(
    server: ScriptedServer,
) -> None:
    """Some providers put the rejected key in their 401 message; the error and the transcript that
    the flight record keeps carry a placeholder instead."""
    server.script("m", Reply(status=401, body={"error": {"message": f"Incorrect API key provided: {KEY}"}}))
    r = reasoner(server, "m")
    req = rank_request()
    with pytest.raises(EndpointError) as info:
        await r.rank(req)
    await r.aclose()
    assert "Incorrect API key provided: [api key]" in str(info.value)
    assert KEY not in str(info.value)
    assert req.transcript
    assert KEY not in json.dumps(req.transcript)
