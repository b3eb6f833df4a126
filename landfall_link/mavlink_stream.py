"""MAVLink 2 over a byte stream, on asyncio: a TCP connection (``tcp:`` connects out, ``tcpin:`` listens)
or a serial port (``serial:DEVICE:BAUD``, via pyserial).

A stream has one peer (an autopilot's TELEM port, mavlink-router's TCP server): every frame goes to it and
the target ids inside a message route it beyond. pymavlink's parser keeps a partial frame between reads
and, with robust parsing, turns garbage into counted BAD_DATA, so a byte stream needs nothing more.

The link never dies with its connection: a refused connect, a peer that goes away, a serial device that
disappears or cannot be opened is counted (:class:`LinkStats` ``link_errors``), logged once per change of
state and tried again every ``retry_s``; a ``tcp:`` or serial link reopens, a ``tcpin:`` link takes the
next peer. Meanwhile :meth:`MavlinkStreamLink.send` goes on being called and drops (and counts) frames.
"""

from __future__ import annotations

import asyncio
import os
from typing import Any, Unpack

import serial

from landfall_link.mavlink_base import (
    STREAM_MODES,
    Address,
    LinkOptions,
    LinkUrl,
    MavlinkEndpoint,
    MessageHandler,
)

RETRY_S = 1.0  # between attempts to (re)open a connection or a device
OPEN_TIMEOUT_S = 5.0  # a connect to a host that never answers gives up after this, then retries
# A peer that stops reading (a stalled router) must not grow our memory: past this many bytes waiting in
# the write buffer, new frames are dropped (and counted). 64 KiB is 0.7 s at 921600 baud, and seconds of
# what the companion sends (setpoints at 20 Hz, heartbeats) even at 57600.
MAX_BUFFERED_BYTES = 64 * 1024


class _Connection(asyncio.Protocol):
    """One open connection of a link: a TCP socket (both ways), or a serial device's read pipe with
    ``writer`` a write pipe on a duplicate of its descriptor. ``lost`` is set when it ends."""

    def __init__(self, link: MavlinkStreamLink, peer: Address | None = None) -> None:
        self._link = link
        self.peer: Address = peer or ("", 0)
        self.transports: list[asyncio.BaseTransport] = []
        self.writer: asyncio.WriteTransport | None = None
        self.lost = asyncio.Event()

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self.transports.append(transport)
        if isinstance(transport, asyncio.Transport):  # a socket: readable and writable, up at once
            self.writer = transport
            host, port = transport.get_extra_info("peername")[:2]
            self.peer = (str(host), int(port))
            self._link._connected(self)

    def data_received(self, data: bytes) -> None:
        self._link._received(data, self.peer)

    def eof_received(self) -> bool:
        return False  # the peer closed its side: close ours too (connection_lost follows)

    def connection_lost(self, exc: Exception | None) -> None:
        self.close()
        if not self.lost.is_set():
            self.lost.set()
            self._link._lost(self, exc)

    def close(self) -> None:
        for transport in self.transports:
            transport.close()


class _WriteSide(asyncio.BaseProtocol):
    """The protocol of a serial device's write pipe: its end is its connection's end."""

    def __init__(self, conn: _Connection) -> None:
        self._conn = conn

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self._conn.transports.append(transport)

    def connection_lost(self, exc: Exception | None) -> None:
        self._conn.connection_lost(exc)


