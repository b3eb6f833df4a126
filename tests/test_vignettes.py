"""Vignettes (simbridge.world.vignettes): small fine-grained training worlds."""

from __future__ import annotations

import math

import numpy as np
import pytest

from simbridge.geo import euler_to_quat
from simbridge.world.camera import CameraModel, render
from simbridge.world.live import LiveWorld
from simbridge.world.model import Material as M
from simbridge.world.model import SurfaceClass as C
from simbridge.world.vignettes import (
    VIGNETTE_KINDS,
    build_vignette,
    build_vignette_roofs,
    gable_heights,
    hip_heights,
)

# the classes each kind must hold (view strata are drawn by the class under the centre)
EXPECTED = {
    "house": (C.ROOF_PITCHED, C.GRASS),
    "hip_house": (C.ROOF_PITCHED, C.GRASS),
    "barn": (C.ROOF_PITCHED, C.GROUND),
    "flat_roof": (C.ROOF_FLAT,),
    "garden": (C.GRASS,),
    "street": (C.ROAD, C.SIDEWALK),
    "car_park": (C.PARKING_LOT, C.VEHICLE),
    "pond": (C.WATER, C.GRASS),
    "yard": (C.GROUND,),
}


def test_kinds_listed() -> None:
    assert set(EXPECTED) == set(VIGNETTE_KINDS)


@pytest.mark.parametrize("kind", VIGNETTE_KINDS)
def test_every_kind_builds(kind: str) -> None:
    for seed in (0, 1):
        w = build_vignette(seed, kind)
        g = w.grid
        assert 0.04 <= g.res <= 0.08
        n0, n1, e0, e1 = g.extent_m
        assert 29.0 <= n1 - n0 <= 51.0
        assert 29.0 <= e1 - e0 <= 51.0
        assert 15.0 <= w.sun.elevation_deg <= 80.0
        assert np.isfinite(g.height).all()
        for cls in EXPECTED[kind]:
            assert (g.cls == int(cls)).sum() > 500, (kind, seed, cls.name)


def test_deterministic() -> None:
    for kind in (None, "street", "garden"):
        a, b = build_vignette(7, kind), build_vignette(7, kind)
        assert a.grid.digest() == b.grid.digest()
        assert np.array_equal(a.grid.mat, b.grid.mat)
        assert np.array_equal(a.grid.region, b.grid.region)
        assert a.sun == b.sun
    assert build_vignette(7, "house").grid.digest() != build_vignette(8, "house").grid.digest()
    assert build_vignette(3).name == build_vignette(3).name


def test_unknown_kind() -> None:
    with pytest.raises(ValueError, match="house"):
        build_vignette(0, "castle")


def test_clear_and_cluttered_roofs() -> None:
    levels: dict[str, int] = {}
    styles: set[str] = set()
    materials: set[M] = set()
    for seed in range(12):
        for kind in ("house", "hip_house", "flat_roof", "barn", "street"):
            w, roofs = build_vignette_roofs(seed, kind)
            g = w.grid
            for r in roofs:
                own = g.region == r.region
                assert own.any()
                clutter = int((own & (g.cls == int(C.ROOF_CLUTTER))).sum())
                if r.clutter == "clear":
                    assert clutter == 0, (seed, kind, r)
                else:
                    assert clutter > 0, (seed, kind, r)
                levels[r.clutter] = levels.get(r.clutter, 0) + 1
                styles.add(r.style)
                materials.add(r.material)
    total = sum(levels.values())
    assert set(levels) == {"clear", "single", "some", "heavy"}
    assert 0.3 < levels["clear"] / total < 0.7
    assert styles == {"gable", "hip", "flat", "barn"}
    assert {M.TILES, M.SLATE, M.SHINGLE, M.CORRUGATED} <= materials


def test_single_object_is_small() -> None:
    """A roof of clutter level ``single`` holds one object: a few square metres of clutter at most."""
    seen = 0
    for seed in range(30):
        w, roofs = build_vignette_roofs(seed, "flat_roof" if seed % 2 else "house")
        for r in roofs:
            if r.clutter == "single":
                cells = ((w.grid.region == r.region) & (w.grid.cls == int(C.ROOF_CLUTTER))).sum()
                assert 0 < cells * w.grid.res**2 < 8.0
                seen += 1
    assert seen > 0


