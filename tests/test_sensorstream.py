"""The sensor stream over real loopback sockets: a fake capture stands in for the simulator's renderer."""

from __future__ import annotations

import asyncio
import contextlib
import json
import math
import socket
from collections.abc import AsyncIterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pytest

from landfall_link.sensorstream import (
    MAX_LINE_BYTES,
    SensorClient,
    SensorFrame,
    SensorStreamConnectionError,
    SensorStreamError,
    SensorStreamProtocolError,
    SensorStreamServer,
    SensorStreamServerError,
    SensorStreamTimeoutError,
)

HOST = "127.0.0.1"
WAIT_S = 5.0  # deadline for every wait in these tests; none of them should come near it
CAMERA: dict[str, Any] = {"fx": 40.0, "fy": 40.5, "cx": 40.0, "cy": 24.0, "width": 80, "height": 48}
INFO = {"simulator": "simbridge", "camera": {"width": 80, "height": 48, "hfov_deg": 90.0}}
POS_NED_M = (12.5, -3.25, -101.123456789012)
_Q = np.array([0.9, 0.1, -0.2, 0.3])
QUAT_WXYZ = tuple(float(v) for v in _Q / np.linalg.norm(_Q))


def smooth_image() -> np.ndarray:
    """A gradient image: exact for png/raw, and JPEG keeps it within a few levels."""
    y, x = np.mgrid[0:48, 0:80]
    return np.stack([x * 3, y * 5, np.full_like(x, 128)], axis=-1).astype(np.uint8)


def make_frame(t_s: float = 12.345678901234567, *, lidar: bool = True) -> SensorFrame:
    rng = np.random.default_rng(7)
    depth = rng.uniform(1.0, 150.0, (48, 80)).astype(np.float32)
    depth[:3, :5] = np.nan  # sky
    return SensorFrame(
        t_s=t_s,
        time_boot_ms=123_456_789,
        pos_ned_m=POS_NED_M,
        quat_wxyz=QUAT_WXYZ,  # type: ignore[arg-type]
        rangefinder_m=98.765432101,
        weather="fog",
        **CAMERA,
        image_rgb=smooth_image(),
        depth_m=depth,
        lidar_frd=rng.standard_normal((500, 4)).astype(np.float32) if lidar else None,
    )


@dataclass
class FakeSim:
    """A capture function with knobs: it records what was asked and can block, fail or rendezvous."""

    calls: list[set[str]] = field(default_factory=list)
    gate: asyncio.Event | None = None  # when set: captures wait for it
    block_first: bool = False  # the first capture waits forever, later ones answer
    fail_first: Exception | None = None
    barrier: asyncio.Barrier | None = None
    lidar: bool = True
    started: asyncio.Event = field(default_factory=asyncio.Event)  # set when a capture begins

    async def capture(self, want: set[str]) -> SensorFrame:
        self.calls.append(set(want))
        self.started.set()
        if self.barrier is not None:
            async with asyncio.timeout(WAIT_S):
                await self.barrier.wait()
        if self.gate is not None or (self.block_first and len(self.calls) == 1):
            await (self.gate or asyncio.Event()).wait()
        if self.fail_first is not None and len(self.calls) == 1:
            raise self.fail_first
        return make_frame(t_s=float(len(self.calls)), lidar=self.lidar)


@pytest.fixture
def sim() -> FakeSim:
    return FakeSim()


@pytest.fixture
async def server(sim: FakeSim) -> AsyncIterator[SensorStreamServer]:
    async with SensorStreamServer(HOST, 0, sim.capture, INFO) as srv:
        yield srv


@contextlib.asynccontextmanager
async def raw_connection(port: int) -> AsyncIterator[tuple[asyncio.StreamReader, asyncio.StreamWriter]]:
    async with asyncio.timeout(WAIT_S):
        reader, writer = await asyncio.open_connection(HOST, port)
    try:
        yield reader, writer
    finally:
        writer.close()
        async with asyncio.timeout(WAIT_S):
            await writer.wait_closed()