class MavlinkStreamLink(MavlinkEndpoint):
    """A TCP or serial MAVLink 2 endpoint as (``system_id``, ``component_id``): a ``MavlinkLink``.

    Use as ``async with MavlinkStreamLink(url, ...) as link:``; ``handler(msg, addr)`` (given here or by
    :meth:`attach`) is called for every valid message, in the event loop, ``addr`` the TCP peer or
    ``(device, baud)``. Entering opens nothing but a ``tcpin:`` server (a port in use raises there, as a
    UDP link's bind does); the connection itself is made, and remade, in the background.
    """

    def __init__(
        self,
        url: str,
        system_id: int,
        component_id: int,
        handler: MessageHandler | None = None,
        *,
        retry_s: float = RETRY_S,
        **options: Unpack[LinkOptions],
    ) -> None:
        self.url = LinkUrl.parse(url, allowed=STREAM_MODES)
        super().__init__(system_id, component_id, handler, **options)
        self._retry_s = retry_s
        self._conn: _Connection | None = None
        self._ever_connected = False
        self._failing = False  # the last attempt to open failed and was logged
        self._server: asyncio.Server | None = None
        self._runner: asyncio.Task[None] | None = None
        self._parser_start_length = self.mav.expected_length

    @property
    def connected(self) -> bool:
        """Whether a peer (or the serial device) is connected now."""
        return self._conn is not None

    @property
    def local_port(self) -> int:
        """The port a ``tcpin:`` link listens on (the kernel's choice for port 0)."""
        if self._server is None or not self._server.sockets:
            raise RuntimeError(f"{self.url} is not a listening tcpin link, or it is closed")
        return int(self._server.sockets[0].getsockname()[1])

    async def __aenter__(self) -> MavlinkStreamLink:
        if self.url.mode == "tcpin":
            loop = asyncio.get_running_loop()
            self._server = await loop.create_server(lambda: _Connection(self), self.url.host, self.url.port)
            self._log.info("MAVLink %s: listening for a peer", self.url)
        else:
            self._runner = asyncio.create_task(self._keep_open(), name=f"mavlink {self.url}")
        return self

    async def __aexit__(self, *exc: object) -> None:
        runner = self._runner
        self.close()
        if runner is not None:
            try:
                await runner
            except asyncio.CancelledError:
                # ours ends cancelled; a cancellation of the task exiting the context goes on up
                current = asyncio.current_task()
                if current is not None and current.cancelling():
                    raise

    def close(self) -> None:
        """Stop reconnecting, stop listening and close the connection."""
        if self._runner is not None:
            self._runner.cancel()
            self._runner = None
        if self._server is not None:
            self._server.close()
            self._server = None
        if self._conn is not None:
            conn, self._conn = self._conn, None
            conn.close()

    # ---------------------------------------------------------------- connection state
    async def _keep_open(self) -> None:
        """Open the connection (``tcp:`` or serial), wait for its end, wait ``retry_s``, again."""
        while True:
            try:
                async with asyncio.timeout(OPEN_TIMEOUT_S):
                    conn = await (self._open_serial() if self.url.mode == "serial" else self._open_tcp())
            except (OSError, serial.SerialException) as exc:  # TimeoutError is an OSError
                self._open_failed(exc)
            else:
                await conn.lost.wait()
            await asyncio.sleep(self._retry_s)

    async def _open_tcp(self) -> _Connection:
        loop = asyncio.get_running_loop()
        _, conn = await loop.create_connection(lambda: _Connection(self), self.url.host, self.url.port)
        return conn

    async def _open_serial(self) -> _Connection:
        """Open the device with pyserial (which sets the baud and raw mode) and hand its descriptor to the
        event loop as a read pipe and, on a duplicate, a write pipe. asyncio's pipe transports take
        character devices, so serial bytes arrive in the loop exactly as TCP's do: no reader thread to
        stop, no locking between a thread and the loop, and a vanished device ends as a lost pipe."""
        port = serial.Serial(self.url.device, self.url.baud, timeout=0, exclusive=True)
        loop = asyncio.get_running_loop()
        conn = _Connection(self, (self.url.device, self.url.baud))
        try:
            await loop.connect_read_pipe(lambda: conn, port)
            out = os.fdopen(os.dup(port.fileno()), "wb", buffering=0)
            transport, _ = await loop.connect_write_pipe(lambda: _WriteSide(conn), out)
        except BaseException:
            conn.close()
            port.close()
            raise
        conn.writer = transport
        self._connected(conn)
        return conn

    def _open_failed(self, exc: BaseException) -> None:
        self.stats.link_errors += 1
        if self._failing:
            self._log.debug("MAVLink %s: still cannot open: %s", self.url, exc)
            return
        self._failing = True
        self._log.warning("MAVLink %s: cannot open (%s); trying every %.0f s", self.url, exc, self._retry_s)

    def _connected(self, conn: _Connection) -> None:
        """``conn`` is up: it becomes the link's connection (a ``tcpin`` link's newer peer replaces the
        older: a peer whose cable was pulled sends no FIN and would otherwise hold the port for good)."""
        if self._conn is not None:
            self._log.warning("MAVLink %s: %s replaces %s", self.url, conn.peer, self._conn.peer)
            old, self._conn = self._conn, None
            old.close()
        if self._ever_connected:
            self.stats.reconnects += 1
        self._ever_connected = True
        self._failing = False
        # a partial frame left by the last connection would eat the start of this one's first frame
        self.mav.buf = bytearray()
        self.mav.buf_index = 0
        self.mav.expected_length = self._parser_start_length
        self._conn = conn
        self._log.info("MAVLink %s: connected to %s", self.url, conn.peer)

    def _lost(self, conn: _Connection, exc: Exception | None) -> None:
        if conn is not self._conn:
            return  # replaced or closed by us
        self._conn = None
        self.stats.link_errors += 1
        then = "awaiting the next peer" if self.url.mode == "tcpin" else f"retry in {self._retry_s:.0f} s"
        self._log.warning("MAVLink %s: lost %s (%s); %s", self.url, conn.peer, exc or "closed", then)

    def _received(self, data: bytes, peer: Address) -> None:
        for msg in self._parse(data, peer):
            self._dispatch(msg, peer)

    # ---------------------------------------------------------------- sending
    def send(self, msg: Any) -> None:
        """Pack ``msg`` (signed when a key is set) and write it to the peer; dropped (and counted in
        ``stats.dropped``) while none is connected or the peer is not reading."""
        conn = self._conn
        writer = conn.writer if conn is not None else None
        if writer is None or writer.is_closing() or writer.get_write_buffer_size() > MAX_BUFFERED_BYTES:
            self.stats.dropped += 1
            return
        writer.write(self._pack(msg))
        self.stats.sent += 1

    def send_to(self, msg: Any, system: int, component: int) -> None:
        """A stream has one peer: ``msg`` goes to it, routed beyond by its own target ids."""
        self.send(msg)
