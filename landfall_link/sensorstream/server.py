"""The sensor stream's server: frames on request to any number of clients (simbridge serves it)."""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import math
from collections.abc import Mapping
from types import TracebackType
from typing import Any, Self

from landfall_link.sensorstream.wire import (
    _SHUTDOWN_TIMEOUT_S,
    DEFAULT_JPEG_QUALITY,
    MAX_INFO_BYTES,
    MAX_LINE_BYTES,
    PROTOCOL_VERSION,
    SUPPORTED_VERSIONS,
    Capture,
    ErrorCode,
    ImageEncoding,
    Part,
    SensorFrame,
    SensorStreamConnectionError,
    SensorStreamError,
    _dump_line,
    _encode_frame,
    _error,
    _LineTooLongError,
    _log,
    _read_line,
)


class _BadRequestError(Exception):
    pass


def _parse_frame_request(request: Mapping[str, Any]) -> tuple[frozenset[Part], ImageEncoding, int]:
    want = request.get("want")
    names = {p.value for p in Part}
    if not isinstance(want, list) or not all(isinstance(w, str) and w in names for w in want):
        raise _BadRequestError(f'"want" must be a list of part names from {sorted(names)}, got {want!r}')
    if len(set(want)) != len(want):
        raise _BadRequestError(f'"want" names a part twice: {want!r}')
    encoding = request.get("image_encoding", ImageEncoding.PNG.value)
    if encoding not in {e.value for e in ImageEncoding}:
        raise _BadRequestError(f'"image_encoding" must be one of png, jpeg, raw; got {encoding!r}')
    quality = request.get("jpeg_quality", DEFAULT_JPEG_QUALITY)
    if type(quality) is not int or not 1 <= quality <= 100:
        raise _BadRequestError(f'"jpeg_quality" must be an integer in 1..100, got {quality!r}')
    return frozenset(Part(w) for w in want), ImageEncoding(encoding), quality


