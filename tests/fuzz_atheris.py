"""Coverage-guided fuzzing with atheris (libFuzzer) of the readers of outside input, one target per
run: ``python tests/fuzz_atheris.py TARGET [libFuzzer flags, e.g. -runs=20000 -seed=1]``.

Targets: ``rank`` and ``confirm`` (the LVLM answer parsers), ``config`` (the TOML config loader),
``sensor`` (the sensor-stream frame decoder), ``mavlink`` (pymavlink's parser, then the companion's
message handlers called directly, so that a handler's exception is not hidden by the link's guard),
``mqtt`` (the MQTT alarm intake). Each reader may refuse an input only with its documented error;
anything else is a crash that libFuzzer reports with the input that caused it (exit status != 0).
tests/test_fuzz_atheris.py runs every target; tests/test_fuzz.py covers the same readers with
hypothesis where atheris does not install.
"""

from __future__ import annotations

import json
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path

import atheris

with atheris.instrument_imports(include=["companion", "simbridge", "landfall_link"]):
    from companion.config import ConfigError, load_config
    from companion.daemon import Companion
    from companion.ground import alarm_from_mqtt
    from companion.reasoning.base import ReasonerError
    from companion.reasoning.parsing import parse_confirm, parse_rank
    from landfall_link.sensorstream import SensorStreamError
    from landfall_link.sensorstream.wire import _frame_from_wire, _part_specs

from pymavlink.dialects.v20 import common as mavlink2

ROOT = Path(__file__).resolve().parent.parent


def _says_why(exc: Exception) -> None:
    if not str(exc):
        raise AssertionError(f"a refusal without a reason: {exc!r}")


def rank(data: bytes) -> None:
    fdp = atheris.FuzzedDataProvider(data)
    n = fdp.ConsumeIntInRange(1, 6)
    try:
        order, _ = parse_rank(fdp.ConsumeUnicodeNoSurrogates(len(data)), n)
    except ReasonerError:
        return
    assert order
    assert all(0 <= k < n for k in order)
    assert len(set(order)) == len(order)


def confirm(data: bytes) -> None:
    try:
        accept, _ = parse_confirm(atheris.FuzzedDataProvider(data).ConsumeUnicodeNoSurrogates(len(data)))
    except ReasonerError:
        return
    assert isinstance(accept, bool)


_CONFIG = Path(tempfile.mkdtemp(prefix="landfall-fuzz-")) / "companion.toml"


def config(data: bytes) -> None:
    _CONFIG.write_bytes(data)
    try:
        load_config(_CONFIG, {}, {})
    except ConfigError as exc:
        _says_why(exc)


def sensor(data: bytes) -> None:
    """As on the wire: a JSON header line, then each announced part's ``nbytes`` in order."""
    line, _, rest = data.partition(b"\n")
    try:
        header = json.loads(line)
    except (ValueError, RecursionError):
        return  # the stream reader refuses a header line that is not JSON before decoding
    if not isinstance(header, dict):
        return
    try:
        specs = _part_specs(header)
        blobs = []
        for spec in specs:
            if spec.nbytes > len(rest):
                return  # the reader would wait for the rest (and time out)
            blobs.append(rest[: spec.nbytes])
            rest = rest[spec.nbytes :]
        frame = _frame_from_wire(header, list(zip(specs, blobs, strict=True)))
    except SensorStreamError:
        return
    assert frame.image_rgb is None or frame.image_rgb.shape == (frame.height, frame.width, 3)
    assert frame.lidar_frd is None or frame.lidar_frd.shape[1] >= 3


_COMPANION = Companion(mavlink_url="udp:14550", sensors=None, watch_battery_pct=None)
_PARSER = mavlink2.MAVLink(None)


def mavlink(data: bytes) -> None:
    try:
        msgs = _PARSER.parse_buffer(data) or []
    except Exception:  # pymavlink raises bare Exceptions on malformed input; the link counts them
        return
    for msg in msgs:
        if msg.get_type() != "BAD_DATA":
            _COMPANION._on_message(msg, ("127.0.0.1", 14551))
    assert _COMPANION.recovery is None  # no vehicle telemetry: no alarm may start a recovery


