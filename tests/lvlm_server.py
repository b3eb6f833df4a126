"""A scripted OpenAI-compatible chat-completions server on loopback, for the LVLM client tests.

Real HTTP (the standard library's threading server), so the client under test goes through httpx,
sockets, status codes and headers exactly as against a real endpoint. What it answers is scripted per
model name: ``server.script("m", Reply(...), Reply(...))`` makes the first request for model ``m`` get
the first reply, the second the second, and every later one the last; ``stage="rank"`` or
``"confirm"`` scripts one stage of that model apart (told by the request's schema name or prompt).
Every request is kept (path, headers, parsed body, arrival time) for the tests to inspect.
"""

from __future__ import annotations

import json
import threading
import time
from dataclasses import dataclass, field
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any


@dataclass(frozen=True)
class Reply:
    status: int = 200
    body: Any = None  # dict -> JSON; str -> sent as is
    delay_s: float = 0.0
    headers: dict[str, str] = field(default_factory=dict)


def completion(content: str | None, *, finish: str = "stop", refusal: str | None = None) -> dict[str, Any]:
    """A chat-completions response body with one choice."""
    message: dict[str, Any] = {"role": "assistant", "content": content}
    if refusal is not None:
        message["refusal"] = refusal
    return {
        "id": "chatcmpl-test",
        "object": "chat.completion",
        "created": 0,
        "model": "scripted",
        "choices": [{"index": 0, "message": message, "finish_reason": finish}],
        "usage": {"prompt_tokens": 1, "completion_tokens": 1, "total_tokens": 2},
    }


def answer(payload: dict[str, Any]) -> Reply:
    """A 200 reply whose content is ``payload`` as JSON text."""
    return Reply(body=completion(json.dumps(payload)))


@dataclass
class Seen:
    path: str
    headers: dict[str, str]
    body: Any
    t_monotonic: float


class ScriptedServer:
    def __init__(self) -> None:
        self._scripts: dict[str, list[Reply]] = {}
        self._served: dict[str, int] = {}
        self.requests: list[Seen] = []
        self._lock = threading.Lock()
        self._closing = threading.Event()
        server = self

        class Handler(BaseHTTPRequestHandler):
            protocol_version = "HTTP/1.1"

            def log_message(self, format: str, *args: Any) -> None:
                return None

            def do_POST(self) -> None:
                length = int(self.headers.get("content-length", "0"))
                raw = self.rfile.read(length)
                try:
                    body = json.loads(raw)
                except ValueError:
                    body = None
                reply = server._next(self.path, dict(self.headers), body)
                if reply.delay_s:
                    server._closing.wait(reply.delay_s)
                data = (
                    reply.body.encode()
                    if isinstance(reply.body, str)
                    else json.dumps(reply.body if reply.body is not None else {}).encode()
                )
                try:
                    self.send_response(reply.status)
                    self.send_header("content-type", "application/json")
                    self.send_header("content-length", str(len(data)))
                    for k, v in reply.headers.items():
                        self.send_header(k, v)
                    self.end_headers()
                    self.wfile.write(data)
                except (BrokenPipeError, ConnectionResetError):
                    pass  # the client gave up (its timeout): that is the behaviour under test

        self.httpd = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.httpd.daemon_threads = True
        self.port = self.httpd.server_address[1]
        self.base_url = f"http://127.0.0.1:{self.port}/v1"
        self._thread = threading.Thread(target=self.httpd.serve_forever, args=(0.05,), daemon=True)
        self._thread.start()

    def script(self, model: str, *replies: Reply, stage: str | None = None) -> None:
        key = model if stage is None else f"{model}/{stage}"
        with self._lock:
            self._scripts[key] = list(replies)
            self._served[key] = 0

    @staticmethod
    def _stage(body: dict[str, Any]) -> str:
        fmt = body.get("response_format") or {}
        name = str((fmt.get("json_schema") or {}).get("name", ""))
        if name:
            return "rank" if name.endswith("rank") else "confirm"
        return "rank" if "Final Ranking" in json.dumps(body.get("messages")) else "confirm"

    def _next(self, path: str, headers: dict[str, str], body: Any) -> Reply:
        with self._lock:
            self.requests.append(
                Seen(path, {k.lower(): v for k, v in headers.items()}, body, time.monotonic())
            )
            model = body.get("model") if isinstance(body, dict) else None
            key = str(model)
            if isinstance(body, dict) and f"{model}/{self._stage(body)}" in self._scripts:
                key = f"{model}/{self._stage(body)}"
            replies = self._scripts.get(key)
            if not replies:
                return Reply(404, {"error": {"message": f"no such model {model!r}", "code": 404}})
            k = self._served[key]
            self._served[key] = k + 1
            return replies[min(k, len(replies) - 1)]

    def seen(self, model: str) -> list[Seen]:
        with self._lock:
            return [r for r in self.requests if isinstance(r.body, dict) and r.body.get("model") == model]

    def close(self) -> None:
        self._closing.set()
        self.httpd.shutdown()
        self.httpd.server_close()
        self._thread.join(timeout=5)