async def read_header(reader: asyncio.StreamReader) -> dict[str, Any]:
    async with asyncio.timeout(WAIT_S):
        header = json.loads(await reader.readuntil(b"\n"))
    assert isinstance(header, dict)
    return header


async def send(writer: asyncio.StreamWriter, data: bytes) -> None:
    writer.write(data)
    async with asyncio.timeout(WAIT_S):
        await writer.drain()


HELLO = b'{"v": 1, "op": "hello"}\n'


# ------------------------------------------------------------------------------------------ round trip
@pytest.mark.parametrize("encoding", ["png", "raw"])
async def test_sensorclient_frame_lossless_encodings_round_trip_exactly(
    server: SensorStreamServer, sim: FakeSim, encoding: str
) -> None:
    async with SensorClient(HOST, server.port, timeout_s=WAIT_S) as client:
        frame = await client.frame(want=("image", "lidar", "depth"), image_encoding=encoding)
    sent = make_frame(t_s=1.0)
    assert sim.calls == [{"image", "lidar", "depth"}]
    assert frame.image_rgb is not None
    assert frame.depth_m is not None
    assert frame.lidar_frd is not None
    np.testing.assert_array_equal(frame.image_rgb, sent.image_rgb)
    assert frame.image_rgb.dtype == np.uint8
    np.testing.assert_array_equal(frame.depth_m, sent.depth_m)  # NaN sky included
    assert frame.depth_m.dtype == np.float32
    np.testing.assert_array_equal(frame.lidar_frd, sent.lidar_frd)
    assert frame.lidar_frd.shape == (500, 4)
    assert frame.t_s == 1.0
    assert frame.time_boot_ms == 123_456_789
    assert frame.pos_ned_m == POS_NED_M
    assert frame.quat_wxyz == QUAT_WXYZ
    assert frame.rangefinder_m == 98.765432101
    assert {name: getattr(frame, name) for name in CAMERA} == CAMERA
    np.testing.assert_array_equal(frame.intrinsics(), [[40.0, 0.0, 40.0], [0.0, 40.5, 24.0], [0.0, 0.0, 1.0]])
    assert frame.weather == "fog"


async def test_sensorclient_frame_jpeg_image_close(server: SensorStreamServer) -> None:
    async with SensorClient(HOST, server.port, timeout_s=WAIT_S) as client:
        frame = await client.frame(want=("image",), image_encoding="jpeg", jpeg_quality=90)
    assert frame.image_rgb is not None
    assert frame.image_rgb.shape == (48, 80, 3)
    diff = np.abs(frame.image_rgb.astype(np.int16) - smooth_image().astype(np.int16))
    assert float(diff.mean()) < 3.0
    assert int(diff.max()) < 40
    assert frame.depth_m is None
    assert frame.lidar_frd is None


async def test_sensorclient_frame_only_requested_parts_sent(server: SensorStreamServer, sim: FakeSim) -> None:
    async with SensorClient(HOST, server.port, timeout_s=WAIT_S) as client:
        frame = await client.frame(want=("depth",))
        bare = await client.frame(want=())
    assert sim.calls == [{"depth"}, set()]
    assert frame.depth_m is not None
    assert frame.image_rgb is None
    assert frame.lidar_frd is None  # the capture rendered it, but it was not asked for
    assert (bare.image_rgb, bare.depth_m, bare.lidar_frd) == (None, None, None)
    assert bare.pos_ned_m == POS_NED_M


async def test_sensorclient_frame_failed_lidar_is_none(server: SensorStreamServer, sim: FakeSim) -> None:
    sim.lidar = False
    async with SensorClient(HOST, server.port, timeout_s=WAIT_S) as client:
        frame = await client.frame(want=("image", "lidar"))
    assert frame.image_rgb is not None
    assert frame.lidar_frd is None


async def test_sensorclient_frame_arrays_read_only(server: SensorStreamServer) -> None:
    async with SensorClient(HOST, server.port, timeout_s=WAIT_S) as client:
        frame = await client.frame(want=("image", "depth", "lidar"))
    for array in (frame.image_rgb, frame.depth_m, frame.lidar_frd):
        assert array is not None
        assert not array.flags.writeable


