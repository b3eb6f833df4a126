"""The companion's video camera input: URLs, the mount rotation, a video file replayed through
the decoder thread, the autopilot's clock fitted from telemetry."""

from __future__ import annotations

import fractions
import socket
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from companion.camera import CameraError, CameraStream, mount_rotation, parse_camera_url
from companion.guidance.frames import CAMERA_TO_BODY
from landfall_link.boot_clock import BootClock
from landfall_link.camera_info import CameraInfo
from tests.conftest import free_udp_port


@pytest.mark.parametrize(
    ("url", "kind", "host", "port"),
    [("udp://:5600", "rtp", "0.0.0.0", 5600), ("udp://127.0.0.1:5601", "rtp", "127.0.0.1", 5601),
     ("rtsp://192.168.1.10:8554/main", "rtsp", "", 0), ("/dev/video2", "v4l2", "", 0),
     ("tcp://raspberrypi:8888", "tcp", "raspberrypi", 8888)],
)  # fmt: skip
def test_camera_urls_are_parsed(url: str, kind: str, host: str, port: int) -> None:
    spec = parse_camera_url(url)
    assert (spec.kind, spec.host, spec.port) == (kind, host, port)


@pytest.mark.parametrize(
    ("url", "says"),
    [("udp://:0", "expected udp://[HOST]:PORT"), ("udp://host", "expected udp://[HOST]:PORT"),
     ("http://cam/stream.mjpg", "unsupported scheme"), ("/no/such/video.mp4", "no such video file"),
     ("tcp://:8888", "expected tcp://HOST:PORT")],
)  # fmt: skip
def test_bad_camera_urls_are_refused_saying_why(url: str, says: str) -> None:
    with pytest.raises(CameraError, match=says.replace("[", r"\[").replace("]", r"\]")):
        parse_camera_url(url)


def test_the_mount_rotation_turns_a_rotated_view_back_to_the_nominal_one() -> None:
    """A camera mounted yawed 90 degrees right: a point ahead of the vehicle appears on its image's
    left; turned back, it sits toward the image top, where the nominal mount shows it."""
    r = mount_rotation(0.0, 0.0, 90.0)
    assert np.allclose(r @ r.T, np.eye(3))
    ahead_body = np.array([1.0, 0.0, 1.0])  # ahead and below
    yaw90 = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    raw_cam = (yaw90 @ CAMERA_TO_BODY).T @ ahead_body  # in the mounted camera's axes
    assert raw_cam[0] < 0  # left of its image centre
    nominal = r @ raw_cam
    assert np.allclose(nominal, CAMERA_TO_BODY.T @ ahead_body)  # the nominal camera's view
    assert nominal[1] < 0  # toward the image top
    assert np.allclose(mount_rotation(0.0, 0.0, 0.0), np.eye(3))


def _video(path: Path, frames: int, fps: int) -> None:
    import av

    with av.open(str(path), mode="w") as out:
        stream = out.add_stream("libx264", rate=fps)
        stream.width, stream.height, stream.pix_fmt = 64, 48, "yuv420p"
        stream.codec_context.time_base = fractions.Fraction(1, fps)
        for i in range(frames):
            rgb = np.zeros((48, 64, 3), np.uint8)
            rgb[:, : 8 * (i + 1)] = 200  # a bar growing to the right, one step a frame
            frame = av.VideoFrame.from_ndarray(rgb, format="rgb24")
            frame.pts = i
            for packet in stream.encode(frame):
                out.mux(packet)
        for packet in stream.encode():
            out.mux(packet)


