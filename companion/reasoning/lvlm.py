"""A vision-language model behind any OpenAI-compatible chat-completions endpoint, called with httpx.

One :class:`LvlmProfile` says where and how (base URL, model, the environment variable holding the key,
which schema variant the endpoint accepts, image size, token parameters); :class:`LvlmReasoner` turns a
:class:`~companion.reasoning.base.RankRequest` or ``ConfirmRequest`` into one chat completion:

- images go as JPEG data URLs, resized so their longer side is at most ``max_side_px`` (on current models
  the pixel count, not ``detail``, drives cost and latency);
- ``response_format`` carries the strict JSON schema, the relaxed variant (Gemini's endpoint rejects
  ``additionalProperties``) or nothing (Ollama and llama.cpp may ignore schemas); the prompt states the
  format too and :mod:`companion.reasoning.parsing` reads JSON or free text;
- GPT-5 models take ``max_completion_tokens`` and ``reasoning_effort`` and no temperature;
- every attempt has a timeout that ends before the request's deadline; 408, 429 and 5xx answers are
  retried after their ``Retry-After`` (or a short backoff) only while the deadline leaves room;
- refusals, empty content, truncated or malformed JSON and bad indices raise the typed errors of
  :mod:`companion.reasoning.base`.

The API key is read from the environment at call time and sent only in the ``Authorization`` header: it
never enters the transcript, a log line or an error message.
"""

from __future__ import annotations

import asyncio
import base64
import email.utils
import logging
import math
import os
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Literal

import cv2
import numpy as np

from companion.reasoning.base import (
    ConfirmRequest,
    DeadlineExceeded,
    Decision,
    EmptyAnswer,
    EndpointError,
    ErrorBody,
    MalformedAnswer,
    NotConfigured,
    Ranking,
    RankRequest,
    RateLimited,
    ReasonerError,
    Refusal,
    TruncatedAnswer,
    Unreachable,
)
from companion.reasoning.parsing import parse_confirm, parse_rank
from companion.reasoning.prompts import (
    SYSTEM_PROMPT,
    SchemaMode,
    confirm_prompt,
    rank_prompt,
    response_format,
)

if TYPE_CHECKING:  # httpx is imported when an LVLM tier is built: the onboard tier alone does without it
    import httpx

__all__ = ["LvlmProfile", "LvlmReasoner", "encode_image"]

_log = logging.getLogger(__name__)

MIN_ATTEMPT_S = 0.5  # an attempt with less time than this left is not started
BACKOFF_S = (0.5, 1.0, 2.0)  # waits before retries 1, 2, 3+ when the server gives no Retry-After


@dataclass(frozen=True, slots=True)
class LvlmProfile:
    """One model at one endpoint (``[reasoner.profiles.NAME]`` in the config)."""

    name: str
    base_url: str  # ends before /chat/completions, e.g. https://api.openai.com/v1
    model: str
    api_key_env: str | None = None  # environment variable with the key; None for keyless local servers
    schema: SchemaMode = "strict"
    max_side_px: int = 512
    jpeg_quality: int = 85
    max_tokens: int | None = 1024  # classic models
    max_completion_tokens: int | None = None  # GPT-5 family (reasoning tokens count against it)
    reasoning_effort: Literal["minimal", "low", "medium", "high"] | None = None
    temperature: float | None = 0.0  # None: not sent (GPT-5 accepts only its default)
    headers: Mapping[str, str] = field(default_factory=dict)  # e.g. OpenRouter's HTTP-Referer, X-Title
    extra_body: Mapping[str, Any] = field(default_factory=dict)  # e.g. OpenRouter's provider options
    attempt_timeout_s: float = 30.0  # per HTTP attempt, further capped by the stage deadline
    max_attempts: int = 3

    @property
    def url(self) -> str:
        return self.base_url.rstrip("/") + "/chat/completions"


