"""What every MAVLink link shares, whatever carries its bytes: the ``--mavlink`` URL, the counters, the
signing key and :class:`MavlinkEndpoint` (codec, signing, robust parsing, handler dispatch, packing).

The transports live beside it: UDP datagrams in :mod:`landfall_link.mavlink`, TCP and serial byte
streams in :mod:`landfall_link.mavlink_stream`; users import all of it from :mod:`landfall_link.mavlink`.
"""

from __future__ import annotations

import abc
import logging
import time
from collections.abc import Callable, Collection
from dataclasses import dataclass
from typing import Any, TypedDict, Unpack

from pymavlink.dialects.v20 import common as mavlink2

Address = tuple[str, int]  # an IP peer (host, port); a serial port is (device path, baud)
MessageHandler = Callable[[Any, Address], None]

_STATUSTEXT_CHUNK = 50
_MAVLINK_EPOCH_UNIX_S = 1420070400  # signing timestamps count 10 us units from 2015-01-01

UDP_MODES = ("udpin", "udpout")
STREAM_MODES = ("tcp", "tcpin", "serial")
# pymavlink's own default (mavutil.mavlink_connection and mavserial: baud=115200); a Pixhawk's TELEM2
# and a Raspberry Pi UART are usually set to 921600 and say so in the URL
DEFAULT_BAUD = 115200
URL_FORMS = (
    "udpin:HOST:PORT, udp:PORT, udpout:HOST:PORT, tcp:HOST:PORT, tcpin:HOST:PORT, "
    "serial:DEVICE[:BAUD], DEVICE[,BAUD] or DEVICE:BAUD (DEVICE a path such as /dev/ttyAMA0)"
)


class LinkUrlError(ValueError):
    """A --mavlink URL that cannot be used: ``url`` as given and ``problem``, what is wrong with it."""

    def __init__(self, url: str, problem: str) -> None:
        super().__init__(f"MAVLink URL {url!r}: {problem}")
        self.url = url
        self.problem = problem


@dataclass(frozen=True, slots=True)
class LinkUrl:
    """A parsed ``--mavlink`` URL, in pymavlink's spelling.

    ``mode`` is ``udpin`` (binds ``host:port``, learns peers), ``udpout`` (sends to ``host:port``),
    ``tcp`` (connects out to ``host:port``), ``tcpin`` (listens on ``host:port``, one peer at a time)
    or ``serial`` (``device`` at ``baud`` bits/s; :data:`DEFAULT_BAUD` when the URL names none).
    """

    mode: str
    host: str = ""
    port: int = 0
    device: str = ""
    baud: int = 0

    def __str__(self) -> str:
        if self.mode == "serial":
            return f"serial:{self.device}:{self.baud}"
        return f"{self.mode}:{self.host}:{self.port}"

    @staticmethod
    def parse(url: str, allowed: Collection[str] = UDP_MODES + STREAM_MODES) -> LinkUrl:
        """Parse ``url`` (one of :data:`URL_FORMS`), accepting only the modes in ``allowed``."""
        if url.startswith("/"):
            parsed = _parse_serial(url, url)
        else:
            scheme, sep, rest = url.partition(":")
            scheme = {"udp": "udpin"}.get(scheme, scheme)
            if not sep or scheme not in UDP_MODES + STREAM_MODES:
                raise LinkUrlError(url, f"unknown form; expected {URL_FORMS}")
            parsed = _parse_serial(url, rest) if scheme == "serial" else _parse_ip(url, scheme, rest)
        if parsed.mode not in allowed:
            raise LinkUrlError(url, f"a {parsed.mode} link is not possible here (only {', '.join(allowed)})")
        return parsed


def _parse_ip(url: str, scheme: str, rest: str) -> LinkUrl:
    """``HOST:PORT`` after a udp/tcp scheme; only ``udpin`` and ``udpout`` may leave out the host."""
    host, _, port_text = rest.rpartition(":")
    if not host:
        if scheme == "tcp":
            raise LinkUrlError(url, "a tcp link needs HOST:PORT, e.g. tcp:127.0.0.1:5760")
        host = "127.0.0.1" if scheme == "udpout" else "0.0.0.0"
    if not port_text:
        raise LinkUrlError(url, "the port is missing (expected HOST:PORT)")
    try:
        port = int(port_text)
    except ValueError:
        raise LinkUrlError(url, f"port {port_text!r} is not a number") from None
    listening = scheme in ("udpin", "tcpin")
    if not 0 < port < 65536 and not (port == 0 and listening):  # port 0 when listening: any free port
        raise LinkUrlError(url, f"port {port} is out of range 1..65535")
    return LinkUrl(scheme, host, port)


