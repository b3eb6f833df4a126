"""The sensor stream: synchronized camera, depth, LiDAR and rangefinder frames over local TCP.

simbridge serves frames on request (``--sensors HOST:PORT``); the companion asks for one when it needs
one. Protocol version 1 (``docs/sensor-stream.md``): the client sends one JSON request line, the server
answers one JSON header line and then the binary parts the header lists, in that order.

Frames and units, stated once: positions are NED metres from the scenario origin; attitude is a unit
quaternion (w, x, y, z) rotating body FRD vectors into NED; LiDAR points are body FRD metres plus an
intensity in [0, 1]; depth is z-depth along the camera's optical axis in metres (NaN where no surface);
images are RGB, row 0 at the image top (= vehicle forward), pixel centres at (u + 0.5, v + 0.5).

Exceptions::

    SensorStreamError
    ├── SensorFrameError (also ValueError)            a frame field with a wrong type, shape or value
    ├── EndpointError (also ValueError)               a HOST:PORT that cannot be used
    ├── SensorStreamTimeoutError (also TimeoutError)  a client call ran past its timeout_s
    ├── SensorStreamConnectionError                   cannot connect or listen, or the connection broke
    ├── SensorStreamProtocolError                     the peer sent what protocol version 1 does not allow
    └── SensorStreamServerError                       the server answered with an error (code, message)
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import math
from collections.abc import AsyncIterator, Awaitable, Callable, Iterable, Mapping
from dataclasses import dataclass
from enum import StrEnum
from numbers import Integral, Real
from types import TracebackType
from typing import Any, Self

import cv2
import numpy as np

PROTOCOL_VERSION = 1
SUPPORTED_VERSIONS: tuple[int, ...] = (1,)
MAX_LINE_BYTES = 65536  # any request or header line, not counting its "\n"
MAX_PART_BYTES = 256 * 1024 * 1024
MAX_INFO_BYTES = 32768  # the hello "info" object, serialised
DEFAULT_JPEG_QUALITY = 90
QUAT_NORM_TOLERANCE = 1e-3
_SHUTDOWN_TIMEOUT_S = 2.0
_log = logging.getLogger(__name__)

Capture = Callable[[set[str]], Awaitable["SensorFrame"]]
"""Renders one synchronized frame holding (at least) the named parts: "image", "depth", "lidar"."""


class Part(StrEnum):
    IMAGE = "image"
    DEPTH = "depth"
    LIDAR = "lidar"


PART_ORDER = (Part.IMAGE, Part.DEPTH, Part.LIDAR)  # the order of binary parts on the wire


class ImageEncoding(StrEnum):
    PNG = "png"
    JPEG = "jpeg"
    RAW = "raw"


class ErrorCode(StrEnum):
    BAD_JSON = "bad_json"
    BAD_REQUEST = "bad_request"
    UNKNOWN_OP = "unknown_op"
    UNSUPPORTED_VERSION = "unsupported_version"
    LINE_TOO_LONG = "line_too_long"
    CAPTURE_FAILED = "capture_failed"
    CAPTURE_TIMEOUT = "capture_timeout"


_WIRE_DTYPES: dict[str, np.dtype[Any]] = {
    "uint8": np.dtype("u1"),
    "float32": np.dtype("<f4"),
}  # multi-byte values little-endian


# ---------------------------------------------------------------------------------------------- errors
class SensorStreamError(Exception):
    """Base of every sensor-stream error."""


class SensorFrameError(SensorStreamError, ValueError):
    """A SensorFrame field with the wrong type, shape, dtype or value."""

    def __init__(self, field_name: str, expected: str, actual: str) -> None:
        super().__init__(f"{field_name}: expected {expected}, got {actual}")
        self.field_name = field_name
        self.expected = expected
        self.actual = actual


class EndpointError(SensorStreamError, ValueError):
    """A ``HOST:PORT`` text that cannot be used."""

    def __init__(self, text: str, reason: str) -> None:
        super().__init__(f"bad sensor endpoint {text!r}: {reason}; expected HOST:PORT, e.g. 127.0.0.1:5600")
        self.text = text
        self.reason = reason


class SensorStreamTimeoutError(SensorStreamError, TimeoutError):
    """A client call did not finish within the client's ``timeout_s``; the connection was dropped."""

    def __init__(self, operation: str, timeout_s: float, host: str, port: int) -> None:
        super().__init__(f"sensor stream {operation} to {host}:{port} timed out after {timeout_s} s")
        self.operation = operation
        self.timeout_s = timeout_s
        self.host = host
        self.port = port


