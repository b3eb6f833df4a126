"""The sensor stream's wire format (protocol version 1, docs/sensor-stream.md): its constants, errors,
the frame and its validation, endpoints, and the encoding and decoding of a frame's header and parts."""

from __future__ import annotations

import asyncio
import json
import logging
import math
from collections.abc import Awaitable, Callable, Mapping
from dataclasses import dataclass
from enum import StrEnum
from numbers import Integral, Real
from typing import Any

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
        super().__init__(f"bad sensor endpoint {text!r}: {reason}; expected HOST:PORT, e.g. 127.0.0.1:5601")
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
        raise EndpointError(text, "an IPv6 host must be written in brackets, e.g. [::1]:5601")
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