# --------------------------------------------------------------------------------------------- server
class SensorStreamServer:
    """Serves frames from ``capture`` to any number of local clients, one request at a time each.

    Use as ``async with SensorStreamServer(host, port, capture, info) as server:``; ``server.port`` is
    the bound port (useful with port 0). ``capture`` may run concurrently for several clients.
    Deadlines: a capture (plus encoding) over ``capture_timeout_s`` answers ``capture_timeout``; a client
    idle for ``idle_timeout_s`` (None: never) or not reading a response for ``send_timeout_s`` is
    disconnected. Leaving the context closes the listener and every connection.
    """

    def __init__(
        self,
        host: str,
        port: int,
        capture: Capture,
        info: Mapping[str, Any],
        *,
        capture_timeout_s: float = 10.0,
        idle_timeout_s: float | None = 600.0,
        send_timeout_s: float = 10.0,
        logger: logging.Logger | None = None,
    ) -> None:
        if isinstance(port, bool) or not isinstance(port, int) or not 0 <= port <= 65535:
            raise ValueError(f"port must be an integer in 0..65535, got {port!r}")
        try:
            info_size = len(json.dumps(dict(info), allow_nan=False))
        except (TypeError, ValueError) as exc:
            raise ValueError(f"info must be a JSON-serialisable mapping: {exc}") from exc
        if info_size > MAX_INFO_BYTES:
            raise ValueError(f"info serialises to {info_size} bytes; at most {MAX_INFO_BYTES} allowed")
        for name, value in (("capture_timeout_s", capture_timeout_s), ("send_timeout_s", send_timeout_s),
                            ("idle_timeout_s", idle_timeout_s)):  # fmt: skip
            if value is not None and not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a finite number > 0, got {value!r}")
        self._host = host
        self._requested_port = port
        self._capture = capture
        self._info = dict(info)
        self._capture_timeout_s = capture_timeout_s
        self._idle_timeout_s = idle_timeout_s
        self._send_timeout_s = send_timeout_s
        self._log = logger if logger is not None else _log
        self._server: asyncio.Server | None = None
        self._port: int | None = None
        self._connections: set[asyncio.Task[Any]] = set()

    @property
    def port(self) -> int:
        """The bound TCP port (the first socket's, when a host name binds several)."""
        if self._port is None:
            raise SensorStreamError("SensorStreamServer.port is known only inside 'async with'")
        return self._port

    async def __aenter__(self) -> Self:
        try:
            async with asyncio.timeout(_SHUTDOWN_TIMEOUT_S):
                self._server = await asyncio.start_server(
                    self._on_connect, self._host, self._requested_port, limit=MAX_LINE_BYTES
                )
        except (OSError, TimeoutError) as exc:
            raise SensorStreamConnectionError(
                f"cannot listen: {exc!r}", self._host, self._requested_port
            ) from exc
        self._port = int(self._server.sockets[0].getsockname()[1])
        self._log.info(
            "sensor stream serving on %s:%s (protocol v%s)", self._host, self._port, PROTOCOL_VERSION
        )
        return self

    async def __aexit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        server, self._server = self._server, None
        if server is None:
            return
        server.close()
        tasks = set(self._connections)
        for task in tasks:
            task.cancel()
        if tasks:
            _, pending = await asyncio.wait(tasks, timeout=_SHUTDOWN_TIMEOUT_S)
            if pending:
                self._log.warning("sensor stream: %s connections did not close in time", len(pending))
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(_SHUTDOWN_TIMEOUT_S):
                await server.wait_closed()
        self._port = None
        self._log.info("sensor stream on %s stopped", self._host)

    def _on_connect(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        # Our own task, not one asyncio.start_server makes from a coroutine: on Python 3.11 that one
        # reports its cancellation at shutdown as an error in a callback.
        peer = writer.get_extra_info("peername")
        task = asyncio.get_running_loop().create_task(
            self._serve_connection(reader, writer, peer), name=f"sensorstream-client-{peer}"
        )
        self._connections.add(task)
        task.add_done_callback(self._connections.discard)

    async def _serve_connection(
        self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter, peer: Any
    ) -> None:
        self._log.info("sensor client %s connected", peer)
        try:
            await self._serve_requests(reader, writer, peer)
        except (ConnectionError, asyncio.IncompleteReadError) as exc:
            self._log.info("sensor client %s: connection lost (%r)", peer, exc)
        except Exception:  # one broken connection must not stop the others
            self._log.exception("sensor client %s: unexpected error; closing the connection", peer)
        finally:
            writer.close()
            try:
                async with asyncio.timeout(_SHUTDOWN_TIMEOUT_S):
                    await writer.wait_closed()
            except TimeoutError:
                writer.transport.abort()
            except OSError:
                pass
            self._log.info("sensor client %s disconnected", peer)

    async def _serve_requests(
        self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter, peer: Any
    ) -> None:
        while True:
            header: dict[str, Any]
            blobs: list[bytes] = []
            try:
                async with asyncio.timeout(self._idle_timeout_s):
                    line = await _read_line(reader)
            except TimeoutError:
                self._log.info("sensor client %s idle for %s s; closing", peer, self._idle_timeout_s)
                return
            except _LineTooLongError:
                self._log.warning("sensor client %s sent a line over %s bytes", peer, MAX_LINE_BYTES)
                header = _error(ErrorCode.LINE_TOO_LONG, f"request line over {MAX_LINE_BYTES} bytes")
            else:
                if line is None:
                    return
                header, blobs = await self._respond(line, peer)
            try:
                async with asyncio.timeout(self._send_timeout_s):
                    writer.write(_dump_line(header))
                    writer.writelines(blobs)
                    await writer.drain()
            except TimeoutError:
                self._log.warning(
                    "sensor client %s not reading for %s s; closing", peer, self._send_timeout_s
                )
                return

    async def _respond(self, line: bytes, peer: Any) -> tuple[dict[str, Any], list[bytes]]:
        try:
            request = json.loads(line)
        except ValueError as exc:  # also UnicodeDecodeError
            return _error(ErrorCode.BAD_JSON, f"request is not valid JSON: {exc}"), []
        if not isinstance(request, dict):
            return _error(
                ErrorCode.BAD_REQUEST, f"request must be a JSON object, got {type(request).__name__}"
            ), []
        if "v" not in request:
            return _error(ErrorCode.BAD_REQUEST, 'request has no "v" (protocol version)'), []
        version = request["v"]
        if type(version) is not int or version not in SUPPORTED_VERSIONS:
            supported = ", ".join(str(v) for v in SUPPORTED_VERSIONS)
            message = f"protocol version {version!r} is not supported; supported versions: {supported}"
            return _error(ErrorCode.UNSUPPORTED_VERSION, message, supported=list(SUPPORTED_VERSIONS)), []
        op = request.get("op")
        if op == "hello":
            hello = {"v": PROTOCOL_VERSION, "op": "hello", "supported_versions": list(SUPPORTED_VERSIONS),
                     "max_line_bytes": MAX_LINE_BYTES, "info": self._info}  # fmt: skip
            return hello, []
        if op == "frame":
            return await self._frame(request, peer)
        return _error(ErrorCode.UNKNOWN_OP, f"unknown op {op!r}; expected one of: hello, frame"), []

    async def _frame(self, request: Mapping[str, Any], peer: Any) -> tuple[dict[str, Any], list[bytes]]:
        try:
            want, encoding, quality = _parse_frame_request(request)
        except _BadRequestError as exc:
            return _error(ErrorCode.BAD_REQUEST, str(exc)), []
        try:
            async with asyncio.timeout(self._capture_timeout_s):
                frame = await self._capture({p.value for p in want})
                if not isinstance(frame, SensorFrame):
                    raise TypeError(f"capture returned {type(frame).__name__}, expected SensorFrame")
                return await asyncio.to_thread(_encode_frame, frame, want, encoding, quality)
        except TimeoutError:
            self._log.warning("sensor client %s: capture over %s s", peer, self._capture_timeout_s)
            return _error(ErrorCode.CAPTURE_TIMEOUT, f"no frame within {self._capture_timeout_s} s"), []
        except Exception as exc:  # the simulator's failure is reported to the client, not fatal
            self._log.warning("sensor client %s: capture failed", peer, exc_info=True)
            return _error(ErrorCode.CAPTURE_FAILED, f"capture failed: {type(exc).__name__}: {exc}"), []