def encode_image(rgb: np.ndarray, max_side_px: int, quality: int = 85) -> tuple[str, tuple[int, int]]:
    """``rgb`` (H x W x 3 uint8) as a JPEG data URL, shrunk so its longer side is <= ``max_side_px``;
    returns the URL and the sent size (width, height)."""
    if not (isinstance(rgb, np.ndarray) and rgb.ndim == 3 and rgb.shape[2] == 3 and rgb.dtype == np.uint8):
        raise ValueError(f"an image must be H x W x 3 uint8 RGB, got {getattr(rgb, 'shape', type(rgb))}")
    h, w = rgb.shape[:2]
    if h == 0 or w == 0:
        raise ValueError("an image is empty (0 pixels)")
    scale = min(1.0, max_side_px / max(h, w))
    if scale < 1.0:
        rgb = cv2.resize(
            rgb, (max(round(w * scale), 1), max(round(h * scale), 1)), interpolation=cv2.INTER_AREA
        )
    ok, jpeg = cv2.imencode(".jpg", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, quality])
    if not ok:
        raise ValueError("JPEG encoding failed")
    url = "data:image/jpeg;base64," + base64.b64encode(jpeg.tobytes()).decode("ascii")
    return url, (rgb.shape[1], rgb.shape[0])


def _retry_after_s(headers: httpx.Headers) -> float | None:
    value = headers.get("retry-after")
    if value is None:
        return None
    value = value.strip()
    try:
        return max(float(value), 0.0)
    except ValueError:
        pass
    try:
        when = email.utils.parsedate_to_datetime(value)
    except (TypeError, ValueError):
        return None
    return max(when.timestamp() - time.time(), 0.0)


def _content_text(content: Any) -> str | None:
    """Message content as text: a string, or a list of parts whose text parts are joined."""
    if content is None or isinstance(content, str):
        return content
    if isinstance(content, list):
        parts = [p.get("text", "") for p in content if isinstance(p, dict) and p.get("type") == "text"]
        return "".join(parts)
    raise MalformedAnswer(f"message content is a {type(content).__name__}, not text")


def _scrubbed(text: str | None, headers: dict[str, str]) -> str | None:
    """``text`` without the API key this request sent (a server may quote it back in an answer or an
    error message, which the log and the flight record keep)."""
    key = headers.get("authorization", "").removeprefix("Bearer ").strip()
    if text is None or len(key) < 4:
        return text
    return text.replace(key, "[api key]")


def _error_text(body: Any) -> str:
    err = body.get("error") if isinstance(body, dict) else None
    if isinstance(err, dict):
        return str(err.get("message") or err.get("code") or err)[:300]
    return str(err or body)[:300]


