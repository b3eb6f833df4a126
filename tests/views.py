"""Views of simbridge scenes for the onboard-reasoner tests (tests/test_image_cues.py and
tests/test_onboard_reasoner.py): the renders, ground rectangles seen from scenario1's launch pose, and
the crops and ground-truth class shares inside them. The fixtures that build on them are in
tests/conftest.py (``city``, ``scene``, ``launch``)."""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from companion.perception.crops import site_box
from companion.perception.site_check import SiteCheck, check_site
from simbridge.geo import euler_to_quat
from simbridge.scenarios import load_scenario
from simbridge.world.camera import Frame
from simbridge.world.live import LiveWorld
from simbridge.world.model import SurfaceClass as C

if TYPE_CHECKING:
    from companion.reasoning.onboard import OnboardReasoner

SCENE = Path(__file__).with_name("onboard_scene.toml")
LEVEL = euler_to_quat(0.0, 0.0, 0.0)
WEATHERS = ("clear", "fog", "rain")
LAUNCH = (0.0, 0.0, -110.0)  # scenario1's launch pose: 110 m above Quay Street, level, facing north
Box = tuple[int, int, int, int]


def world(name: str) -> LiveWorld:
    w = load_scenario(name, 0).terrain
    assert isinstance(w, LiveWorld)
    return w


def render(w: LiveWorld, pos: tuple[float, float, float], weather: str = "clear", t_s: float = 0.0) -> Frame:
    return w.camera_frame(pos, LEVEL, t_s, weather, np.random.default_rng(7))


def ground_box(
    w: LiveWorld,
    cam: tuple[float, float, float],
    north: tuple[float, float],
    east: tuple[float, float],
    up: float,
) -> Box:
    """Pixel box of a north x east rectangle at height ``up`` seen by the level nadir camera at ``cam``
    (image top = north, right = east; pinhole, focal (W / 2) / tan(hfov / 2))."""
    f = w.camera.focal_px
    cx, cy = w.camera.principal_px
    k = f / (-cam[2] - up)
    x0, x1 = (cx + (e - cam[1]) * k for e in east)
    y0, y1 = (cy - (n - cam[0]) * k for n in reversed(north))
    return round(x0), round(y0), round(x1), round(y1)


def crop(frame: Frame, box: Box) -> np.ndarray:
    x0, y0, x1, y1 = box
    return np.ascontiguousarray(frame.rgb[y0:y1, x0:x1])


def share(frame: Frame, box: Box, classes: Iterable[C]) -> float:
    x0, y0, x1, y1 = box
    return float(np.isin(frame.hit_class[y0:y1, x0:x1], [int(c) for c in classes]).mean())


def centre_window(frame: Frame, frac: float = 0.3) -> tuple[int, int, int, int]:
    """The middle ``frac`` of each side (what site mode looks at)."""
    h, w = frame.hit_class.shape
    ch, cw = round(h * frac), round(w * frac)
    return (w - cw) // 2, (h - ch) // 2, (w - cw) // 2 + cw, (h - ch) // 2 + ch


# Ground rectangles in scenario1 (simbridge/world/scenarios/scenario1.toml), seen from LAUNCH.
CLEAR_ROOF = ((-16.0, 16.0), (-39.0, -15.0), 22.0)  # the gravel roof, 4 m in from its parapet
CLUTTERED_ROOF = ((-18.0, 18.0), (14.0, 44.0), 18.0)  # the tar roof with HVAC units, vents, pipes
ROAD = ((-60.0, -27.0), (-6.0, 6.0), 0.0)  # Quay Street south of the roofs, half in a building's shadow
HIGHWAY = ((-40.0, 40.0), (-87.0, -73.0), 9.0)  # the elevated deck, rails and lanes
WATER = ((12.0, 48.0), (95.0, 108.0), -0.8)  # the harbour, between the piers
ROAD_CLASSES = (C.ROAD, C.VEHICLE, C.CROSSWALK)
HIGHWAY_CLASSES = (C.HIGHWAY, C.GUARD_RAIL, C.VEHICLE)


def close_up(
    w: LiveWorld,
    ne: tuple[float, float],
    up_m: float,
    height_m: float,
    weather: str = "clear",
    t_s: float = 0.0,
) -> tuple[Frame, SiteCheck]:
    """A close-up frame ``height_m`` above the surface at ``ne`` (``up_m`` high) and the LiDAR site check."""
    pos = (ne[0], ne[1], -(up_m + height_m))
    frame = render(w, pos, weather, t_s)
    lidar = w.lidar_sweep(pos, LEVEL, t_s, np.random.default_rng(2))
    return frame, check_site(lidar, pos, LEVEL, ne)


def site_cut(w: LiveWorld, frame: Frame, height_m: float, half_m: float = 6.0) -> np.ndarray:
    """The close-up the recovery loop sends: +-``half_m`` around the site under the camera
    (companion/recovery/core.py, ``closeup_half_m``; companion/perception/crops.py, ``site_box``)."""
    h, wd = frame.rgb.shape[:2]
    half = int(w.camera.focal_px * half_m / height_m)
    return crop(frame, site_box(*w.camera.principal_px, half, wd, h))


def open_field_toml(half_m: float, launch_height_m: float) -> str:
    """A scenario file of a bare flat soil field ``2 * half_m`` across and nothing else, launch above its
    middle."""
    return f"""
name = "open_field"
description = "a bare flat field and nothing else"
extent = {{ north = [{-half_m}, {half_m}], east = [{-half_m}, {half_m}] }}
resolution_m = 0.5
ground = "soil"
launch = {{ north = 0.0, east = 0.0, height_m = {launch_height_m}, yaw_deg = 0.0 }}
"""


def landnet_judge(model: str) -> OnboardReasoner:
    """The onboard tier judging with the packaged LandNet ``model`` (``landnet-s``, ``landnet-e``)."""
    from companion.reasoning.landnet import PACKAGED, LandNet
    from companion.reasoning.onboard import OnboardReasoner

    return OnboardReasoner(judge="landnet", landnet=LandNet.load(PACKAGED[model]))
