"""MAVLink links by URL: the forms pymavlink names, and the TCP and serial stream links on real loopback
sockets and pseudo-terminals: signed frames both ways, garbage between frames, peers that go away and
come back, devices that vanish; then one flight with the companion on a ``tcp:`` link."""

from __future__ import annotations

import asyncio
import logging
import os
import select
import socket
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import suppress
from typing import Any

import pytest
from pymavlink.dialects.v20 import common as mavlink2

from landfall_link.mavlink import (
    DEFAULT_BAUD,
    UDP_MODES,
    URL_FORMS,
    LinkUrl,
    LinkUrlError,
    MavlinkStreamLink,
    MavlinkUdpLink,
    open_link,
)
from tests.conftest import Rig, free_tcp_port

KEY = bytes(range(32))
MAV_CMD_USER_1 = 31010
RETRY_S = 0.05  # the links under test retry fast: the tests wait on their state, not on the clock


# ------------------------------------------------------------------------------------------- URLs
@pytest.mark.parametrize(
    ("url", "parsed"),
    [
        ("udp:14550", LinkUrl("udpin", "0.0.0.0", 14550)),
        ("udpout:10.0.0.2:14550", LinkUrl("udpout", "10.0.0.2", 14550)),
        ("tcp:127.0.0.1:5760", LinkUrl("tcp", "127.0.0.1", 5760)),
        ("tcpin:0.0.0.0:5760", LinkUrl("tcpin", "0.0.0.0", 5760)),
        ("tcpin:5760", LinkUrl("tcpin", "0.0.0.0", 5760)),
        ("serial:/dev/ttyAMA0:921600", LinkUrl("serial", device="/dev/ttyAMA0", baud=921600)),
        ("serial:/dev/ttyAMA0", LinkUrl("serial", device="/dev/ttyAMA0", baud=DEFAULT_BAUD)),
        ("serial:COM3:57600", LinkUrl("serial", device="COM3", baud=57600)),
        ("/dev/ttyUSB0", LinkUrl("serial", device="/dev/ttyUSB0", baud=DEFAULT_BAUD)),
        ("/dev/ttyUSB0,57600", LinkUrl("serial", device="/dev/ttyUSB0", baud=57600)),
        ("/dev/ttyUSB0:57600", LinkUrl("serial", device="/dev/ttyUSB0", baud=57600)),
        # a by-path name has colons of its own: they stay in the device's name
        (
            "/dev/serial/by-path/pci-0000:00:14.0-usb-0:2:1.0",
            LinkUrl("serial", device="/dev/serial/by-path/pci-0000:00:14.0-usb-0:2:1.0", baud=DEFAULT_BAUD),
        ),
        (
            "/dev/serial/by-path/pci-0000:00:14.0-usb-0:2:1.0,921600",
            LinkUrl("serial", device="/dev/serial/by-path/pci-0000:00:14.0-usb-0:2:1.0", baud=921600),
        ),
    ],
)
def test_link_url_parse_accepts_pymavlink_forms(url: str, parsed: LinkUrl) -> None:
    assert LinkUrl.parse(url) == parsed


@pytest.mark.parametrize(
    ("url", "problem"),
    [
        ("14550", f"unknown form; expected {URL_FORMS}"),
        ("ftp:host:21", f"unknown form; expected {URL_FORMS}"),
        ("tcp:5760", "a tcp link needs HOST:PORT, e.g. tcp:127.0.0.1:5760"),
        ("tcp:host:", "the port is missing (expected HOST:PORT)"),
        ("tcpin:host:x", "port 'x' is not a number"),
        ("tcp:host:70000", "port 70000 is out of range 1..65535"),
        ("tcp:host:0", "port 0 is out of range 1..65535"),
        ("serial:/dev/ttyAMA0:fast", "baud 'fast' is not a positive whole number (e.g. 57600, 921600)"),
        ("/dev/ttyS0,0", "baud '0' is not a positive whole number (e.g. 57600, 921600)"),
        ("/dev/ttyS0,", "the baud after ',' is missing"),
        ("/dev/ttyS0:", "the baud after ':' is missing"),
        ("serial:", "the serial device is missing, e.g. serial:/dev/ttyAMA0:921600"),
        ("serial::921600", "the serial device is missing, e.g. serial:/dev/ttyAMA0:921600"),
    ],
)
def test_link_url_parse_bad_form_says_what_is_wrong(url: str, problem: str) -> None:
    with pytest.raises(LinkUrlError) as err:
        LinkUrl.parse(url)
    assert (err.value.url, err.value.problem) == (url, problem)
    assert str(err.value) == f"MAVLink URL {url!r}: {problem}"


