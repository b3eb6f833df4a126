"""A video camera as the companion's eyes: ``companion --camera URL`` (configuration ``[camera]``).

What a real vehicle's camera sends, decoded by FFmpeg through PyAV (the ``camera`` extra) or, for a
V4L2 device, by OpenCV:

- ``udp://[HOST]:PORT``: H.264 on UDP, either in RTP (payload type 96), what PX4's and ArduPilot's
  Gazebo cameras, many gimbal cameras and QGroundControl use (port 5600 by convention), or raw (an
  Annex B byte stream cut into datagrams, what ``rpicam-vid --inline -o udp://HOST:PORT`` sends from a
  Raspberry Pi camera); ``HOST`` is the address to listen on, any when left out. Which one is told
  from the first datagrams each time the stream is opened (RTP: version 2 headers of one source with
  consecutive sequence numbers). FFmpeg reads RTP through a session description, written for the port.
- ``tcp://HOST:PORT``: raw H.264 from a TCP server (``rpicam-vid --inline --listen -o
  tcp://0.0.0.0:PORT``).
- ``rtsp://...``: an IP camera or gimbal (RTP over TCP, the most robust over a radio link).
- ``/dev/videoN``: a V4L2 device on the onboard computer.
- any other path: a video file, replayed at its own frame rate (for tests and replays).

Raw H.264 carries no presentation times: its frames are dated by when they were decoded, and the
decoder's one-frame hold is the median step between decodes.

A thread decodes; the newest frame is kept with the moment it was decoded (this computer's monotonic
clock). The daemon maps that moment to the autopilot's boot clock (``landfall_link.boot_clock.BootClock``)
and subtracts the camera's latency (``camera.latency_ms``) and the decoder's one-frame hold
(:attr:`CameraStream.decode_delay_s`) to get the capture time, then takes the autopilot's pose at that
time, as for the sensor stream. A stream that stops or cannot be opened is
logged and opened again every second; frames then grow old and are refused by age, as sensor frames are.

Lens distortion and the camera's mounting come from a calibration file (``camera.info``:
:mod:`landfall_link.camera_info`) and the configuration; each frame is undistorted and turned to the
nominal nadir view (image top toward the nose) in one remap before anything reads it.
"""

from __future__ import annotations

import collections
import contextlib
import itertools
import logging
import re
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "CameraError", "CameraSpec", "CameraStream", "VideoFrame", "mount_rotation", "parse_camera_url",
    "stream_capture_time",
]  # fmt: skip

REOPEN_S = 1.0
# A live stream, decoded for the newest frame: no input buffering, and a start without seconds of probing.
# FFmpeg's H.264 parser still holds each frame until the next one starts (it finds the end of an access
# unit there): one frame period, which the daemon takes off the frame's time (``decode_delay_s``). Without
# the parser a frame of several slices comes out in pieces (tried: grey-green frames read as vegetation).
LIVE_OPTIONS = {"fflags": "nobuffer", "flags": "low_delay", "analyzeduration": "0", "probesize": "32"}
READ_TIMEOUT_S = 5.0
DECODER_SWITCH_INTERVAL_S = 0.001  # the interpreter's thread switch interval with a camera (start())
PTS_STEPS_KEPT = 10  # the frame interval is the median of the last steps of the presentation times
ARRIVALS_KEPT = 120  # frames whose decode delays date the next ones (a minute at 2 frames a second)
RTP_PAYLOAD_TYPE = 96


class CameraError(ValueError):
    """A camera URL or set-up that cannot be used (at start)."""


@dataclass(frozen=True, slots=True)
class CameraSpec:
    """A parsed ``--camera`` URL. ``kind``: ``rtp`` (``udp://``: RTP or raw H.264, told when opened),
    ``tcp`` (raw H.264), ``rtsp``, ``v4l2`` or ``file``."""

    kind: str
    url: str
    host: str = ""
    port: int = 0


