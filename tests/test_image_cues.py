"""Image cues (companion/reasoning/image_cues.py) on simbridge renders whose content the renderer's
per-pixel ground truth (``Frame.hit_class``) states: a clear gravel roof, a cluttered roof, a road, the
elevated highway, water, a park, and (tests/onboard_scene.toml) a tiled roof, a roof with one HVAC unit
and painted letters, a shaded roof and a person on a roof. Each crop's content is checked against the
ground truth before its cues are.

The scene helpers are in tests/views.py, shared with tests/test_onboard_reasoner.py.
"""

from __future__ import annotations

import json
import math

import cv2
import numpy as np
import pytest

from companion.reasoning.image_cues import ImageCues, analyse
from simbridge.world.camera import Frame
from simbridge.world.live import LiveWorld
from simbridge.world.model import Material
from simbridge.world.model import SurfaceClass as C
from tests.views import (
    CLEAR_ROOF,
    CLUTTERED_ROOF,
    HIGHWAY,
    HIGHWAY_CLASSES,
    LAUNCH,
    ROAD,
    ROAD_CLASSES,
    WATER,
    WEATHERS,
    centre_window,
    crop,
    ground_box,
    render,
    share,
)


def cues_of(
    city: LiveWorld, frame: Frame, rect: tuple[tuple[float, float], tuple[float, float], float]
) -> ImageCues:
    return analyse(crop(frame, ground_box(city, LAUNCH, *rect)))


# ------------------------------------------------------------------------------------------ surfaces
@pytest.mark.parametrize("weather", WEATHERS)
def test_image_cues_clear_gravel_roof_has_no_hazard(
    city: LiveWorld, launch: dict[str, Frame], weather: str
) -> None:
    frame = launch[weather]
    box = ground_box(city, LAUNCH, *CLEAR_ROOF)
    assert share(frame, box, [C.ROOF_FLAT]) == 1.0
    cues = analyse(crop(frame, box))
    assert cues.hazard < 0.3, cues.observations()
    assert cues.raised_blobs == 0
    assert cues.lane_lines == 0
    assert cues.water_share == 0.0
    assert "no clutter" in cues.observations()


def test_image_cues_gravel_grain_is_named_not_counted(city: LiveWorld, launch: dict[str, Frame]) -> None:
    cues = cues_of(city, launch["clear"], CLEAR_ROOF)
    assert cues.uniform_grain
    assert cues.grain > 0.03
    assert any("texture (not a hazard)" in o for o in cues.observations())


@pytest.mark.parametrize("weather", WEATHERS)
def test_image_cues_cluttered_roof_has_raised_objects(
    city: LiveWorld, launch: dict[str, Frame], weather: str
) -> None:
    frame = launch[weather]
    box = ground_box(city, LAUNCH, *CLUTTERED_ROOF)
    assert share(frame, box, [C.ROOF_FLAT, C.ROOF_CLUTTER]) > 0.99
    assert share(frame, box, [C.ROOF_CLUTTER]) > 0.15
    cues = analyse(crop(frame, box))
    assert cues.raised_blobs >= 5
    assert cues.hazard >= 2.5
    assert cues.observations()[0].startswith("HVAC-like blobs with shadows")


@pytest.mark.parametrize("weather", WEATHERS)
def test_image_cues_road_has_lane_markings(city: LiveWorld, launch: dict[str, Frame], weather: str) -> None:
    frame = launch[weather]
    box = ground_box(city, LAUNCH, *ROAD)
    assert share(frame, box, ROAD_CLASSES) == 1.0
    cues = analyse(crop(frame, box))
    assert cues.lane_lines >= 2
    assert any(o.startswith("lane markings") for o in cues.observations())
    assert cues.hazard >= 0.4  # markings alone in fog (the haze hides the asphalt's darkness)


@pytest.mark.parametrize("weather", WEATHERS)
def test_image_cues_highway_has_markings_and_traffic(
    city: LiveWorld, launch: dict[str, Frame], weather: str
) -> None:
    frame = launch[weather]
    box = ground_box(city, LAUNCH, *HIGHWAY)
    assert share(frame, box, HIGHWAY_CLASSES) == 1.0
    assert share(frame, box, [C.VEHICLE]) > 0.0
    cues = analyse(crop(frame, box))
    assert cues.lane_lines >= 5
    assert cues.road
    assert cues.raised_blobs >= 1
    assert cues.hazard >= 3.0


@pytest.mark.parametrize("weather", WEATHERS)
def test_image_cues_water(city: LiveWorld, launch: dict[str, Frame], weather: str) -> None:
    frame = launch[weather]
    box = ground_box(city, LAUNCH, *WATER)
    assert share(frame, box, [C.WATER]) == 1.0
    cues = analyse(crop(frame, box))
    assert cues.water_share > 0.9
    assert cues.hazard >= 3.0
    assert cues.observations()[0].startswith("water")


