"""MAVLink 2 links on asyncio: one UDP socket with several peers, or a TCP or serial byte stream.

pymavlink supplies the codec (a bare ``MAVLink`` object fed with ``parse_buffer``); asyncio owns the
socket. On UDP every frame we send goes to every live peer, as a flight controller's UDP link does;
replies are addressed inside the message (target system/component), never by "last sender".

URLs, in pymavlink's spelling (:data:`URL_FORMS`): ``udpout:HOST:PORT`` sends to a fixed address (and
also to peers that talk to us); ``udpin:HOST:PORT`` (alias ``udp:``) binds and learns peers from what
arrives; ``tcp:HOST:PORT``, ``tcpin:HOST:PORT``, ``serial:DEVICE:BAUD`` and ``DEVICE[,BAUD]`` are stream
links (:mod:`landfall_link.mavlink_stream`). :func:`open_link` builds the right one for a URL.

Users of a link depend on the protocols :class:`MavlinkSender` (a codec and ``send_to``: what flying a
vehicle needs) and :class:`MavlinkLink` (the whole endpoint), not on a transport class: a test hands them
a link without a socket, the way httpx's client takes a transport.
"""

from __future__ import annotations

import asyncio
import time
from typing import Any, Protocol, Unpack

from landfall_link.mavlink_base import (
    DEFAULT_BAUD,
    STREAM_MODES,
    UDP_MODES,
    URL_FORMS,
    Address,
    LinkOptions,
    LinkStats,
    LinkUrl,
    LinkUrlError,
    MavlinkEndpoint,
    MessageHandler,
    parse_signing_key,
)
from landfall_link.mavlink_stream import MavlinkStreamLink

__all__ = [
    "DEFAULT_BAUD",
    "STREAM_MODES",
    "UDP_MODES",
    "URL_FORMS",
    "Address",
    "LinkOptions",
    "LinkStats",
    "LinkUrl",
    "LinkUrlError",
    "MavlinkLink",
    "MavlinkSender",
    "MavlinkStreamLink",
    "MavlinkUdpLink",
    "MessageHandler",
    "open_link",
    "parse_signing_key",
]

_PEER_TIMEOUT_S = 10.0


class MavlinkSender(Protocol):
    """What commanding one vehicle needs of a link: the codec that builds messages (pymavlink's
    ``MAVLink``: its ``*_encode`` methods and ``srcSystem``) and sending one to a peer."""

    @property
    def mav(self) -> Any: ...

    def send_to(self, msg: Any, system: int, component: int) -> None:
        """Send ``msg`` to the peer ``(system, component)`` (component 0: every component of it)."""
        ...


class MavlinkLink(MavlinkSender, Protocol):
    """One MAVLink endpoint as a daemon uses it: opened and closed as an async context, every valid
    message that arrives handed to the handler :meth:`attach` set, frames sent to one peer or all."""

    @property
    def stats(self) -> LinkStats: ...

    async def __aenter__(self) -> Any: ...

    async def __aexit__(self, *exc: object) -> None: ...

    def attach(self, handler: MessageHandler) -> None:
        """Call ``handler(msg, addr)`` for every valid message from now on (in place of the last)."""
        ...

    def send(self, msg: Any) -> None:
        """Send ``msg`` to every live peer."""
        ...

    def send_statustext(self, severity: int, text: str) -> None:
        """STATUSTEXT to every peer."""
        ...


class MavlinkUdpLink(MavlinkEndpoint, asyncio.DatagramProtocol):
    """One UDP endpoint speaking MAVLink 2 as (``system_id``, ``component_id``): a :class:`MavlinkLink`.

    Use as ``async with MavlinkUdpLink(url, ...) as link:``; ``handler(msg, addr)`` (given here or by
    :meth:`attach`) is called for every valid message, in the event loop.
    """

    def __init__(
        self,
        url: str,
        system_id: int,
        component_id: int,
        handler: MessageHandler | None = None,
        **options: Unpack[LinkOptions],
    ) -> None:
        self.url = LinkUrl.parse(url, allowed=UDP_MODES)
        super().__init__(system_id, component_id, handler, **options)
        self._transport: asyncio.DatagramTransport | None = None
        self._fixed: Address | None = None
        self._peers: dict[Address, float] = {}
        self._routes: dict[tuple[int, int], Address] = {}  # (system, component) -> where it spoke from

    async def __aenter__(self) -> MavlinkUdpLink:
        loop = asyncio.get_running_loop()
        if self.url.mode == "udpin":
            transport, _ = await loop.create_datagram_endpoint(
                lambda: self, local_addr=(self.url.host, self.url.port)
            )
        else:
            self._fixed = (self.url.host, self.url.port)
            transport, _ = await loop.create_datagram_endpoint(lambda: self, local_addr=("0.0.0.0", 0))
        self._transport = transport
        return self

    async def __aexit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        if self._transport is not None:
            self._transport.close()
            self._transport = None

    @property
    def local_port(self) -> int:
        if self._transport is None:
            raise RuntimeError("link is not open")
        return int(self._transport.get_extra_info("sockname")[1])

    # ---------------------------------------------------------------- asyncio callbacks
    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self._transport = transport  # type: ignore[assignment]

    def datagram_received(self, data: bytes, addr: Address) -> None:
        for msg in self._parse(data, addr):
            self._peers[addr] = time.monotonic()
            self._routes[(msg.get_srcSystem(), msg.get_srcComponent())] = addr
            self._dispatch(msg, addr)

    def error_received(self, exc: Exception) -> None:
        # ICMP port unreachable when a peer is gone; keep serving the others
        self._log.debug("UDP error: %s", exc)

    def send(self, msg: Any) -> None:
        """Pack ``msg`` (signed when a key is set) and send it to every live peer."""
        if self._transport is None:
            return
        buf = self._pack(msg)
        now = time.monotonic()
        dests = [a for a, seen in self._peers.items() if now - seen < _PEER_TIMEOUT_S]
        if self._fixed is not None and self._fixed not in dests:
            dests.append(self._fixed)
        for addr in dests:
            self._transport.sendto(buf, addr)
        self.stats.sent += 1

    def send_to(self, msg: Any, system: int, component: int) -> None:
        """Send to the address ``(system, component)`` last spoke from; to every peer when unknown
        (component 0 addresses every component of the system: sent to each of its addresses)."""
        if self._transport is None:
            return
        if component == 0:
            dests = {a for (s, _), a in self._routes.items() if s == system}
        else:
            addr = self._routes.get((system, component))
            dests = {addr} if addr is not None else set()
        if not dests:
            self.send(msg)
            return
        buf = self._pack(msg)
        for addr in dests:
            self._transport.sendto(buf, addr)
        self.stats.sent += 1

    def route(self, system: int, component: int) -> Address | None:
        return self._routes.get((system, component))

    @property
    def peer_count(self) -> int:
        now = time.monotonic()
        return sum(1 for seen in self._peers.values() if now - seen < _PEER_TIMEOUT_S)


def open_link(
    url: str,
    system_id: int,
    component_id: int,
    handler: MessageHandler | None = None,
    **options: Unpack[LinkOptions],
) -> MavlinkUdpLink | MavlinkStreamLink:
    """The link a ``--mavlink`` URL names (UDP, TCP or serial), not yet open: use it as ``async with``.

    Raises:
        LinkUrlError: ``url`` is none of :data:`URL_FORMS`.
    """
    if LinkUrl.parse(url).mode in UDP_MODES:
        return MavlinkUdpLink(url, system_id, component_id, handler, **options)
    return MavlinkStreamLink(url, system_id, component_id, handler, **options)