def test_a_video_file_is_replayed_at_its_own_rate_and_undistorted(tmp_path: Path) -> None:
    pytest.importorskip("av", reason="the camera extra: pip install 'landfall[camera]'")
    path = tmp_path / "clip.mp4"
    _video(path, frames=8, fps=20)
    und = CameraInfo.pinhole(64, 48, 50.0, 50.0, 32.0, 24.0).undistorter()
    cam = CameraStream(parse_camera_url(str(path)), und)
    t0 = time.monotonic()
    cam.start()
    deadline = time.monotonic() + 20
    seen = []
    while time.monotonic() < deadline:
        f = cam.latest()
        if f is not None and (not seen or f.seq != seen[-1].seq):
            seen.append(f)
        if f is not None and f.seq == 8:
            break
        time.sleep(0.005)
    cam.close()
    assert seen[-1].seq == 8, [f.seq for f in seen]
    assert seen[-1].decoded_s - t0 >= 0.3  # 8 frames at 20 fps: 0.35 s of video, not all at once
    last = seen[-1]
    assert last.image_rgb.shape == (48, 64, 3)
    assert not last.image_rgb.flags.writeable
    assert last.pts_s == pytest.approx(7 / 20)
    assert int(last.image_rgb[24, 60].mean()) > 150  # the bar reached the right edge
    assert (cam.intrinsics.fx, cam.intrinsics.cx) == (50.0, 32.0)
    assert cam.errors == 0


def test_a_stream_that_cannot_be_opened_is_retried_and_its_error_kept(tmp_path: Path) -> None:
    pytest.importorskip("av", reason="the camera extra: pip install 'landfall[camera]'")
    path = tmp_path / "not-a-video.mp4"
    path.write_bytes(b"\x00" * 1000)
    cam = CameraStream(parse_camera_url(str(path)), CameraInfo.pinhole(64, 48, 50, 50, 32, 24).undistorter())
    cam.start()
    deadline = time.monotonic() + 10
    while cam.errors == 0 and time.monotonic() < deadline:
        time.sleep(0.01)
    cam.close()
    assert cam.latest() is None
    assert cam.errors >= 1
    assert cam.last_error


def test_the_boot_clock_follows_a_sped_up_autopilot_through_jittery_arrivals() -> None:
    """Arrivals 0-30 ms late (jitter), an autopilot clock running 4x this computer's (the simulator at
    --speed 4): the fitted clock is within the least delay of the truth, and a reboot starts it again."""
    clock = BootClock()
    assert clock.boot_at(1.0) is None
    rng = np.random.default_rng(0)
    for k in range(200):
        mono = 100.0 + 0.05 * k
        boot = 4.0 * (mono - 100.0) + 7.0
        clock.add(mono + rng.uniform(0.0, 0.03), boot)
    assert clock.rate == pytest.approx(4.0, rel=0.01)
    at = clock.boot_at(109.0)
    assert at is not None
    assert at == pytest.approx(4.0 * 9.0 + 7.0, abs=0.05)
    clock.add(111.0, 0.5)  # rebooted
    assert clock.boot_at(111.0) is None


def test_simbridge_refuses_a_bad_camera_stream_or_frame_rate() -> None:
    from simbridge.camera_stream import parse_stream_url
    from simbridge.sim import SimConfig

    assert parse_stream_url("udp://127.0.0.1:5600") == ("127.0.0.1", 5600, "rtp")
    assert parse_stream_url("raw+udp://10.0.0.2:5600") == ("10.0.0.2", 5600, "raw-udp")
    assert parse_stream_url("raw+tcp://0.0.0.0:8888") == ("0.0.0.0", 8888, "raw-tcp")
    for bad in ("udp://:5600", "rtp://127.0.0.1:5600", "udp://host:99999", "raw+tcp://:8888"):
        with pytest.raises(ValueError, match="--camera-stream: expected udp://HOST:PORT"):
            parse_stream_url(bad)
    with pytest.raises(ValueError, match="--camera-fps must be in"):
        SimConfig(camera_fps=0.0)