def test_hip_heights() -> None:
    length, width, eave, pitch = 12.0, 8.0, 3.0, 30.0
    u, v = np.meshgrid(np.linspace(-6, 6, 241), np.linspace(-4, 4, 161), indexing="ij")
    h = hip_heights(u, v, length, width, eave, pitch)
    slope = math.tan(math.radians(pitch))
    ridge = eave + slope * width / 2
    assert h.max() == pytest.approx(ridge, abs=1e-4)
    # the ridge lies inside the footprint: along v = 0 for |u| <= (length - width) / 2
    top = np.argwhere(np.isclose(h, ridge, atol=1e-4))
    assert np.abs(v[top[:, 0], top[:, 1]]).max() < 0.06
    assert np.abs(u[top[:, 0], top[:, 1]]).max() <= (length - width) / 2 + 0.06
    # eaves all round the edge
    for edge in (h[0], h[-1], h[:, 0], h[:, -1]):
        assert np.allclose(edge, eave, atol=1e-4)
    # every face has the roof's slope
    gu, gv = np.gradient(h.astype(np.float64), u[:, 0], v[0])
    grad = np.hypot(gu, gv)
    faces = np.abs(np.abs(u) - (length / 2 - width / 2) - np.abs(v)) > 0.2  # away from hips and ridge
    faces &= np.abs(v) > 0.2
    assert np.allclose(grad[1:-1, 1:-1][faces[1:-1, 1:-1]], slope, atol=1e-3)
    g = gable_heights(v, width, eave, pitch)
    assert g.max() == pytest.approx(ridge, abs=1e-4)
    assert np.allclose(g[:, 0], eave)


def test_hipped_roof_in_world() -> None:
    w, roofs = build_vignette_roofs(2, "hip_house")
    r = roofs[0]
    assert r.style == "hip"
    g = w.grid
    roof = (g.region == r.region) & (g.cls == int(C.ROOF_PITCHED))
    h = np.where(roof, g.height, -np.inf)
    i, j = np.unravel_index(int(np.argmax(h)), h.shape)
    # the peak lies well inside the footprint, no higher than the ridge
    n, e = g.n0 + (i + 0.5) * g.res, g.e0 + (j + 0.5) * g.res
    cs, sn = math.cos(r.yaw_rad), math.sin(r.yaw_rad)
    du, dv = (
        (n - r.centre_ne[0]) * cs + (e - r.centre_ne[1]) * sn,
        -(n - r.centre_ne[0]) * sn + (e - r.centre_ne[1]) * cs,
    )
    assert abs(dv) < r.width_m / 4
    assert abs(du) < r.length_m / 2
    ridge = r.height_m + math.tan(math.radians(r.pitch_deg)) * r.width_m / 2
    assert float(g.height[i, j]) <= ridge + 1e-3
    assert float(g.height[roof].min()) >= r.height_m - 1e-3


def test_actors_have_colours() -> None:
    w = build_vignette(4, "car_park")
    g = w.grid
    cars = g.cls == int(C.VEHICLE)
    assert cars.any()
    assert (g.region[cars & (g.mat == int(M.CAR_PAINT))] < 0).all()
    assert len(np.unique(g.region[cars])) > 3


@pytest.mark.parametrize("kind", VIGNETTE_KINDS)
def test_renders(kind: str) -> None:
    world = build_vignette(5, kind)
    live = LiveWorld(world)
    g = live.grid
    camera = CameraModel(96, 96, 50.0)
    above = 0.05 * camera.focal_px  # 5 cm per pixel
    frame = render(
        g, live.pyramid, live.shadow, camera, (0.0, 0.0, -(g.height_at(0.0, 0.0) + above)),
        euler_to_quat(0.0, 0.0, 0.0), live.sun_neu, "clear", np.random.default_rng(0),
    )  # fmt: skip
    assert frame.rgb.shape == (96, 96, 3)
    assert float(frame.rgb.std()) > 4.0
    assert (frame.hit_class != 255).all()  # looking straight down: no sky