def test_link_url_parse_refuses_a_mode_not_allowed_and_prints_back() -> None:
    with pytest.raises(LinkUrlError, match=r"a tcp link is not possible here \(only udpin, udpout\)"):
        LinkUrl.parse("tcp:h:1", allowed=UDP_MODES)
    assert str(LinkUrl.parse("/dev/ttyAMA0,921600")) == "serial:/dev/ttyAMA0:921600"
    assert str(LinkUrl.parse("udp:14550")) == "udpin:0.0.0.0:14550"


def test_open_link_chooses_the_class_by_scheme() -> None:
    assert type(open_link("udp:14550", 1, 191)) is MavlinkUdpLink
    for url in ("tcp:127.0.0.1:5760", "tcpin:5760", "serial:/dev/ttyAMA0:921600", "/dev/ttyUSB0"):
        assert type(open_link(url, 1, 191)) is MavlinkStreamLink
    with pytest.raises(LinkUrlError):
        open_link("tcp:5760", 1, 191)


# ------------------------------------------------------------------------------------------- helpers
class Inbox:
    """A link's handler: every message it is handed, waited on by type."""

    def __init__(self) -> None:
        self.msgs: list[Any] = []
        self._new = asyncio.Event()

    def __call__(self, msg: Any, addr: tuple[str, int]) -> None:
        self.msgs.append(msg)
        self._new.set()

    def of(self, kind: str) -> list[Any]:
        return [m for m in self.msgs if m.get_type() == kind]

    async def get(self, kind: str, count: int = 1, timeout_s: float = 5.0) -> Any:
        """The ``count``-th message of type ``kind`` to arrive."""
        async with asyncio.timeout(timeout_s):
            while len(self.of(kind)) < count:
                self._new.clear()
                await self._new.wait()
        return self.of(kind)[count - 1]


async def until(cond: Callable[[], bool], timeout_s: float = 5.0) -> None:
    """Poll ``cond`` (link state another task changes) until it holds; fails the test at the deadline."""
    async with asyncio.timeout(timeout_s):
        while not cond():  # noqa: ASYNC110 - counters and state that transport callbacks change
            await asyncio.sleep(0.01)


def codec(system: int, component: int, key: bytes | None = KEY) -> Any:
    """A bare pymavlink codec, signing with ``key`` (and refusing unsigned frames) when given."""
    mav = mavlink2.MAVLink(None, srcSystem=system, srcComponent=component)
    mav.robust_parsing = True
    if key is not None:
        mav.signing.secret_key = key
        mav.signing.sign_outgoing = True
        # 10 us units since 2015-01-01 (pymavlink's epoch): the link refuses timestamps from long ago
        mav.signing.timestamp = int((time.time() - 1420070400) * 1e5)
        mav.signing.allow_unsigned_callback = lambda _mav, _msgid: False
    return mav


def heartbeat(mav: Any) -> bytes:
    return bytes(mav.heartbeat_encode(2, 12, 129, 0, 4).pack(mav))


def alarm(mav: Any, target: tuple[int, int] = (1, 191)) -> Any:
    return mav.command_long_encode(*target, MAV_CMD_USER_1, 0, 4.0, 2.0, 0, 0, 0, 0, 0)


