"""MAVLink frames from a pretend autopilot, fed into a companion's receive path through a link without a
socket (``tests.fake_link``)."""

from __future__ import annotations

from typing import Any

from pymavlink.dialects.v20 import common as mavlink2

from companion.daemon import Companion
from tests.fake_link import FakeLink

AUTOPILOT = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)


def frames(*msgs: Any) -> bytes:
    """The messages packed as the autopilot sends them: each with the next sequence number (``pack``
    alone leaves it where it is; a real link's ``send`` advances it)."""
    out = b""
    for m in msgs:
        out += m.pack(AUTOPILOT)
        AUTOPILOT.seq = (AUTOPILOT.seq + 1) % 256
    return out


def on_fake_link(**options: Any) -> Companion:
    """A companion built on a :class:`FakeLink` (``answer`` goes to the link, the rest to the daemon)."""
    return Companion(link=FakeLink(answer=options.pop("answer", None)), **options)


def link_of(c: Companion) -> FakeLink:
    if not isinstance(c.link, FakeLink):
        raise TypeError(f"the companion flies on {type(c.link).__name__}; these helpers need a FakeLink")
    return c.link


def feed(c: Companion, *msgs: Any) -> None:
    """The messages received from the autopilot, in one datagram."""
    link_of(c).receive(frames(*msgs))


def accept_commands(msg: Any) -> bytes:
    """The autopilot's part: COMMAND_ACK ACCEPTED for every COMMAND_LONG (an ``answer`` for FakeLink)."""
    if msg.get_type() != "COMMAND_LONG":
        return b""
    return frames(AUTOPILOT.command_ack_encode(msg.command, mavlink2.MAV_RESULT_ACCEPTED, 0, 0, 0, 0))