def parse_camera_url(text: str) -> CameraSpec:
    """``udp://[HOST]:PORT``, ``tcp://HOST:PORT``, ``rtsp://...``, ``/dev/videoN`` or a video file; a
    clear error otherwise."""
    text = text.strip()
    if text.startswith("udp://"):
        m = re.fullmatch(r"udp://(?:\[?([^\]/@]*?)\]?)?:(\d{1,5})/?", text)
        if m is None or not 1 <= int(m.group(2)) <= 65535:
            raise CameraError(
                f"camera {text!r}: expected udp://[HOST]:PORT (H.264, RTP or raw), e.g. udp://:5600"
            )
        return CameraSpec("rtp", text, m.group(1) or "0.0.0.0", int(m.group(2)))
    if text.startswith("tcp://"):
        m = re.fullmatch(r"tcp://([^:/\s]+):(\d{1,5})/?", text)
        if m is None or not 1 <= int(m.group(2)) <= 65535:
            raise CameraError(
                f"camera {text!r}: expected tcp://HOST:PORT (raw H.264), e.g. tcp://raspberrypi:8888"
            )
        return CameraSpec("tcp", text, m.group(1), int(m.group(2)))
    if text.startswith(("rtsp://", "rtsps://")):
        if len(text.split("://", 1)[1]) < 1:
            raise CameraError(f"camera {text!r}: expected rtsp://HOST[:PORT]/PATH")
        return CameraSpec("rtsp", text)
    if re.fullmatch(r"/dev/video\d+", text):
        return CameraSpec("v4l2", text)
    if "://" in text:
        raise CameraError(
            f"camera {text!r}: unsupported scheme; use udp://[HOST]:PORT (H.264, RTP or raw), "
            "tcp://HOST:PORT (raw H.264), rtsp://..., /dev/videoN or a video file"
        )
    if not Path(text).is_file():
        raise CameraError(f"camera {text!r}: no such video file (or use udp://, rtsp:// or /dev/videoN)")
    return CameraSpec("file", text)


def mount_rotation(roll_deg: float, pitch_deg: float, yaw_deg: float) -> np.ndarray:
    """The rotation (3, 3) that turns a raw image into the nominal nadir view, for a camera mounted turned
    by roll, pitch and yaw (ZYX, about the body's axes) from the nominal mount (looking down the body's
    +z axis, image top toward the nose): ``cv2.initUndistortRectifyMap``'s ``R``."""
    from companion.guidance.frames import CAMERA_TO_BODY
    from landfall_link.lidar_bridge import body_rotation

    turned = body_rotation(roll_deg, pitch_deg, yaw_deg)  # the mounted camera's axes from the nominal ones
    out: np.ndarray = CAMERA_TO_BODY.T @ turned @ CAMERA_TO_BODY
    return out


def stream_capture_time(
    pts_s: float,
    decoded_s: float,
    arrivals: list[tuple[float, float]],
    boot_at: Callable[[float], float | None],
) -> tuple[float, float] | None:
    """A live frame's decode moment on the autopilot's clock as it would have been with the least delay
    seen, and how much later it really was decoded: ``(boot_s, late_s)``; None while the autopilot's
    clock is not known.

    A frame is decoded some time after its capture: the camera's own latency, the network, the parser's
    one-frame hold, and whatever else keeps the decoder back (on a busy computer: with three busy
    threads in the process, decoding fell 1-2 s behind at Python's default thread switch interval, and
    a frame dated by its decode moment is dated that much late). The stream's presentation times are the
    capture clock: a frame is dated by its own presentation time plus the offset of the frame decoded
    soonest after its capture among the recent ``arrivals`` of the same opening of the stream (whose
    presentation times count from its first packet): the lower envelope of the delay, as the autopilot's
    clock is fitted (:class:`landfall_link.boot_clock.BootClock`), both clocks running at real time (or
    both at the simulator's). The caller still takes the camera's latency and the parser's hold off."""
    now = boot_at(decoded_s)
    if now is None:
        return None
    offsets = [b - p for p, d in (*arrivals, (pts_s, decoded_s)) if (b := boot_at(d)) is not None]
    boot = pts_s + min(offsets)
    return boot, now - boot


@dataclass(frozen=True, slots=True)
class VideoFrame:
    """One decoded, undistorted frame.

    Attributes:
        image_rgb: (H, W, 3) uint8, the nominal nadir view.
        decoded_s: this computer's monotonic clock when it was decoded.
        seq: frames decoded since start (1 = the first).
        pts_s: the stream's presentation time of the frame (the sender's clock, for the record), or None.
    """

    image_rgb: np.ndarray
    decoded_s: float
    seq: int
    pts_s: float | None


def _sdp(host: str, port: int) -> str:
    """A session description for H.264 in RTP on ``port``, as FFmpeg needs to read raw RTP."""
    addr = "0.0.0.0" if host in ("", "0.0.0.0") else host
    return (
        "v=0\n"
        f"o=- 0 0 IN IP4 {addr}\n"
        "s=Landfall camera\n"
        f"c=IN IP4 {addr}\n"
        "t=0 0\n"
        f"m=video {port} RTP/AVP {RTP_PAYLOAD_TYPE}\n"
        f"a=rtpmap:{RTP_PAYLOAD_TYPE} H264/90000\n"
        f"a=fmtp:{RTP_PAYLOAD_TYPE} packetization-mode=1\n"
    )