async def test_sensorclient_hello_reports_versions_and_info(server: SensorStreamServer) -> None:
    async with SensorClient(HOST, server.port, timeout_s=WAIT_S) as client:
        hello = await client.hello()
    assert hello.version == 1
    assert hello.supported_versions == (1,)
    assert hello.info == INFO


async def test_sensorclient_several_requests_keep_order(server: SensorStreamServer, sim: FakeSim) -> None:
    async with SensorClient(HOST, server.port, timeout_s=WAIT_S) as client:
        times = [(await client.frame(want=("lidar",))).t_s for _ in range(4)]
        hello = await client.hello()
    assert times == [1.0, 2.0, 3.0, 4.0]
    assert hello.version == 1
    assert len(sim.calls) == 4


async def test_sensorstream_pipelined_requests_on_one_connection(server: SensorStreamServer) -> None:
    frame_request = b'{"v": 1, "op": "frame", "want": ["lidar", "image"], "image_encoding": "raw"}\n'
    async with raw_connection(server.port) as (reader, writer):
        await send(writer, frame_request + HELLO + frame_request)
        for t_s in (1.0, None, 2.0):
            header = await read_header(reader)
            if t_s is None:
                assert header["op"] == "hello"
                continue
            assert header["t_s"] == t_s
            assert [p["name"] for p in header["parts"]] == ["image", "lidar"]  # wire order, not asked order
            assert header["parts"] == [
                {"name": "image", "encoding": "raw", "dtype": "uint8", "shape": [48, 80, 3], "nbytes": 11520},
                {"name": "lidar", "encoding": "raw", "dtype": "float32", "shape": [500, 4], "nbytes": 8000},
            ]
            async with asyncio.timeout(WAIT_S):
                image = await reader.readexactly(48 * 80 * 3)
                lidar = await reader.readexactly(500 * 16)
            assert image == smooth_image().tobytes()
            assert lidar == make_frame().lidar_frd.astype("<f4").tobytes()  # type: ignore[union-attr]


async def test_sensorstream_two_clients_served_concurrently(server: SensorStreamServer, sim: FakeSim) -> None:
    sim.barrier = asyncio.Barrier(2)  # each capture waits for the other: serial serving would time out
    async with (
        SensorClient(HOST, server.port, timeout_s=WAIT_S) as first,
        SensorClient(HOST, server.port, timeout_s=WAIT_S) as second,
    ):
        a, b = await asyncio.gather(first.frame(want=("image",)), second.frame(want=("depth",)))
    assert (a.image_rgb is not None, a.depth_m is None) == (True, True)
    assert (b.depth_m is not None, b.image_rgb is None) == (True, True)
    assert sorted(map(sorted, sim.calls)) == [["depth"], ["image"]]


# ------------------------------------------------------------------------------------------------ errors
@pytest.mark.parametrize(
    ("line", "code", "needle"),
    [
        (b"{not json\n", "bad_json", "not valid JSON"),
        (b"\n", "bad_json", "not valid JSON"),
        (b"\xff\xfe\n", "bad_json", "not valid JSON"),
        (b"[1, 2]\n", "bad_request", "JSON object"),
        (b'{"op": "hello"}\n', "bad_request", '"v"'),
        (b'{"v": 1, "op": "teleport"}\n', "unknown_op", "teleport"),
        (b'{"v": 1}\n', "unknown_op", "hello, frame"),
        (b'{"v": 2, "op": "hello"}\n', "unsupported_version", "supported versions: 1"),
        (b'{"v": "1", "op": "hello"}\n', "unsupported_version", "supported versions: 1"),
        (b'{"v": 1, "op": "frame"}\n', "bad_request", '"want"'),
        (b'{"v": 1, "op": "frame", "want": "image"}\n', "bad_request", '"want"'),
        (b'{"v": 1, "op": "frame", "want": ["radar"]}\n', "bad_request", "radar"),
        (b'{"v": 1, "op": "frame", "want": ["image", "image"]}\n', "bad_request", "twice"),
        (b'{"v": 1, "op": "frame", "want": ["image"], "image_encoding": "gif"}\n', "bad_request", "gif"),
        (b'{"v": 1, "op": "frame", "want": ["image"], "jpeg_quality": 0}\n', "bad_request", "1..100"),
    ],
)
async def test_sensorstream_bad_request_answered_then_serves(
    server: SensorStreamServer, sim: FakeSim, line: bytes, code: str, needle: str
) -> None:
    async with raw_connection(server.port) as (reader, writer):
        await send(writer, line)
        header = await read_header(reader)
        assert header["v"] == 1
        assert header["error"]["code"] == code
        assert needle in header["error"]["message"]
        assert set(header) == {"v", "error"}  # no body follows an error
        await send(writer, HELLO)
        assert (await read_header(reader))["op"] == "hello"
    assert sim.calls == []


