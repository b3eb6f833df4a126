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

The package: :mod:`~landfall_link.sensorstream.wire` (the format), :mod:`~landfall_link.sensorstream.server`
and :mod:`~landfall_link.sensorstream.client`.
"""

from landfall_link.sensorstream.client import SensorClient
from landfall_link.sensorstream.server import SensorStreamServer
from landfall_link.sensorstream.wire import (
    DEFAULT_JPEG_QUALITY,
    MAX_INFO_BYTES,
    MAX_LINE_BYTES,
    MAX_PART_BYTES,
    PART_ORDER,
    PROTOCOL_VERSION,
    QUAT_NORM_TOLERANCE,
    SUPPORTED_VERSIONS,
    Capture,
    EndpointError,
    ErrorCode,
    ImageEncoding,
    Part,
    SensorFrame,
    SensorFrameError,
    SensorStreamConnectionError,
    SensorStreamError,
    SensorStreamProtocolError,
    SensorStreamServerError,
    SensorStreamTimeoutError,
    ServerHello,
    parse_endpoint,
)

__all__ = [
    "DEFAULT_JPEG_QUALITY",
    "MAX_INFO_BYTES",
    "MAX_LINE_BYTES",
    "MAX_PART_BYTES",
    "PART_ORDER",
    "PROTOCOL_VERSION",
    "QUAT_NORM_TOLERANCE",
    "SUPPORTED_VERSIONS",
    "Capture",
    "EndpointError",
    "ErrorCode",
    "ImageEncoding",
    "Part",
    "SensorClient",
    "SensorFrame",
    "SensorFrameError",
    "SensorStreamConnectionError",
    "SensorStreamError",
    "SensorStreamProtocolError",
    "SensorStreamServer",
    "SensorStreamServerError",
    "SensorStreamTimeoutError",
    "ServerHello",
    "parse_endpoint",
]