# ------------------------------------------------------------------------------------------- TCP
async def test_stream_link_tcp_to_tcpin_exchanges_signed_heartbeat_and_command_long() -> None:
    autopilot_in, companion_in = Inbox(), Inbox()
    async with MavlinkStreamLink("tcpin:127.0.0.1:0", 1, 1, autopilot_in, signing_key=KEY) as server:
        url = f"tcp:127.0.0.1:{server.local_port}"
        async with MavlinkStreamLink(url, 1, 191, companion_in, signing_key=KEY, retry_s=RETRY_S) as client:
            await until(lambda: client.connected and server.connected)
            server.send(server.mav.heartbeat_encode(2, 12, 129, 0, 4))
            client.send(client.mav.heartbeat_encode(18, 8, 0, 0, 4))
            client.send_to(alarm(client.mav), 1, 191)
            server.send_to(server.mav.command_ack_encode(MAV_CMD_USER_1, 0, 0, 0, 1, 191), 1, 191)
            hb = await companion_in.get("HEARTBEAT")
            cmd = await autopilot_in.get("COMMAND_LONG")
            ack = await companion_in.get("COMMAND_ACK")
            await autopilot_in.get("HEARTBEAT")
    assert (hb.get_srcSystem(), hb.get_srcComponent(), hb.autopilot) == (1, 1, 12)
    assert (cmd.get_srcComponent(), cmd.command, cmd.param1, cmd.param2) == (191, MAV_CMD_USER_1, 4.0, 2.0)
    assert (ack.command, ack.result) == (MAV_CMD_USER_1, 0)
    assert all(m.get_signed() for m in companion_in.msgs + autopilot_in.msgs)
    assert (client.stats.sent, client.stats.received, client.stats.bad_frames) == (2, 2, 0)
    assert (server.stats.sent, server.stats.received, server.stats.bad_frames) == (2, 2, 0)
    assert (client.stats.reconnects, client.stats.link_errors, client.stats.dropped) == (0, 0, 0)


class FeedServer:
    """A plain asyncio TCP server standing in for an autopilot: it hands each connection to the test."""

    def __init__(self) -> None:
        self.conns: asyncio.Queue[tuple[asyncio.StreamReader, asyncio.StreamWriter]] = asyncio.Queue()
        self.server: asyncio.Server | None = None

    async def start(self, port: int = 0) -> int:
        self.server = await asyncio.start_server(
            lambda r, w: self.conns.put_nowait((r, w)), "127.0.0.1", port
        )
        return int(self.server.sockets[0].getsockname()[1])

    async def next(self) -> tuple[asyncio.StreamReader, asyncio.StreamWriter]:
        async with asyncio.timeout(5.0):
            return await self.conns.get()

    def close(self) -> None:
        if self.server is not None:
            self.server.close()


async def read_message(reader: asyncio.StreamReader, mav: Any, kind: str) -> Any:
    """The next message of type ``kind`` parsed by ``mav`` from ``reader``."""
    async with asyncio.timeout(5.0):
        while True:
            for msg in mav.parse_buffer(await reader.read(4096)) or []:
                if msg.get_type() == kind:
                    return msg


