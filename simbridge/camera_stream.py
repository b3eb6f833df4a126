"""simbridge's camera as a video stream: ``simbridge --camera-stream udp://HOST:PORT``.

The camera is rendered at ``--camera-fps`` frames per simulated second from the vehicle's true pose and
sent as H.264 over RTP on UDP (payload type 96, 90 kHz clock), the way PX4's and ArduPilot's Gazebo
cameras send theirs to port 5600: x264 through PyAV (the ``sim`` extra), tuned for latency (no
B-frames, SPS/PPS repeated before every key frame so a receiver can join at any time, a key frame every
second of simulated time). ``--camera-info-out FILE`` writes the camera's calibration as a ROS
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


def parse_stream_url(text: str) -> tuple[str, int]:
    """``udp://HOST:PORT`` -> (host, port); ValueError naming the flag otherwise."""
    m = re.fullmatch(r"udp://([^:/\s]+):(\d{1,5})/?", text.strip())
    if m is None or not 1 <= int(m.group(2)) <= 65535:
        raise ValueError(f"--camera-stream: expected udp://HOST:PORT (H.264 over RTP), got {text!r}")
    return m.group(1), int(m.group(2))


class CameraStreamer:
    """An H.264 RTP sender for frames of one size."""

    def __init__(self, host: str, port: int, width: int, height: int, fps: float) -> None:
        try:
            import av
        except ImportError:
            raise ValueError("--camera-stream needs PyAV: pip install 'landfall[sim]'") from None
        self.url = f"rtp://{host}:{port}"
        self._out: Any = av.open(self.url, mode="w", format="rtp")
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