async def test_sensorstream_unsupported_version_names_supported(server: SensorStreamServer) -> None:
    async with raw_connection(server.port) as (reader, writer):
        await send(writer, b'{"v": 7, "op": "frame", "want": []}\n')
        error = (await read_header(reader))["error"]
    assert error["code"] == "unsupported_version"
    assert error["supported"] == [1]


@pytest.mark.parametrize("excess", [1, 3 * MAX_LINE_BYTES])
async def test_sensorstream_oversize_line_refused_then_serves(
    server: SensorStreamServer, excess: int
) -> None:
    async with raw_connection(server.port) as (reader, writer):
        await send(writer, b'{"v": 1, "op": "hello", "pad": "' + b"x" * (MAX_LINE_BYTES + excess) + b'"}\n')
        header = await read_header(reader)
        assert header["error"]["code"] == "line_too_long"
        assert str(MAX_LINE_BYTES) in header["error"]["message"]
        await send(writer, HELLO)
        assert (await read_header(reader))["op"] == "hello"


async def test_sensorstream_line_at_limit_accepted(server: SensorStreamServer) -> None:
    line = b'{"v": 1, "op": "hello", "pad": "'
    line += b"x" * (MAX_LINE_BYTES - len(line) - 2) + b'"}'
    assert len(line) == MAX_LINE_BYTES
    async with raw_connection(server.port) as (reader, writer):
        await send(writer, line + b"\n")
        assert (await read_header(reader))["op"] == "hello"


async def test_sensorclient_server_error_keeps_connection(server: SensorStreamServer, sim: FakeSim) -> None:
    sim.fail_first = RuntimeError("renderer exploded")
    async with SensorClient(HOST, server.port, timeout_s=WAIT_S) as client:
        with pytest.raises(SensorStreamServerError) as caught:
            await client.frame(want=("image",))
        frame = await client.frame(want=("image",))
    assert caught.value.code == "capture_failed"
    assert "renderer exploded" in caught.value.message
    assert frame.t_s == 2.0


async def test_sensorclient_bad_want_reports_server_code(server: SensorStreamServer) -> None:
    async with SensorClient(HOST, server.port, timeout_s=WAIT_S) as client:
        with pytest.raises(SensorStreamServerError) as caught:
            await client.frame(want=("radar",))
        with pytest.raises(TypeError, match="collection of part names"):
            await client.frame(want="image")
        assert (await client.hello()).version == 1
    assert caught.value.code == "bad_request"
    assert "radar" in caught.value.message


async def test_sensorstream_capture_timeout_reported(sim: FakeSim) -> None:
    sim.gate = asyncio.Event()  # never set
    async with (
        SensorStreamServer(HOST, 0, sim.capture, INFO, capture_timeout_s=0.05) as server,
        SensorClient(HOST, server.port, timeout_s=WAIT_S) as client,
    ):
        with pytest.raises(SensorStreamServerError) as caught:
            await client.frame(want=("image",))
    assert caught.value.code == "capture_timeout"


async def test_sensorclient_timeout_when_capture_never_answers(
    server: SensorStreamServer, sim: FakeSim
) -> None:
    sim.gate = asyncio.Event()  # never set
    async with SensorClient(HOST, server.port, timeout_s=0.1) as client:
        with pytest.raises(SensorStreamTimeoutError) as caught:
            await client.frame(want=("image",))
    assert caught.value.operation == "frame"
    assert caught.value.timeout_s == 0.1
    assert caught.value.port == server.port
    assert isinstance(caught.value, TimeoutError)
    assert sim.calls == [{"image"}]