async def test_stream_link_tcp_client_counts_garbage_refuses_unsigned_and_reconnects() -> None:
    feed, inbox, autopilot = FeedServer(), Inbox(), codec(1, 1)
    port = await feed.start()
    async with MavlinkStreamLink(
        f"tcp:127.0.0.1:{port}", 1, 191, inbox, signing_key=KEY, retry_s=RETRY_S
    ) as link:
        reader, writer = await feed.next()
        await until(lambda: link.connected)
        unsigned = heartbeat(codec(1, 2, key=None))
        writer.write(heartbeat(autopilot) + b"garbage!" + unsigned + heartbeat(autopilot))
        await inbox.get("HEARTBEAT", 2)
        link.send(alarm(link.mav))
        cmd = await read_message(reader, codec(9, 9), "COMMAND_LONG")
        assert cmd.command == MAV_CMD_USER_1
        assert (link.stats.bad_frames, link.stats.rejected_unsigned, link.stats.received) == (1, 1, 2)

        writer.close()  # the autopilot's side goes away: the link sees it, drops sends, reconnects
        await until(lambda: not link.connected)
        link.send(alarm(link.mav))
        assert (link.stats.dropped, link.stats.link_errors) == (1, 1)
        reader, writer = await feed.next()
        await until(lambda: link.connected)
        writer.write(heartbeat(autopilot))
        await inbox.get("HEARTBEAT", 3)
        link.send(alarm(link.mav))
        cmd = await read_message(reader, codec(9, 9), "COMMAND_LONG")
        writer.close()
    feed.close()
    assert link.stats.reconnects == 1
    assert [m.get_srcComponent() for m in inbox.of("HEARTBEAT")] == [1, 1, 1]  # never the unsigned one


async def test_stream_link_tcp_client_retries_a_refused_connect_quietly(
    caplog: pytest.LogCaptureFixture,
) -> None:
    port = free_tcp_port()  # nothing listens there yet
    inbox, feed = Inbox(), FeedServer()
    with caplog.at_level(logging.DEBUG, logger="landfall_link.mavlink"):
        async with MavlinkStreamLink(f"tcp:127.0.0.1:{port}", 1, 191, inbox, retry_s=RETRY_S) as link:
            await until(lambda: link.stats.link_errors >= 3)
            link.send(alarm(link.mav))
            assert (link.connected, link.stats.dropped, link.stats.sent) == (False, 1, 0)
            await feed.start(port)
            _, writer = await feed.next()
            writer.write(heartbeat(codec(1, 1, key=None)))
            await inbox.get("HEARTBEAT")
            writer.close()
    feed.close()
    warnings = [r for r in caplog.records if r.levelno == logging.WARNING and "cannot open" in r.message]
    assert len(warnings) == 1  # logged once per change of state, the retries at debug level
    assert link.stats.reconnects == 0  # the first connection made is not a reconnection


async def test_stream_link_tcpin_takes_the_next_peer_and_a_newer_one_replaces_it() -> None:
    inbox, autopilot = Inbox(), codec(1, 1, key=None)
    async with MavlinkStreamLink("tcpin:127.0.0.1:0", 1, 191, inbox, retry_s=RETRY_S) as link:
        _, first = await asyncio.open_connection("127.0.0.1", link.local_port)
        first.write(heartbeat(autopilot))
        await inbox.get("HEARTBEAT")
        first.close()
        await until(lambda: not link.connected)

        reader, second = await asyncio.open_connection("127.0.0.1", link.local_port)
        second.write(heartbeat(autopilot))
        await inbox.get("HEARTBEAT", 2)
        link.send(alarm(link.mav))
        assert (await read_message(reader, codec(9, 9, key=None), "COMMAND_LONG")).command == MAV_CMD_USER_1

        third_reader, third = await asyncio.open_connection("127.0.0.1", link.local_port)
        third.write(heartbeat(autopilot))
        await inbox.get("HEARTBEAT", 3)
        async with asyncio.timeout(5.0):
            assert await reader.read() == b""  # the second peer was closed for the third
        second.close()
        link.send(alarm(link.mav))
        assert (
            await read_message(third_reader, codec(9, 9, key=None), "COMMAND_LONG")
        ).command == MAV_CMD_USER_1
        third.close()
    assert (link.stats.reconnects, link.stats.received) == (2, 3)


