"""The camera's opt-in domain randomisation (``render(..., variety=)``) and the roof materials 22..27.

The fixed look (no variety) must stay byte for byte what the flight simulator and the benchmarks
were built on: ``_FIXED_DIGESTS`` were recorded from the renderer before varieties existed.
"""

from __future__ import annotations

import hashlib
import math
from typing import Any

import numpy as np
import pytest

from simbridge.geo import euler_to_quat
from simbridge.world.camera import CameraModel, Frame, RenderVariety, ShadowMap, render
from simbridge.world.model import Material as M
from simbridge.world.model import SurfaceClass as C
from simbridge.world.model import WorldGrid
from simbridge.world.raycast import Pyramid

SUN = (0.45, 0.35, 0.82)
LEVEL = euler_to_quat(0.0, 0.0, 0.0)
NEW_MATERIALS = (M.CORRUGATED, M.SLATE, M.SHINGLE, M.SEAM_METAL, M.GLASS, M.POOL)

# (position NED, attitude, weather): nadir; pitched up over the edge of the grid (open ground beyond
# it, sky); fog (the float image path rather than the one-pass clear path).
_POSES = (
    ((0.0, 0.0, -70.0), euler_to_quat(0.0, 0.0, 0.0), "clear"),
    ((-30.0, 0.0, -40.0), euler_to_quat(0.1, math.radians(60.0), 0.4), "clear"),
    ((5.0, 5.0, -55.0), euler_to_quat(0.05, 0.0, 1.0), "fog"),
)
# sha256 of those frames' RGB bytes, rendered before ``RenderVariety`` existed
_FIXED_DIGESTS = (
    "fc8937230d077bdc7c3bb3ec70741020188aefbec993496b5177cb471e9e7443",
    "91bfcfc13eb46b9af39032246cca426164b05251b33da912c5f4740305e71d92",
    "cbd85315f2aa0c33d85190bcac44dce9397cf75850a48d57c44ba3a04b475bd8",
)


def _fixed_world() -> WorldGrid:
    """A small world of the materials that had a fixed look before the roof materials 22..27."""
    g = WorldGrid.empty((-40.0, 40.0), (-40.0, 40.0), res=0.2, ground_cls=C.GRASS, ground_mat=M.GRASS)
    g.fill_rect((0.0, -25.0), 80.0, 8.0, 0.0, cls=C.ROAD, mat=M.ASPHALT)
    g.fill_rect((0.0, -19.0), 80.0, 3.0, 0.0, cls=C.SIDEWALK, mat=M.PAVING)
    g.fill_rect((-20.0, 0.0), 14.0, 12.0, 0.3, height_m=9.0, cls=C.ROOF_FLAT, mat=M.GRAVEL, region=1)
    g.fill_pitched((15.0, 0.0), 16.0, 10.0, 0.5, 6.0, 10.0, region=2, mat=M.TILES)
    g.fill_rect((0.0, 20.0), 10.0, 10.0, 0.0, height_m=12.0, cls=C.ROOF_FLAT, mat=M.MEMBRANE, region=3)
    g.fill_rect(
        (0.0, 20.0), 3.0, 4.0, 0.0, height_m=1.5, cls=C.ROOF_CLUTTER, mat=M.METAL, region=3, mode="add"
    )
    g.fill_rect((-25.0, 25.0), 10.0, 8.0, 0.0, height_m=4.0, cls=C.ROOF_FLAT, mat=M.TAR, region=4)
    g.fill_rect((25.0, 25.0), 8.0, 8.0, 0.0, height_m=3.0, cls=C.ROOF_FLAT, mat=M.CONCRETE, region=5)
    g.fill_rect(
        (25.0, 25.0), 4.0, 3.4, 0.0, height_m=0.3, cls=C.ROOF_CLUTTER, mat=M.SOLAR, region=5, mode="add"
    )
    g.fill_disc((-5.0, 5.0), 3.0, height_m=7.0, dome=True, cls=C.TREE, mat=M.FOLIAGE, mode="max")
    g.fill_rect((30.0, -5.0), 6.0, 10.0, 0.0, cls=C.WATER, mat=M.WATER)
    g.fill_rect((-32.0, -8.0), 6.0, 6.0, 0.0, height_m=0.5, cls=C.PIER, mat=M.WOOD)
    g.fill_rect((-10.0, 32.0), 6.0, 6.0, 0.0, height_m=0.4, cls=C.ROOF_CLUTTER, mat=M.RUBBLE)
    g.fill_rect((10.0, -10.0), 6.0, 6.0, 0.0, cls=C.GROUND, mat=M.SOIL)
    return g