def test_image_cues_park_is_vegetation(city: LiveWorld) -> None:
    cam = (-87.0, -213.0, -80.0)  # over Harbour Park's western block
    frame = render(city, cam)
    box = ground_box(city, cam, (-112.0, -62.0), (-233.0, -193.0), 0.0)
    assert share(frame, box, [C.GRASS, C.TREE]) > 0.95
    cues = analyse(crop(frame, box))
    assert cues.vegetation_share > 0.5
    assert cues.observations()[0].startswith("vegetation")


# ------------------------------------------------------------------------------ what is not a hazard
@pytest.mark.parametrize(
    ("roof", "ne", "up"), [("tiles", (-55.0, -35.0), 16.0), ("gravel", (0.0, -35.0), 20.0)]
)
@pytest.mark.parametrize("height_m", [6.0, 12.0, 30.0])
def test_image_cues_uniform_texture_is_not_clutter(
    scene: LiveWorld, roof: str, ne: tuple[float, float], up: float, height_m: float
) -> None:
    """Tiles and gravel close up, where their grain is coarse: no objects, no hazard (smaller models in
    the reference study called them "uneven")."""
    frame = render(scene, (ne[0], ne[1], -(up + height_m)))
    box = centre_window(frame)
    assert share(frame, box, [C.ROOF_FLAT]) == 1.0
    for cues in (analyse(crop(frame, box)), analyse(frame.rgb, site=True)):
        assert cues.raised_blobs == 0, cues.observations()
        assert cues.flat_blobs == 0
        assert cues.hazard < 0.3
        assert cues.uniform_grain


def test_image_cues_shadow_is_not_a_hazard(scene: LiveWorld) -> None:
    cam = (70.0, 35.0, -60.0)  # over the shaded roof, the tower's shadow across its middle
    frame = render(scene, cam)
    box = ground_box(scene, cam, (60.0, 80.0), (22.0, 48.0), 20.0)
    assert share(frame, box, [C.ROOF_FLAT]) == 1.0
    lum = crop(frame, box).mean(axis=2)
    dark, lit = np.percentile(lum, 20), np.percentile(lum, 80)
    assert dark < 0.6 * lit  # a cast shadow really lies across the crop
    cues = analyse(crop(frame, box))
    assert cues.shadow_share > 0.3
    assert cues.hazard < 0.5
    assert cues.raised_blobs == 0
    assert any(o.startswith("shadow") and "(not a hazard)" in o for o in cues.observations())


def test_image_cues_hvac_casts_a_shadow_painted_letters_do_not(scene: LiveWorld) -> None:
    cam = (-55.0, 35.0, -50.0)
    frame = render(scene, cam)
    hvac = ground_box(scene, cam, (-57.0, -47.0), (35.0, 45.0), 18.0)
    letters = ground_box(scene, cam, (-64.0, -60.0), (28.0, 37.0), 18.0)
    assert share(frame, hvac, [C.ROOF_CLUTTER]) > 0.03
    assert share(frame, letters, [C.ROOF_FLAT]) == 1.0  # paint keeps the roof's class ...
    grid = scene.grid
    rows = slice(round((-64.0 - grid.n0) / grid.res), round((-60.0 - grid.n0) / grid.res))
    cols = slice(round((28.0 - grid.e0) / grid.res), round((37.0 - grid.e0) / grid.res))
    assert (grid.mat[rows, cols] == Material.PAINT_TEXT).any()  # ... and only changes the material
    raised = analyse(crop(frame, hvac))
    assert raised.raised_blobs == 1
    assert raised.observations()[0].startswith("HVAC-like blobs with shadows (1)")
    paint = analyse(crop(frame, letters))
    assert paint.raised_blobs == 0
    assert paint.flat_blobs >= 1
    assert paint.hazard < 1.0


@pytest.mark.parametrize("height_m", [10.0, 20.0])
@pytest.mark.parametrize("weather", ["clear", "rain"])
def test_image_cues_person_on_a_roof(scene: LiveWorld, height_m: float, weather: str) -> None:
    frame = render(scene, (0.0, 35.0, -(20.0 + height_m)), weather)
    assert share(frame, centre_window(frame), [C.PEDESTRIAN]) > 0.0
    cues = analyse(frame.rgb, site=True)
    assert cues.raised_blobs >= 1
    empty = analyse(render(scene, (0.0, -35.0, -(20.0 + height_m)), weather).rgb, site=True)
    assert empty.raised_blobs == 0  # the same roof without anyone on it