# ------------------------------------------------------------------------------------------- serial
class Pty:
    """A pseudo-terminal pair: the link opens the slave's path, the test speaks on the master."""

    def __init__(self) -> None:
        self.master, self.slave = os.openpty()
        self.path = os.ttyname(self.slave)
        os.set_blocking(self.master, False)
        self._rx = bytearray()
        self._more = asyncio.Event()
        asyncio.get_running_loop().add_reader(self.master, self._read)

    def _read(self) -> None:
        with suppress(BlockingIOError, OSError):  # EIO while no slave is open
            self._rx += os.read(self.master, 4096)
            self._more.set()

    def write(self, data: bytes) -> None:
        os.write(self.master, data)

    async def message(self, mav: Any, kind: str) -> Any:
        """The next message of type ``kind`` the link wrote to the device."""
        async with asyncio.timeout(5.0):
            while True:
                data, self._rx = bytes(self._rx), bytearray()
                for msg in mav.parse_buffer(data) or []:
                    if msg.get_type() == kind:
                        return msg
                self._more.clear()
                await self._more.wait()

    def close(self) -> None:
        """Pull the cable: the device goes away under the link."""
        asyncio.get_running_loop().remove_reader(self.master)
        os.close(self.master)
        os.close(self.slave)


def reopen_pty(path: str) -> Pty | None:
    """A new pair on the vanished ``path``: Linux gives the lowest free pty number, so taking (and holding)
    pairs until ``path`` comes back reaches it unless another process takes it first; None then."""
    held: list[Pty] = []
    try:
        for _ in range(64):
            pty = Pty()
            if pty.path == path:
                return pty
            held.append(pty)
        return None
    finally:
        for other in held:
            other.close()


async def test_stream_link_serial_over_a_pty_survives_the_device_vanishing_and_returning() -> None:
    pty, inbox, autopilot = Pty(), Inbox(), codec(1, 1)
    async with MavlinkStreamLink(
        f"serial:{pty.path}:921600", 1, 191, inbox, signing_key=KEY, retry_s=RETRY_S
    ) as link:
        await until(lambda: link.connected)
        pty.write(heartbeat(autopilot) + b"noise" + heartbeat(autopilot))
        await inbox.get("HEARTBEAT", 2)
        link.send(alarm(link.mav))
        assert (await pty.message(codec(9, 9), "COMMAND_LONG")).command == MAV_CMD_USER_1
        assert inbox.msgs[0].get_signed()
        assert link.stats.bad_frames == 1

        path = pty.path
        pty.close()
        await until(lambda: not link.connected)
        link.send(alarm(link.mav))
        await until(lambda: link.stats.link_errors >= 3)  # the lost device, then failed reopens
        assert link.stats.dropped == 1
        pty2 = reopen_pty(path)
        if pty2 is None:
            pytest.skip(f"another process took {path} before the test could make it again")
        await until(lambda: link.connected)
        pty2.write(heartbeat(autopilot))
        await inbox.get("HEARTBEAT", 3)
        link.send(alarm(link.mav))
        assert (await pty2.message(codec(9, 9), "COMMAND_LONG")).command == MAV_CMD_USER_1
    pty2.close()
    assert link.stats.reconnects == 1
    assert inbox.msgs[-1].get_srcSystem() == 1


async def test_stream_link_serial_device_that_cannot_be_opened_is_retried_and_counted() -> None:
    async with MavlinkStreamLink("serial:/dev/landfall-no-such-uart:57600", 1, 191, retry_s=RETRY_S) as link:
        await until(lambda: link.stats.link_errors >= 3)
        link.send_statustext(4, "nobody hears this")
        assert (link.connected, link.stats.dropped, link.stats.sent) == (False, 1, 0)