def _udp_framing(host: str, port: int, datagrams: int = 4) -> str:
    """``rtp`` or ``raw``: what the H.264 arriving on ``port`` is framed in, from its first
    ``datagrams`` (fewer when no more come within a second after the first). RTP: every one a version 2
    header (the first two bits 10) of one source (SSRC) with consecutive sequence numbers; a raw stream's
    datagrams are cut anywhere in the byte stream, so one alone could look like a header by chance.

    Raises:
        TimeoutError: nothing arrived within ``READ_TIMEOUT_S``."""
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind((host or "0.0.0.0", port))
        sock.settimeout(READ_TIMEOUT_S)
        got = [sock.recv(65536)]
        sock.settimeout(1.0)
        with contextlib.suppress(TimeoutError):
            while len(got) < datagrams:
                got.append(sock.recv(65536))
    if any(len(d) < 12 or d[0] >> 6 != 2 for d in got):
        return "raw"
    if len({d[8:12] for d in got}) != 1:
        return "raw"
    seqs = [int.from_bytes(d[2:4], "big") for d in got]
    return "rtp" if all((b - a) % 65536 == 1 for a, b in itertools.pairwise(seqs)) else "raw"


class CameraStream:
    """Decodes ``spec`` in a thread and keeps the newest frame (:meth:`latest`)."""

    def __init__(self, spec: CameraSpec, undistort: Any, log: logging.Logger | None = None) -> None:
        """``undistort``: a :class:`landfall_link.camera_info.Undistorter`; its intrinsics are the frames'."""
        if spec.kind != "v4l2":
            try:
                import av  # noqa: F401
            except ImportError:
                raise CameraError(
                    f"camera {spec.url}: decoding video needs PyAV: pip install 'landfall[camera]'"
                ) from None
        self.spec = spec
        self._undistort = undistort
        self.intrinsics = undistort  # fx, fy, cx, cy, width, height of every frame handed out
        self.log = log or logging.getLogger("companion.camera")
        self._latest: VideoFrame | None = None
        self._lock = threading.Lock()
        self._closed = threading.Event()
        self._thread: threading.Thread | None = None
        self.frames = 0
        self._arrivals: collections.deque[tuple[float, float]] = collections.deque(maxlen=ARRIVALS_KEPT)
        self.errors = 0
        self.last_error: str | None = None
        self._tmp: tempfile.TemporaryDirectory[str] | None = None
        self.raw = (
            spec.kind == "tcp"
        )  # raw H.264 (no presentation times); a udp:// stream's is told when opened
        self._decodes: collections.deque[float] = collections.deque(maxlen=PTS_STEPS_KEPT + 1)

    def start(self) -> None:
        # The decoder thread takes the interpreter lock many times a frame (every packet read, the
        # conversion, the remap); at Python's default switch interval (5 ms), three busy threads beside
        # it held it back 1-2 s (simbridge's stream, 2 frames a second); at 1 ms it kept to 0.5 s, the
        # parser's one-frame hold. The interval is the process's: a shorter one costs a few more switches.
        if sys.getswitchinterval() > DECODER_SWITCH_INTERVAL_S:
            sys.setswitchinterval(DECODER_SWITCH_INTERVAL_S)
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name="camera", daemon=True)
            self._thread.start()

    def close(self) -> None:
        self._closed.set()
        if self._thread is not None:
            self._thread.join(READ_TIMEOUT_S + 1.0)
        if self._tmp is not None:
            self._tmp.cleanup()

    def latest(self) -> VideoFrame | None:
        with self._lock:
            return self._latest

    @property
    def decode_delay_s(self) -> float | None:
        """How long before its decoding a live frame was whole, on the stream's clock: one frame interval
        (the median step of the presentation times), which the H.264 parser holds each frame for; None
        until two frames with presentation times have come; 0 for a file (replayed by its own times)
        and a V4L2 device."""
        if self.spec.kind not in ("rtp", "rtsp", "tcp"):
            return 0.0
        with self._lock:
            if self.raw:  # no presentation times: the steps between decodes
                recent = list(self._decodes)
            else:
                recent = [p for p, _d in list(self._arrivals)[-PTS_STEPS_KEPT - 1 :]]
        steps = sorted(b - a for a, b in itertools.pairwise(recent) if 0 < b - a < 5)
        return steps[len(steps) // 2] if steps else None

    def arrivals(self) -> list[tuple[float, float]]:
        """(presentation time, monotonic moment decoded) of the last ``ARRIVALS_KEPT`` frames that had a
        presentation time: what :func:`stream_capture_time` dates a frame by."""
        with self._lock:
            return list(self._arrivals)

    def _publish(self, rgb: np.ndarray, pts_s: float | None, decoded_s: float) -> None:
        image = self._undistort(rgb)
        image.flags.writeable = False
        with self._lock:
            self.frames += 1
            if pts_s is not None:
                self._arrivals.append((pts_s, decoded_s))
            self._decodes.append(decoded_s)
            self._latest = VideoFrame(image, decoded_s, self.frames, pts_s)
        if self.frames == 1:
            self.log.info("camera: first frame from %s (%d x %d)", self.spec.url, rgb.shape[1], rgb.shape[0])

    def _run(self) -> None:
        failing = False
        while not self._closed.is_set():
            try:
                if self.spec.kind == "v4l2":
                    self._read_v4l2()
                else:
                    self._read_av()
                if self.spec.kind == "file":
                    self.log.info("camera: end of %s after %d frames", self.spec.url, self.frames)
                    return
            except Exception as exc:  # a decoder or network error: say it once, open the stream again
                self.errors += 1
                self.last_error = f"{type(exc).__name__}: {exc}"
                if not failing:
                    self.log.warning(
                        "camera %s: %s; opening it again every %g s", self.spec.url, exc, REOPEN_S
                    )
                failing = True
            else:
                failing = False
            self._closed.wait(REOPEN_S)

    def _open_av(self) -> Any:
        import av

        live, wait = {**LIVE_OPTIONS}, (READ_TIMEOUT_S, READ_TIMEOUT_S)
        if self.spec.kind == "tcp":
            return av.open(self.spec.url, format="h264", options=live, timeout=wait)
        if self.spec.kind == "rtp":
            self.raw = _udp_framing(self.spec.host, self.spec.port) == "raw"
            self.log.info("camera %s: %s", self.spec.url, "raw H.264" if self.raw else "H.264 over RTP")
            if self.raw:
                url = f"udp://{self.spec.host}:{self.spec.port}?overrun_nonfatal=1"
                return av.open(url, format="h264", options=live, timeout=wait)
            if self._tmp is None:
                self._tmp = tempfile.TemporaryDirectory(prefix="landfall-camera-")
            sdp = Path(self._tmp.name) / "camera.sdp"
            sdp.write_text(_sdp(self.spec.host, self.spec.port))
            options = {"protocol_whitelist": "file,udp,rtp", "reorder_queue_size": "0", **LIVE_OPTIONS}
            return av.open(str(sdp), format="sdp", options=options, timeout=(READ_TIMEOUT_S, READ_TIMEOUT_S))
        if self.spec.kind == "rtsp":
            options = {"rtsp_transport": "tcp", **LIVE_OPTIONS}
            return av.open(self.spec.url, options=options, timeout=(READ_TIMEOUT_S, READ_TIMEOUT_S))
        return av.open(self.spec.url)

    def _read_av(self) -> None:
        import av

        container = self._open_av()
        with self._lock:  # a stream opened again counts its presentation times from a new first packet
            self._arrivals.clear()
            self._decodes.clear()
        try:
            stream = container.streams.video[0]
            if self.spec.kind in ("rtp", "rtsp", "tcp"):
                # frame threads hold each frame back by one more per thread (seen: three frames late):
                # slices only, and the decoder's low-delay mode
                stream.thread_type = "SLICE"
                stream.codec_context.flags = int(stream.codec_context.flags) | int(
                    av.codec.context.Flags.low_delay
                )
            else:
                stream.thread_type = "AUTO"
            t0: float | None = None
            for frame in container.decode(stream):
                decoded_s = time.monotonic()  # before the colour conversion and the undistortion
                if self._closed.is_set():
                    return
                pts_s = (
                    float(frame.pts * frame.time_base)
                    if frame.pts is not None and frame.time_base and not self.raw  # raw: the demuxer's guess
                    else None
                )
                if self.spec.kind == "file" and pts_s is not None:  # replay at the file's own rate
                    t0 = time.monotonic() - pts_s if t0 is None else t0
                    self._closed.wait(max(0.0, t0 + pts_s - time.monotonic()))
                    decoded_s = time.monotonic()
                self._publish(frame.to_ndarray(format="rgb24"), pts_s, decoded_s)
        finally:
            with contextlib.suppress(Exception):
                container.close()

    def _read_v4l2(self) -> None:
        import cv2

        cap = cv2.VideoCapture(self.spec.url, cv2.CAP_V4L2)
        try:
            if not cap.isOpened():
                raise OSError(f"cannot open {self.spec.url} as a V4L2 camera")
            while not self._closed.is_set():
                ok, bgr = cap.read()
                if not ok:
                    raise OSError(f"{self.spec.url} stopped giving frames")
                decoded_s = time.monotonic()
                self._publish(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), None, decoded_s)
        finally:
            cap.release()
