"""Camera calibration files: ROS camera_info and OpenCV YAML read alike, bad files refused
naming the field, undistortion that puts each pixel where the calibrated lens model says."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from landfall_link.camera_info import CameraInfo, CameraInfoError, load_camera_info

ROS = """\
image_width: 640
image_height: 480
camera_name: nadir
camera_matrix:
  rows: 3
  cols: 3
  data: [520.5, 0.0, 318.2, 0.0, 521.0, 243.9, 0.0, 0.0, 1.0]
distortion_model: plumb_bob
distortion_coefficients:
  rows: 1
  cols: 5
  data: [-0.28, 0.07, 0.0008, -0.0004, 0.0]
rectification_matrix:
  rows: 3
  cols: 3
  data: [1, 0, 0, 0, 1, 0, 0, 0, 1]
projection_matrix:
  rows: 3
  cols: 4
  data: [520.5, 0.0, 318.2, 0.0, 0.0, 521.0, 243.9, 0.0, 0.0, 0.0, 1.0, 0.0]
"""
K = np.array([[520.5, 0.0, 318.2], [0.0, 521.0, 243.9], [0.0, 0.0, 1.0]])
D = np.array([-0.28, 0.07, 0.0008, -0.0004, 0.0])


def _write(tmp_path: Path, text: str, name: str = "cam.yaml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def test_a_ros_camera_info_file_is_read(tmp_path: Path) -> None:
    info = load_camera_info(_write(tmp_path, ROS))
    assert (info.width, info.height, info.name, info.distortion_model) == (640, 480, "nadir", "plumb_bob")
    np.testing.assert_array_equal(info.k, K)
    np.testing.assert_array_equal(info.d, D)
    assert info.source == tmp_path / "cam.yaml"


def test_an_opencv_calibration_file_is_read_the_same(tmp_path: Path) -> None:
    path = tmp_path / "opencv.yaml"
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)  # as OpenCV's calibration sample writes it
    fs.write("image_width", 640)
    fs.write("image_height", 480)
    fs.write("camera_matrix", K)
    fs.write("distortion_coefficients", D.reshape(5, 1))
    fs.release()
    info = load_camera_info(path)
    np.testing.assert_array_equal(info.k, K)
    np.testing.assert_array_equal(info.d, D)
    assert info.distortion_model == "plumb_bob"  # OpenCV's files do not name it: five coefficients


def test_the_ros_file_written_reads_back(tmp_path: Path) -> None:
    info = CameraInfo.pinhole(960, 540, 600.0, 600.0, 480.0, 270.0, name="simbridge")
    back = load_camera_info(_write(tmp_path, info.to_ros_yaml()))
    np.testing.assert_allclose(back.k, info.k)
    assert (back.width, back.height, back.name, back.distortion_model) == (960, 540, "simbridge", "plumb_bob")
    u = back.undistorter()
    assert (u.fx, u.fy, u.cx, u.cy) == (600.0, 600.0, 480.0, 270.0)  # Landfall's pixel centres: + 0.5


@pytest.mark.parametrize(
    ("edit", "says"),
    [
        (lambda t: t.replace("image_width: 640\n", ""), "image_width is missing"),
        (lambda t: t.replace("image_height: 480", "image_height: 480.5"), "whole number of pixels"),
        (lambda t: t.replace("  data: [520.5, 0.0, 318.2, 0.0, 521.0, 243.9, 0.0, 0.0, 1.0]\n", ""),
         "camera_matrix must have rows, cols and a data list"),
        (lambda t: t.replace("243.9, 0.0, 0.0, 1.0]", "243.9, 0.0, 0.0]"), "does not match 8 data values"),
        (lambda t: t.replace("[520.5, 0.0, 318.2", "[-520.5, 0.0, 318.2"), "focal lengths must be positive"),
        (lambda t: t.replace("[520.5, 0.0, 318.2", "[520.5, 3.0, 318.2"), "no skew"),
        (lambda t: t.replace("318.2, 0.0, 521.0", "918.2, 0.0, 521.0"), "outside the 640 x 480 image"),
        (lambda t: t.replace("plumb_bob", "kannala_brandt"), "'kannala_brandt' is not one of"),
        (lambda t: t.replace("distortion_model: plumb_bob", "distortion_model: equidistant"),
         "equidistant takes 4-4 coefficients, the file gives 5"),
        (lambda t: t.replace("-0.28, 0.07", "-0.28, .nan"), "not a finite number"),
        (lambda t: t.replace("-0.28, 0.07", "-0.28, fast"), "data value 1 is not a number"),
    ],
)  # fmt: skip
def test_a_bad_field_is_refused_naming_it(tmp_path: Path, edit: object, says: str) -> None:
    path = _write(tmp_path, edit(ROS))  # type: ignore[operator]
    with pytest.raises(CameraInfoError, match=str(path)) as err:
        load_camera_info(path)
    assert says in str(err.value)


def test_a_missing_or_unreadable_file_is_refused(tmp_path: Path) -> None:
    with pytest.raises(CameraInfoError, match="no such file"):
        load_camera_info(tmp_path / "absent.yaml")
    with pytest.raises(CameraInfoError, match="YAML"):
        load_camera_info(_write(tmp_path, "image_width: [640\n  : :\n\x00", "broken.yaml"))


@pytest.mark.parametrize("model", ["plumb_bob", "equidistant"])
def test_undistortion_puts_each_pixel_where_the_lens_model_says(tmp_path: Path, model: str) -> None:
    """A pixel of the undistorted image is read from the raw pixel that the calibrated lens model (OpenCV's
    own projectPoints) gives for the same ray."""
    d = D if model == "plumb_bob" else np.array([0.05, -0.01, 0.002, -0.0005])
    fisheye = ROS.replace("plumb_bob", "equidistant").replace(
        "  cols: 5\n  data: [-0.28, 0.07, 0.0008, -0.0004, 0.0]",
        "  cols: 4\n  data: [0.05, -0.01, 0.002, -0.0005]",
    )
    text = ROS if model == "plumb_bob" else fisheye
    info = load_camera_info(_write(tmp_path, text))
    und = info.undistorter()
    mx, my = cv2.convertMaps(und.map1, und.map2, cv2.CV_32FC1)
    rng = np.random.default_rng(0)
    for _ in range(50):
        col, row = int(rng.integers(40, 600)), int(rng.integers(40, 440))
        u, v = col + 0.5, row + 0.5  # the output pixel's centre, Landfall's convention
        ray = np.array([[[(u - und.cx) / und.fx, (v - und.cy) / und.fy, 1.0]]])
        if model == "equidistant":
            raw, _ = cv2.fisheye.projectPoints(ray, np.zeros(3), np.zeros(3), K, d.reshape(4, 1))
        else:
            raw, _ = cv2.projectPoints(ray, np.zeros(3), np.zeros(3), K, d)
        # the map holds the raw pixel (OpenCV's integer-centred coordinates) each output pixel reads
        assert float(mx[row, col]) == pytest.approx(float(raw[0, 0, 0]), abs=0.05)
        assert float(my[row, col]) == pytest.approx(float(raw[0, 0, 1]), abs=0.05)


def test_an_image_of_the_wrong_size_is_refused() -> None:
    und = CameraInfo.pinhole(64, 48, 50.0, 50.0, 32.0, 24.0).undistorter()
    assert und(np.zeros((48, 64, 3), np.uint8)).shape == (48, 64, 3)
    with pytest.raises(ValueError, match="the calibration is for 64 x 48"):
        und(np.zeros((480, 640, 3), np.uint8))