# ------------------------------------------------------------------------------------------- e2e
def _alarm_through(start_rig: Callable[..., Rig], link: str, udp_port: int) -> Rig:
    """scenario1 on the PX4 emulation at 4x, simbridge sending to ``udp_port`` (a relay's) and the
    companion on ``link`` (the relay's other side); once it is up, an alarm through the relay too."""
    from tests.test_companion_e2e import _wait_for_companion

    rig = start_rig(
        ["--scenario", "scenario1", "--autopilot", "px4", "--speed", "4"],
        ["--mavlink", link],  # the later --mavlink wins
        mavlink_via=lambda _port: udp_port,
    )
    _wait_for_companion(rig)
    to = f"udpout:127.0.0.1:{udp_port}"
    out = rig.alarm_accepted("--mavlink", to, "--reason", "GPS spoofing", "--criticality", "high")
    assert out.returncode == 0, out.stdout + out.stderr
    return rig


class UdpTcpRouter:
    """mavlink-router in miniature: datagrams from every UDP peer (simbridge, trigger_alarm.py) go down the
    one TCP connection it serves (the companion's ``tcp:`` link); what comes up goes to every UDP peer."""

    def __init__(self) -> None:
        self._udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._udp.bind(("127.0.0.1", 0))
        self.udp_port = int(self._udp.getsockname()[1])
        self._listener = socket.create_server(("127.0.0.1", 0))
        self.tcp_port = int(self._listener.getsockname()[1])
        self._peers: set[tuple[str, int]] = set()
        self._tcp: socket.socket | None = None
        self.connections = 0
        for target in (self._accept, self._down):
            threading.Thread(target=target, daemon=True).start()

    def _accept(self) -> None:
        with suppress(OSError):  # the listener closed
            while True:
                conn, _ = self._listener.accept()
                self._tcp = conn
                self.connections += 1
                threading.Thread(target=self._up, args=(conn,), daemon=True).start()

    def _down(self) -> None:
        with suppress(OSError):
            while True:
                data, peer = self._udp.recvfrom(65536)
                self._peers.add(peer)
                if (tcp := self._tcp) is not None:
                    with suppress(OSError):
                        tcp.sendall(data)

    def _up(self, conn: socket.socket) -> None:
        with suppress(OSError):
            while data := conn.recv(65536):
                for peer in list(self._peers):
                    self._udp.sendto(data, peer)

    def close(self) -> None:
        for s in (self._listener, self._udp, self._tcp):
            if s is not None:
                with suppress(OSError):
                    s.shutdown(socket.SHUT_RDWR)
                s.close()


@pytest.fixture
def router() -> Iterator[UdpTcpRouter]:
    r = UdpTcpRouter()
    yield r
    r.close()


@pytest.mark.slow
@pytest.mark.timeout(420)
def test_companion_on_a_tcp_link_lands_px4_emulation_on_the_clear_roof(
    start_rig: Callable[..., Rig], router: UdpTcpRouter
) -> None:
    """The companion speaks ``tcp:`` to a router that serves simbridge's UDP, as mavlink-router's TCP
    port 5760 would; the alarm reaches it through the router too. It lands on scenario1's clear roof."""
    from tests.test_companion_e2e import _wait_touchdown

    rig = _alarm_through(start_rig, f"tcp:127.0.0.1:{router.tcp_port}", router.udp_port)
    td = _wait_touchdown(rig, timeout_s=240)
    assert td["surface"] == "rooftop_clear", (td, rig.log_text()[-3000:])
    assert td["safe"] is True
    log = rig.wait_log("recovery ended: landed", timeout_s=60)
    assert f"MAVLink tcp:127.0.0.1:{router.tcp_port}: connected to" in log
    assert router.connections == 1


