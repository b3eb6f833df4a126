"""MAVLink frames from a pretend autopilot, fed straight into a companion's receive path."""

from __future__ import annotations

from typing import Any

from pymavlink.dialects.v20 import common as mavlink2

from companion.daemon import Companion

AUTOPILOT = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
ADDR = ("127.0.0.1", 14580)


def frames(*msgs: Any) -> bytes:
    """The messages packed as the autopilot sends them: each with the next sequence number (``pack``
    alone leaves it where it is; a real link's ``send`` advances it)."""
    out = b""
    for m in msgs:
        out += m.pack(AUTOPILOT)
        AUTOPILOT.seq = (AUTOPILOT.seq + 1) % 256
    return out


def feed(c: Companion, *msgs: Any) -> None:
    c.link.datagram_received(frames(*msgs), ADDR)  # type: ignore[attr-defined]
