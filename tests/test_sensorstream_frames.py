"""What the sensor stream's frames and endpoints accept (landfall_link.sensorstream): every field of a
SensorFrame checked with an error naming the field, what it expected and what it got; endpoint text
parsed or refused with the reason. The stream itself: tests/test_sensorstream.py."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from landfall_link.sensorstream import EndpointError, SensorFrame, SensorFrameError, parse_endpoint
from tests.test_sensorstream import CAMERA


# -------------------------------------------------------------------------------------- frame validation
def _frame_args(**changes: Any) -> dict[str, Any]:
    base: dict[str, Any] = {
        "t_s": 1.0, "time_boot_ms": 1000, "pos_ned_m": (0.0, 0.0, -100.0), "quat_wxyz": (1.0, 0.0, 0.0, 0.0),
        "rangefinder_m": 100.0, "weather": "clear", **CAMERA,
    }  # fmt: skip
    return {**base, **changes}


@pytest.mark.parametrize(
    ("changes", "field_name", "actual"),
    [
        ({"image_rgb": np.zeros((48, 80, 3), np.float32)}, "image_rgb", "(48, 80, 3) float32"),
        ({"image_rgb": np.zeros((80, 48, 3), np.uint8)}, "image_rgb", "(80, 48, 3) uint8"),
        ({"image_rgb": np.zeros((48, 80), np.uint8)}, "image_rgb", "(48, 80) uint8"),
        ({"image_rgb": [[0]]}, "image_rgb", "list"),
        ({"depth_m": np.zeros((48, 80), np.float64)}, "depth_m", "(48, 80) float64"),
        ({"lidar_frd": np.zeros((10, 3), np.float32)}, "lidar_frd", "(10, 3) float32"),
        ({"quat_wxyz": (1.0, 0.1, 0.0, 0.0)}, "quat_wxyz", "norm"),
        ({"quat_wxyz": (1.0, 0.0, 0.0)}, "quat_wxyz", "(1.0, 0.0, 0.0)"),
        ({"pos_ned_m": (0.0, math.nan, 1.0)}, "pos_ned_m[1]", "nan"),
        ({"t_s": math.inf}, "t_s", "inf"),
        ({"t_s": -1.0}, "t_s", "-1.0"),
        ({"time_boot_ms": 1.5}, "time_boot_ms", "float 1.5"),
        ({"time_boot_ms": True}, "time_boot_ms", "bool True"),
        ({"rangefinder_m": "100"}, "rangefinder_m", "str '100'"),
        ({"weather": ""}, "weather", "''"),
        ({"fx": 0.0}, "fx", "0.0"),
        ({"cy": math.nan}, "cy", "nan"),
        ({"width": 0, "image_rgb": np.zeros((48, 0, 3), np.uint8)}, "width", "int 0"),
        ({"height": 48.0}, "height", "float 48.0"),
    ],
)
def test_sensorframe_invalid_field_rejected(changes: dict[str, Any], field_name: str, actual: str) -> None:
    with pytest.raises(SensorFrameError) as caught:
        SensorFrame(**_frame_args(**changes))
    assert caught.value.field_name == field_name
    assert actual in caught.value.actual
    assert str(caught.value).startswith(f"{field_name}: expected ")


def test_sensorframe_image_shape_error_names_expected_shape() -> None:
    with pytest.raises(
        SensorFrameError, match=r"expected a \(48, 80, 3\) uint8 array or None, got a \(80, 48, 3\)"
    ):
        SensorFrame(**_frame_args(image_rgb=np.zeros((80, 48, 3), np.uint8)))


def test_sensorframe_numbers_normalised() -> None:
    frame = SensorFrame(**_frame_args(t_s=2, pos_ned_m=np.array([1.0, 2.0, 3.0]), time_boot_ms=np.int64(7)))
    assert (frame.t_s, type(frame.t_s)) == (2.0, float)
    assert (frame.pos_ned_m, type(frame.pos_ned_m)) == ((1.0, 2.0, 3.0), tuple)
    assert (frame.time_boot_ms, type(frame.time_boot_ms)) == (7, int)


# ------------------------------------------------------------------------------------------- endpoints
@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("127.0.0.1:5600", ("127.0.0.1", 5600)),
        ("localhost:0", ("localhost", 0)),
        ("[::1]:65535", ("::1", 65535)),
    ],
)
def test_parse_endpoint_valid(text: str, expected: tuple[str, int]) -> None:
    assert parse_endpoint(text) == expected


@pytest.mark.parametrize(
    ("text", "reason"),
    [
        ("", "empty"),
        (" 127.0.0.1:5600", "whitespace"),
        ("127.0.0.1", "no ':'"),
        (":5600", "host is empty"),
        ("host:", "port ''"),
        ("host:http", "port 'http'"),
        ("host:65536", "0..65535"),
        ("host:-1", "0..65535"),
        ("::1:5600", "brackets"),
    ],
)
def test_parse_endpoint_invalid_rejected(text: str, reason: str) -> None:
    with pytest.raises(EndpointError) as caught:
        parse_endpoint(text)
    assert reason in caught.value.reason
    assert "HOST:PORT" in str(caught.value)