class LvlmReasoner:
    """A reasoning tier backed by one :class:`LvlmProfile`.

    ``client`` may be shared between tiers (connection reuse); without one the reasoner makes its own
    and :meth:`aclose` closes it. ``env`` is where the key variable is looked up (``os.environ``).
    """

    def __init__(
        self,
        profile: LvlmProfile,
        *,
        client: httpx.AsyncClient | None = None,
        env: Mapping[str, str] | None = None,
    ) -> None:
        import httpx  # here, not at the top: ~10 MB and 60 ms that an onboard-only daemon never needs

        self.profile = profile
        self._own_client = client is None
        self._client = client or httpx.AsyncClient()
        self._env = os.environ if env is None else env

    @property
    def name(self) -> str:
        return self.profile.name

    async def aclose(self) -> None:
        if self._own_client:
            await self._client.aclose()

    # ------------------------------------------------------------------ the two stages
    async def rank(self, request: RankRequest) -> Ranking:
        t0 = time.monotonic()
        n = len(request.crops)
        images = [(f"Candidate {k}:", crop) for k, crop in enumerate(request.crops)]
        if request.context is not None:
            images.append(("Whole camera view (context only, not a candidate):", request.context))
        text = rank_prompt(n, with_context=request.context is not None)
        answer = await self._complete("rank", text, images, request.deadline, request.transcript)
        try:
            order, explanation = parse_rank(answer, n)
        except ReasonerError as exc:
            self._note(request.transcript, {"stage": "rank", "parse_error": f"{exc.kind}: {exc}"})
            raise
        return Ranking(order, explanation or f"ranking {list(order)}", self.name, time.monotonic() - t0)

    async def confirm(self, request: ConfirmRequest) -> Decision:
        t0 = time.monotonic()
        answer = await self._complete(
            "confirm",
            confirm_prompt(),
            [("Close-up of the site:", request.image)],
            request.deadline,
            request.transcript,
        )
        try:
            accept, explanation = parse_confirm(answer)
        except ReasonerError as exc:
            self._note(request.transcript, {"stage": "confirm", "parse_error": f"{exc.kind}: {exc}"})
            raise
        why = explanation or ("safe" if accept else "not safe")
        return Decision(accept, why, self.name, time.monotonic() - t0)

    # ------------------------------------------------------------------ one chat completion
    def _body(
        self, stage: Literal["rank", "confirm"], text: str, images: list[tuple[str, np.ndarray]]
    ) -> tuple[dict[str, Any], list[dict[str, Any]]]:
        p = self.profile
        content: list[dict[str, Any]] = [{"type": "text", "text": text}]
        refs: list[dict[str, Any]] = []
        for label, rgb in images:
            url, size = encode_image(rgb, p.max_side_px, p.jpeg_quality)
            content.append({"type": "text", "text": label})
            content.append({"type": "image_url", "image_url": {"url": url}})
            refs.append({"label": label, "sent_px": list(size), "jpeg_bytes": len(url) * 3 // 4})
        body: dict[str, Any] = {
            "model": p.model,
            "messages": [
                {"role": "system", "content": SYSTEM_PROMPT},
                {"role": "user", "content": content},
            ],
        }
        fmt = response_format(stage, p.schema)
        if fmt is not None:
            body["response_format"] = fmt
        if p.max_completion_tokens is not None:
            body["max_completion_tokens"] = p.max_completion_tokens
        elif p.max_tokens is not None:
            body["max_tokens"] = p.max_tokens
        if p.reasoning_effort is not None:
            body["reasoning_effort"] = p.reasoning_effort
        if p.temperature is not None:
            body["temperature"] = p.temperature
        body.update(p.extra_body)
        return body, refs

    def _headers(self) -> dict[str, str]:
        headers = {"content-type": "application/json", **self.profile.headers}
        env_name = self.profile.api_key_env
        if env_name:
            key = self._env.get(env_name, "").strip()
            if not key:
                raise NotConfigured(f"{self.name}: no API key: set the environment variable {env_name}")
            headers["authorization"] = f"Bearer {key}"
        return headers

    def _note(self, transcript: list[dict[str, Any]] | None, entry: dict[str, Any]) -> None:
        if transcript is not None:
            transcript.append({"tier": self.name, **entry})

    async def _complete(
        self,
        stage: Literal["rank", "confirm"],
        text: str,
        images: list[tuple[str, np.ndarray]],
        deadline: float | None,
        transcript: list[dict[str, Any]] | None,
    ) -> str | None:
        """The answer text of one chat completion, retried on transient failures while time remains."""
        p = self.profile
        headers = self._headers()
        body, refs = self._body(stage, text, images)
        self._note(
            transcript,
            {
                "stage": stage,
                "model": p.model,
                "url": p.url,
                "system": SYSTEM_PROMPT,
                "prompt": text,
                "images": refs,
            },
        )
        last: ReasonerError | None = None
        for attempt in range(1, p.max_attempts + 1):
            left = math.inf if deadline is None else deadline - time.monotonic()
            timeout = min(p.attempt_timeout_s, left)
            if timeout < MIN_ATTEMPT_S:
                raise last or DeadlineExceeded(f"{self.name}: {left:.2f} s left, too little for an attempt")
            t0 = time.monotonic()
            entry: dict[str, Any] = {"stage": stage, "attempt": attempt, "timeout_s": round(timeout, 3)}
            try:
                answer = _scrubbed(await self._attempt(body, headers, timeout), headers)
            except ReasonerError as exc:
                exc.args = (_scrubbed(str(exc), headers),)  # some providers echo a rejected key
                entry.update(latency_s=round(time.monotonic() - t0, 4), error=f"{exc.kind}: {exc}")
                if isinstance(exc, EndpointError):
                    entry["status"] = exc.status
                self._note(transcript, entry)
                last = exc
                wait = self._retry_wait(exc, attempt)
                if wait is None or attempt == p.max_attempts:
                    raise
                left = math.inf if deadline is None else deadline - time.monotonic()
                if wait + MIN_ATTEMPT_S > left:
                    raise
                await asyncio.sleep(wait)
                continue
            entry.update(latency_s=round(time.monotonic() - t0, 4), status=200, raw=answer)
            self._note(transcript, entry)
            return answer
        raise last or DeadlineExceeded(f"{self.name}: no attempt made")  # pragma: no cover (loop returns)

    @staticmethod
    def _retry_wait(exc: ReasonerError, attempt: int) -> float | None:
        """Seconds to wait before retrying after ``exc``; ``None`` when retrying is pointless."""
        if isinstance(exc, EndpointError) and exc.retryable:
            if exc.retry_after_s is not None:
                return exc.retry_after_s
            return BACKOFF_S[min(attempt - 1, len(BACKOFF_S) - 1)]
        if isinstance(exc, Unreachable | ErrorBody):
            return BACKOFF_S[min(attempt - 1, len(BACKOFF_S) - 1)]
        return None  # deadline, refusal, empty/truncated/malformed: the next tier, not the same again

    async def _attempt(self, body: dict[str, Any], headers: dict[str, str], timeout_s: float) -> str | None:
        import httpx

        try:
            async with asyncio.timeout(timeout_s):
                resp = await self._client.post(
                    self.profile.url, json=body, headers=headers, timeout=httpx.Timeout(timeout_s)
                )
        except (TimeoutError, httpx.TimeoutException) as exc:
            raise DeadlineExceeded(f"{self.name}: no answer within {timeout_s:.1f} s") from exc
        except httpx.HTTPError as exc:
            raise Unreachable(f"{self.name}: {type(exc).__name__}: {exc}") from exc
        return self._read(resp)

    def _read(self, resp: httpx.Response) -> str | None:
        try:
            data = resp.json()
        except ValueError:
            data = None
        if resp.status_code != 200:
            detail = _error_text(data) if data is not None else resp.text[:200]
            cls = RateLimited if resp.status_code == 429 else EndpointError
            raise cls(
                f"{self.name}: HTTP {resp.status_code}: {detail}",
                resp.status_code,
                _retry_after_s(resp.headers),
            )
        if not isinstance(data, dict):
            raise MalformedAnswer(f"{self.name}: the response is not a JSON object: {resp.text[:120]!r}")
        if "error" in data:
            raise ErrorBody(f"{self.name}: error in a 200 response: {_error_text(data)}")
        choices = data.get("choices")
        if not isinstance(choices, list) or not choices or not isinstance(choices[0], dict):
            raise MalformedAnswer(f"{self.name}: the response has no choices")
        choice = choices[0]
        message = choice.get("message") or {}
        if not isinstance(message, dict):
            raise MalformedAnswer(f"{self.name}: the choice has no message")
        refusal = message.get("refusal")
        if refusal:
            raise Refusal(f"{self.name}: the model refused: {str(refusal)[:200]}")
        text = _content_text(message.get("content"))
        finish = choice.get("finish_reason")
        if not text or not text.strip():
            if finish == "length":
                raise TruncatedAnswer(
                    f"{self.name}: empty answer with finish_reason 'length' (the token cap was spent, "
                    "e.g. on reasoning: raise max_completion_tokens)"
                )
            raise EmptyAnswer(f"{self.name}: the answer is empty (finish_reason {finish!r})")
        if finish == "length":
            # The text may still hold a complete answer; parsing decides, and a cut-off JSON object is
            # reported as truncated there.
            _log.debug("%s: finish_reason 'length'", self.name)
        return text
