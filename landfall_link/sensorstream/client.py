"""The sensor stream's client: one connection, a frame on request, reconnection (the companion uses it)."""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import math
from collections.abc import AsyncIterator, Iterable, Mapping
from types import TracebackType
from typing import Any, Self

from landfall_link.sensorstream.wire import (
    _SHUTDOWN_TIMEOUT_S,
    DEFAULT_JPEG_QUALITY,
    MAX_LINE_BYTES,
    PROTOCOL_VERSION,
    ImageEncoding,
    Part,
    SensorFrame,
    SensorStreamConnectionError,
    SensorStreamError,
    SensorStreamProtocolError,
    SensorStreamServerError,
    SensorStreamTimeoutError,
    ServerHello,
    _dump_line,
    _frame_from_wire,
    _log,
    _part_specs,
    _PartSpec,
)


# --------------------------------------------------------------------------------------------- client
class SensorClient:
    """Asks a sensor-stream server for frames over one TCP connection (asyncio).

    Use as ``async with SensorClient(host, port) as client:``. Each call is bounded end to end by
    ``timeout_s`` (connect, request, capture, transfer, decode). A timeout, a broken connection or a
    protocol error drops the connection and the next call reconnects; a server-reported error keeps it.
    A request on a connection the server had already closed is retried once on a fresh one (frames are
    side-effect free). Calls from several tasks are serialised on the one connection.
    """

    def __init__(
        self, host: str, port: int, *, timeout_s: float = 5.0, logger: logging.Logger | None = None
    ) -> None:
        if isinstance(port, bool) or not isinstance(port, int) or not 1 <= port <= 65535:
            raise ValueError(f"port must be an integer in 1..65535, got {port!r}")
        if not (math.isfinite(timeout_s) and timeout_s > 0):
            raise ValueError(f"timeout_s must be a finite number > 0, got {timeout_s!r}")
        self._host = host
        self._port = port
        self._timeout_s = timeout_s
        self._log = logger if logger is not None else _log
        self._lock = asyncio.Lock()
        self._reader: asyncio.StreamReader | None = None
        self._writer: asyncio.StreamWriter | None = None
        self._answered = False  # the current connection has carried a whole exchange
        self._open = False

    async def __aenter__(self) -> Self:
        async with self._deadline("connect"):
            await self._connect()
        self._open = True
        return self

    async def __aexit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self._open = False
        writer = self._writer
        self._drop()
        if writer is not None:
            with contextlib.suppress(TimeoutError, OSError):
                async with asyncio.timeout(_SHUTDOWN_TIMEOUT_S):
                    await writer.wait_closed()

    async def hello(self) -> ServerHello:
        """The server's protocol versions and simulator description."""
        self._require_open("hello")
        async with self._deadline("hello"):
            header, _ = await self._exchange({"v": PROTOCOL_VERSION, "op": "hello"})
        versions, info = header.get("supported_versions"), header.get("info")
        if (
            not isinstance(versions, list)
            or not all(type(v) is int for v in versions)
            or not isinstance(info, dict)
        ):
            raise SensorStreamProtocolError(f"bad hello header: {header!r}")
        return ServerHello(version=header["v"], supported_versions=tuple(versions), info=info)

    async def frame(
        self,
        want: Iterable[str] = (Part.IMAGE, Part.LIDAR),
        image_encoding: str = ImageEncoding.PNG,
        jpeg_quality: int = DEFAULT_JPEG_QUALITY,
    ) -> SensorFrame:
        """One synchronized frame holding the ``want`` parts ("image", "depth", "lidar").

        A part the simulator could not produce (a failed LiDAR) is None in the result.
        """
        self._require_open("frame")
        if isinstance(want, str):
            raise TypeError(
                f'want must be a collection of part names, e.g. ("image",), not the string {want!r}'
            )
        request = {"v": PROTOCOL_VERSION, "op": "frame", "want": [str(w) for w in want],
                   "image_encoding": str(image_encoding), "jpeg_quality": jpeg_quality}  # fmt: skip
        async with self._deadline("frame"):
            header, parts = await self._exchange(request)
            return await asyncio.to_thread(_frame_from_wire, header, parts)

    def _require_open(self, operation: str) -> None:
        if not self._open:
            raise SensorStreamError(f"SensorClient.{operation}() needs 'async with SensorClient(...)'")

    @contextlib.asynccontextmanager
    async def _deadline(self, operation: str) -> AsyncIterator[None]:
        try:
            async with asyncio.timeout(self._timeout_s):
                yield
        except TimeoutError as exc:
            raise SensorStreamTimeoutError(operation, self._timeout_s, self._host, self._port) from exc

    async def _connect(self) -> tuple[asyncio.StreamReader, asyncio.StreamWriter]:
        try:
            reader, writer = await asyncio.open_connection(self._host, self._port, limit=MAX_LINE_BYTES)
        except OSError as exc:
            raise SensorStreamConnectionError(f"cannot connect: {exc!r}", self._host, self._port) from exc
        self._reader, self._writer = reader, writer
        self._answered = False
        self._log.info("sensor stream connected to %s:%s", self._host, self._port)
        return reader, writer

    def _drop(self) -> None:
        """Forget the connection (its stream position is unknown after a failure or a cancellation)."""
        if self._writer is not None:
            self._writer.close()
        self._reader = self._writer = None

    async def _exchange(
        self, request: Mapping[str, Any]
    ) -> tuple[dict[str, Any], list[tuple[_PartSpec, bytes]]]:
        line = _dump_line(request)
        async with self._lock:
            try:
                return await self._exchange_locked(line, str(request["op"]))
            except SensorStreamServerError:
                raise  # the whole error response was read: the connection is still in step
            except BaseException:
                self._drop()
                raise

    async def _exchange_locked(
        self, line: bytes, op: str
    ) -> tuple[dict[str, Any], list[tuple[_PartSpec, bytes]]]:
        retried = False
        while True:
            reader, writer = self._reader, self._writer
            if reader is None or writer is None or writer.is_closing() or reader.at_eof():
                self._drop()
                reader, writer = await self._connect()
            # Only a connection that has answered before may have gone stale in between.
            stale_possible = self._answered
            try:
                writer.write(line)
                await writer.drain()
                header_line = await reader.readuntil(b"\n")
                self._answered = True
                break
            except (OSError, asyncio.IncompleteReadError) as exc:
                self._drop()
                partial = isinstance(exc, asyncio.IncompleteReadError) and bool(exc.partial)
                if not stale_possible or partial or retried:
                    raise SensorStreamConnectionError(
                        f"connection lost: {exc!r}", self._host, self._port
                    ) from exc
                self._log.info(
                    "sensor stream %s:%s: stale connection (%r); reconnecting", self._host, self._port, exc
                )
                retried = True
            except asyncio.LimitOverrunError as exc:
                raise SensorStreamProtocolError(f"response header line over {MAX_LINE_BYTES} bytes") from exc
        try:
            header = json.loads(header_line)
        except ValueError as exc:
            raise SensorStreamProtocolError(f"response header is not JSON: {exc}") from exc
        if not isinstance(header, dict) or header.get("v") != PROTOCOL_VERSION:
            raise SensorStreamProtocolError(
                f"expected a protocol v{PROTOCOL_VERSION} header, got {header!r:.200}"
            )
        if "error" in header:
            error = header["error"]
            if not isinstance(error, dict) or not isinstance(error.get("code"), str):
                raise SensorStreamProtocolError(f"bad error header: {header!r:.200}")
            raise SensorStreamServerError(error["code"], str(error.get("message", "")), error)
        if header.get("op") != op:
            raise SensorStreamProtocolError(f"asked for {op!r}, the answer is for {header.get('op')!r}")
        parts: list[tuple[_PartSpec, bytes]] = []
        for spec in _part_specs(header):
            try:
                parts.append((spec, await reader.readexactly(spec.nbytes)))
            except (OSError, asyncio.IncompleteReadError) as exc:
                raise SensorStreamConnectionError(
                    f"connection lost mid-response: {exc!r}", self._host, self._port
                ) from exc
        return header, parts
