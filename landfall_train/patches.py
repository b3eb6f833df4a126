"""Labelled training patches rendered from simbridge's procedural cities.

Each *world* is one procedural city (``generate_city(seed, CITY_SIZE_M, CITY_RES_M)``) under its own sun
(azimuth any, elevation ``SUN_ELEVATION_DEG``), with its traffic and pedestrians at random times. Views are
stratified by what lies under the camera (``STRATA``: clear and cluttered roofs, pitched roofs, roads,
markings, water, lawns, trees, sidewalks, vehicles, people), so every class is seen often enough; each
view randomises the ground resolution (``GSD_M``, log-uniform), the lens (``HFOV_DEG``), the tilt (up to
``MAX_TILT_DEG``), the heading, the weather (clear, fog, rain) and the palette (each material's RGB
scaled by up to +-``PALETTE_JITTER`` per channel). A patch is a ``PATCH_PX`` square RGB image and its
per-pixel class map (:func:`landfall_train.labels.label_map`).

A city at 0.1 m cells is too coarse for a close-up at 2-5 cm per pixel and has few roof kinds, so most
patches come from **vignettes** (:mod:`simbridge.world.vignettes`): small scenes at 4-8 cm cells
(houses with gable or hipped roofs of tiles, slate, shingle, corrugated or standing-seam sheet; barns;
flat roofs; gardens with pools, people and cars; streets and car parks; ponds; yards), each in clear
and cluttered variants, seen at ``VIGNETTE_GSD_M`` under the renderer's domain randomisation
(``RenderVariety.sample`` per view: overcast or sunny light, a colour tint per building, texture scale
and direction, stains, soft shadows). City views keep the flight simulator's own look.

**Excluded worlds.** What the evaluation flies never becomes training data: city seeds below
``MIN_CITY_SEED`` (``companion-bench city`` flies city 0), and no scenario file (scenario1, scenario2,
tests/onboard_scene.toml) is ever loaded here.

Patches go to ``OUT/shard-SEED.npz`` (vignettes: ``shard-FIRST.npz`` per ``VIGNETTES_PER_SHARD``, a
shorter last shard ``shard-FIRST-COUNT.npz``)
(``rgb`` (N, S, S, 3) uint8, ``labels`` (N, S, S) uint8, ``meta``
JSON text), one shard per city; the same seed gives the same bytes.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from landfall_train.labels import label_map
from simbridge.geo import euler_to_quat
from simbridge.world.camera import WEATHERS, CameraModel, RenderVariety, default_palette, render
from simbridge.world.city import generate_city
from simbridge.world.live import LiveWorld
from simbridge.world.model import Material as M
from simbridge.world.model import SurfaceClass as C
from simbridge.world.model import WorldGrid
from simbridge.world.vignettes import build_vignette
from simbridge.world.world import Sun

__all__ = [
    "MIN_CITY_SEED",
    "STRATA",
    "generate",
    "generate_places",
    "generate_vignettes",
    "load_shards",
    "render_city",
    "render_place",
    "render_vignettes",
]

GENERATOR = "2"  # bump when what a seed renders changes: the cache of patches is keyed by it
MIN_CITY_SEED = 100  # city seeds below this are never training data (companion-bench city flies 0)
CITY_SIZE_M = 400.0
CITY_RES_M = 0.1
PATCH_PX = 160
GSD_M = (0.03, 0.25)  # metres per pixel, log-uniform
HFOV_DEG = (30.0, 70.0)
MAX_TILT_DEG = 12.0
SUN_ELEVATION_DEG = (20.0, 75.0)
WEATHER_P = (0.7, 0.15, 0.15)  # clear, fog, rain
PALETTE_JITTER = 0.2
VIGNETTE_GSD_M = (0.015, 0.15)  # metres per pixel over the vignettes (real close-ups: about 1-10 cm)
VIGNETTE_SALT = 7_000_003  # separates a vignette's view stream from a city's of the same number
PLACE_SALT = 7_000_019  # and a kind of place's
VIGNETTES_PER_SHARD = 20
VIEWS_PER_TIME = 25  # views rendered at one simulated time (actors stamped once)
ACTOR_STEP_S = (5.0, 60.0)  # simulated time between two such sets of views (actors only move forward)
MAX_CELLS = 200_000  # cells kept per stratum to draw view centres from
INTERIOR_M = 3.0  # roof_interior views: this far from the roof's edge and its clutter at least, and the
#                   view's footprint (half side) no wider than that distance: clear sites are rare otherwise

# (name, share of views, classes under the view's centre; "marking" means the lane-marking material)
STRATA: tuple[tuple[str, float, tuple[int, ...]], ...] = (
    ("roof_interior", 0.18, (C.ROOF_FLAT, C.ROOF_PITCHED)),  # at least INTERIOR_M from anything but roof
    ("flat_roof", 0.14, (C.ROOF_FLAT,)),
    ("clutter", 0.15, (C.ROOF_CLUTTER,)),
    ("pitched_roof", 0.08, (C.ROOF_PITCHED,)),
    ("road", 0.10, (C.ROAD, C.HIGHWAY, C.PARKING_LOT, C.PARKING_ROOF)),
    ("marking", 0.07, (C.CROSSWALK,)),
    ("water", 0.06, (C.WATER,)),
    ("grass", 0.05, (C.GRASS,)),
    ("tree", 0.05, (C.TREE,)),
    ("ground", 0.05, (C.SIDEWALK, C.GROUND, C.PIER, C.PARAPET)),
    ("vehicle", 0.04, (C.VEHICLE,)),
    ("person", 0.03, (C.PEDESTRIAN,)),
    ("crop", 0.0, (C.CROP,)),  # no crops downtown: drawn in the kinds of place (PLACE_SHARES)
)

# The kinds of place (simbridge.world.places) are seen from close up to high above (a rank from 110 m, a
# confirmation 40 m up: 0.2-0.6 m per pixel at the net's input), water and crops more often.
PLACE_GSD_M = (0.05, 0.6)
PLACE_SHARES = {
    "roof_interior": 0.12, "flat_roof": 0.09, "clutter": 0.10, "pitched_roof": 0.08, "road": 0.10,
    "marking": 0.04, "water": 0.14, "grass": 0.08, "tree": 0.05, "ground": 0.06, "vehicle": 0.04,
    "person": 0.03, "crop": 0.07,
}  # fmt: skip

# Vignettes are mostly houses and roofs close up: their views lean to roofs (same strata, other shares).
VIGNETTE_SHARES = {
    "roof_interior": 0.14, "flat_roof": 0.10, "clutter": 0.18, "pitched_roof": 0.18, "road": 0.07,
    "marking": 0.05, "water": 0.05, "grass": 0.05, "tree": 0.04, "ground": 0.07, "vehicle": 0.04,
    "person": 0.03, "crop": 0.0,
}  # fmt: skip


def _cells(
    grid: WorldGrid, classes: tuple[int, ...], name: str, rng: np.random.Generator, interior: np.ndarray
) -> np.ndarray:
    """Flat indices of up to ``MAX_CELLS`` cells of a stratum (drawn by ``rng`` when there are more)."""
    mask = np.isin(grid.cls, classes)
    if name == "marking":
        mask |= grid.mat == int(M.LANE_MARKING)
    if name == "roof_interior":
        mask &= interior >= INTERIOR_M
    idx = np.flatnonzero(mask)
    if idx.size > MAX_CELLS:
        idx = rng.choice(idx, MAX_CELLS, replace=False)
    return idx


def _interior_m(grid: WorldGrid) -> np.ndarray:
    """Distance (metres) of each cell to the nearest cell that is not roof surface, flat or pitched."""
    roof = np.isin(grid.cls, (int(C.ROOF_FLAT), int(C.ROOF_PITCHED))).astype(np.uint8)
    return np.asarray(cv2.distanceTransform(roof, cv2.DIST_L2, 5), np.float32) * np.float32(grid.res)


def _palette(rng: np.random.Generator) -> np.ndarray:
    base = default_palette()
    gain = rng.uniform(1.0 - PALETTE_JITTER, 1.0 + PALETTE_JITTER, base.shape).astype(np.float32)
    return np.clip(base * gain, 0.0, 1.0).astype(np.float32)


def render_city(city_seed: int, count: int, seed: int) -> tuple[np.ndarray, np.ndarray, list[dict[str, Any]]]:
    """``count`` labelled patches of one city (the module docstring says what varies).

    Returns:
        rgb (count, PATCH_PX, PATCH_PX, 3) uint8, labels (count, PATCH_PX, PATCH_PX) uint8, and one
        metadata dict per patch (stratum, gsd_m, hfov_deg, tilt_deg, weather, pose).

    Raises:
        ValueError: a city seed below ``MIN_CITY_SEED`` (reserved for evaluation).
    """
    if city_seed < MIN_CITY_SEED:
        raise ValueError(
            f"city seed {city_seed} is reserved for evaluation: training uses >= {MIN_CITY_SEED}"
        )
    rng = np.random.default_rng([seed, city_seed])
    world = generate_city(city_seed, CITY_SIZE_M, CITY_RES_M)
    return _render_world(world, city_seed, count, rng, GSD_M)


def render_place(place: str, place_seed: int, count: int, seed: int) -> tuple[
    np.ndarray, np.ndarray, list[dict[str, Any]]
]:  # fmt: skip
    """``count`` labelled patches of the kind of place ``place`` built from ``place_seed``
    (:func:`simbridge.world.places.generate_place`), seen at ``PLACE_GSD_M`` with ``PLACE_SHARES``'
    strata; standing crops labelled ``crop`` (:data:`landfall_train.labels.CLASSES_WITH_CROP`). Returns
    what :func:`render_city` returns.

    Raises:
        ValueError: a seed below ``MIN_CITY_SEED`` (reserved for evaluation), or an unknown kind.
    """
    from simbridge.world.places import generate_place

    if place_seed < MIN_CITY_SEED:
        raise ValueError(
            f"place seed {place_seed} is reserved for evaluation: training uses >= {MIN_CITY_SEED}"
        )
    rng = np.random.default_rng([seed, place_seed, PLACE_SALT])
    world = generate_place(place, place_seed)
    return _render_world(world, place_seed, count, rng, PLACE_GSD_M, shares=PLACE_SHARES, crops=True)


def _render_world(
    world: Any,
    actor_seed: int,
    count: int,
    rng: np.random.Generator,
    gsd_range: tuple[float, float],
    shares: dict[str, float] | None = None,
    crops: bool = False,
) -> tuple[np.ndarray, np.ndarray, list[dict[str, Any]]]:
    """``count`` views of ``world`` under a sun of its own, its actors moving on between sets of views."""
    world.sun = Sun(float(rng.uniform(0.0, 360.0)), float(rng.uniform(*SUN_ELEVATION_DEG)))
    live = LiveWorld(world, camera=CameraModel(PATCH_PX, PATCH_PX, 50.0), actor_seed=actor_seed)
    out = _Patches(count)
    interior = _interior_m(live.grid)
    static = {
        name: _cells(live.grid, classes, name, rng, interior)
        for name, _w, classes in STRATA
        if name not in ("vehicle", "person")
    }
    cells: dict[str, np.ndarray] = {}
    t_s = 0.0
    for k in range(count):
        if k % VIEWS_PER_TIME == 0:
            t_s += float(rng.uniform(*ACTOR_STEP_S))
            live.sync(t_s)  # every actor stamped: the strata of vehicles and people come from the grid
            cells = dict(static)
            cells["vehicle"] = _cells(live.grid, (C.VEHICLE,), "vehicle", rng, interior)
            cells["person"] = _cells(live.grid, (C.PEDESTRIAN,), "person", rng, interior)
        view = _view(live, cells, interior, gsd_range, rng, variety=None, shares=shares, crops=crops)
        out.add(k, view, t_s)
    return out.rgb, out.labels, out.meta


def render_vignettes(first: int, worlds: int, per_world: int, seed: int) -> tuple[
    np.ndarray, np.ndarray, list[dict[str, Any]]
]:  # fmt: skip
    """``worlds x per_world`` labelled patches of the vignettes ``first .. first + worlds - 1``
    (:func:`simbridge.world.vignettes.build_vignette`): houses, barns, flat roofs, gardens, streets,
    car parks, ponds and yards at 4-8 cm cells, seen at ``VIGNETTE_GSD_M`` under the renderer's domain
    randomisation (a :meth:`simbridge.world.camera.RenderVariety.sample` per view). Returns what
    :func:`render_city` returns."""
    out = _Patches(worlds * per_world)
    k = 0
    for v in range(first, first + worlds):
        rng = np.random.default_rng([seed, VIGNETTE_SALT, v])
        world = build_vignette(v)
        live = LiveWorld(world, camera=CameraModel(PATCH_PX, PATCH_PX, 50.0), actor_seed=v)
        interior = _interior_m(live.grid)
        cells = {name: _cells(live.grid, classes, name, rng, interior) for name, _w, classes in STRATA}
        for _ in range(per_world):
            variety = RenderVariety.sample(rng)
            view = _view(live, cells, interior, VIGNETTE_GSD_M, rng, variety=variety, shares=VIGNETTE_SHARES)
            out.add(k, view, 0.0, vignette=v)
            k += 1
    return out.rgb, out.labels, out.meta


class _Patches:
    """The arrays and metadata of ``count`` patches being rendered."""

    def __init__(self, count: int) -> None:
        self.rgb = np.empty((count, PATCH_PX, PATCH_PX, 3), np.uint8)
        self.labels = np.empty((count, PATCH_PX, PATCH_PX), np.uint8)
        self.meta: list[dict[str, Any]] = []

    def add(
        self, k: int, view: tuple[np.ndarray, np.ndarray, dict[str, Any]], t_s: float, **extra: Any
    ) -> None:
        self.rgb[k], self.labels[k], meta = view
        self.meta.append({**meta, "t_s": round(t_s, 2), **extra})


def _view(
    live: LiveWorld,
    cells: dict[str, np.ndarray],
    interior: np.ndarray,
    gsd_range: tuple[float, float],
    rng: np.random.Generator,
    variety: RenderVariety | None,
    shares: dict[str, float] | None = None,
    crops: bool = False,
) -> tuple[np.ndarray, np.ndarray, dict[str, Any]]:
    """One labelled view: a stratum (``STRATA``, among those with cells), a cell of it near the middle,
    a ground resolution in ``gsd_range`` (log-uniform), a lens, a tilt, a heading, a weather and a
    palette. ``interior``: :func:`_interior_m` of the world; ``shares`` replaces the strata's shares;
    ``crops``: :func:`landfall_train.labels.label_map`'s.
    Returns (RGB, class map, metadata)."""
    grid = live.grid
    names = [n for n, _w, _c in STRATA]
    share = shares or {n: w for n, w, _c in STRATA}
    weights = np.array([share[n] for n in names]) * np.array([cells[n].size > 0 for n in names])
    stratum = names[int(rng.choice(len(names), p=weights / weights.sum()))]
    i, j = divmod(int(rng.choice(cells[stratum])), grid.shape[1])
    gsd_max = gsd_range[1]
    if stratum == "roof_interior":  # the footprint's half side within the clear distance
        clear_m = float(interior[i, j])
        gsd_max = max(gsd_range[0], min(gsd_max, clear_m / (0.5 * PATCH_PX)))
    gsd = math.exp(rng.uniform(math.log(gsd_range[0]), math.log(gsd_max)))
    hfov = float(rng.uniform(*HFOV_DEG))
    camera = CameraModel(PATCH_PX, PATCH_PX, hfov)
    above = gsd * camera.focal_px  # metres above the surface under the centre, for that resolution
    shift = 0.25 * gsd * PATCH_PX  # the centre's cell lies within a quarter patch of the middle
    north = grid.n0 + (i + 0.5) * grid.res + float(rng.uniform(-shift, shift))
    east = grid.e0 + (j + 0.5) * grid.res + float(rng.uniform(-shift, shift))
    pos = (north, east, -(float(grid.height[i, j]) + above))
    tilt = math.radians(float(rng.uniform(0.0, MAX_TILT_DEG)))
    tilt_dir = float(rng.uniform(0.0, 2 * math.pi))
    yaw = float(rng.uniform(-math.pi, math.pi))
    quat = euler_to_quat(tilt * math.cos(tilt_dir), tilt * math.sin(tilt_dir), yaw)
    weather = WEATHERS[int(rng.choice(3, p=WEATHER_P))]
    frame = render(
        grid, live.pyramid, live.shadow, camera, pos, quat, live.sun_neu, weather, rng,
        labels=True, palette=_palette(rng), variety=variety,
    )  # fmt: skip
    if frame.hit_material is None or frame.hit_kind is None:
        raise RuntimeError("render(labels=True) returned no labels")
    meta = {
        "stratum": stratum,
        "gsd_m": round(gsd, 4),
        "hfov_deg": round(hfov, 2),
        "tilt_deg": round(math.degrees(tilt), 2),
        "weather": weather,
        "pos_ned_m": [round(v, 2) for v in pos],
        "yaw_rad": round(yaw, 4),
    }
    return frame.rgb, label_map(frame.hit_class, frame.hit_material, frame.hit_kind, crops=crops), meta


def _one_shard(args: tuple[Path, str, int, int, int, int]) -> str:
    out, kind, key, worlds, count, seed = args
    os.environ.setdefault("NUMBA_NUM_THREADS", "1")
    # a shard of fewer vignettes than a full one carries its count: asking for more later renders them
    partial = kind == "vignettes" and worlds != VIGNETTES_PER_SHARD
    path = out / (f"shard-{key}-{worlds}.npz" if partial else f"shard-{key}.npz")
    if kind.startswith("place:"):
        path = out / f"shard-{kind[6:]}-{key}-{count}.npz"
    if not path.exists():
        if kind == "city":
            rgb, labels, meta = render_city(key, count, seed)
        elif kind.startswith("place:"):
            rgb, labels, meta = render_place(kind[6:], key, count, seed)
        else:
            rgb, labels, meta = render_vignettes(key, worlds, count, seed)
        tmp = path.with_suffix(".tmp.npz")
        np.savez(tmp, rgb=rgb, labels=labels, meta=np.array(json.dumps(meta)))
        tmp.replace(path)
    return path.name


def generate(out: Path, city_seeds: Sequence[int], per_city: int, seed: int, workers: int = 1) -> list[Path]:
    """Render ``per_city`` patches for each city seed into ``out`` (shards already there are kept: the
    same arguments make the same bytes) with ``workers`` processes; returns the shard paths in seed order."""
    bad = [s for s in city_seeds if s < MIN_CITY_SEED]
    if bad:
        raise ValueError(f"city seeds {bad} are reserved for evaluation: training uses >= {MIN_CITY_SEED}")
    return _run(out, [(out, "city", int(s), 1, per_city, seed) for s in city_seeds], workers)


def generate_places(
    out: Path, places: Sequence[str], seeds: Sequence[int], per_place: int, seed: int, workers: int = 1
) -> list[Path]:
    """Render ``per_place`` patches of each kind of place in ``places`` built from each of ``seeds``
    (:func:`render_place`) into ``out`` (shards already there are kept), with ``workers`` processes."""
    bad = [s for s in seeds if s < MIN_CITY_SEED]
    if bad:
        raise ValueError(f"place seeds {bad} are reserved for evaluation: training uses >= {MIN_CITY_SEED}")
    jobs = [(out, f"place:{p}", int(s), 1, per_place, seed) for p in places for s in seeds]
    return _run(out, jobs, workers)


def generate_vignettes(
    out: Path, first: int, worlds: int, per_world: int, seed: int, workers: int = 1
) -> list[Path]:
    """Render ``per_world`` patches of each vignette ``first .. first + worlds - 1`` into ``out``, in
    shards of ``VIGNETTES_PER_SHARD`` worlds (kept when there already), with ``workers`` processes."""
    jobs = [
        (out, "vignettes", v, min(VIGNETTES_PER_SHARD, first + worlds - v), per_world, seed)
        for v in range(first, first + worlds, VIGNETTES_PER_SHARD)
    ]
    return _run(out, jobs, workers)


def _run(out: Path, jobs: list[tuple[Path, str, int, int, int, int]], workers: int) -> list[Path]:
    out.mkdir(parents=True, exist_ok=True)
    if workers <= 1:
        names = [_one_shard(j) for j in jobs]
    else:
        with ProcessPoolExecutor(max_workers=workers) as pool:
            names = list(pool.map(_one_shard, jobs))
    return [out / n for n in names]


def load_shards(paths: Sequence[Path]) -> tuple[np.ndarray, np.ndarray, str]:
    """Concatenated ``rgb`` and ``labels`` of the shards, and a sha256 digest of their bytes."""
    digest = hashlib.sha256()
    rgbs, labs = [], []
    for p in paths:
        with np.load(p) as z:
            rgbs.append(z["rgb"])
            labs.append(z["labels"])
        digest.update(rgbs[-1].tobytes())
        digest.update(labs[-1].tobytes())
    return np.concatenate(rgbs), np.concatenate(labs), digest.hexdigest()