@pytest.fixture(scope="module")
def fixed_scene() -> tuple[WorldGrid, Pyramid, ShadowMap]:
    g = _fixed_world()
    p = Pyramid(g.height)
    return g, p, ShadowMap(g, p, SUN)


def _frames(scene: tuple[WorldGrid, Pyramid, ShadowMap], **kw: Any) -> list[Frame]:
    g, p, sh = scene
    cam = CameraModel(320, 240, 90.0)
    return [render(g, p, sh, cam, pos, q, SUN, w, np.random.default_rng(7), **kw) for pos, q, w in _POSES]


def _digest(frame: Frame) -> str:
    return hashlib.sha256(frame.rgb.tobytes()).hexdigest()


@pytest.mark.parametrize(
    "variety", [None, RenderVariety(), RenderVariety(salt=12345)], ids=["none", "neutral", "neutral-salted"]
)
def test_fixed_look_is_byte_identical_to_before_varieties(
    fixed_scene: tuple[WorldGrid, Pyramid, ShadowMap], variety: RenderVariety | None
) -> None:
    assert tuple(_digest(f) for f in _frames(fixed_scene, variety=variety)) == _FIXED_DIGESTS


def _varied() -> RenderVariety:
    return RenderVariety(
        ambient=0.5, sun_gain=0.6, tint=0.3, texture_scale=(0.7, 1.5), orient=True, stain=0.6,
        soft_shadow=0.8, shadow_depth=0.8, salt=3,
    )  # fmt: skip


def test_variety_changes_the_image_and_is_deterministic(
    fixed_scene: tuple[WorldGrid, Pyramid, ShadowMap],
) -> None:
    once = [_digest(f) for f in _frames(fixed_scene, variety=_varied())]
    again = [_digest(f) for f in _frames(fixed_scene, variety=_varied())]
    assert once == again
    assert not set(once) & set(_FIXED_DIGESTS)
    other_salt = [_digest(f) for f in _frames(fixed_scene, variety=RenderVariety(tint=0.3, salt=4))]
    assert not set(other_salt) & set(once)


def _material_frame(mat: M, variety: RenderVariety | None = None) -> Frame:
    """A roof of one material filling a 256 px view from 5 m (about 4 cm a pixel)."""
    g = WorldGrid.empty((-15.0, 15.0), (-15.0, 15.0), res=0.1, ground_cls=C.ROOF_FLAT, ground_mat=mat)
    g.region[:] = 1
    p = Pyramid(g.height)
    return render(
        g, p, ShadowMap(g, p, SUN), CameraModel(256, 256, 90.0), (0.0, 0.0, -5.0), LEVEL, SUN,
        rng=np.random.default_rng(1), labels=True, variety=variety,
    )  # fmt: skip