class SensorStreamConnectionError(SensorStreamError):
    """Cannot connect (or listen), or the connection broke during a call."""

    def __init__(self, message: str, host: str, port: int) -> None:
        super().__init__(f"sensor stream {host}:{port}: {message}")
        self.host = host
        self.port = port


class SensorStreamProtocolError(SensorStreamError):
    """The peer sent something protocol version 1 does not allow; the connection was dropped."""


class SensorStreamServerError(SensorStreamError):
    """The server answered with an error header; the connection stays usable."""

    def __init__(self, code: str, message: str, details: Mapping[str, Any]) -> None:
        super().__init__(f"sensor server error {code}: {message}")
        self.code = code
        self.message = message
        self.details = details  # the whole "error" object, e.g. "supported" for unsupported_version


# ------------------------------------------------------------------------------------------------ data
def _real(name: str, value: object, minimum: float | None = None, exclusive: bool = False) -> float:
    bound = "" if minimum is None else f" {'>' if exclusive else '>='} {minimum}"
    if isinstance(value, bool) or not isinstance(value, Real):
        raise SensorFrameError(name, f"a finite number{bound}", f"{type(value).__name__} {value!r}")
    out = float(value)
    low = minimum is not None and (out <= minimum if exclusive else out < minimum)
    if not math.isfinite(out) or low:
        raise SensorFrameError(name, f"a finite number{bound}", repr(out))
    return out


def _integer(name: str, value: object, minimum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, Integral) or int(value) < minimum:
        raise SensorFrameError(name, f"an integer >= {minimum}", f"{type(value).__name__} {value!r}")
    return int(value)


def _vector(name: str, value: object, n: int) -> tuple[float, ...]:
    items = list(value) if isinstance(value, tuple | list | np.ndarray) else None
    if items is None or len(items) != n:
        raise SensorFrameError(name, f"{n} numbers", repr(value))
    return tuple(_real(f"{name}[{i}]", v) for i, v in enumerate(items))


def _array(name: str, value: object, dtype: str, shape: tuple[int | None, ...]) -> np.ndarray | None:
    if value is None:
        return None
    dims = ", ".join("N" if s is None else str(s) for s in shape)
    expected = f"a ({dims}) {dtype} array or None"
    if not isinstance(value, np.ndarray):
        raise SensorFrameError(name, expected, type(value).__name__)
    fits = value.ndim == len(shape) and all(
        s is None or s == a for s, a in zip(shape, value.shape, strict=False)
    )
    if value.dtype != np.dtype(dtype) or not fits:
        raise SensorFrameError(name, expected, f"a {tuple(value.shape)} {value.dtype} array")
    return value


