"""Fuzzing (hypothesis) of everything that reads outside input: the LVLM answer parser, the config
loader, the sensor-stream decoder, the MAVLink receive path with the companion's handlers, and the
MQTT alarm intake. Thousands of cases each; the only exceptions allowed are each reader's documented
errors, and what a reader accepts must satisfy its contract."""

from __future__ import annotations

import json
import math
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pymavlink.dialects.v20 import common as mavlink2

from companion.alarms import Alarm
from companion.config import ConfigError, load_config
from companion.config_schema import CompanionConfig
from companion.daemon import Companion
from companion.ground import alarm_from_mqtt
from companion.reasoning.base import ReasonerError
from companion.reasoning.parsing import parse_confirm, parse_rank
from landfall_link.sensorstream import ImageEncoding, Part, SensorFrame, SensorStreamError
from landfall_link.sensorstream.wire import _encode_frame, _frame_from_wire, _part_specs

# Examples per property: 2,000 where more examples reach more branches (the LVLM answer parsers reach
# 95 % of parsing.py's lines at 2,000, 89 % at 1,000, 85 % at 500); 500 where they reach no more (the
# sensor frame decoder's and the MQTT intake's lines and branches, measured 2026-11-28 with
# `coverage run --branch`: the same at 500 as at 2,000, which took 4x as long).
MANY = settings(max_examples=2000, deadline=None, suppress_health_check=[HealthCheck.too_slow])
SOME = settings(max_examples=500, deadline=None, suppress_health_check=[HealthCheck.too_slow])

json_values = st.recursive(
    st.none() | st.booleans() | st.integers(-(2**40), 2**40) | st.floats(allow_nan=False)
    | st.text(max_size=20),
    lambda inner: st.lists(inner, max_size=6) | st.dictionaries(st.text(max_size=12), inner, max_size=6),
    max_leaves=20,
)  # fmt: skip


# ------------------------------------------------------------------------------------------ LVLM answers
def answer_texts() -> st.SearchStrategy[str]:
    keyed = st.dictionaries(
        st.sampled_from(["ranking", "explanation", "decision", "order", "reason"]), json_values, max_size=4
    )
    fenced = keyed.map(lambda d: f"Here you go:\n```json\n{json.dumps(d)}\n```")
    cut = keyed.map(json.dumps).flatmap(lambda s: st.integers(0, len(s)).map(lambda k: s[:k]))
    final = st.lists(st.integers(-3, 9), max_size=6).map(lambda xs: f"Reasoning... FINAL RANKING: {xs}")
    return st.one_of(st.text(max_size=200), keyed.map(json.dumps), fenced, cut, final)


@MANY
@given(answer_texts(), st.integers(1, 6))
def test_rank_parser_returns_a_valid_order_or_its_own_error(text: str, n: int) -> None:
    try:
        order, explanation = parse_rank(text, n)
    except ReasonerError:
        return
    assert order
    assert all(isinstance(k, int) and 0 <= k < n for k in order)
    assert len(set(order)) == len(order)
    assert isinstance(explanation, str)


@MANY
@given(answer_texts())
def test_confirm_parser_returns_a_decision_or_its_own_error(text: str) -> None:
    try:
        accept, explanation = parse_confirm(text)
    except ReasonerError:
        return
    assert isinstance(accept, bool)
    assert isinstance(explanation, str)


# ------------------------------------------------------------------------------------------ config
def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float) and not math.isfinite(v):
        return "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf")
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    return json.dumps(v)


OPTIONS = [(s, k) for s, m in CompanionConfig.model_fields.items() for k in m.annotation.model_fields]  # type: ignore[union-attr]
toml_scalars = st.booleans() | st.integers(-(2**63), 2**63 - 1) | st.floats() | st.text(max_size=30)
config_files = st.one_of(
    st.text(max_size=300),
    st.lists(
        st.tuples(st.sampled_from(OPTIONS), toml_scalars | st.lists(toml_scalars, max_size=3)), max_size=8
    ).map(
        lambda items: "\n".join(
            f"[{s}]\n{k} = {_toml_value(v)}" for (s, k), v in {o: v for o, v in items}.items()
        )
    ),
)
env_vars = st.dictionaries(
    st.sampled_from([f"LANDFALL_{s.upper()}_{k.upper()}" for s, k in OPTIONS] + ["LANDFALL_MQTT_NOPE"]),
    st.text(max_size=20).filter(lambda t: "\x00" not in t),
    max_size=4,
)


@SOME
@given(config_files, env_vars)
def test_config_loader_gives_a_config_or_a_config_error(text: str, env: dict[str, str]) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "companion.toml"
        path.write_text(text, encoding="utf-8", errors="surrogatepass")
        try:
            cfg = load_config(path, env, {})
        except ConfigError as exc:
            problem = str(exc)
        else:
            assert isinstance(cfg, CompanionConfig)
            return
    assert problem  # it names a problem


