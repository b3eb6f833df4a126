"""The real camera path end to end: simbridge sends its camera as H.264 over RTP, as a Gazebo
camera does; the companion reads it from the video stream with the calibration file simbridge wrote,
dates each frame on the autopilot's clock, and takes only the LiDAR from the sensor socket."""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from landfall_eval.episode_grade import match_video_frames
from tests.conftest import Rig, free_udp_port
from tests.test_companion_e2e import _events
from tests.test_sitl import _wait_event

pytestmark = pytest.mark.slow
pytest.importorskip("av", reason="the video stream needs PyAV: pip install 'landfall[sim,camera]'")


def _camera_info(tmp_path: Path) -> Path:
    """simbridge's camera calibration, written before anything flies (as a calibration file is)."""
    path = tmp_path / "camera.yaml"
    res = subprocess.run(
        [sys.executable, "-m", "simbridge", "--scenario", "scenario1", "--camera-info-out", str(path),
         "--duration", "0.01", "--mavlink", f"udpout:127.0.0.1:{free_udp_port()}"],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr[-2000:]
    return path


def _alarm_lands_on_the_clear_roof(rig: Rig) -> str:
    """Once the sensor stream is up: an alarm, and the landing on scenario1's clear roof, confirmed on
    streamed frames ("descending N m, site clear"); the companion's log."""
    rig.wait_log("sensor stream connected", timeout_s=60)
    out = rig.alarm_accepted("--reason", "GPS spoofing detected", "--criticality", "high")
    assert out.returncode == 0, out.stdout + out.stderr
    td = _wait_event(rig.sim, "touchdown", 300)
    log = rig.wait_log("recovery ended: landed", timeout_s=60)
    assert td["surface"] == "rooftop_clear", (td, log[-3000:])
    assert td["safe"] is True
    assert "m, site clear" in log
    return log


def test_an_alarm_lands_on_the_clear_roof_with_the_camera_read_from_an_rtp_stream(
    start_rig: Callable[..., Rig], tmp_path: Path
) -> None:
    info = _camera_info(tmp_path)
    assert "distortion_model: plumb_bob" in info.read_text()
    video = free_udp_port()
    record = tmp_path / "record"
    rig = start_rig(
        ["--scenario", "scenario1", "--autopilot", "px4", "--speed", "2",
         "--camera-stream", f"udp://127.0.0.1:{video}", "--camera-fps", "1"],
        ["--camera", f"udp://127.0.0.1:{video}", "--camera-info", str(info), "--record", str(record)],
        # one frame a simulated second (the renderer's cost), which the decoder holds one frame: a frame
        # is up to 2.5 s old when the newest is taken, older than the 2 s default allows for a 30 fps camera
        env={"LANDFALL_CAMERA_LATENCY_MS": "0", "LANDFALL_SENSORS_MAX_FRAME_AGE_S": "3"},
    )  # fmt: skip
    rig.wait_log("camera: first frame from", timeout_s=60)
    _alarm_lands_on_the_clear_roof(rig)

    # every decision frame was a video frame, dated on the autopilot's clock: against the truth, the
    # boot clock at the pose simbridge rendered the frame with the same presentation time from
    events = _events(record)
    used = [e for e in events if e["kind"] == "camera_frame"]
    assert len(used) >= 3, [e["kind"] for e in events]
    sent = rig.sim.events("camera_frame")
    # the frame simbridge sent for each one the companion used (the decoder's presentation times count
    # from the first packet it received: landfall_eval.episode_grade.match_video_frames finds the base)
    pairs = {id(u): r for u, r in zip(used, match_video_frames(sent, used), strict=True)}

    def truth_of(frame: dict[str, Any]) -> dict[str, Any]:
        row = pairs[id(frame)]
        assert row is not None, (frame, sent[:5])
        return row

    errors_ms, dating_ms = [], []
    for e in used:
        truth = truth_of(e)
        assert e["decoded_s"] > float(truth["sent_monotonic_s"]) - 0.01  # sent, then decoded
        rate = float(e["clock_rate"])
        posed_boot = float(truth["time_boot_ms"]) / 1000.0
        sent_boot = posed_boot + rate * (float(truth["sent_monotonic_s"]) - float(truth["posed_monotonic_s"]))
        errors_ms.append(round(1000 * (e["capture_boot_s"] - posed_boot)))  # against the pose (reported)
        dating_ms.append(round(1000 * (e["capture_boot_s"] - sent_boot)))  # against the send (checked)
    assert all(e["lidar"] for e in used)  # the LiDAR from the sensor socket
    # What the companion controls is the dating from the moment the frame left the camera: the clock fit
    # and the decoder's one-frame hold (1 s of the stream's clock here). Within one frame interval of
    # that moment, whatever the machine's load (the three-frame decoder delay once seen was 3 s off).
    # simbridge's render, the simulated camera's own latency, grows with the load (some 160 ms of this
    # computer's clock on a free core, 2 s seen on a loaded one): it is in the reported pose-time error
    # and is what camera.latency_ms stands for on a vehicle (docs/camera.md has the figures)
    assert max(abs(x) for x in dating_ms) < 1000, (dating_ms, errors_ms)
    # glass to decision: from the pose a frame was rendered at to the rank or confirmation made on it
    glass_ms, last = [], None
    for e in events:
        if e["kind"] == "camera_frame":
            last = e
        elif e["kind"] in ("rank", "confirm") and last is not None:
            truth = truth_of(last)
            glass_ms.append(round(1000 * (e["time_mono_s"] - float(truth["posed_monotonic_s"]))))
    assert glass_ms
    assert all(g > 0 for g in glass_ms), glass_ms
    print(json.dumps({"pose_time_error_ms": errors_ms, "dating_from_send_ms": dating_ms,
                      "glass_to_decision_ms": glass_ms}))  # fmt: skip


def test_a_camera_alone_lands_with_the_autopilots_rangefinder(
    start_rig: Callable[..., Rig], tmp_path: Path
) -> None:
    """No LiDAR and no sensor stream at all (``--sensors none``): the image from the video stream, the
    distance from the autopilot's downward DISTANCE_SENSOR, surfaces proposed by their look
    (companion.perception.appearance) and placed on flat ground at the rangefinder's distance. It comes
    down, and the record says every decision was made without a LiDAR sweep.

    What it does not do yet: find scenario1's clear roof. Placed on the ground plane, a roof's pixel
    lands some 20 % beyond the roof (the ground is 110 m down, the roof 88 m), the close-up is judged
    there and the site refused; the search then runs out its window and the vehicle lands where it is
    (docs/camera.md, "A camera alone"). So this checks that it lands and says why, not where."""
    info = _camera_info(tmp_path)
    video = free_udp_port()
    record = tmp_path / "record"
    rig = start_rig(
        ["--scenario", "scenario1", "--autopilot", "px4", "--speed", "4",
         "--camera-stream", f"udp://127.0.0.1:{video}", "--camera-fps", "0.5"],
        ["--camera", f"udp://127.0.0.1:{video}", "--camera-info", str(info), "--record", str(record),
         "--sensors", "none"],
        env={"LANDFALL_CAMERA_LATENCY_MS": "0", "LANDFALL_SENSORS_MAX_FRAME_AGE_S": "8"},
    )  # fmt: skip
    rig.wait_log("camera: first frame from", timeout_s=60)
    # critical: a minute to search (recovery.search_window_s), the test's flight short
    out = rig.alarm_accepted("--reason", "battery critical", "--criticality", "critical")
    assert out.returncode == 0, out.stdout + out.stderr
    td = _wait_event(rig.sim, "touchdown", 400)
    log = rig.wait_log("recovery ended: landed", timeout_s=60)
    assert "sensor stream" not in log  # never dialled
    assert "clear roof surfaces by their look" in log  # candidates, not the quadrant fallback
    assert "flat ground at the rangefinder distance" in log
    used = [e for e in _events(record) if e["kind"] == "camera_frame"]
    assert len(used) >= 2, [e["kind"] for e in _events(record)]
    assert not any(e["lidar"] for e in used)
    print(json.dumps({"touchdown": td}))


def _raw_h264_rig(
    start_rig: Callable[..., Rig], tmp_path: Path, sends: str, reads: str, speed: int = 2
) -> tuple[Rig, str]:
    """simbridge sending its camera as ``rpicam-vid --inline`` does (raw H.264 without RTP) to
    ``sends`` at ``speed`` times real time and the companion reading ``reads``, once its first frame is
    decoded at the calibration's size: the rig and the URL read."""
    info = _camera_info(tmp_path)
    port = free_udp_port()  # a free TCP port is as good
    rig = start_rig(
        ["--scenario", "scenario1", "--autopilot", "px4", "--speed", str(speed),
         "--camera-stream", sends.format(port=port), "--camera-fps", "1"],
        ["--camera", reads.format(port=port), "--camera-info", str(info)],
        env={"LANDFALL_CAMERA_LATENCY_MS": "0", "LANDFALL_SENSORS_MAX_FRAME_AGE_S": "3"},
    )  # fmt: skip
    url = reads.format(port=port)
    rig.wait_log(f"camera: first frame from {url}", timeout_s=60)
    size = dict(line.split(": ", 1) for line in info.read_text().splitlines()[:2])
    first = f"camera: first frame from {url} ({size['image_width']} x {size['image_height']})"
    assert first in rig.log_text(), rig.log_text()[-2000:]  # decoded at the calibration's size
    return rig, url


def test_raw_h264_as_a_raspberry_pi_camera_sends_it_lands_on_the_clear_roof(
    start_rig: Callable[..., Rig], tmp_path: Path
) -> None:
    """Raw H.264 datagrams (``rpicam-vid --inline -o udp://``), read as ``companion --camera
    udp://...``, which tells them from RTP by the first datagrams. Frames without presentation times
    are dated by their decoding; the landing is on the clear roof. Flown in real time: a frame dated by
    its decoding is dated late by however far the decoder fell behind, and on a loaded machine at twice
    real time that lateness counts double on the autopilot's clock (one run of the suite at 2x refused
    this roof's close-up for lane markings, most likely a crop placed off the roof by a late-dated frame,
    and landed elsewhere after its round budget)."""
    rig, url = _raw_h264_rig(
        start_rig, tmp_path, "raw+udp://127.0.0.1:{port}", "udp://127.0.0.1:{port}", speed=1
    )
    rig.wait_log(f"camera {url}: raw H.264", timeout_s=5)
    _alarm_lands_on_the_clear_roof(rig)


def test_raw_h264_from_a_tcp_server_as_a_raspberry_pi_camera_listens_is_read(
    start_rig: Callable[..., Rig], tmp_path: Path
) -> None:
    """``rpicam-vid --inline --listen -o tcp://``: a TCP server the companion dials (``--camera
    tcp://...``). Its frames are decoded at the calibration's size; what follows a decoded frame (its
    dating without presentation times, the flight on it) is the raw datagrams' path, flown above."""
    _raw_h264_rig(start_rig, tmp_path, "raw+tcp://127.0.0.1:{port}", "tcp://127.0.0.1:{port}")
