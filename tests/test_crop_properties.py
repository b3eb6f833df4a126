"""Properties (hypothesis) of the recovery chain's second stage, the crops (stage 2 of
tests/test_chain_properties.py): a rank's crops of any box in any context variant hold the box at
their core, padding and site boxes stay inside the image down to one pixel at every edge and corner,
invalid boxes are a CropError, and a confirmation's close-up is never empty.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from companion.guidance.frames import PinholeCamera, quat_to_matrix
from companion.perception.crops import (
    MIN_SITE_HALF_PX,
    CropError,
    crop,
    pad_box,
    pad_of,
    rank_crops,
    site_box,
)
from companion.recovery import site_closeup
from tests.test_chain_properties import CONTEXTS, QUICK, Box, assert_box_inside, attitudes, cameras, spans


# ---------------------------------------------------------------------------------------- 2. crops
@st.composite
def image_and_box(draw: st.DrawFn, max_side: int = 80) -> tuple[np.ndarray, Box]:
    w, h = draw(st.integers(1, max_side)), draw(st.integers(1, max_side))
    x0, x1 = draw(spans(w, 4))
    y0, y1 = draw(spans(h, 4))
    # every pixel distinct: a crop can only equal the image where it was cut from
    image = np.arange(h * w * 3, dtype=np.uint32).reshape(h, w, 3)
    return image, (x0, y0, x1, y1)


@QUICK
@given(image_and_box(), st.sampled_from(CONTEXTS))
def test_rank_crops_any_box_any_context_holds_the_box_at_its_core(
    image_box: tuple[np.ndarray, Box], context: str
) -> None:
    image, box = image_box
    h, w = image.shape[:2]
    (one,), (core,) = rank_crops(image, [box], context)
    assert one.size > 0
    assert_box_inside(core, one.shape[1], one.shape[0])
    x0, y0, x1, y1 = box
    cx0, cy0, cx1, cy1 = core
    assert np.array_equal(one[cy0:cy1, cx0:cx1], image[y0:y1, x0:x1])
    px0, py0, px1, py1 = pad_box(box, pad_of(context), w, h)
    assert np.array_equal(one, image[py0:py1, px0:px1])
    if pad_of(context) == 0:
        assert core == (0, 0, x1 - x0, y1 - y0)


@QUICK
@given(image_and_box(), st.floats(min_value=0.0, allow_infinity=False))
def test_crop_any_box_any_padding_contains_the_box(image_box: tuple[np.ndarray, Box], pad: float) -> None:
    image, box = image_box
    h, w = image.shape[:2]
    out = crop(image, box, pad)
    x0, y0, x1, y1 = pad_box(box, pad, w, h)
    assert_box_inside((x0, y0, x1, y1), w, h)
    assert x0 <= box[0]
    assert y0 <= box[1]
    assert x1 >= box[2]
    assert y1 >= box[3]
    assert out.shape[:2] == (y1 - y0, x1 - x0)


ONE_PIXEL_PLACES = [(fx, fy) for fx in (0.0, 0.5, 1.0) for fy in (0.0, 0.5, 1.0)]


@pytest.mark.parametrize("context", CONTEXTS)
@pytest.mark.parametrize(("w", "h"), [(960, 540), (1, 1), (7, 1), (1, 7), (2, 2)])
def test_rank_crops_one_pixel_box_at_every_edge_and_corner(context: str, w: int, h: int) -> None:
    image = np.arange(h * w * 3, dtype=np.uint32).reshape(h, w, 3)
    boxes = []
    for fx, fy in ONE_PIXEL_PLACES:
        x, y = min(int(fx * w), w - 1), min(int(fy * h), h - 1)
        boxes.append((x, y, x + 1, y + 1))
    crops, cores = rank_crops(image, boxes, context)
    for (x, y, _, _), one, (cx0, cy0, cx1, cy1) in zip(boxes, crops, cores, strict=True):
        assert one.size > 0
        assert (cx1 - cx0, cy1 - cy0) == (1, 1)
        assert np.array_equal(one[cy0, cx0], image[y, x])


@pytest.mark.parametrize(
    ("box", "pad"),
    [
        ((0, 0, 961, 10), 0.2),  # past the right edge
        ((-1, 0, 10, 10), 0.2),  # left of the image
        ((5, 5, 5, 6), 0.0),  # no width: a box with no width
        ((5, 6, 6, 6), 0.0),  # no height
        ((10, 0, 5, 10), 0.0),  # inverted
        ((0, 0, 10, 10), -0.1),  # negative padding
        ((0, 0, 10, 10), math.nan),
        ((0, 0, 10, 10), math.inf),
        ((0, 0, math.nan, 10), 0.2),
        ((0, 0, 10), 0.2),
    ],
)
def test_pad_box_invalid_box_or_padding_raises_crop_error(box: tuple[float, ...], pad: float) -> None:
    with pytest.raises(CropError) as info:
        pad_box(box, pad, 960, 540)  # type: ignore[arg-type]
    assert isinstance(info.value, ValueError)


@QUICK
@given(
    st.integers(1, 2000),
    st.integers(1, 2000),
    st.floats(0.0, 1.0, exclude_max=True),
    st.floats(0.0, 1.0, exclude_max=True),
    st.one_of(st.integers(-100, 5000), st.just(math.inf), st.just(-math.inf), st.floats(0.0, 1e12)),
)
def test_site_box_any_pixel_inside_gives_a_box_around_it(
    w: int, h: int, fu: float, fv: float, half_px: float
) -> None:
    u, v = fu * w, fv * h
    u, v = min(u, math.nextafter(w, 0.0)), min(v, math.nextafter(h, 0.0))
    box = site_box(u, v, half_px, w, h)
    assert_box_inside(box, w, h)
    x0, y0, x1, y1 = box
    assert x0 <= int(u) < x1
    assert y0 <= int(v) < y1
    assert x1 - x0 >= min(w, MIN_SITE_HALF_PX)
    assert y1 - y0 >= min(h, MIN_SITE_HALF_PX)


@pytest.mark.parametrize(("u", "v"), [(-0.01, 5.0), (960.0, 5.0), (5.0, 540.0), (math.nan, 5.0)])
def test_site_box_pixel_outside_raises_crop_error(u: float, v: float) -> None:
    with pytest.raises(CropError, match="outside"):
        site_box(u, v, 50, 960, 540)


@st.composite
def site_positions(
    draw: st.DrawFn, cam: PinholeCamera, pos: np.ndarray, quat: tuple[float, float, float, float]
) -> np.ndarray:
    """A site NED point: in view, on the image border, outside it, behind the camera, at the camera."""
    kind = draw(st.sampled_from(["inside", "border", "outside", "behind", "zero", "far"]))
    if kind == "zero":
        return pos.copy()
    if kind == "inside":
        u, v = draw(st.floats(0.0, cam.width - 1e-6)), draw(st.floats(0.0, cam.height - 1e-6))
    elif kind == "border":
        u = draw(st.sampled_from([0.0, math.nextafter(cam.width, 0.0), cam.width - 0.5, cam.width / 2]))
        v = draw(st.sampled_from([0.0, math.nextafter(cam.height, 0.0), cam.height - 0.5, cam.height / 2]))
    else:
        u, v = draw(st.floats(-3.0 * cam.width, 4.0 * cam.width)), draw(st.floats(-3.0, 4.0)) * cam.height
    dist = draw(st.floats(1e-4, 1e5))
    if kind == "behind":
        dist = -dist
    elif kind == "far":
        dist = 1e6
    ray_frd = cam.pixel_ray_frd(u, v)
    out: np.ndarray = pos + quat_to_matrix(quat) @ (ray_frd * dist)
    return out


@QUICK
@given(st.data(), cameras, attitudes(60.0), st.floats(0.5, 300.0), st.floats(0.0, 50.0))
def test_site_closeup_any_site_position_gives_a_nonempty_image(
    data: st.DataObject,
    cam: PinholeCamera,
    quat: tuple[float, float, float, float],
    alt_m: float,
    half_m: float,
) -> None:
    pos = np.array([3.0, -7.0, -alt_m])
    target = data.draw(site_positions(cam, pos, quat))
    image = np.zeros((cam.height, cam.width, 3), np.uint8)
    out = site_closeup(image, cam, tuple(pos), quat, tuple(target), half_m)
    assert out.dtype == np.uint8
    assert out.ndim == 3
    assert out.shape[2] == 3
    assert 1 <= out.shape[0] <= cam.height
    assert 1 <= out.shape[1] <= cam.width