# ------------------------------------------------------------------------------------------ site mode, scale
def test_image_cues_site_mode_judges_the_surface_under_the_centre(city: LiveWorld) -> None:
    """60 m above the clear roof the frame's middle also shows Quay Street beyond the roof's edge: the
    whole window sees the street, site mode sees the roof."""
    frame = render(city, (0.0, -27.0, -82.0))
    window = centre_window(frame)
    assert share(frame, window, ROAD_CLASSES) > 0.0
    whole = analyse(crop(frame, window))
    site = analyse(frame.rgb, site=True)
    assert whole.lane_lines >= 1
    assert site.lane_lines == 0
    assert site.hazard < 0.3
    assert 0.3 < site.site_share < 1.0


def test_image_cues_verdicts_hold_across_pixel_scales(city: LiveWorld, launch: dict[str, Frame]) -> None:
    """The same surfaces from 110 m (a 130 px crop), 40 m above them (the whole close-up), and the far
    crop blown up 4 times: a clear roof stays clear, a cluttered one cluttered."""
    far_clear = crop(launch["clear"], ground_box(city, LAUNCH, *CLEAR_ROOF))
    far_clutter = crop(launch["clear"], ground_box(city, LAUNCH, *CLUTTERED_ROOF))
    near_clear = render(city, (0.0, -27.0, -62.0)).rgb
    near_clutter = render(city, (0.0, 29.0, -58.0)).rgb
    for img in (
        far_clear,
        near_clear,
        cv2.resize(far_clear, None, fx=4, fy=4, interpolation=cv2.INTER_NEAREST),
    ):
        cues = analyse(img, site=img is near_clear)
        assert cues.raised_blobs == 0
        assert cues.hazard < 0.3
    for img in (
        far_clutter,
        near_clutter,
        cv2.resize(far_clutter, None, fx=4, fy=4, interpolation=cv2.INTER_NEAREST),
    ):
        cues = analyse(img, site=img is near_clutter)
        assert cues.raised_blobs >= 3
        assert cues.hazard >= 2.5


# ------------------------------------------------------------------------------------------ inputs, output
@pytest.mark.parametrize(
    ("bad", "message"),
    [
        (np.zeros((0, 5, 3), np.uint8), "non-empty"),
        (np.zeros((5, 0, 3), np.uint8), "non-empty"),
        (np.zeros((5, 5), np.uint8), r"\(height, width, 3\)"),
        (np.zeros((5, 5, 4), np.uint8), r"\(height, width, 3\)"),
        (np.zeros((5, 5, 3), np.float32), "dtype uint8"),
        (np.zeros((5, 5, 3), np.int16), "dtype uint8"),
        ([[[0, 0, 0]]], "numpy array"),
    ],
)
def test_image_cues_bad_input_raises(bad: object, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        analyse(bad)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=message):
        analyse(bad, site=True)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    "img",
    [
        np.zeros((120, 160, 3), np.uint8),
        np.full((120, 160, 3), 128, np.uint8),
        np.full((120, 160, 3), 255, np.uint8),
        np.zeros((1, 1, 3), np.uint8),
        np.full((2, 3, 3), 90, np.uint8),
        np.full((7, 300, 3), 200, np.uint8),
        np.random.default_rng(3).integers(0, 256, (64, 64, 3), dtype=np.uint8),
        np.zeros((2000, 3000, 3), np.uint8),
    ],
    ids=["black", "grey", "white", "1x1", "2x3", "sliver", "noise", "large"],
)
def test_image_cues_degenerate_images_do_not_crash(img: np.ndarray) -> None:
    for site in (False, True):
        cues = analyse(img, site=site)
        assert math.isfinite(cues.hazard)
        assert cues.hazard >= 0.0
        assert cues.size_px == img.shape[:2]
        json.dumps(cues.to_json())
    if img.std() == 0:  # a featureless image shows no object, line, water or vegetation
        cues = analyse(img)
        assert (cues.raised_blobs, cues.flat_blobs, cues.lane_lines) == (0, 0, 0)
        assert cues.water_share == cues.vegetation_share == 0.0


def test_image_cues_are_deterministic_and_serialise(city: LiveWorld, launch: dict[str, Frame]) -> None:
    img = crop(launch["rain"], ground_box(city, LAUNCH, *CLUTTERED_ROOF))
    a, b = analyse(img), analyse(img.copy())
    assert a == b
    doc = json.loads(json.dumps(a.to_json()))
    assert doc["hazard"] == round(a.hazard, 3)
    assert doc["counts"]["raised_blobs"] == a.raised_blobs
    assert doc["observations"] == list(a.observations())
    assert set(doc["terms"]) <= {"water", "vegetation", "markings", "raised", "coloured", "lines_raised",
                                 "dark_blobs", "flat_blobs", "asphalt", "road_texture", "edges"}  # fmt: skip
    assert sum(doc["terms"].values()) == pytest.approx(a.hazard, abs=0.01)