def _luma(rgb: np.ndarray) -> np.ndarray:
    """Luminance of the central 96 x 96 pixels (where the vignette hardly varies)."""
    h, w = rgb.shape[:2]
    centre = rgb[h // 2 - 48 : h // 2 + 48, w // 2 - 48 : w // 2 + 48]
    return np.asarray(centre.astype(np.float64) @ np.array([0.3, 0.59, 0.11]))


@pytest.mark.parametrize("variety", [None, RenderVariety(orient=True, texture_scale=(0.7, 1.5), salt=2)])
@pytest.mark.parametrize("mat", NEW_MATERIALS, ids=[m.name for m in NEW_MATERIALS])
def test_roof_materials_are_textured_and_deterministic(mat: M, variety: RenderVariety | None) -> None:
    flat = _luma(_material_frame(M.NONE).rgb).std()  # a flat colour: sensor noise alone
    frame = _material_frame(mat, variety)
    assert frame.hit_material is not None
    assert (frame.hit_material == mat).all()
    assert _luma(frame.rgb).std() > max(3.0 * flat, 6.0), mat.name
    assert _material_frame(mat, variety).rgb.tobytes() == frame.rgb.tobytes()


def _roof_colour(salt: int) -> np.ndarray:
    frame = _material_frame(M.TILES, RenderVariety(tint=0.35, salt=salt))
    return np.asarray(frame.rgb.reshape(-1, 3).mean(axis=0))


def test_salts_tint_the_same_region_differently() -> None:
    colours = np.array([_roof_colour(salt) for salt in range(5)])
    spread = colours.max(axis=0) - colours.min(axis=0)
    assert spread.max() > 15.0  # brightness / hue of the same roof varies with the salt
    hue = colours[:, 0] / np.maximum(colours[:, 2], 1.0)  # red-to-blue: red, orange, brown, grey tiles
    assert hue.max() - hue.min() > 0.3
    assert np.array_equal(_roof_colour(3), colours[3])


def _shadow_edge(variety: RenderVariety | None) -> np.ndarray:
    """A row of pixels across the far edge of a box's shadow on flat grey ground."""
    g = WorldGrid.empty((-20.0, 20.0), (-20.0, 20.0), res=0.2, ground_mat=M.NONE)
    g.fill_rect((0.0, 0.0), 8.0, 8.0, 0.0, height_m=6.0, cls=C.ROOF_FLAT, mat=M.NONE, region=1)
    p = Pyramid(g.height)
    cam = CameraModel(160, 160, 90.0)
    frame = render(
        g, p, ShadowMap(g, p, SUN), cam, (0.0, 0.0, -30.0), LEVEL, SUN, rng=np.random.default_rng(1),
        variety=variety,
    )  # fmt: skip
    return np.asarray(frame.rgb[94:108, 70:80, 0], np.float64)  # rows: shadow, then lit ground


def test_soft_shadow_has_a_penumbra() -> None:
    hard = _shadow_edge(None)
    lit, dark = np.median(hard[-4:]), np.median(hard[:4])
    assert lit - dark > 60.0  # the crop does cross the shadow's edge
    between = (dark + 15.0, lit - 15.0)
    n_hard = int(((hard > between[0]) & (hard < between[1])).sum())
    soft = _shadow_edge(RenderVariety(soft_shadow=1.0))
    n_soft = int(((soft > between[0]) & (soft < between[1])).sum())
    assert n_hard == 0
    assert n_soft >= 2 * hard.shape[1]  # at least two rows of intermediate values along the edge
    shallow = _shadow_edge(RenderVariety(shadow_depth=0.5))
    assert np.median(shallow[:4]) > dark + 20.0  # a shallower shadow is lighter


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"tint": -0.1}, "tint"),
        ({"ambient": 1.5}, "ambient"),
        ({"ambient": -0.01}, "ambient"),
        ({"sun_gain": float("nan")}, "sun_gain"),
        ({"stain": 2.0}, "stain"),
        ({"soft_shadow": -1.0}, "soft_shadow"),
        ({"shadow_depth": 1.1}, "shadow_depth"),
        ({"texture_scale": (1.5, 0.7)}, "texture_scale"),
        ({"texture_scale": (0.1, 1.0)}, "texture_scale"),
        ({"salt": -1}, "salt"),
        ({"salt": 2**31}, "salt"),
        ({"orient": 1}, "orient"),
    ],
)
def test_invalid_variety_is_rejected(kwargs: dict[str, Any], message: str) -> None:
    with pytest.raises(ValueError, match=f"RenderVariety.{message} must be"):
        RenderVariety(**kwargs)


def test_render_rejects_a_variety_of_the_wrong_type(
    fixed_scene: tuple[WorldGrid, Pyramid, ShadowMap],
) -> None:
    g, p, sh = fixed_scene
    with pytest.raises(ValueError, match="variety must be a RenderVariety"):
        render(g, p, sh, CameraModel(32, 32), (0.0, 0.0, -50.0), LEVEL, SUN, variety={"tint": 0.2})  # type: ignore[arg-type]


def test_sampled_varieties_are_valid_seeded_and_varied() -> None:
    a = [RenderVariety.sample(np.random.default_rng(seed)) for seed in range(20)]
    b = [RenderVariety.sample(np.random.default_rng(seed)) for seed in range(20)]
    assert a == b
    assert len({v.salt for v in a}) == 20
    assert not any(v.is_neutral for v in a)
    assert min(v.ambient for v in a) < 0.5 < max(v.ambient for v in a)  # hard sun and overcast


def test_ray_cache_stays_bounded_over_many_lenses() -> None:
    # Training data draws a new lens per view: the per-model ray cache must not grow without bound.
    from simbridge.world import camera as cam

    for k in range(3 * cam._RAYS_CACHED):
        model = cam.CameraModel(32, 32, 30.0 + k * 0.5)
        rays, norms = model.unit_rays_body(), model.ray_norms()
        assert rays.shape == (32 * 32, 3)
        assert norms.shape == (32 * 32,)
    assert len(cam._RAYS_BODY) <= cam._RAYS_CACHED