def _parse_serial(url: str, rest: str) -> LinkUrl:
    """``DEVICE``, ``DEVICE,BAUD`` or ``DEVICE:BAUD``. A colon suffix made of letters and digits is
    taken for a baud (and must be a number); one with other characters (``/dev/serial/by-path/...-0:1.0``)
    belongs to the device's name: give such a device its baud after a comma."""
    device, baud_text = rest, ""
    if "," in rest:
        device, _, baud_text = rest.rpartition(",")
        if not baud_text:
            raise LinkUrlError(url, "the baud after ',' is missing")
    elif ":" in rest:
        head, _, tail = rest.rpartition(":")
        if not tail:
            raise LinkUrlError(url, "the baud after ':' is missing")
        if tail.isalnum():
            device, baud_text = head, tail
    if not device:
        raise LinkUrlError(url, "the serial device is missing, e.g. serial:/dev/ttyAMA0:921600")
    if not baud_text:
        return LinkUrl("serial", device=device, baud=DEFAULT_BAUD)
    if not baud_text.isdigit() or int(baud_text) == 0:
        raise LinkUrlError(url, f"baud {baud_text!r} is not a positive whole number (e.g. 57600, 921600)")
    return LinkUrl("serial", device=device, baud=int(baud_text))


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
    """Counters of one link since it was built. The last three stay 0 on UDP, which has no connection."""

    received: int = 0
    sent: int = 0
    bad_frames: int = 0  # bad CRC, bad prefix (garbage between frames), truncated
    rejected_unsigned: int = 0
    rejected_bad_signature: int = 0
    reconnects: int = 0  # connections made after the first (a stream link)
    link_errors: int = 0  # failed opens and connections lost
    dropped: int = 0  # frames not sent: no connection, or the write buffer full (a stalled peer)


class LinkOptions(TypedDict, total=False):
    """What every link takes beyond its URL, ids and handler, whatever its transport."""

    signing_key: bytes | None  # 32 bytes: sign what we send, refuse unsigned and badly signed frames
    logger: logging.Logger | None  # default: the "landfall_link.mavlink" logger
    dialect: Any  # the pymavlink dialect module; default: common, MAVLink 2


class MavlinkEndpoint(abc.ABC):
    """A MAVLink 2 endpoint as (``system_id``, ``component_id``), whatever its transport: the codec
    (``mav``, pymavlink's ``MAVLink`` fed with ``parse_buffer``), signing, counters and the handler.

    A transport subclass feeds received bytes to :meth:`_parse` and hands each message it returns to
    :meth:`_dispatch`; it sends what :meth:`_pack` returns.
    """

    def __init__(
        self,
        system_id: int,
        component_id: int,
        handler: MessageHandler | None,
        **options: Unpack[LinkOptions],
    ) -> None:
        dialect = options.get("dialect", mavlink2)
        self.mav = dialect.MAVLink(None, srcSystem=system_id, srcComponent=component_id)
        self.mav.robust_parsing = True  # bad input becomes BAD_DATA messages, never an exception
        self.stats = LinkStats()
        self._handler = handler
        self._log = options.get("logger") or logging.getLogger("landfall_link.mavlink")
        signing_key = options.get("signing_key")
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

    def _parse(self, data: bytes, addr: Address) -> list[Any]:
        """The valid messages in ``data``; bad frames and refused signatures are counted and logged.
        A partial frame at the end stays in the codec's buffer for the next call (a byte stream)."""
        try:
            msgs = self.mav.parse_buffer(data) or []
        except Exception as exc:  # pymavlink raises bare Exceptions on some malformed input
            self.stats.bad_frames += 1
            self._log.debug("malformed MAVLink from %s: %s", addr, exc)
            return []
        good = []
        for msg in msgs:
            if msg.get_type() == "BAD_DATA":
                self._count_bad(msg, addr)
            else:
                good.append(msg)
        return good

    def _dispatch(self, msg: Any, addr: Address) -> None:
        """Count ``msg`` and hand it to the handler; a handler's exception is logged, never raised."""
        self.stats.received += 1
        if self._handler is None:
            return
        try:
            self._handler(msg, addr)
        except Exception:
            # a handler bug must never take the link (and the vehicle) down
            self._log.exception("handler failed on %s from %s", msg.get_type(), addr)

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

    def _pack(self, msg: Any) -> bytes:
        """Pack (signed when a key is set) and advance the sequence number."""
        buf: bytes = msg.pack(self.mav)
        self.mav.seq = (self.mav.seq + 1) % 256
        return buf

    @abc.abstractmethod
    def send(self, msg: Any) -> None:
        """Send ``msg`` to every peer (the transport's business)."""

    def send_statustext(self, severity: int, text: str) -> None:
        """STATUSTEXT to every peer, in 50-character chunks sharing an id when it is longer."""
        chunks = [text[i : i + _STATUSTEXT_CHUNK] for i in range(0, len(text), _STATUSTEXT_CHUNK)] or [""]
        msg_id = ((hash(text) & 0xFFFF) or 1) if len(chunks) > 1 else 0
        for seq, chunk in enumerate(chunks):
            self.send(self.mav.statustext_encode(severity, chunk.encode(), msg_id, seq))
