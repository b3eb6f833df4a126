"""The OpenCV that tests and benchmarks import is the headless build a vehicle's install gets.

The companion depends on ``opencv-python-headless``; MAVProxy, a test tool in the dev extra, depends on
``opencv-python``, the build with Qt. Both write the one ``cv2`` package, and whichever pip writes last is
imported. The Qt build maps its GUI libraries into every process that imports cv2 (about 10 MB more
resident), so memory figures measured with it would not be the vehicle's. The Makefile writes the
headless build again after the extras (``HEADLESS_CV2``)."""

from __future__ import annotations

import re

import cv2


def test_cv2_is_the_headless_build_without_a_gui() -> None:
    info = cv2.getBuildInformation()
    gui = re.search(r"^\s*GUI:\s*(\S+)", info, re.MULTILINE)
    assert gui is not None, "OpenCV's build information has no GUI line"
    assert gui.group(1) == "NONE", (
        f"cv2 is the {gui.group(1)} build: reinstall opencv-python-headless last "
        "(make's HEADLESS_CV2 step) so that the tests load what a vehicle loads"
    )
