"""simbridge's camera as a video stream: ``simbridge --camera-stream URL``.

The camera is rendered at ``--camera-fps`` frames per simulated second from the vehicle's true pose and
sent as H.264 over RTP on UDP (payload type 96, 90 kHz clock), the way PX4's and ArduPilot's Gazebo
cameras send theirs to port 5600 (``udp://HOST:PORT``), or as raw H.264 the way a Raspberry Pi camera's
``rpicam-vid --inline`` sends it: datagrams of the byte stream to ``raw+udp://HOST:PORT`` (its ``-o
udp://``), or a TCP server on ``raw+tcp://HOST:PORT`` that the receiver connects to (its ``--listen -o
tcp://``; simbridge waits for it before the first frame). x264 through PyAV (the ``sim`` extra), tuned
for latency (no B-frames, SPS/PPS repeated before every key frame so a receiver can join at any time, a
key frame every second of simulated time). ``--camera-info-out FILE`` writes the camera's calibration as a ROS
``camera_info`` YAML for ``companion --camera-info``.

Each frame sent is in the episode log (``camera_frame``: its index, presentation time, the autopilot's
boot clock at the pose it was rendered from, that pose and the monotonic clock when it was sent), so a
harness can tell how far the companion's dating of a frame is from the truth.
"""

from __future__ import annotations

import fractions
import re
from typing import Any

import numpy as np

__all__ = ["CameraStreamer", "parse_stream_url"]

RTP_CLOCK_HZ = 90_000


FRAMINGS = {"udp": "rtp", "raw+udp": "raw-udp", "raw+tcp": "raw-tcp"}  # URL scheme -> framing


def parse_stream_url(text: str) -> tuple[str, int, str]:
    """``udp://HOST:PORT``, ``raw+udp://HOST:PORT`` or ``raw+tcp://HOST:PORT`` -> (host, port, framing:
    ``rtp``, ``raw-udp`` or ``raw-tcp``); ValueError naming the flag otherwise."""
    m = re.fullmatch(r"(udp|raw\+udp|raw\+tcp)://([^:/\s]+):(\d{1,5})/?", text.strip())
    if m is None or not 1 <= int(m.group(3)) <= 65535:
        raise ValueError(
            "--camera-stream: expected udp://HOST:PORT (H.264 over RTP), raw+udp://HOST:PORT or "
            f"raw+tcp://HOST:PORT (raw H.264), got {text!r}"
        )
    return m.group(2), int(m.group(3)), FRAMINGS[m.group(1)]


class CameraStreamer:
    """An H.264 sender for frames of one size, in RTP or raw (``framing``: :func:`parse_stream_url`'s)."""

    def __init__(
        self, host: str, port: int, width: int, height: int, fps: float, framing: str = "rtp"
    ) -> None:
        try:
            import av
        except ImportError:
            raise ValueError("--camera-stream needs PyAV: pip install 'landfall[sim]'") from None
        if framing == "rtp":
            self.url = f"rtp://{host}:{port}"
            self._out: Any = av.open(self.url, mode="w", format="rtp")
        elif framing == "raw-udp":
            self.url = f"udp://{host}:{port}?pkt_size=1316"
            self._out = av.open(self.url, mode="w", format="h264")
        elif framing == "raw-tcp":  # a server: blocks until the receiver connects
            self.url = f"tcp://{host}:{port}?listen=1"
            self._out = av.open(self.url, mode="w", format="h264")
        else:
            raise ValueError(f"unknown framing {framing!r}")
        stream = self._out.add_stream("libx264", rate=max(1, round(fps)))
        stream.width, stream.height, stream.pix_fmt = width, height, "yuv420p"
        keyint = max(1, round(fps))
        stream.options = {
            "preset": "ultrafast",
            "tune": "zerolatency",
            "x264-params": f"repeat-headers=1:keyint={keyint}:min-keyint={keyint}:bframes=0",
        }
        stream.codec_context.time_base = fractions.Fraction(1, RTP_CLOCK_HZ)
        self._stream = stream
        self.sent = 0

    def send(self, rgb: np.ndarray, pts_s: float) -> None:
        import av

        frame = av.VideoFrame.from_ndarray(np.ascontiguousarray(rgb), format="rgb24").reformat(
            format="yuv420p"
        )
        frame.pts = round(pts_s * RTP_CLOCK_HZ)
        frame.time_base = self._stream.codec_context.time_base
        for packet in self._stream.encode(frame):
            self._out.mux(packet)
        self.sent += 1

    def close(self) -> None:
        try:
            for packet in self._stream.encode():
                self._out.mux(packet)
        finally:
            self._out.close()