# ------------------------------------------------------------------------------------------ sensor stream
def _wire() -> tuple[dict[str, Any], list[bytes]]:
    frame = SensorFrame(
        t_s=1.0, time_boot_ms=1000, pos_ned_m=(0.0, 0.0, -50.0), quat_wxyz=(1.0, 0.0, 0.0, 0.0),
        rangefinder_m=50.0, fx=4.0, fy=4.0, cx=4.0, cy=3.0, width=8, height=6, weather="clear",
        image_rgb=np.full((6, 8, 3), 100, np.uint8), depth_m=None,
        lidar_frd=np.zeros((5, 4), np.float32),
    )  # fmt: skip
    return _encode_frame(frame, frozenset({Part.IMAGE, Part.LIDAR}), ImageEncoding.RAW, 90)


HEADER, BLOBS = _wire()
PART_KEYS = ["name", "encoding", "dtype", "shape", "nbytes"]


@SOME
@given(
    st.dictionaries(st.sampled_from(sorted(HEADER)), json_values, max_size=3),
    st.lists(st.tuples(st.sampled_from(PART_KEYS), json_values), max_size=3),
    st.integers(0, 1),
    st.binary(max_size=300) | st.none(),
)  # fmt: skip
def test_sensor_frame_decoder_gives_a_frame_or_a_stream_error(
    changes: dict[str, Any], part_changes: list[tuple[str, Any]], which: int, blob: bytes | None
) -> None:
    header = json.loads(json.dumps(HEADER)) | changes
    blobs = list(BLOBS)
    parts = header.get("parts")
    if isinstance(parts, list) and len(parts) == 2 and isinstance(parts[which], dict):
        for key, value in part_changes:
            header["parts"][which][key] = value
    if blob is not None:
        blobs[which] = blob
    try:
        specs = _part_specs(header)
        if len(specs) != len(blobs) or any(len(b) != s.nbytes for s, b in zip(specs, blobs, strict=False)):
            return  # the stream reader refuses a part whose length is not the announced nbytes
        frame = _frame_from_wire(header, list(zip(specs, blobs, strict=True)))
    except SensorStreamError:
        return
    assert frame.image_rgb is None or frame.image_rgb.shape == (frame.height, frame.width, 3)
    assert frame.lidar_frd is None or frame.lidar_frd.shape[1] >= 3


# ------------------------------------------------------------------------------------------ MAVLink
def _companion() -> Companion:
    return Companion(mavlink_url="udp:14550", sensors=None, watch_battery_pct=None)


def _frames(mav: Any) -> st.SearchStrategy[bytes]:
    floats = st.floats(width=32) | st.sampled_from([math.nan, math.inf, -math.inf, 0.0, 1.0, 2.0, 31010.0])
    command = st.builds(
        lambda ts, tc, cmd, p: mav.command_long_encode(ts, tc, cmd, 0, *p).pack(mav),
        st.integers(0, 255), st.sampled_from([0, 191, 1]), st.sampled_from([31010, 176, 400, 0]),
        st.lists(floats, min_size=7, max_size=7),
    )  # fmt: skip
    text = st.builds(
        lambda sev, t: mav.statustext_encode(sev, t.encode("utf-8", "replace")[:50]).pack(mav),
        st.integers(0, 255), st.text(max_size=60).map(lambda t: "LANDFALL_ALARM:" + t),
    )  # fmt: skip
    heartbeat = st.builds(
        lambda *a: mav.heartbeat_encode(*a).pack(mav),
        st.integers(0, 255), st.integers(0, 255), st.integers(0, 255), st.integers(0, 2**32 - 1),
        st.integers(0, 255),
    )  # fmt: skip
    valid = command | text | heartbeat
    flipped = st.tuples(valid, st.integers(0, 400), st.integers(1, 255)).map(lambda t: _flip(*t))
    return st.lists(valid | flipped | st.binary(max_size=300), min_size=1, max_size=6).map(b"".join)


def _flip(frame: bytes, at: int, mask: int) -> bytes:
    k = at % len(frame)
    return frame[:k] + bytes([frame[k] ^ mask]) + frame[k + 1 :]


COMPANION = _companion()
SENDER = mavlink2.MAVLink(None, srcSystem=255, srcComponent=190)


@MANY
@given(_frames(SENDER))
def test_mavlink_receive_path_survives_any_datagram(data: bytes) -> None:
    link = COMPANION.link
    before = link.stats.received + link.stats.bad_frames
    link.datagram_received(data, ("127.0.0.1", 14551))  # never raises, whatever the handlers meet
    assert link.stats.received + link.stats.bad_frames >= before
    assert COMPANION.recovery is None  # no vehicle telemetry: no alarm may start a recovery


@MANY
@given(st.floats() | st.integers(), st.floats() | st.integers(), st.text(max_size=60))
def test_alarm_command_decodes_or_says_why(p1: float, p2: float, text: str) -> None:
    try:
        alarm = Alarm.from_command(p1, p2, text, (255, 190))
    except ValueError as exc:
        assert str(exc)  # noqa: PT017 (fuzzed: most inputs are refused, some are alarms)
        return
    assert alarm.criticality in (0, 1, 2)
    assert alarm.reason


@SOME
@given(st.binary(max_size=200) | json_values.map(lambda v: json.dumps(v).encode()))
def test_mqtt_alarm_intake_decodes_or_says_why(payload: bytes) -> None:
    try:
        alarm = alarm_from_mqtt(payload)
    except ValueError as exc:
        assert str(exc)  # noqa: PT017 (fuzzed: most inputs are refused, some are alarms)
        return
    assert 0 < len(alarm.reason) <= 50
    assert alarm.source == (0, 0)