@dataclass(frozen=True, slots=True, eq=False, kw_only=True)
class SensorFrame:
    """One synchronized capture: every field describes the same simulated instant (keyword-only).

    Attributes:
        t_s: simulated seconds since the episode started.
        time_boot_ms: the autopilot's boot clock at capture (as in MAVLink ``time_boot_ms``).
        pos_ned_m: vehicle position, NED metres from the scenario origin.
        quat_wxyz: attitude, unit quaternion (w, x, y, z), body FRD -> NED.
        rangefinder_m: downward rangefinder distance along body +z, metres.
        fx, fy, cx, cy: pinhole intrinsics of the camera in pixels (``simbridge.world.camera``).
        width, height: camera image size in pixels; ``image_rgb`` and ``depth_m`` must match it.
        weather: "clear", "fog" or "rain".
        image_rgb: (height, width, 3) uint8 RGB, or None when not asked for or not available.
        depth_m: (height, width) float32 z-depth, metres, NaN for sky; or None.
        lidar_frd: (N, 4) float32 rows of body FRD x, y, z (metres) and intensity (0..1); or None.

    Arrays are not copied; frames from ``SensorClient`` hold read-only arrays.
    """

    t_s: float
    time_boot_ms: int
    pos_ned_m: tuple[float, float, float]
    quat_wxyz: tuple[float, float, float, float]
    rangefinder_m: float
    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int
    weather: str
    image_rgb: np.ndarray | None = None
    depth_m: np.ndarray | None = None
    lidar_frd: np.ndarray | None = None

    def __post_init__(self) -> None:
        put = object.__setattr__
        put(self, "t_s", _real("t_s", self.t_s, 0.0))
        put(self, "time_boot_ms", _integer("time_boot_ms", self.time_boot_ms, 0))
        put(self, "pos_ned_m", _vector("pos_ned_m", self.pos_ned_m, 3))
        quat = _vector("quat_wxyz", self.quat_wxyz, 4)
        norm = math.sqrt(sum(v * v for v in quat))
        if abs(norm - 1.0) > QUAT_NORM_TOLERANCE:
            raise SensorFrameError(
                "quat_wxyz", f"a unit quaternion (norm 1 +- {QUAT_NORM_TOLERANCE})", f"norm {norm}"
            )
        put(self, "quat_wxyz", quat)
        put(self, "rangefinder_m", _real("rangefinder_m", self.rangefinder_m, 0.0))
        put(self, "fx", _real("fx", self.fx, 0.0, exclusive=True))
        put(self, "fy", _real("fy", self.fy, 0.0, exclusive=True))
        put(self, "cx", _real("cx", self.cx))
        put(self, "cy", _real("cy", self.cy))
        put(self, "width", _integer("width", self.width, 1))
        put(self, "height", _integer("height", self.height, 1))
        if not isinstance(self.weather, str) or not self.weather:
            raise SensorFrameError("weather", "a non-empty string", repr(self.weather))
        _array("image_rgb", self.image_rgb, "uint8", (self.height, self.width, 3))
        _array("depth_m", self.depth_m, "float32", (self.height, self.width))
        _array("lidar_frd", self.lidar_frd, "float32", (None, 4))

    def intrinsics(self) -> np.ndarray:
        """The 3x3 camera matrix K (pixels)."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def part(self, name: Part) -> np.ndarray | None:
        """The array of one binary part (None when absent)."""
        return {Part.IMAGE: self.image_rgb, Part.DEPTH: self.depth_m, Part.LIDAR: self.lidar_frd}[name]


@dataclass(frozen=True, slots=True)
class ServerHello:
    """The answer to "hello": what the server speaks and what it simulates."""

    version: int
    supported_versions: tuple[int, ...]
    info: Mapping[str, Any]  # e.g. {"simulator": "simbridge", "camera": {...}, "lidar": {...}}


def parse_endpoint(text: str) -> tuple[str, int]:
    """``"HOST:PORT"`` (IPv6 as ``"[::1]:PORT"``) -> (host, port); port 0 means any free port (servers)."""
    if not isinstance(text, str) or text != text.strip() or not text:
        raise EndpointError(str(text), "empty or surrounded by whitespace")
    host, sep, port_text = text.rpartition(":")
    if not sep:
        raise EndpointError(text, "no ':' before the port")
    if host.startswith("[") and host.endswith("]"):
        host = host[1:-1]
    elif ":" in host:
        raise EndpointError(text, "an IPv6 host must be written in brackets, e.g. [::1]:5600")
    if not host:
        raise EndpointError(text, "the host is empty")
    if not (port_text.isascii() and port_text.isdigit()) or not 0 <= int(port_text) <= 65535:
        raise EndpointError(text, f"port {port_text!r} is not an integer in 0..65535")
    return host, int(port_text)


# ----------------------------------------------------------------------------------------- wire codec
class _LineTooLongError(Exception):
    pass


def _dump_line(obj: Mapping[str, Any]) -> bytes:
    return json.dumps(obj, separators=(",", ":"), allow_nan=False).encode() + b"\n"


def _error(code: ErrorCode, message: str, **extra: Any) -> dict[str, Any]:
    return {"v": PROTOCOL_VERSION, "error": {"code": code.value, "message": message, **extra}}


async def _read_line(reader: asyncio.StreamReader) -> bytes | None:
    """One line without its "\\n"; None at a clean EOF. A line over the reader's limit is skipped whole
    and raises ``_LineTooLongError``, so the next line is read in step."""
    try:
        return (await reader.readuntil(b"\n"))[:-1]
    except asyncio.IncompleteReadError as exc:
        if exc.partial:
            _log.debug("peer closed in the middle of a line (%s bytes)", len(exc.partial))
        return None
    except asyncio.LimitOverrunError as exc:
        consumed = exc.consumed
    while True:
        await reader.readexactly(consumed)  # drop what was looked at without finding the newline
        try:
            await reader.readuntil(b"\n")
        except asyncio.LimitOverrunError as exc:
            consumed = exc.consumed
        else:
            raise _LineTooLongError


def _encode_frame(
    frame: SensorFrame, want: frozenset[Part], encoding: ImageEncoding, jpeg_quality: int
) -> tuple[dict[str, Any], list[bytes]]:
    """The response header and the binary parts for a frame (CPU-bound: runs in a worker thread)."""
    specs: list[dict[str, Any]] = []
    blobs: list[bytes] = []
    for name in PART_ORDER:
        array = frame.part(name)
        if name not in want or array is None:
            continue
        part_encoding = ImageEncoding.RAW
        if name is Part.IMAGE:
            part_encoding = encoding
            blob = _encode_image(array, encoding, jpeg_quality)
            dtype = "uint8"
        else:
            blob = np.ascontiguousarray(array, dtype=_WIRE_DTYPES["float32"]).tobytes()
            dtype = "float32"
        specs.append(
            {"name": name.value, "encoding": part_encoding.value, "dtype": dtype,
             "shape": list(array.shape), "nbytes": len(blob)}
        )  # fmt: skip
        blobs.append(blob)
    header = {
        "v": PROTOCOL_VERSION,
        "op": "frame",
        "t_s": frame.t_s,
        "time_boot_ms": frame.time_boot_ms,
        "pos_ned_m": list(frame.pos_ned_m),
        "quat_wxyz": list(frame.quat_wxyz),
        "rangefinder_m": frame.rangefinder_m,
        "weather": frame.weather,
        "camera": {"fx": frame.fx, "fy": frame.fy, "cx": frame.cx, "cy": frame.cy,
                   "width": frame.width, "height": frame.height},
        "parts": specs,
    }  # fmt: skip
    return header, blobs


def _encode_image(rgb: np.ndarray, encoding: ImageEncoding, jpeg_quality: int) -> bytes:
    if encoding is ImageEncoding.RAW:
        return np.ascontiguousarray(rgb).tobytes()
    bgr = cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)  # OpenCV codecs speak BGR
    if encoding is ImageEncoding.PNG:
        ok, buf = cv2.imencode(".png", bgr)
    else:
        ok, buf = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, jpeg_quality])
    if not ok:
        raise SensorStreamError(f"OpenCV could not encode a {rgb.shape} image as {encoding.value}")
    return buf.tobytes()


@dataclass(frozen=True, slots=True)
class _PartSpec:
    name: Part
    encoding: ImageEncoding
    dtype: np.dtype[Any]
    shape: tuple[int, ...]
    nbytes: int


def _part_specs(header: Mapping[str, Any]) -> list[_PartSpec]:
    raw = header.get("parts", [])
    if not isinstance(raw, list):
        raise SensorStreamProtocolError(f'header "parts" must be a list, got {raw!r}')
    specs: list[_PartSpec] = []
    for item in raw:
        try:
            name = Part(item["name"])
            encoding = ImageEncoding(item["encoding"])
            dtype = _WIRE_DTYPES[item["dtype"]]
            shape = tuple(item["shape"])
            nbytes = item["nbytes"]
            if not all(type(s) is int and s >= 0 for s in shape) or type(nbytes) is not int:
                raise TypeError("shape and nbytes must be non-negative integers")
        except (KeyError, TypeError, ValueError) as exc:
            raise SensorStreamProtocolError(f"bad part description {item!r}: {exc!r}") from exc
        if not 0 <= nbytes <= MAX_PART_BYTES or any(s.name is name for s in specs):
            raise SensorStreamProtocolError(f"part {item!r}: duplicate or over {MAX_PART_BYTES} bytes")
        if encoding is ImageEncoding.RAW and nbytes != math.prod(shape) * dtype.itemsize:
            raise SensorStreamProtocolError(f"raw part {item!r}: nbytes does not match shape and dtype")
        if encoding is not ImageEncoding.RAW and (name is not Part.IMAGE or len(shape) != 3):
            raise SensorStreamProtocolError(f"part {item!r}: only the image may be png/jpeg")
        specs.append(_PartSpec(name, encoding, dtype, shape, nbytes))
    return specs


def _decode_part(spec: _PartSpec, blob: bytes) -> np.ndarray:
    if spec.encoding is ImageEncoding.RAW:
        array = np.frombuffer(blob, dtype=spec.dtype).reshape(spec.shape)
        array = array.astype(spec.dtype.newbyteorder("="), copy=False)
    else:
        bgr = cv2.imdecode(np.frombuffer(blob, np.uint8), cv2.IMREAD_COLOR)
        if bgr is None:
            raise SensorStreamProtocolError(f"{spec.name} part is not a decodable {spec.encoding.value}")
        array = cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
        if array.shape != spec.shape:
            raise SensorStreamProtocolError(f"{spec.name} decoded to {array.shape}, header said {spec.shape}")
    array.flags.writeable = False
    return array


def _frame_from_wire(header: Mapping[str, Any], parts: list[tuple[_PartSpec, bytes]]) -> SensorFrame:
    """Decode a frame response (CPU-bound: runs in a worker thread)."""
    arrays = {spec.name: _decode_part(spec, blob) for spec, blob in parts}
    try:
        return SensorFrame(
            t_s=header["t_s"],
            time_boot_ms=header["time_boot_ms"],
            pos_ned_m=header["pos_ned_m"],
            quat_wxyz=header["quat_wxyz"],
            rangefinder_m=header["rangefinder_m"],
            **_camera_fields(header["camera"]),
            weather=header["weather"],
            image_rgb=arrays.get(Part.IMAGE),
            depth_m=arrays.get(Part.DEPTH),
            lidar_frd=arrays.get(Part.LIDAR),
        )
    except (KeyError, TypeError, ValueError) as exc:
        raise SensorStreamProtocolError(f"bad frame header: {exc!r}") from exc


def _camera_fields(camera: object) -> dict[str, Any]:
    names = ("fx", "fy", "cx", "cy", "width", "height")
    if not isinstance(camera, dict) or not set(names) <= set(camera):
        raise SensorStreamProtocolError(f'header "camera" must hold {", ".join(names)}; got {camera!r}')
    return {name: camera[name] for name in names}


class _BadRequestError(Exception):
    pass


def _parse_frame_request(request: Mapping[str, Any]) -> tuple[frozenset[Part], ImageEncoding, int]:
    want = request.get("want")
    names = {p.value for p in Part}
    if not isinstance(want, list) or not all(isinstance(w, str) and w in names for w in want):
        raise _BadRequestError(f'"want" must be a list of part names from {sorted(names)}, got {want!r}')
    if len(set(want)) != len(want):
        raise _BadRequestError(f'"want" names a part twice: {want!r}')
    encoding = request.get("image_encoding", ImageEncoding.PNG.value)
    if encoding not in {e.value for e in ImageEncoding}:
        raise _BadRequestError(f'"image_encoding" must be one of png, jpeg, raw; got {encoding!r}')
    quality = request.get("jpeg_quality", DEFAULT_JPEG_QUALITY)
    if type(quality) is not int or not 1 <= quality <= 100:
        raise _BadRequestError(f'"jpeg_quality" must be an integer in 1..100, got {quality!r}')
    return frozenset(Part(w) for w in want), ImageEncoding(encoding), quality


# --------------------------------------------------------------------------------------------- server
class SensorStreamServer:
    """Serves frames from ``capture`` to any number of local clients, one request at a time each.

    Use as ``async with SensorStreamServer(host, port, capture, info) as server:``; ``server.port`` is
    the bound port (useful with port 0). ``capture`` may run concurrently for several clients.
    Deadlines: a capture (plus encoding) over ``capture_timeout_s`` answers ``capture_timeout``; a client
    idle for ``idle_timeout_s`` (None: never) or not reading a response for ``send_timeout_s`` is
    disconnected. Leaving the context closes the listener and every connection.
    """

    def __init__(
        self,
        host: str,
        port: int,
        capture: Capture,
        info: Mapping[str, Any],
        *,
        capture_timeout_s: float = 10.0,
        idle_timeout_s: float | None = 600.0,
        send_timeout_s: float = 10.0,
        logger: logging.Logger | None = None,
    ) -> None:
        if isinstance(port, bool) or not isinstance(port, int) or not 0 <= port <= 65535:
            raise ValueError(f"port must be an integer in 0..65535, got {port!r}")
        try:
            info_size = len(json.dumps(dict(info), allow_nan=False))
        except (TypeError, ValueError) as exc:
            raise ValueError(f"info must be a JSON-serialisable mapping: {exc}") from exc
        if info_size > MAX_INFO_BYTES:
            raise ValueError(f"info serialises to {info_size} bytes; at most {MAX_INFO_BYTES} allowed")
        for name, value in (("capture_timeout_s", capture_timeout_s), ("send_timeout_s", send_timeout_s),
                            ("idle_timeout_s", idle_timeout_s)):  # fmt: skip
            if value is not None and not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a finite number > 0, got {value!r}")
        self._host = host
        self._requested_port = port
        self._capture = capture
        self._info = dict(info)
        self._capture_timeout_s = capture_timeout_s
        self._idle_timeout_s = idle_timeout_s
        self._send_timeout_s = send_timeout_s
        self._log = logger if logger is not None else _log
        self._server: asyncio.Server | None = None
        self._port: int | None = None
        self._connections: set[asyncio.Task[Any]] = set()

    @property
    def port(self) -> int:
        """The bound TCP port (the first socket's, when a host name binds several)."""
        if self._port is None:
            raise SensorStreamError("SensorStreamServer.port is known only inside 'async with'")
        return self._port

    async def __aenter__(self) -> Self:
        try:
            async with asyncio.timeout(_SHUTDOWN_TIMEOUT_S):
                self._server = await asyncio.start_server(
                    self._on_connect, self._host, self._requested_port, limit=MAX_LINE_BYTES
                )
        except (OSError, TimeoutError) as exc:
            raise SensorStreamConnectionError(
                f"cannot listen: {exc!r}", self._host, self._requested_port
            ) from exc
        self._port = int(self._server.sockets[0].getsockname()[1])
        self._log.info(
            "sensor stream serving on %s:%s (protocol v%s)", self._host, self._port, PROTOCOL_VERSION
        )
        return self

    async def __aexit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        server, self._server = self._server, None
        if server is None:
            return
        server.close()
        tasks = set(self._connections)
        for task in tasks:
            task.cancel()
        if tasks:
            _, pending = await asyncio.wait(tasks, timeout=_SHUTDOWN_TIMEOUT_S)
            if pending:
                self._log.warning("sensor stream: %s connections did not close in time", len(pending))
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(_SHUTDOWN_TIMEOUT_S):
                await server.wait_closed()
        self._port = None
        self._log.info("sensor stream on %s stopped", self._host)

    def _on_connect(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        # Our own task, not one asyncio.start_server makes from a coroutine: on Python 3.11 that one
        # reports its cancellation at shutdown as an error in a callback.
        peer = writer.get_extra_info("peername")
        task = asyncio.get_running_loop().create_task(
            self._serve_connection(reader, writer, peer), name=f"sensorstream-client-{peer}"
        )
        self._connections.add(task)
        task.add_done_callback(self._connections.discard)

    async def _serve_connection(
        self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter, peer: Any
    ) -> None:
        self._log.info("sensor client %s connected", peer)
        try:
            await self._serve_requests(reader, writer, peer)
        except (ConnectionError, asyncio.IncompleteReadError) as exc:
            self._log.info("sensor client %s: connection lost (%r)", peer, exc)
        except Exception:  # one broken connection must not stop the others
            self._log.exception("sensor client %s: unexpected error; closing the connection", peer)
        finally:
            writer.close()
            try:
                async with asyncio.timeout(_SHUTDOWN_TIMEOUT_S):
                    await writer.wait_closed()
            except TimeoutError:
                writer.transport.abort()
            except OSError:
                pass
            self._log.info("sensor client %s disconnected", peer)

    async def _serve_requests(
        self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter, peer: Any
    ) -> None:
        while True:
            header: dict[str, Any]
            blobs: list[bytes] = []
            try:
                async with asyncio.timeout(self._idle_timeout_s):
                    line = await _read_line(reader)
            except TimeoutError:
                self._log.info("sensor client %s idle for %s s; closing", peer, self._idle_timeout_s)
                return
            except _LineTooLongError:
                self._log.warning("sensor client %s sent a line over %s bytes", peer, MAX_LINE_BYTES)
                header = _error(ErrorCode.LINE_TOO_LONG, f"request line over {MAX_LINE_BYTES} bytes")
            else:
                if line is None:
                    return
                header, blobs = await self._respond(line, peer)
            try:
                async with asyncio.timeout(self._send_timeout_s):
                    writer.write(_dump_line(header))
                    writer.writelines(blobs)
                    await writer.drain()
            except TimeoutError:
                self._log.warning(
                    "sensor client %s not reading for %s s; closing", peer, self._send_timeout_s
                )
                return

    async def _respond(self, line: bytes, peer: Any) -> tuple[dict[str, Any], list[bytes]]:
        try:
            request = json.loads(line)
        except ValueError as exc:  # also UnicodeDecodeError
            return _error(ErrorCode.BAD_JSON, f"request is not valid JSON: {exc}"), []
        if not isinstance(request, dict):
            return _error(
                ErrorCode.BAD_REQUEST, f"request must be a JSON object, got {type(request).__name__}"
            ), []
        if "v" not in request:
            return _error(ErrorCode.BAD_REQUEST, 'request has no "v" (protocol version)'), []
        version = request["v"]
        if type(version) is not int or version not in SUPPORTED_VERSIONS:
            supported = ", ".join(str(v) for v in SUPPORTED_VERSIONS)
            message = f"protocol version {version!r} is not supported; supported versions: {supported}"
            return _error(ErrorCode.UNSUPPORTED_VERSION, message, supported=list(SUPPORTED_VERSIONS)), []
        op = request.get("op")
        if op == "hello":
            hello = {"v": PROTOCOL_VERSION, "op": "hello", "supported_versions": list(SUPPORTED_VERSIONS),
                     "max_line_bytes": MAX_LINE_BYTES, "info": self._info}  # fmt: skip
            return hello, []
        if op == "frame":
            return await self._frame(request, peer)
        return _error(ErrorCode.UNKNOWN_OP, f"unknown op {op!r}; expected one of: hello, frame"), []

    async def _frame(self, request: Mapping[str, Any], peer: Any) -> tuple[dict[str, Any], list[bytes]]:
        try:
            want, encoding, quality = _parse_frame_request(request)
        except _BadRequestError as exc:
            return _error(ErrorCode.BAD_REQUEST, str(exc)), []
        try:
            async with asyncio.timeout(self._capture_timeout_s):
                frame = await self._capture({p.value for p in want})
                if not isinstance(frame, SensorFrame):
                    raise TypeError(f"capture returned {type(frame).__name__}, expected SensorFrame")
                return await asyncio.to_thread(_encode_frame, frame, want, encoding, quality)
        except TimeoutError:
            self._log.warning("sensor client %s: capture over %s s", peer, self._capture_timeout_s)
            return _error(ErrorCode.CAPTURE_TIMEOUT, f"no frame within {self._capture_timeout_s} s"), []
        except Exception as exc:  # the simulator's failure is reported to the client, not fatal
            self._log.warning("sensor client %s: capture failed", peer, exc_info=True)
            return _error(ErrorCode.CAPTURE_FAILED, f"capture failed: {type(exc).__name__}: {exc}"), []


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
