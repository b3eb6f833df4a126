"""The downward hemispherical LiDAR and the downward rangefinder, ray cast against the world.

LiDAR rays are fixed in the body frame (FRD): ``channels`` elevation rings from just below the
horizontal to straight down, ``points_per_ring`` azimuths each. Points come back in body FRD
metres with an intensity column: an (N, 4) float32 array; misses and dropouts are left out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from simbridge.geo import Quat
from simbridge.world.camera import body_to_neu, quat_matrix
from simbridge.world.model import Material, WorldGrid
from simbridge.world.raycast import HIT_MISS, HIT_TOP, HIT_WALL_N, Pyramid, cast_rays
from simbridge.world.wire_sensing import wire_returns
from simbridge.world.world import Wire

_REFLECTIVITY = np.full(32, 0.3, np.float32)
for _m, _r in {
    Material.WATER: 0.02, Material.ASPHALT: 0.12, Material.TAR: 0.08, Material.LANE_MARKING: 0.8,
    Material.ZEBRA: 0.8, Material.MEMBRANE: 0.7, Material.CONCRETE: 0.45, Material.GRAVEL: 0.35,
    Material.METAL: 0.6, Material.SOLAR: 0.1, Material.FOLIAGE: 0.4, Material.GRASS: 0.35,
    Material.CAR_PAINT: 0.5, Material.PAINT_TEXT: 0.8,
}.items():  # fmt: skip
    _REFLECTIVITY[int(_m)] = _r


@dataclass(frozen=True, slots=True)
class LidarModel:
    channels: int = 100
    points_per_ring: int = 512
    range_m: float = 100.0
    min_elevation_deg: float = 0.5  # the top ring's angle below the horizontal
    noise_sigma_m: float = 0.02
    dropout: float = 0.02

    def __post_init__(self) -> None:
        if self.channels < 1 or self.points_per_ring < 1:
            raise ValueError("LiDAR channels and points_per_ring must be >= 1")
        if not 0.0 < self.range_m <= 1000.0:
            raise ValueError(f"LiDAR range_m must be in (0, 1000], got {self.range_m}")
        if not 0.0 <= self.dropout < 1.0 or self.noise_sigma_m < 0:
            raise ValueError("LiDAR dropout must be in [0, 1) and noise_sigma_m >= 0")

    def rays_body(self) -> np.ndarray:
        """(channels * points_per_ring, 3) unit rays in body FRD, ring by ring."""
        key = (self.channels, self.points_per_ring, self.min_elevation_deg)
        if key not in _RAYS:
            el = np.radians(np.linspace(self.min_elevation_deg, 90.0, self.channels))
            az = np.linspace(0.0, 2 * math.pi, self.points_per_ring, endpoint=False)
            e, a = np.meshgrid(el, az, indexing="ij")
            _RAYS[key] = np.ascontiguousarray(
                np.stack([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)], axis=-1).reshape(-1, 3)
            )
        return _RAYS[key]


_RAYS: dict[tuple[int, int, float], np.ndarray] = {}


def sweep(
    grid: WorldGrid, pyramid: Pyramid, model: LidarModel, pos_ned_m: tuple[float, float, float], quat: Quat,
    rng: np.random.Generator, wires: tuple[Wire, ...] = (),
) -> np.ndarray:  # fmt: skip
    """One sweep: (N, 4) float32 of body-FRD x, y, z (m) and intensity (0..1).

    ``wires``: overhead wires; a beam passing within a few centimetres of a conductor comes back from
    it now and then (:func:`~simbridge.world.wire_sensing.wire_returns`, drawn from ``rng``). Without
    wires the sweep is byte for byte what it was.
    """
    rays = model.rays_body()
    dirs = body_to_neu(rays, quat)
    origin = np.array([[pos_ned_m[0], pos_ned_m[1], -pos_ned_m[2]]])
    ts, ii, jj, kinds, _ = cast_rays(
        grid.height, pyramid.maps, pyramid.h_max,
        grid.res, grid.n0, grid.e0, origin, dirs, model.range_m, model.points_per_ring,
    )  # fmt: skip
    # beyond the modelled area: open ground (soil) at height 0, as the camera and the rangefinder see it
    beyond = (kinds == HIT_MISS) & (dirs[:, 2] < -1e-6)
    if beyond.any():
        idx = np.flatnonzero(beyond)
        t_open = origin[0, 2] / -dirs[idx, 2]
        seen = (t_open > 0.0) & (t_open <= model.range_m)  # a vehicle below height 0 sees none of it
        beyond[idx[~seen]] = False
        ts[idx[seen]] = t_open[seen]
        kinds[idx[seen]] = HIT_TOP
    on_wire = np.zeros(ts.shape[0], bool)
    if wires:
        r_body_neu = quat_matrix(quat) * np.array([[1.0], [1.0], [-1.0]])
        rings = (model.channels, model.points_per_ring, model.min_elevation_deg)
        got, t_wire = wire_returns(
            wires, dirs, origin[0], rings, r_body_neu, model.range_m, ts, kinds != HIT_MISS, rng
        )
        ts[got], kinds[got], beyond[got], on_wire[got] = t_wire, HIT_WALL_N, False, True
    keep = (kinds != HIT_MISS) & (rng.random(ts.shape[0]) >= model.dropout)
    rng_m = ts[keep] + rng.normal(0.0, model.noise_sigma_m, int(keep.sum())).astype(np.float32)
    rng_m = np.clip(rng_m, 0.05, model.range_m)
    pts = rays[keep] * rng_m[:, None]
    mat = grid.mat[ii[keep], jj[keep]]  # a ground hit beyond the grid has no cell: its index is -1
    mat[beyond[keep]] = int(Material.SOIL)
    mat[on_wire[keep]] = int(Material.METAL)
    refl = _REFLECTIVITY[mat]
    incidence = np.where(kinds[keep] == HIT_TOP, np.abs(dirs[keep, 2]), 0.6)
    intensity = np.clip(refl * (0.3 + 0.7 * incidence) * (1.0 - 0.3 * rng_m / model.range_m), 0.0, 1.0)
    return np.column_stack([pts, intensity]).astype(np.float32)


def rangefinder_m(
    grid: WorldGrid, pyramid: Pyramid, pos_ned_m: tuple[float, float, float], quat: Quat, max_m: float = 200.0
) -> float:
    """Distance along body +z to the first surface; ``max_m`` when nothing is in range."""
    dirs = body_to_neu(np.array([[0.0, 0.0, 1.0]]), quat)
    origin = np.array([[pos_ned_m[0], pos_ned_m[1], -pos_ned_m[2]]])
    ts, _, _, kinds, _ = cast_rays(
        grid.height, pyramid.maps, pyramid.h_max,
        grid.res, grid.n0, grid.e0, origin, dirs, max_m,
    )  # fmt: skip
    if kinds[0] == HIT_MISS:
        if dirs[0, 2] < -1e-6:  # beyond the modelled area: open ground at height 0
            return float(min(origin[0, 2] / -dirs[0, 2], max_m))
        return max_m
    return float(ts[0])