class UdpPtyBridge:
    """A flight controller's UART in miniature: simbridge's UDP datagrams go out on the master of a
    pseudo-terminal pair whose slave the companion opens as ``serial:``; what it writes goes back to
    simbridge. :meth:`pull` closes the pair (the cable pulled), :meth:`replug` makes the same device
    path again."""

    def __init__(self) -> None:
        self._udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._udp.bind(("127.0.0.1", 0))
        self._udp.settimeout(0.2)
        self.udp_port = int(self._udp.getsockname()[1])
        self._peers: set[tuple[str, int]] = set()  # simbridge, and trigger_alarm.py while it runs
        self._lock = threading.Lock()
        self._fds: tuple[int, int] | None = None
        self.path = self._open()
        self._stop = threading.Event()
        for target in (self._down, self._up):
            threading.Thread(target=target, daemon=True).start()

    def _open(self) -> str:
        master, slave = os.openpty()
        with self._lock:
            self._fds = (master, slave)
        return os.ttyname(slave)

    def _down(self) -> None:
        while not self._stop.is_set():
            try:
                data, peer = self._udp.recvfrom(65536)
            except (TimeoutError, OSError):
                continue
            self._peers.add(peer)
            with self._lock, suppress(OSError):
                if self._fds is not None:
                    os.write(self._fds[0], data)

    def _up(self) -> None:
        while not self._stop.is_set():
            with self._lock:
                master = self._fds[0] if self._fds is not None else None
            if master is None:
                time.sleep(0.02)
                continue
            ready, _, _ = select.select([master], [], [], 0.05)
            if not ready:
                continue
            with suppress(OSError):  # EIO while the companion has the slave closed
                data = os.read(master, 65536)
                for peer in list(self._peers):
                    self._udp.sendto(data, peer)

    def pull(self) -> None:
        with self._lock:
            fds, self._fds = self._fds, None
        if fds is not None:
            for fd in fds:
                os.close(fd)

    def replug(self) -> bool:
        """The same device path again (False: another process took it meanwhile)."""
        held: list[tuple[int, int]] = []
        try:
            for _ in range(64):
                master, slave = os.openpty()
                if os.ttyname(slave) == self.path:
                    with self._lock:
                        self._fds = (master, slave)
                    return True
                held.append((master, slave))
            return False
        finally:
            for fds in held:
                for fd in fds:
                    os.close(fd)

    def close(self) -> None:
        self._stop.set()
        self.pull()
        self._udp.close()


@pytest.mark.slow
@pytest.mark.timeout(420)
def test_companion_on_a_serial_line_lands_px4_emulation_through_the_line_pulled_mid_flight(
    start_rig: Callable[..., Rig],
) -> None:
    """The companion speaks ``serial:`` on a pseudo-terminal whose other end carries simbridge's PX4
    emulation. Mid-flight, descending toward scenario1's clear roof, the line is pulled for 2 s (PX4
    takes over when the setpoints stop) and plugged back on the same device: the companion reopens it,
    takes the vehicle back, and lands on the clear roof."""
    from tests.test_companion_e2e import _wait_touchdown

    bridge = UdpPtyBridge()
    try:
        rig = _alarm_through(start_rig, f"serial:{bridge.path}:921600", bridge.udp_port)
        rig.wait_log("descending", timeout_s=120)
        bridge.pull()
        time.sleep(2.0)
        if not bridge.replug():
            pytest.skip(f"another process took {bridge.path} before the test could make it again")
        td = _wait_touchdown(rig, timeout_s=300)
        log = rig.log_text()
        assert td["surface"] == "rooftop_clear", (td, log[-3000:])
        assert td["safe"] is True
        # the pull mattered: PX4 fell back when the setpoints stopped, and flew them again after. At 4x
        # a stall of a quarter second in this test's relay threads (a loaded CI machine) is a second
        # offboard loss; each such fallback must clear too, and none may be of another kind
        timeline = [e for e in rig.sim.events() if str(e.get("event", "")).startswith("failsafe")]
        why = f"{timeline}\n{log[-3000:]}"
        lost = [e["reason"] for e in rig.sim.events("failsafe")]
        assert lost, why
        assert set(lost) == {"offboard_loss"}, why
        assert [e["reason"] for e in rig.sim.events("failsafe_cleared")] == lost, why
        rig.companion.terminate()
        rig.companion.wait(timeout=30)
        log = rig.log_text()
        assert "link: 1 reconnects" in log, log[-3000:]
    finally:
        bridge.close()
