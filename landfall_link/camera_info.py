"""Camera calibration files: read the formats people already have, write ROS's.

Two layouts are read, both YAML, both through OpenCV's ``cv2.FileStorage`` (which reads either):

- **ROS** ``camera_info`` (what ``camera_calibration`` and ``camera_info_manager`` write)::

      image_width: 640
      image_height: 480
      camera_name: nadir
      camera_matrix: {rows: 3, cols: 3, data: [fx, 0, cx, 0, fy, cy, 0, 0, 1]}
      distortion_model: plumb_bob
      distortion_coefficients: {rows: 1, cols: 5, data: [k1, k2, p1, p2, k3]}

- **OpenCV** (what its ``calibration`` sample and ``cv2.FileStorage`` write): the same key names with
  ``!!opencv-matrix`` values, and no ``distortion_model`` (read as ``plumb_bob``, or
  ``rational_polynomial`` for 8 coefficients and more).

Distortion models: ``plumb_bob`` (OpenCV's k1 k2 p1 p2 [k3]), ``rational_polynomial`` (k1 k2 p1 p2 k3 k4
k5 k6, OpenCV's rational model), ``equidistant`` (k1..k4, ``cv2.fisheye``), or ``none``.

Pixel convention: OpenCV's and ROS's calibration put pixel centres at integer coordinates; Landfall's
cameras (``companion.guidance.frames``) put them at ``+ 0.5``. :attr:`CameraInfo.k` is the file's
matrix; :meth:`CameraInfo.undistorter` returns maps for ``cv2.remap`` and the pinhole intrinsics of the
undistorted image in Landfall's convention.

A file that cannot be read, a missing or malformed field, a matrix that is not a camera matrix or a
distortion model this module does not know is a :class:`CameraInfoError` naming the file and the
field: at start, never a wrong geometry in flight.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["DISTORTION_MODELS", "CameraInfo", "CameraInfoError", "Undistorter", "load_camera_info"]

DISTORTION_MODELS = {
    "plumb_bob": (4, 5),
    "rational_polynomial": (8, 14),
    "equidistant": (4, 4),
    "none": (0, 0),
}
"""Model -> (fewest, most) coefficients it takes."""


class CameraInfoError(ValueError):
    """A calibration file that cannot be used; the message names the file and the field."""


@dataclass(frozen=True, slots=True)
class Undistorter:
    """Maps that turn a raw image into an undistorted pinhole image (and, given a rotation, into the
    view of a camera turned by it about its own centre), with that image's intrinsics.

    Attributes:
        map1, map2: for ``cv2.remap(raw, map1, map2, cv2.INTER_LINEAR)``.
        width, height: the output image size (the raw image's).
        fx, fy, cx, cy: pinhole intrinsics of the output, pixel centres at ``+ 0.5`` (Landfall's).
    """

    map1: np.ndarray
    map2: np.ndarray
    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float

    def __call__(self, image: np.ndarray) -> np.ndarray:
        import cv2

        if image.shape[:2] != (self.height, self.width):
            raise ValueError(
                f"image of {image.shape[1]} x {image.shape[0]} px; the calibration is for "
                f"{self.width} x {self.height}"
            )
        out: np.ndarray = cv2.remap(
            image, self.map1, self.map2, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE
        )
        return out


@dataclass(frozen=True, slots=True)
class CameraInfo:
    """One camera's calibration.

    Attributes:
        width, height: the image size it was calibrated at, pixels.
        k: (3, 3) camera matrix as the file has it (pixel centres at integers).
        distortion_model: one of :data:`DISTORTION_MODELS`.
        d: the distortion coefficients, as many as the file gives.
        name: ``camera_name`` when the file has one.
        source: the file it was read from, or None.
    """

    width: int
    height: int
    k: np.ndarray
    distortion_model: str
    d: np.ndarray
    name: str | None = None
    source: Path | None = None

    @property
    def fx(self) -> float:
        return float(self.k[0, 0])

    @property
    def fy(self) -> float:
        return float(self.k[1, 1])

    @property
    def hfov_deg(self) -> float:
        return math.degrees(2 * math.atan(self.width / (2 * self.fx)))

    def undistorter(self, rotation: np.ndarray | None = None) -> Undistorter:
        """Maps to an undistorted image of the same size, whose camera matrix keeps the focal length and
        principal point (so the middle of the view keeps its scale); with ``rotation`` (3, 3; the
        rectification rotation of ``cv2.initUndistortRectifyMap``: new camera axes in the raw camera's
        frame, transposed) the view is also turned, as a camera mounted turned by it would see."""
        import cv2

        r = np.eye(3) if rotation is None else np.asarray(rotation, dtype=np.float64)
        size = (self.width, self.height)
        if self.distortion_model == "equidistant":
            m1, m2 = cv2.fisheye.initUndistortRectifyMap(
                self.k, self.d.reshape(4, 1), r, self.k, size, cv2.CV_16SC2
            )
        else:
            d = self.d if self.distortion_model != "none" else np.zeros(5)
            m1, m2 = cv2.initUndistortRectifyMap(self.k, d, r, self.k, size, cv2.CV_16SC2)
        return Undistorter(
            m1,
            m2,
            self.width,
            self.height,
            self.fx,
            self.fy,
            float(self.k[0, 2]) + 0.5,
            float(self.k[1, 2]) + 0.5,
        )

    def to_ros_yaml(self) -> str:
        """The calibration as a ROS ``camera_info`` YAML file (rectification identity, projection = K)."""

        def row(values: Any) -> str:
            return "[" + ", ".join(f"{float(v):.9g}" for v in np.ravel(values)) + "]"

        p = np.hstack([self.k, np.zeros((3, 1))])
        return (
            f"image_width: {self.width}\n"
            f"image_height: {self.height}\n"
            f"camera_name: {self.name or 'camera'}\n"
            f"camera_matrix:\n  rows: 3\n  cols: 3\n  data: {row(self.k)}\n"
            f"distortion_model: {self.distortion_model}\n"
            f"distortion_coefficients:\n  rows: 1\n  cols: {len(self.d)}\n  data: {row(self.d)}\n"
            f"rectification_matrix:\n  rows: 3\n  cols: 3\n  data: {row(np.eye(3))}\n"
            f"projection_matrix:\n  rows: 3\n  cols: 4\n  data: {row(p)}\n"
        )

    @classmethod
    def pinhole(cls, width: int, height: int, fx: float, fy: float, cx: float, cy: float,
                name: str | None = None) -> CameraInfo:  # fmt: skip
        """An ideal camera given in Landfall's convention (pixel centres at ``+ 0.5``)."""
        k = np.array([[fx, 0.0, cx - 0.5], [0.0, fy, cy - 0.5], [0.0, 0.0, 1.0]])
        return _checked(Path("<pinhole>"), width, height, k, "plumb_bob", np.zeros(5), name)


def load_camera_info(path: str | Path) -> CameraInfo:
    """Read a ROS ``camera_info`` or OpenCV calibration YAML file (see the module docstring)."""
    import cv2

    path = Path(path)
    if not path.is_file():
        raise CameraInfoError(f"camera calibration {path}: no such file")
    try:
        fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    except (cv2.error, SystemError) as exc:  # OpenCV's parser error (SystemError: raised inside its binding)
        reason = str(exc).strip().splitlines()[-1] if str(exc).strip() else type(exc).__name__
        raise CameraInfoError(
            f"camera calibration {path}: not a YAML file OpenCV can read ({reason})"
        ) from exc
    if not fs.isOpened():
        raise CameraInfoError(f"camera calibration {path}: cannot be opened as YAML")
    try:
        width = _integer(path, fs, "image_width")
        height = _integer(path, fs, "image_height")
        k = _matrix(path, fs, "camera_matrix")
        d_node = fs.getNode("distortion_coefficients")
        model_node = fs.getNode("distortion_model")
        model = model_node.string() if not model_node.empty() else ""
        d = (
            np.zeros(0)
            if d_node.empty() and model in ("", "none")
            else _matrix(path, fs, "distortion_coefficients")
        )
        name_node = fs.getNode("camera_name")
        name = name_node.string() if not name_node.empty() and name_node.isString() else None
    finally:
        fs.release()
    d = d.ravel()
    if not model:
        model = "none" if d.size == 0 else "rational_polynomial" if d.size >= 8 else "plumb_bob"
    return _checked(path, width, height, k, model, d, name)


def _checked(path: Path, width: int, height: int, k: np.ndarray, model: str, d: np.ndarray,
             name: str | None) -> CameraInfo:  # fmt: skip
    where = f"camera calibration {path}"
    if k.shape != (3, 3):
        raise CameraInfoError(f"{where}: camera_matrix must be 3 x 3, not {k.shape[0]} x {k.shape[1]}")
    if not np.isfinite(k).all():
        raise CameraInfoError(f"{where}: camera_matrix has a value that is not a finite number")
    fx, fy, cx, cy = k[0, 0], k[1, 1], k[0, 2], k[1, 2]
    if not (fx > 0 and fy > 0):
        raise CameraInfoError(f"{where}: camera_matrix focal lengths must be positive (fx {fx:g}, fy {fy:g})")
    if k[0, 1] != 0 or k[1, 0] != 0 or k[2, 0] != 0 or k[2, 1] != 0 or k[2, 2] != 1:
        raise CameraInfoError(
            f"{where}: camera_matrix must be [fx 0 cx; 0 fy cy; 0 0 1] (no skew), "
            f"got {np.round(k, 4).tolist()}"
        )
    if not (0 <= cx <= width and 0 <= cy <= height):
        raise CameraInfoError(
            f"{where}: principal point ({cx:g}, {cy:g}) lies outside the {width} x {height} image"
        )
    if model not in DISTORTION_MODELS:
        raise CameraInfoError(
            f"{where}: distortion_model {model!r} is not one of {', '.join(sorted(DISTORTION_MODELS))}"
        )
    low, high = DISTORTION_MODELS[model]
    if not low <= d.size <= high:
        raise CameraInfoError(
            f"{where}: distortion_model {model} takes {low}-{high} coefficients, the file gives {d.size}"
        )
    if not np.isfinite(d).all():
        raise CameraInfoError(f"{where}: distortion_coefficients has a value that is not a finite number")
    k = np.array(k, dtype=np.float64)
    d = np.array(d, dtype=np.float64)
    k.flags.writeable = False
    d.flags.writeable = False
    return CameraInfo(width, height, k, model, d, name, None if str(path).startswith("<") else path)


def _integer(path: Path, fs: Any, key: str) -> int:
    node = fs.getNode(key)
    if node.empty():
        raise CameraInfoError(f"camera calibration {path}: {key} is missing")
    if not node.isInt() and not node.isReal():
        raise CameraInfoError(f"camera calibration {path}: {key} must be a whole number of pixels")
    value = node.real()
    if value != int(value) or not 1 <= value <= 65535:
        raise CameraInfoError(
            f"camera calibration {path}: {key} must be a whole number of pixels in 1..65535"
        )
    return int(value)


def _matrix(path: Path, fs: Any, key: str) -> np.ndarray:
    """An ``!!opencv-matrix`` or a ROS ``{rows, cols, data}`` map (or a bare list: one row)."""
    import cv2

    node = fs.getNode(key)
    where = f"camera calibration {path}: {key}"
    if node.empty():
        raise CameraInfoError(f"{where} is missing")
    if node.isMap() and not node.getNode("dt").empty():  # !!opencv-matrix: rows, cols, dt, data
        try:
            mat = node.mat()
        except cv2.error as exc:
            raise CameraInfoError(f"{where} is not a matrix OpenCV can read") from exc
        if mat is None:
            raise CameraInfoError(f"{where} is not a matrix OpenCV can read")
        return np.asarray(mat, dtype=np.float64)
    if node.isSeq():
        values = _numbers(where, node)
        return np.asarray(values, dtype=np.float64).reshape(1, -1)
    if not node.isMap():
        raise CameraInfoError(f"{where} must be a matrix (rows, cols, data)")
    rows, cols, data = node.getNode("rows"), node.getNode("cols"), node.getNode("data")
    if rows.empty() or cols.empty() or data.empty() or not data.isSeq():
        raise CameraInfoError(f"{where} must have rows, cols and a data list")
    values = _numbers(where, data)
    r, c = rows.real(), cols.real()
    if r != int(r) or c != int(c) or r < 1 or c < 1 or int(r) * int(c) != len(values):
        raise CameraInfoError(f"{where}: rows {r:g} x cols {c:g} does not match {len(values)} data values")
    return np.asarray(values, dtype=np.float64).reshape(int(r), int(c))


def _numbers(where: str, seq: Any) -> list[float]:
    out = []
    for i in range(seq.size()):
        item = seq.at(i)
        if not (item.isInt() or item.isReal()):
            raise CameraInfoError(f"{where}: data value {i} is not a number")
        out.append(item.real())
    return out