async def test_sensorclient_after_timeout_reconnects(server: SensorStreamServer, sim: FakeSim) -> None:
    sim.block_first = True
    async with SensorClient(HOST, server.port, timeout_s=0.2) as client:
        with pytest.raises(SensorStreamTimeoutError):
            await client.frame(want=("lidar",))
        frame = await client.frame(want=("lidar",))  # a fresh connection: no stale answer in the way
    assert frame.t_s == 2.0
    assert frame.lidar_frd is not None


async def test_sensorclient_stale_connection_retried_after_server_restart(sim: FakeSim) -> None:
    async with SensorStreamServer(HOST, 0, sim.capture, INFO) as first:
        port = first.port
        client = SensorClient(HOST, port, timeout_s=WAIT_S)
        await client.__aenter__()
    try:
        async with SensorStreamServer(HOST, port, sim.capture, INFO):
            frame = await client.frame(want=())
    finally:
        await client.__aexit__(None, None, None)
    assert frame.t_s == 1.0


async def test_sensorclient_connection_refused() -> None:
    with socket.socket() as probe:
        probe.bind((HOST, 0))
        port = probe.getsockname()[1]  # closed again before the client connects: nobody listens
    with pytest.raises(SensorStreamConnectionError) as caught:
        async with SensorClient(HOST, port, timeout_s=WAIT_S):
            pass
    assert caught.value.port == port


@dataclass
class Script:
    port: int = 0
    connections: int = 0