def mqtt(data: bytes) -> None:
    try:
        alarm = alarm_from_mqtt(data)
    except ValueError as exc:
        _says_why(exc)
        return
    assert 0 < len(alarm.reason) <= 50


TARGETS: dict[str, Callable[[bytes], None]] = {
    "rank": rank,
    "confirm": confirm,
    "config": config,
    "sensor": sensor,
    "mavlink": mavlink,
    "mqtt": mqtt,
}


def seeds(target: str) -> list[bytes]:
    """Valid inputs to start each target's corpus from: libFuzzer mutates from there, so the fuzzing
    reaches past the first check (a CRC, a JSON header) into the code behind it."""
    if target == "rank":
        return [
            b'\x03{"explanation": "1 is clear gravel", "ranking": [1, 0, 2]}',
            b"\x02FINAL RANKING: [1, 0]",
        ]
    if target == "confirm":
        return [b'{"explanation": "clear gravel", "decision": 1}', b'```json\n{"decision": 0}\n```']
    if target == "config":
        return [(ROOT / "deploy" / "companion.toml").read_bytes(), b"[recovery]\nmax_rounds = 3\n"]
    if target == "sensor":
        import numpy as np

        from landfall_link.sensorstream import ImageEncoding, Part, SensorFrame
        from landfall_link.sensorstream.wire import _encode_frame

        frame = SensorFrame(
            t_s=1.0, time_boot_ms=1000, pos_ned_m=(0.0, 0.0, -50.0), quat_wxyz=(1.0, 0.0, 0.0, 0.0),
            rangefinder_m=50.0, fx=4.0, fy=4.0, cx=4.0, cy=3.0, width=8, height=6, weather="clear",
            image_rgb=np.full((6, 8, 3), 100, np.uint8), depth_m=None, lidar_frd=np.ones((5, 4), np.float32),
        )  # fmt: skip
        out = []
        for encoding in (ImageEncoding.RAW, ImageEncoding.JPEG):
            header, blobs = _encode_frame(frame, frozenset({Part.IMAGE, Part.LIDAR}), encoding, 90)
            out.append(json.dumps(header).encode() + b"\n" + b"".join(blobs))
        return out
    if target == "mavlink":
        ap = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
        gcs = mavlink2.MAVLink(None, srcSystem=255, srcComponent=190)
        return [
            ap.heartbeat_encode(2, 12, 157, 6 << 16 | 4 << 24, 4).pack(ap)
            + ap.local_position_ned_encode(1000, 1.0, 2.0, -50.0, 0, 0, 0).pack(ap)
            + ap.extended_sys_state_encode(0, 2).pack(ap)
            + ap.battery_status_encode(0, 0, 1, 2500, [16000] + [65535] * 9, 100, -1, -1, 12).pack(ap),
            gcs.statustext_encode(4, b"ALARM: storm").pack(gcs)
            + gcs.command_long_encode(1, 191, 31010, 0, 4, 1, 0, 0, 0, 0, 0).pack(gcs),
            ap.statustext_encode(2, b"Failsafe: offboard lost").pack(ap)
            + ap.gps_raw_int_encode(0, 0, 0, 0, 0, 0, 0, 0, 0, 0).pack(ap),
        ]
    return [b'{"reason": "storm ahead", "criticality": "high"}', b'{"reason": "x", "code": "weather"}']


if __name__ == "__main__":
    if len(sys.argv) < 2 or sys.argv[1] not in TARGETS:
        sys.exit(f"usage: fuzz_atheris.py {{{','.join(TARGETS)}}} [libFuzzer flags]")
    name = sys.argv.pop(1)
    corpus = Path(tempfile.mkdtemp(prefix=f"landfall-fuzz-{name}-"))
    for k, seed in enumerate(seeds(name)):
        (corpus / f"seed{k}").write_bytes(seed)
    atheris.Setup([*sys.argv, str(corpus)], TARGETS[name])
    atheris.Fuzz()
