"""Labelled training patches rendered from simbridge's procedural cities.

Each *world* is one procedural city (``generate_city(seed, CITY_SIZE_M, CITY_RES_M)``) under its own sun
(azimuth any, elevation ``SUN_ELEVATION_DEG``), with its traffic and pedestrians at random times. Views are
stratified by what lies under the camera (``STRATA``: clear and cluttered roofs, pitched roofs, roads,
markings, water, lawns, trees, sidewalks, vehicles, people), so every class is seen often enough; each
view randomises the ground resolution (``GSD_M``, log-uniform), the lens (``HFOV_DEG``), the tilt (up to
``MAX_TILT_DEG``), the heading, the weather (clear, fog, rain) and the palette (each material's RGB
scaled by up to +-``PALETTE_JITTER`` per channel). A patch is a ``PATCH_PX`` square RGB image and its
per-pixel class map (:func:`landfall_train.labels.label_map`).

**Excluded worlds.** What the evaluation flies never becomes training data: city seeds below
``MIN_CITY_SEED`` (``companion-bench city`` flies city 0), and no scenario file (scenario1, scenario2,
tests/onboard_scene.toml) is ever loaded here.

Patches go to ``OUT/shard-SEED.npz`` (``rgb`` (N, S, S, 3) uint8, ``labels`` (N, S, S) uint8, ``meta``
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
from simbridge.world.camera import WEATHERS, CameraModel, default_palette, render
from simbridge.world.city import generate_city
from simbridge.world.live import LiveWorld
from simbridge.world.model import Material as M
from simbridge.world.model import SurfaceClass as C
from simbridge.world.world import Sun

__all__ = ["MIN_CITY_SEED", "STRATA", "generate", "load_shards", "render_city"]

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
VIEWS_PER_TIME = 25  # views rendered at one simulated time (actors stamped once)
ACTOR_STEP_S = (5.0, 60.0)  # simulated time between two such sets of views (actors only move forward)
MAX_CELLS = 200_000  # cells kept per stratum to draw view centres from
INTERIOR_M = 3.0  # roof_interior views: this far from the roof's edge and its clutter at least, and the
#                   view's footprint (half side) no wider than that distance: clear sites are rare otherwise

# (name, share of views, classes under the view's centre; "marking" means the lane-marking material)
STRATA: tuple[tuple[str, float, tuple[int, ...]], ...] = (
    ("roof_interior", 0.18, (C.ROOF_FLAT,)),  # at least INTERIOR_M from anything but flat roof
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
)


def _cells(
    cls: np.ndarray, mat: np.ndarray, classes: tuple[int, ...], name: str, rng: np.random.Generator
) -> np.ndarray:
    mask = np.isin(cls, classes)
    if name == "marking":
        mask |= mat == int(M.LANE_MARKING)
    if name == "roof_interior":
        mask &= _interior_m(cls) >= INTERIOR_M
    idx = np.flatnonzero(mask)
    if idx.size > MAX_CELLS:
        idx = rng.choice(idx, MAX_CELLS, replace=False)
    return idx


def _interior_m(cls: np.ndarray) -> np.ndarray:
    """Distance (metres) of each cell to the nearest cell that is not flat roof."""
    flat = (cls == int(C.ROOF_FLAT)).astype(np.uint8)
    return np.asarray(cv2.distanceTransform(flat, cv2.DIST_L2, 5), np.float32) * np.float32(CITY_RES_M)


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
    world.sun = Sun(float(rng.uniform(0.0, 360.0)), float(rng.uniform(*SUN_ELEVATION_DEG)))
    live = LiveWorld(world, camera=CameraModel(PATCH_PX, PATCH_PX, 50.0), actor_seed=city_seed)
    grid = live.grid
    names = [s[0] for s in STRATA]
    weights = np.array([s[1] for s in STRATA])
    rgb = np.empty((count, PATCH_PX, PATCH_PX, 3), np.uint8)
    labels = np.empty((count, PATCH_PX, PATCH_PX), np.uint8)
    meta: list[dict[str, Any]] = []
    interior = _interior_m(grid.cls)
    static = {
        name: _cells(grid.cls, grid.mat, classes, name, rng)
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
            cells["vehicle"] = _cells(grid.cls, grid.mat, (C.VEHICLE,), "vehicle", rng)
            cells["person"] = _cells(grid.cls, grid.mat, (C.PEDESTRIAN,), "person", rng)
        avail = np.array([cells[n].size > 0 for n in names])
        p = weights * avail
        stratum = names[int(rng.choice(len(names), p=p / p.sum()))]
        i, j = divmod(int(rng.choice(cells[stratum])), grid.shape[1])
        gsd_max = GSD_M[1]
        if stratum == "roof_interior":  # the footprint's half side within the clear distance
            gsd_max = max(GSD_M[0], min(gsd_max, float(interior[i, j]) / (0.5 * PATCH_PX)))
        gsd = math.exp(rng.uniform(math.log(GSD_M[0]), math.log(gsd_max)))
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
            labels=True, palette=_palette(rng),
        )  # fmt: skip
        if frame.hit_material is None or frame.hit_kind is None:
            raise RuntimeError("render(labels=True) returned no labels")
        rgb[k] = frame.rgb
        labels[k] = label_map(frame.hit_class, frame.hit_material, frame.hit_kind)
        meta.append(
            {
                "stratum": stratum,
                "gsd_m": round(gsd, 4),
                "hfov_deg": round(hfov, 2),
                "tilt_deg": round(math.degrees(tilt), 2),
                "weather": weather,
                "t_s": round(t_s, 2),
                "pos_ned_m": [round(v, 2) for v in pos],
                "yaw_rad": round(yaw, 4),
            }
        )
    return rgb, labels, meta


def _one_shard(args: tuple[Path, int, int, int]) -> str:
    out, city_seed, count, seed = args
    os.environ.setdefault("NUMBA_NUM_THREADS", "1")
    path = out / f"shard-{city_seed}.npz"
    if not path.exists():
        rgb, labels, meta = render_city(city_seed, count, seed)
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
    out.mkdir(parents=True, exist_ok=True)
    jobs = [(out, int(s), per_city, seed) for s in city_seeds]
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