@contextlib.asynccontextmanager
async def scripted_server(*scripts: tuple[bytes | None, ...]) -> AsyncIterator[Script]:
    """A TCP peer: connection k answers its n-th line with ``scripts[k][n]`` (the last script repeats for
    later connections); None hangs up."""
    script = Script()

    async def handle(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        answers = scripts[min(script.connections, len(scripts) - 1)]
        script.connections += 1
        with contextlib.suppress(asyncio.IncompleteReadError, ConnectionError):
            async with asyncio.timeout(WAIT_S):
                for answer in answers:
                    await reader.readuntil(b"\n")
                    if answer is None:
                        break
                    writer.write(answer)
                    await writer.drain()
        writer.close()

    srv = await asyncio.start_server(handle, HOST, 0)
    async with srv:
        script.port = int(srv.sockets[0].getsockname()[1])
        yield script


async def test_sensorclient_connection_lost_raises() -> None:
    async with (
        scripted_server((None,)) as script,
        SensorClient(HOST, script.port, timeout_s=WAIT_S) as client,
    ):
        with pytest.raises(SensorStreamConnectionError, match="connection lost"):
            await client.hello()
    assert script.connections == 1  # a fresh connection that breaks is not retried


async def test_sensorclient_request_retried_once_when_server_hangs_up() -> None:
    hello = b'{"v": 1, "op": "hello", "supported_versions": [1], "info": {}}\n'
    async with (
        scripted_server((hello, None), (hello,)) as script,
        SensorClient(HOST, script.port, timeout_s=WAIT_S) as client,
    ):
        await client.hello()
        second = await client.hello()  # the peer hangs up on it; answered on a fresh connection
    assert second.version == 1
    assert script.connections == 2


async def test_sensorclient_retry_that_fails_again_raises() -> None:
    hello = b'{"v": 1, "op": "hello", "supported_versions": [1], "info": {}}\n'
    async with (
        scripted_server((hello, None), (None,)) as script,
        SensorClient(HOST, script.port, timeout_s=WAIT_S) as client,
    ):
        await client.hello()
        with pytest.raises(SensorStreamConnectionError, match="connection lost"):
            await client.hello()  # hung up on the retry as well: reported, not retried again
    assert script.connections == 2


@pytest.mark.parametrize(
    "answer",
    [
        b"hello there\n",
        b'{"v": 1, "op": "hello", "supported_versions": [1], "info": {}}\n',  # an answer to another op
        b'{"v": 2, "op": "hello"}\n',
        b'{"v": 1, "error": "nope"}\n',
        b'{"v": 1, "op": "frame", "parts": [{"name": "image", "encoding": "raw"}]}\n',
        b'{"v": 1, "op": "frame", "parts": [{"name": "lidar", "encoding": "raw", "dtype": "float32",'
        b' "shape": [2, 4], "nbytes": 31}]}\n',
    ],
)
async def test_sensorclient_protocol_violation_raises(answer: bytes) -> None:
    async with (
        scripted_server((answer,)) as script,
        SensorClient(HOST, script.port, timeout_s=WAIT_S) as client,
    ):
        with pytest.raises(SensorStreamProtocolError):
            await client.frame(want=("lidar",))


async def test_sensorclient_missing_body_raises_connection_error() -> None:
    header = json.dumps(
        {"v": 1, "op": "frame", "parts": [
            {"name": "lidar", "encoding": "raw", "dtype": "float32", "shape": [2, 4], "nbytes": 32}]}
    )  # fmt: skip
    async with (
        scripted_server((header.encode() + b"\n" + b"\0" * 10,)) as script,
        SensorClient(HOST, script.port, timeout_s=WAIT_S) as client,
    ):
        with pytest.raises(SensorStreamConnectionError, match="mid-response"):
            await client.frame(want=("lidar",))


async def test_sensorclient_outside_context_refused(server: SensorStreamServer) -> None:
    client = SensorClient(HOST, server.port)
    with pytest.raises(SensorStreamError, match="async with"):
        await client.hello()


async def test_sensorstream_idle_connection_closed() -> None:
    async with (
        SensorStreamServer(HOST, 0, FakeSim().capture, INFO, idle_timeout_s=0.05) as server,
        raw_connection(server.port) as (reader, _),
    ):
        async with asyncio.timeout(WAIT_S):
            assert await reader.read() == b""  # EOF: the server hung up


@pytest.mark.parametrize("mid_capture", [False, True])
async def test_sensorstream_shutdown_closes_clients_cleanly(sim: FakeSim, mid_capture: bool) -> None:
    sim.gate = asyncio.Event()  # never set: a capture in flight at shutdown must be cancelled
    loop = asyncio.get_running_loop()
    loop_errors: list[dict[str, Any]] = []
    loop.set_exception_handler(lambda _loop, context: loop_errors.append(context))
    try:
        server = SensorStreamServer(HOST, 0, sim.capture, INFO)
        await server.__aenter__()
        async with raw_connection(server.port) as (reader, writer):
            await send(writer, HELLO)
            await read_header(reader)  # the connection is being served
            if mid_capture:
                await send(writer, b'{"v": 1, "op": "frame", "want": ["image"]}\n')
                async with asyncio.timeout(WAIT_S):
                    await sim.started.wait()
            await server.__aexit__(None, None, None)
            async with asyncio.timeout(WAIT_S):
                assert await reader.read() == b""  # EOF, no half answer
    finally:
        loop.set_exception_handler(None)
    assert loop_errors == []
    assert sim.calls == ([{"image"}] if mid_capture else [])


async def test_sensorstream_server_port_known_only_inside_context() -> None:
    server = SensorStreamServer(HOST, 0, FakeSim().capture, INFO)
    with pytest.raises(SensorStreamError, match="async with"):
        _ = server.port


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"port": 70000}, "0..65535"),
        ({"info": {"bad": object()}}, "JSON-serialisable"),
        ({"info": {"pad": "x" * 40000}}, "at most"),
        ({"capture_timeout_s": 0.0}, "capture_timeout_s"),
        ({"idle_timeout_s": math.inf}, "idle_timeout_s"),
    ],
)
def test_sensorstreamserver_bad_arguments_rejected(kwargs: dict[str, Any], message: str) -> None:
    args: dict[str, Any] = {"host": HOST, "port": 0, "capture": FakeSim().capture, "info": INFO, **kwargs}
    with pytest.raises(ValueError, match=message):
        SensorStreamServer(**args)
