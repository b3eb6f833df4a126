"""MAVLink 2 over one UDP socket with several peers, on asyncio.

pymavlink supplies the codec (a bare ``MAVLink`` object fed with ``parse_buffer``); asyncio owns
the socket. Every frame we send goes to every live peer, as a flight controller's UDP link does;
replies are addressed inside the message (target system/component), never by "last sender".

URLs: ``udpout:HOST:PORT`` sends to a fixed address (and also to peers that talk to us);
``udpin:HOST:PORT`` (alias ``udp:``) binds and learns peers from what arrives.

Users of a link depend on the protocols :class:`MavlinkSender` (a codec and ``send_to``: what flying a
vehicle needs) and :class:`MavlinkLink` (the whole endpoint), not on the UDP class: a test hands them
a link without a socket, the way httpx's client takes a transport.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

from pymavlink.dialects.v20 import common as mavlink2

Address = tuple[str, int]
MessageHandler = Callable[[Any, Address], None]

_PEER_TIMEOUT_S = 10.0
_STATUSTEXT_CHUNK = 50
_MAVLINK_EPOCH_UNIX_S = 1420070400  # signing timestamps count 10 us units from 2015-01-01


class LinkUrlError(ValueError):
    """A --mavlink URL that cannot be used."""


@dataclass(frozen=True, slots=True)
class LinkUrl:
    mode: str  # "udpin" or "udpout"
    host: str
    port: int

    @staticmethod
    def parse(url: str) -> LinkUrl:
        scheme, sep, rest = url.partition(":")
        if not sep:
            raise LinkUrlError(f"MAVLink URL {url!r}: expected udpin:HOST:PORT, udp:PORT or udpout:HOST:PORT")
        scheme = {"udp": "udpin"}.get(scheme, scheme)
        if scheme not in ("udpin", "udpout"):
            raise LinkUrlError(f"MAVLink URL {url!r}: scheme {scheme!r} is not udpin, udp or udpout")
        host, _, port_text = rest.rpartition(":")
        if not host:
            host = "0.0.0.0" if scheme == "udpin" else "127.0.0.1"
        try:
            port = int(port_text)
        except ValueError:
            raise LinkUrlError(f"MAVLink URL {url!r}: port {port_text!r} is not a number") from None
        if not 0 < port < 65536 and not (port == 0 and scheme == "udpin"):  # udpin port 0: any free port
            raise LinkUrlError(f"MAVLink URL {url!r}: port {port} is out of range")
        return LinkUrl(scheme, host, port)


def parse_signing_key(text: str) -> bytes:
    """A 32-byte MAVLink 2 signing key given as 64 hex digits."""
    try:
        key = bytes.fromhex(text.strip())
    except ValueError:
        raise ValueError("signing key must be hexadecimal (64 hex digits for 32 bytes)") from None
    if len(key) != 32:
        raise ValueError(f"signing key must be 32 bytes (64 hex digits), got {len(key)} bytes")
    return key


@dataclass
class LinkStats:
    received: int = 0
    sent: int = 0
    bad_frames: int = 0  # bad CRC, bad prefix, truncated
    rejected_unsigned: int = 0
    rejected_bad_signature: int = 0


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


class MavlinkUdpLink(asyncio.DatagramProtocol):
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
        *,
        signing_key: bytes | None = None,
        logger: logging.Logger | None = None,
        dialect: Any = mavlink2,
    ) -> None:
        self.url = LinkUrl.parse(url)
        self.mav = dialect.MAVLink(None, srcSystem=system_id, srcComponent=component_id)
        self.mav.robust_parsing = True
        self.stats = LinkStats()
        self._handler = handler
        self._log = logger or logging.getLogger("landfall_link.mavlink")
        self._transport: asyncio.DatagramTransport | None = None
        self._fixed: Address | None = None
        self._peers: dict[Address, float] = {}
        self._routes: dict[tuple[int, int], Address] = {}  # (system, component) -> where it spoke from
        self._signing = signing_key is not None
        if signing_key is not None:
            sig = self.mav.signing
            sig.secret_key = signing_key
            sig.link_id = 0
            sig.sign_outgoing = True
            sig.timestamp = int((time.time() - _MAVLINK_EPOCH_UNIX_S) * 1e5)
            sig.allow_unsigned_callback = lambda _mav, _msgid: False

    def attach(self, handler: MessageHandler) -> None:
        """Call ``handler(msg, addr)`` for every valid message from now on (in place of the last)."""
        self._handler = handler

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
        try:
            msgs = self.mav.parse_buffer(data) or []
        except Exception as exc:  # pymavlink raises bare Exceptions on some malformed input
            self.stats.bad_frames += 1
            self._log.debug("malformed MAVLink from %s: %s", addr, exc)
            return
        for msg in msgs:
            if msg.get_type() == "BAD_DATA":
                self._count_bad(msg, addr)
                continue
            self.stats.received += 1
            self._peers[addr] = time.monotonic()
            self._routes[(msg.get_srcSystem(), msg.get_srcComponent())] = addr
            if self._handler is None:
                continue
            try:
                self._handler(msg, addr)
            except Exception:
                # a handler bug must never take the link (and the vehicle) down
                self._log.exception("handler failed on %s from %s", msg.get_type(), addr)

    def error_received(self, exc: Exception) -> None:
        # ICMP port unreachable when a peer is gone; keep serving the others
        self._log.debug("UDP error: %s", exc)

    def _count_bad(self, msg: Any, addr: Address) -> None:
        reason = str(getattr(msg, "reason", ""))
        if "signature" in reason.lower():
            # with a reject-all callback pymavlink counts every refusal in reject_count and the
            # bad signatures among them in badsig_count; the rest were unsigned
            sig = self.mav.signing
            self.stats.rejected_bad_signature = sig.badsig_count
            self.stats.rejected_unsigned = sig.reject_count - sig.badsig_count
            self._log.warning("rejected unsigned or badly signed MAVLink frame from %s", addr)
        else:
            self.stats.bad_frames += 1
            self._log.debug("bad MAVLink frame from %s: %s", addr, reason)

    # ---------------------------------------------------------------- sending
    def _pack(self, msg: Any) -> bytes:
        """Pack (signed when a key is set) and advance the sequence number."""
        buf: bytes = msg.pack(self.mav)
        self.mav.seq = (self.mav.seq + 1) % 256
        return buf

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

    def send_statustext(self, severity: int, text: str) -> None:
        """STATUSTEXT to every peer, in 50-character chunks sharing an id when it is longer."""
        chunks = [text[i : i + _STATUSTEXT_CHUNK] for i in range(0, len(text), _STATUSTEXT_CHUNK)] or [""]
        msg_id = ((hash(text) & 0xFFFF) or 1) if len(chunks) > 1 else 0
        for seq, chunk in enumerate(chunks):
            self.send(self.mav.statustext_encode(severity, chunk.encode(), msg_id, seq))

    def route(self, system: int, component: int) -> Address | None:
        return self._routes.get((system, component))

    @property
    def peer_count(self) -> int:
        now = time.monotonic()
        return sum(1 for seen in self._peers.values() if now - seen < _PEER_TIMEOUT_S)
