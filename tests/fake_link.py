"""A MAVLink link without a socket, for tests that drive a controller or a daemon at its link.

It satisfies ``landfall_link.mavlink.MavlinkLink``: what is sent is kept in ``sent``; what the test
feeds with :meth:`FakeLink.receive` (wire bytes, so sequence numbers travel as on a real link) goes to
the handler the daemon attached; an ``answer`` function plays the peer: the frames it returns for a
sent message are delivered on the next turn of the event loop, as a reply datagram would be.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from typing import Any

from pymavlink.dialects.v20 import common as mavlink2

from landfall_link.mavlink import Address, LinkStats, MessageHandler

PEER: Address = ("127.0.0.1", 14580)  # where everything received seems to come from


class FakeLink:
    """Records sent messages (with their addressee) and delivers fed frames to the attached handler."""

    def __init__(
        self,
        system_id: int = 1,
        component_id: int = 191,
        *,
        answer: Callable[[Any], bytes] | None = None,
    ) -> None:
        self.mav = mavlink2.MAVLink(None, srcSystem=system_id, srcComponent=component_id)
        self.stats = LinkStats()
        self.sent: list[Any] = []
        self.sent_to: list[tuple[int, int] | None] = []  # None: sent to every peer
        self._answer = answer
        self._handler: MessageHandler | None = None
        self._parser = mavlink2.MAVLink(None)
        self._parser.robust_parsing = True

    async def __aenter__(self) -> FakeLink:
        return self

    async def __aexit__(self, *exc: object) -> None:
        return None

    def attach(self, handler: MessageHandler) -> None:
        self._handler = handler

    def send(self, msg: Any) -> None:
        self._sent(msg, None)

    def send_to(self, msg: Any, system: int, component: int) -> None:
        self._sent(msg, (system, component))

    def send_statustext(self, severity: int, text: str) -> None:
        self.send(self.mav.statustext_encode(severity, text[:50].encode(), 0, 0))

    def _sent(self, msg: Any, to: tuple[int, int] | None) -> None:
        self.sent.append(msg)
        self.sent_to.append(to)
        self.stats.sent += 1
        if self._answer is None:
            return
        reply = self._answer(msg)
        if reply:
            asyncio.get_running_loop().call_soon(self.receive, reply)

    def receive(self, data: bytes, addr: Address = PEER) -> None:
        """Deliver the messages in ``data`` (MAVLink frames) as if they had just arrived."""
        if self._handler is None:
            raise RuntimeError("nothing attached to the link: the daemon attaches its handler when built")
        for msg in self._parser.parse_buffer(data) or []:
            if msg.get_type() == "BAD_DATA":
                self.stats.bad_frames += 1
                continue
            self.stats.received += 1
            self._handler(msg, addr)

    def sent_of(self, kind: str) -> list[Any]:
        """The messages of one type sent so far (``"COMMAND_LONG"``...)."""
        return [m for m in self.sent if m.get_type() == kind]