def test_a_camera_alone_runs_without_a_sensor_stream_and_nothing_at_all_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``--sensors none`` with a camera: no sensor-stream client (the image from the video, the distance
    from the autopilot's rangefinder); without a camera it is a configuration error saying what to give,
    as is a camera without its calibration file."""
    from companion.cli import build_companion, main
    from companion.config import load_config

    info = tmp_path / "camera.yaml"
    info.write_text(CameraInfo.pinhole(640, 480, 320.0, 320.0, 320.0, 240.0).to_ros_yaml())
    url = f"udp://127.0.0.1:{free_udp_port()}"
    cfg = load_config(None, {}, {"sensors.endpoint": "none", "camera.url": url, "camera.info": str(info)})
    companion = build_companion(cfg)
    assert companion._sensors is None  # nothing dials a sensor stream
    assert companion._camera is not None
    assert main(["--mavlink", "udp:14550", "--sensors", "none"]) == 2
    assert "needs a sensor stream (--sensors HOST:PORT) or a camera (--camera URL)" in capsys.readouterr().err
    assert main(["--mavlink", "udp:14550", "--camera", url]) == 2
    assert "a camera needs its calibration" in capsys.readouterr().err


def test_a_frame_decoded_late_is_dated_by_its_presentation_time() -> None:
    """The autopilot's clock runs 4 x the computer's (a sped-up simulator) and the stream's presentation
    clock with it. Frames reach the decoder 2.0-2.1 s of that clock after capture; one is decoded 18 s
    after (a decoder that fell behind on a busy computer). Dated by its presentation time and the
    fastest delay seen, it is 2.0 s after its capture (the hold and latency the caller takes off),
    not 18 s, and ``late_s`` says how much later it came."""
    from companion.camera import stream_capture_time

    def boot_at(monotonic_s: float) -> float:
        return 4.0 * monotonic_s + 100.0

    capture_offset = 50.0  # capture boot time = pts + 50 s
    delays = [2.0, 2.1, 2.05, 2.0, 18.0]
    arrivals = []
    for k, delay in enumerate(delays):
        pts = 2.0 * k
        decoded = (pts + capture_offset + delay - 100.0) / 4.0
        arrivals.append((pts, decoded))
    pts, decoded = arrivals[-1]
    dated = stream_capture_time(pts, decoded, arrivals[:-1], boot_at)
    assert dated is not None
    boot, late = dated
    assert boot == pytest.approx(pts + capture_offset + 2.0)
    assert late == pytest.approx(16.0)
    # the first frame of a stream: its own delay is the only one known
    first = stream_capture_time(*arrivals[0], [], boot_at)
    assert first == pytest.approx((capture_offset + 2.0, 0.0))
    assert stream_capture_time(pts, decoded, arrivals, lambda m: None) is None  # no autopilot clock yet


def _send_later(port: int, datagrams: list[bytes]) -> threading.Thread:
    def send() -> None:
        time.sleep(0.2)  # after the receiver bound the port
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as out:
            for d in datagrams:
                out.sendto(d, ("127.0.0.1", port))
                time.sleep(0.01)

    t = threading.Thread(target=send, daemon=True)
    t.start()
    return t


def _rtp(seq: int, ssrc: bytes = b"\x12\x34\x56\x78") -> bytes:
    return bytes([0x80, 96]) + seq.to_bytes(2, "big") + b"\x00\x00\x00\x00" + ssrc + b"\x5c\x81payload"


@pytest.mark.parametrize(
    ("datagrams", "framing"),
    [
        ([_rtp(65534), _rtp(65535), _rtp(0), _rtp(1)], "rtp"),  # the sequence wraps
        ([b"\x00\x00\x00\x01\x67" + bytes(40), bytes(40), bytes(40), bytes(40)], "raw"),
        # a raw stream cut where each datagram happens to start like an RTP header: not one source's
        ([bytes([0x80, 96, 0, k]) + bytes([k]) * 20 for k in range(4)], "raw"),
        ([_rtp(5), _rtp(9), _rtp(10), _rtp(11)], "raw"),  # not consecutive
    ],
    ids=["rtp", "annex-b", "lookalike", "gaps"],
)
def test_h264_on_udp_is_told_rtp_or_raw_by_its_first_datagrams(datagrams: list[bytes], framing: str) -> None:
    from companion.camera import _udp_framing

    port = free_udp_port()
    sender = _send_later(port, datagrams)
    assert _udp_framing("127.0.0.1", port) == framing
    sender.join()
