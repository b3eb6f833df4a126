"""A built world: the static grid, where the vehicle launches, the sun, the ground-truth safe
landing zones and the actors' routes. Scenario files and the procedural city both produce one."""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from simbridge.world.model import WorldError, WorldGrid


@dataclass(frozen=True, slots=True)
class SafeZone:
    """A ground-truth landing zone (rotated rectangle) for the Surface ID Jaccard index."""

    centre_ne: tuple[float, float]
    length_m: float
    width_m: float
    yaw_rad: float = 0.0
    label: str = ""

    def corners_ne(self) -> np.ndarray:
        """(4, 2) corners in scenario (north, east) metres."""
        c, s = math.cos(self.yaw_rad), math.sin(self.yaw_rad)
        hl, hw = self.length_m / 2, self.width_m / 2
        local = np.array([[hl, hw], [hl, -hw], [-hl, -hw], [-hl, hw]])
        n = self.centre_ne[0] + local[:, 0] * c - local[:, 1] * s
        e = self.centre_ne[1] + local[:, 0] * s + local[:, 1] * c
        return np.stack([n, e], axis=1)


def _check_heights(
    what: str, points_ne: tuple[tuple[float, float], ...], heights_m: tuple[float, ...] | None
) -> None:
    """Per-point heights, where given, one finite number per point, or ``WorldError``."""
    if heights_m is None:
        return
    if len(heights_m) != len(points_ne):
        raise WorldError(
            f"{what}.heights_m needs one height per point: {len(points_ne)}, got {len(heights_m)}"
        )
    if not all(math.isfinite(h) for h in heights_m):
        raise WorldError(f"{what}.heights_m must be finite numbers, got {heights_m}")


@dataclass(frozen=True, slots=True)
class Lane:
    """A traffic lane: cars enter at the first point and leave at the last.

    ``deck_height_m`` is the road surface height (elevated highways); ``arrivals_per_min`` the mean
    rate of a Poisson arrival process; speeds are drawn uniformly from ``speed_m_s``. A lane over
    terrain relief gives ``heights_m`` instead: the road surface's height (metres up) at each of its
    points, linear between them; ``deck_height_m`` is then unused.
    """

    points_ne: tuple[tuple[float, float], ...]
    speed_m_s: tuple[float, float] = (8.0, 14.0)
    arrivals_per_min: float = 6.0
    deck_height_m: float = 0.0
    heights_m: tuple[float, ...] | None = None

    def __post_init__(self) -> None:
        _check_heights("Lane", self.points_ne, self.heights_m)


@dataclass(frozen=True, slots=True)
class Walkway:
    """Pedestrians walking back and forth along a path (sidewalk, plaza, now and then a roof).

    ``surface_height_m`` is the height of the surface they walk on; a path over terrain relief gives
    ``heights_m`` instead: the surface's height (metres up) at each of its points, linear between them
    (the path must be level across its ``width_m``: a person walks up to 0.4 width either side of it).
    """

    points_ne: tuple[tuple[float, float], ...]
    count: int = 4
    surface_height_m: float = 0.0
    width_m: float = 2.0
    heights_m: tuple[float, ...] | None = None

    def __post_init__(self) -> None:
        _check_heights("Walkway", self.points_ne, self.heights_m)


@dataclass(frozen=True, slots=True)
class Wire:
    """An overhead wire (a power line's conductor, a telephone line) strung between poles: its
    ``points_neh`` (north, east, height up, metres) in order, a straight span between each two. Wires
    are not in the grid (a 2 cm conductor is far thinner than a cell, and the ground under it stays
    what it is): the camera draws them, the LiDAR hits them only now and then, and the grader keeps a
    touchdown ``GraderConfig.wire_m`` from the line under them."""

    points_neh: tuple[tuple[float, float, float], ...]
    diameter_m: float = 0.02

    def ground_gap_m(self, north_m: float, east_m: float) -> float:
        """The horizontal distance from (north, east) to the line under the wire, metres."""
        pts = np.asarray(self.points_neh, np.float64)[:, :2]
        if len(pts) == 1:
            return float(math.hypot(north_m - pts[0, 0], east_m - pts[0, 1]))
        a, b = pts[:-1], pts[1:]
        ab = b - a
        t = np.clip(((north_m - a[:, 0]) * ab[:, 0] + (east_m - a[:, 1]) * ab[:, 1]) / np.maximum(
            (ab**2).sum(axis=1), 1e-12), 0.0, 1.0)  # fmt: skip
        n = a[:, 0] + t * ab[:, 0]
        e = a[:, 1] + t * ab[:, 1]
        return float(np.hypot(n - north_m, e - east_m).min())


@dataclass(frozen=True, slots=True)
class Sun:
    """Where the sun is: azimuth from north toward east, elevation above the horizon."""

    azimuth_deg: float = 135.0
    elevation_deg: float = 50.0

    def direction_neu(self) -> tuple[float, float, float]:
        """Unit vector pointing *toward* the sun in (north, east, up)."""
        az, el = math.radians(self.azimuth_deg), math.radians(self.elevation_deg)
        return (math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el))


@dataclass
class World:
    name: str
    seed: int
    grid: WorldGrid
    launch_ne_m: tuple[float, float] = (0.0, 0.0)
    launch_height_m: float = 110.0  # above the ground under the launch point
    launch_yaw_rad: float = 0.0
    sun: Sun = field(default_factory=Sun)
    safe_zones: tuple[SafeZone, ...] = ()
    lanes: tuple[Lane, ...] = ()
    walkways: tuple[Walkway, ...] = ()
    description: str = ""
    wires: tuple[Wire, ...] = ()
    # what a world kept on disk brings along (simbridge.world.cache): its digest and the ray caster's
    # max maps over its static heights, each computed once when it was built (about 0.25 and 0.15-0.2
    # CPU seconds for a 6000 x 6000 city, paid by simbridge and by the grading of every episode)
    known_digest: str | None = field(default=None, compare=False, repr=False)
    pyramid_maps: Any = field(default=None, compare=False, repr=False)

    def digest(self) -> str:
        """The static world's fingerprint (:meth:`WorldGrid.digest`, and the wires where there are
        any): call it before actors are stamped. A world kept on disk gives the one taken when it was
        built."""
        if self.known_digest is not None:
            return self.known_digest
        digest = self.grid.digest()
        if not self.wires:
            return digest
        text = repr([(w.points_neh, w.diameter_m) for w in self.wires]).encode()
        return hashlib.blake2b(digest.encode() + text, digest_size=8).hexdigest()
