"""Painting a validated scenario (:class:`~simbridge.world.scenario_schema.ScenarioSpec`) into a
:class:`~simbridge.world.model.WorldGrid`, in the fixed order of ``docs/scenario-format.md``: ground,
parks, water, roads, piers, highways, buildings, trees, clutter; then the safe zones are checked."""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterator, Sequence
from pathlib import Path

import numpy as np

from simbridge.world.model import FORBIDDEN_CLASSES, OBSTACLE_CLASSES, Material, SurfaceClass, WorldGrid
from simbridge.world.scenario_schema import (
    CLUTTER_KINDS,
    FONT,
    BuildingSpec,
    ClutterSpec,
    HighwaySpec,
    Point,
    RampSpec,
    ScenarioFileError,
    ScenarioSpec,
)
from simbridge.world.world import Lane, SafeZone, Sun, Walkway, World

_GROUND: dict[str, tuple[SurfaceClass, Material]] = {
    "soil": (SurfaceClass.GROUND, Material.SOIL),
    "grass": (SurfaceClass.GRASS, Material.GRASS),
    "paving": (SurfaceClass.GROUND, Material.PAVING),
    "gravel": (SurfaceClass.GROUND, Material.GRAVEL),
}
_ROAD_SURFACE: dict[str, tuple[SurfaceClass, Material]] = {
    "road": (SurfaceClass.ROAD, Material.ASPHALT),
    "sidewalk": (SurfaceClass.SIDEWALK, Material.PAVING),
    "crosswalk": (SurfaceClass.CROSSWALK, Material.ASPHALT),
    "parking": (SurfaceClass.PARKING_LOT, Material.ASPHALT),
}
_ROAD_ORDER = ("parking", "sidewalk", "road", "crosswalk")
_PARAPET_MAT = {"concrete": Material.CONCRETE, "brick": Material.BRICK, "metal": Material.METAL}
_ROOF_TOPS = frozenset(
    {SurfaceClass.ROOF_FLAT, SurfaceClass.ROOF_PITCHED, SurfaceClass.PARKING_ROOF, SurfaceClass.ROOF_CLUTTER}
)
_FLAT_TOPS = (int(SurfaceClass.ROOF_FLAT), int(SurfaceClass.PARKING_ROOF))
# seed salts: one random stream per (table, index) so editing one object leaves the others alone
_SALT_RUBBLE, _SALT_PARK, _SALT_PARKING, _SALT_DECK = 1, 2, 3, 4
DASH_M, GAP_M = 3.0, 5.0  # lane divider dashes
TILE_M = 25.0  # largest tile painted at once
EDGE_INSET_M = 0.4  # solid edge lines this far inside a road's edge
ZEBRA_STRIPE_M = 0.5  # crosswalk stripes and gaps
RAIL_WIDTH_M, RAIL_HEIGHT_M = 0.3, 0.9
BAY_WIDTH_M, BAY_DEPTH_M, AISLE_M = 2.5, 5.0, 6.0
CAR_LENGTH_M, CAR_WIDTH_M, CAR_HEIGHT_M, CAR_COLOURS = 4.5, 1.9, 1.5, 8


def _rng(seed: int, salt: int, index: int) -> np.random.Generator:
    return np.random.default_rng([seed % 2**63, salt, index])


def _local(centre: Point, yaw: float, u: float, v: float) -> Point:
    """Scenario (north, east) of the point ``u`` along and ``v`` across a frame at ``centre``."""
    c, s = math.cos(yaw), math.sin(yaw)
    return (centre[0] + u * c - v * s, centre[1] + u * s + v * c)


def _segments(points: Sequence[Point]) -> Iterator[tuple[Point, float, float]]:
    """``(midpoint, length, yaw_rad)`` of each non-degenerate segment."""
    for (n1, e1), (n2, e2) in itertools.pairwise(points):
        length = math.hypot(n2 - n1, e2 - e1)
        if length > 0:
            yield ((n1 + n2) / 2, (e1 + e2) / 2), length, math.atan2(e2 - e1, n2 - n1)


def _mark_width(grid: WorldGrid) -> float:
    return max(0.15, grid.res * 1.01)


def _tiles(
    grid: WorldGrid, centre: Point, length_m: float, width_m: float, yaw: float
) -> Iterator[tuple[tuple[int, int, int, int], np.ndarray]]:
    """``grid.rect_mask`` in tiles of at most ``TILE_M``: it scans the rectangle's circumscribed
    square, which for a 500 m road is the whole grid; tiles keep the cost near the area."""
    nu, nv = max(1, math.ceil(length_m / TILE_M)), max(1, math.ceil(width_m / TILE_M))
    du, dv = length_m / nu, width_m / nv
    for a in range(nu):
        for b in range(nv):
            at = _local(centre, yaw, -length_m / 2 + (a + 0.5) * du, -width_m / 2 + (b + 0.5) * dv)
            # a hair of overlap so no cell centre falls between two tiles
            got = grid.rect_mask(at, du + 1e-3, dv + 1e-3, yaw)
            if got is not None:
                yield got[0], got[1]


def _fill(
    grid: WorldGrid,
    centre: Point,
    length_m: float,
    width_m: float,
    yaw: float,
    *,
    height_m: float | None = None,
    cls: SurfaceClass | None = None,
    mat: Material | None = None,
) -> None:
    """``grid.fill_rect``, tiled."""
    for win, mask in _tiles(grid, centre, length_m, width_m, yaw):
        grid.paint(win, mask, height_m, cls, mat)


def _strip(
    grid: WorldGrid,
    points: Sequence[Point],
    width_m: float,
    offset_m: float = 0.0,
    *,
    height_m: float | None = None,
    cls: SurfaceClass | None = None,
    mat: Material | None = None,
) -> None:
    """A strip ``width_m`` wide along a path, its centre line ``offset_m`` right of the path (the
    ``fill_polyline`` shape, with the segments lengthened by 1 % of the width to close the joints)."""
    for mid, length, yaw in _segments(points):
        at = _local(mid, yaw, 0.0, offset_m)
        _fill(grid, at, length + width_m * 0.01, width_m, yaw, height_m=height_m, cls=cls, mat=mat)


def _paint_line(
    grid: WorldGrid,
    points: Sequence[Point],
    offset_m: float,
    width_m: float,
    *,
    dashed: bool,
    mat: Material,
) -> None:
    """A marking line ``offset_m`` right of the path (material only: class and height stay)."""
    for mid, length, yaw in _segments(points):
        if not dashed:
            _fill(grid, _local(mid, yaw, 0.0, offset_m), length, width_m, yaw, mat=mat)
            continue
        s = GAP_M / 2
        while s < length:
            d = min(DASH_M, length - s)
            grid.fill_rect(_local(mid, yaw, -length / 2 + s + d / 2, offset_m), d, width_m, yaw, mat=mat)
            s += DASH_M + GAP_M


def _paint_lane_markings(grid: WorldGrid, points: Sequence[Point], width_m: float, lanes: int) -> None:
    """Solid edge lines, and dividers between lanes: dashed, but solid between the two directions of
    a road with an even number (>= 4) of lanes."""
    mark = _mark_width(grid)
    if width_m > 4 * EDGE_INSET_M + 2 * mark:
        for side in (-1, 1):
            _paint_line(
                grid,
                points,
                side * (width_m / 2 - EDGE_INSET_M),
                mark,
                dashed=False,
                mat=Material.LANE_MARKING,
            )
    for k in range(1, lanes):
        solid = lanes >= 4 and lanes % 2 == 0 and k == lanes // 2
        _paint_line(
            grid,
            points,
            -width_m / 2 + k * width_m / lanes,
            mark,
            dashed=not solid,
            mat=Material.LANE_MARKING,
        )


def _paint_zebra(grid: WorldGrid, points: Sequence[Point], width_m: float) -> None:
    """Stripes across the walking direction: ZEBRA and ASPHALT alternate every ``ZEBRA_STRIPE_M``."""
    for mid, length, yaw in _segments(points):
        got = grid.rect_mask(mid, length, width_m, yaw)
        if got is None:
            continue
        win, mask, u, _ = got
        stripe = np.floor((u + length / 2) / ZEBRA_STRIPE_M).astype(np.int64) % 2 == 1
        grid.paint(win, mask & stripe, None, None, Material.ZEBRA)


def _paint_bays(
    grid: WorldGrid,
    centre: Point,
    length_m: float,
    width_m: float,
    yaw: float,
    surface_m: float,
    rng: np.random.Generator,
    parked_fraction: float,
) -> None:
    """Parking bays across a rectangle: rows of 2.5 m bays, 5 m deep, back to back over 6 m aisles.

    Rows run along the length; each pair of rows plus an aisle takes 16 m of the width. A bay holds a
    parked car (a static VEHICLE box) with probability ``parked_fraction``.
    """
    module = 2 * BAY_DEPTH_M + AISLE_M
    rows: list[float] = []  # v of each row's centre, relative to the rectangle's centre
    n_mod = int(width_m // module)
    rest = width_m - n_mod * module
    single = rest >= BAY_DEPTH_M + AISLE_M
    used = n_mod * module + (BAY_DEPTH_M + AISLE_M if single else 0.0)
    v0 = -used / 2
    for k in range(n_mod):
        rows += [v0 + k * module + BAY_DEPTH_M / 2, v0 + (k + 1) * module - BAY_DEPTH_M / 2]
    if single:
        rows.append(v0 + n_mod * module + BAY_DEPTH_M / 2)
    n_bays = int((length_m - 2.0) // BAY_WIDTH_M)
    if n_bays < 1 or not rows:
        return
    mark = _mark_width(grid)
    u0 = -n_bays * BAY_WIDTH_M / 2
    for v in rows:
        for b in range(n_bays + 1):
            at = _local(centre, yaw, u0 + b * BAY_WIDTH_M, v)
            grid.fill_rect(at, mark, BAY_DEPTH_M, yaw, mat=Material.LANE_MARKING)
    if parked_fraction <= 0:
        return
    for v in rows:
        taken = rng.random(n_bays) < parked_fraction
        jitter = rng.uniform(-0.15, 0.15, size=(n_bays, 2))
        colours = rng.integers(0, CAR_COLOURS, size=n_bays)
        for bay in np.flatnonzero(taken):
            at = _local(centre, yaw, u0 + (bay + 0.5) * BAY_WIDTH_M + jitter[bay, 0], v + jitter[bay, 1])
            # nose into the bay: the car's length runs across the row; paint colour as a negative
            # region id, as the moving actors carry it
            grid.fill_rect(
                at,
                CAR_WIDTH_M,
                CAR_LENGTH_M,
                yaw,
                height_m=surface_m + CAR_HEIGHT_M,
                cls=SurfaceClass.VEHICLE,
                mat=Material.CAR_PAINT,
                region=-(int(colours[bay]) + 1),
            )


def _paint_dome(
    grid: WorldGrid,
    centre: Point,
    radius_m: float,
    base_m: float,
    cap_m: float,
    cls: SurfaceClass,
    mat: Material,
    region: int | None = None,
    keep_region: int | None = None,
) -> None:
    """A spherical-cap profile ``base + cap * sqrt(1 - d^2/r^2)``, painted only where it rises above what
    is there (so a canopy's rim does not relabel a roof it overhangs)."""
    got = grid.rect_mask(centre, 2 * radius_m, 2 * radius_m, 0.0)
    if got is None:
        return
    win, _, u, v = got
    d2 = u**2 + v**2
    i0, i1, j0, j1 = win
    heights = (base_m + cap_m * np.sqrt(np.clip(1.0 - d2 / radius_m**2, 0.0, 1.0))).astype(np.float32)
    mask = (d2 <= radius_m**2) & (heights > grid.height[i0:i1, j0:j1])
    if keep_region is not None:
        mask &= grid.region[i0:i1, j0:j1] == keep_region
    grid.paint(win, mask, heights, cls, mat, region, "set")


def _paint_roads(grid: WorldGrid, spec: ScenarioSpec, seed: int) -> None:
    """Parking lots, then sidewalks, then roads, then crosswalks; lane markings stop at junctions."""
    covered = np.zeros(grid.shape, np.uint8)  # how many roads cover each cell
    for kind in _ROAD_ORDER:
        if kind == "crosswalk":
            junction = (covered >= 2) & (grid.mat == int(Material.LANE_MARKING))
            grid.mat[junction] = int(Material.ASPHALT)
        for k, road in enumerate(spec.roads):
            if road.kind != kind:
                continue
            cls, mat = _ROAD_SURFACE[kind]
            _strip(grid, road.points, road.width_m, height_m=0.0, cls=cls, mat=mat)
            if kind == "road":
                mine = np.zeros(grid.shape, bool)
                for mid, length, yaw in _segments(road.points):
                    for (i0, i1, j0, j1), mask in _tiles(grid, mid, length, road.width_m, yaw):
                        mine[i0:i1, j0:j1] |= mask
                covered += mine
                if road.markings:
                    _paint_lane_markings(grid, road.points, road.width_m, road.lanes)
            elif kind == "crosswalk":
                _paint_zebra(grid, road.points, road.width_m)
            elif kind == "parking" and road.markings:
                rng = _rng(seed, _SALT_PARKING, k)
                for mid, length, yaw in _segments(road.points):
                    _paint_bays(grid, mid, length, road.width_m, yaw, 0.0, rng, road.parked_fraction)


def _paint_highway(grid: WorldGrid, hw: HighwaySpec) -> None:
    deck = hw.deck_height_m
    _strip(grid, hw.points, hw.width_m, height_m=deck, cls=SurfaceClass.HIGHWAY, mat=Material.ASPHALT)
    inner = hw.width_m - (2 * RAIL_WIDTH_M if hw.guard_rail else 0.0)
    if hw.markings:
        _paint_lane_markings(grid, hw.points, inner, hw.lanes)
    if hw.guard_rail:
        for side in (-1, 1):
            _strip(
                grid,
                hw.points,
                RAIL_WIDTH_M,
                side * (hw.width_m - RAIL_WIDTH_M) / 2,
                height_m=deck + RAIL_HEIGHT_M,
                cls=SurfaceClass.GUARD_RAIL,
                mat=Material.METAL,
            )
    for ramp in hw.ramps:
        _paint_ramp(grid, ramp)


def _paint_ramp(grid: WorldGrid, ramp: RampSpec) -> None:
    """The deck via ``fill_ramp``; where it leaves a highway, that highway's rail is opened; its own rails
    stand only where the ramp rises more than 0.5 m above what was there before."""
    (n1, e1), (n2, e2) = ramp.start, ramp.end
    length = math.hypot(n2 - n1, e2 - e1)
    yaw = math.atan2(e2 - e1, n2 - n1)
    got = grid.rect_mask(((n1 + n2) / 2, (e1 + e2) / 2), length, ramp.width_m, yaw)
    if got is None:
        return
    win, mask, u, v = got
    i0, i1, j0, j1 = win
    before = grid.height[i0:i1, j0:j1].copy()
    was_rail = grid.cls[i0:i1, j0:j1] == int(SurfaceClass.GUARD_RAIL)
    frac = np.clip(u / length + 0.5, 0.0, 1.0)
    deck = (ramp.start_height_m + frac * (ramp.end_height_m - ramp.start_height_m)).astype(np.float32)
    grid.fill_ramp(ramp.start, ramp.end, ramp.width_m, ramp.start_height_m, ramp.end_height_m)
    opened = mask & was_rail & (before <= deck + RAIL_HEIGHT_M + 0.05)
    grid.paint(win, opened, deck, SurfaceClass.HIGHWAY, Material.ASPHALT)
    if ramp.guard_rail:
        edge = mask & (np.abs(v) > ramp.width_m / 2 - RAIL_WIDTH_M) & (before < deck - 0.5)
        grid.paint(win, edge, deck + RAIL_HEIGHT_M, SurfaceClass.GUARD_RAIL, Material.METAL)


def _paint_building(grid: WorldGrid, b: BuildingSpec, region: int, seed: int, index: int) -> None:
    yaw = math.radians(b.yaw_deg)
    length, width = b.size
    if b.pitched is not None:
        grid.fill_pitched(
            b.centre,
            length,
            width,
            yaw,
            b.height_m,
            b.pitched.ridge_m,
            region=region,
            mat=Material[b.roof.upper()],
        )
        return
    cls = SurfaceClass.PARKING_ROOF if b.parking_structure else SurfaceClass.ROOF_FLAT
    got = grid.rect_mask(b.centre, length, width, yaw)
    if got is None:
        return
    win, mask, u, v = got
    grid.paint(win, mask, b.height_m, cls, Material[b.roof.upper()], region)
    inset = 0.0
    if b.parapet is not None:
        pw = b.parapet.width_m
        ring = mask & ((np.abs(u) > length / 2 - pw) | (np.abs(v) > width / 2 - pw))
        grid.paint(
            win,
            ring,
            b.height_m + b.parapet.height_m,
            SurfaceClass.PARAPET,
            _PARAPET_MAT[b.parapet.material],
            region,
        )
        inset = 2 * pw + 0.5
    if b.parking_structure:
        _paint_bays(
            grid,
            b.centre,
            length - inset,
            width - inset,
            yaw,
            b.height_m,
            _rng(seed, _SALT_DECK, index),
            b.parked_fraction,
        )


def _paint_trees(grid: WorldGrid, spec: ScenarioSpec, seed: int) -> None:
    TREE, FOLIAGE = SurfaceClass.TREE, Material.FOLIAGE
    for k, park in enumerate(spec.parks):
        if park.trees == 0:
            continue
        rng = _rng(seed, _SALT_PARK, k)
        length, width = park.size
        u = rng.uniform(-0.5, 0.5, park.trees) * max(length - 2.0, 0.0)
        v = rng.uniform(-0.5, 0.5, park.trees) * max(width - 2.0, 0.0)
        radii = rng.uniform(*park.tree_radius_m, park.trees)
        heights = rng.uniform(*park.tree_height_m, park.trees)
        yaw = math.radians(park.yaw_deg)
        for t in range(park.trees):
            at = _local(park.centre, yaw, float(u[t]), float(v[t]))
            # trees grow on the lawn only: not on a path, pond or house painted over it
            if grid.class_at(*at) is SurfaceClass.GRASS:
                _paint_dome(grid, at, float(radii[t]), 0.0, float(heights[t]), TREE, FOLIAGE)
    for tree in spec.trees:  # an explicit tree stands on whatever is under its centre
        base = grid.height_at(*tree.centre)
        _paint_dome(grid, tree.centre, tree.radius_m, base, tree.height_m, TREE, FOLIAGE)


def _paint_clutter(grid: WorldGrid, item: ClutterSpec, index: int, seed: int, path: Path) -> None:
    """Clutter stands on the surface under its centre and is clipped to that building's footprint."""
    field = f"clutter[{index}].centre"
    ij = grid.index(*item.centre)
    if ij is None:  # the extent check makes this unreachable for a valid grid
        raise ScenarioFileError(path, [(field, "lies outside the grid")])
    region, under = int(grid.region[ij]), SurfaceClass(int(grid.cls[ij]))
    at = f"({item.centre[0]:g}, {item.centre[1]:g})"
    if region <= 0 or under not in _ROOF_TOPS:
        raise ScenarioFileError(
            path,
            [
                (
                    field,
                    f"not on a building roof: the cell at {at} is {under.name.lower()}; "
                    "clutter must sit on a building",
                )
            ],
        )
    if item.kind == "text" and int(under) not in _FLAT_TOPS:
        raise ScenarioFileError(
            path, [(field, f"text must be painted on a flat roof; the cell at {at} is {under.name.lower()}")]
        )
    base = float(grid.height[ij])
    mat = CLUTTER_KINDS[item.kind][0]
    yaw = math.radians(item.yaw_deg)
    clutter = SurfaceClass.ROOF_CLUTTER
    if item.kind == "dome":
        _paint_dome(grid, item.centre, item.radius(), base, item.rise_m(), clutter, mat, keep_region=region)
        return
    if item.kind in ("vent", "antenna"):
        r = item.radius()
        got = grid.rect_mask(item.centre, 2 * r, 2 * r, 0.0)
        if got is not None:
            win, _, u, v = got
            grid.paint(
                win, _on(grid, win, region) & (u**2 + v**2 <= r**2), base + item.rise_m(), clutter, mat
            )
        return
    if item.kind == "text":
        _paint_text(grid, item, region)
        return
    length, width = item.box()
    got = grid.rect_mask(item.centre, length, width, yaw)
    if got is None:
        return
    win, mask, u, v = got
    mask &= _on(grid, win, region)
    if item.kind != "rubble":
        grid.paint(win, mask, base + item.rise_m(), clutter, mat)
        return
    # rubble: a low debris layer over an elliptical patch, with loose pieces on top
    patch = mask & ((u / (length / 2)) ** 2 + (v / (width / 2)) ** 2 <= 1.0)
    grid.paint(win, patch, base + 0.05, clutter, mat, mode="max")
    rng = _rng(seed, _SALT_RUBBLE, index)
    area = math.pi * length * width / 4
    count = item.count if item.count is not None else int(np.clip(round(area * 0.5), 3, 200))
    top = item.rise_m()
    rad = np.sqrt(rng.random(count))
    ang = rng.uniform(0, 2 * math.pi, count)
    sizes = rng.uniform(0.3, 1.0, (count, 2))
    yaws = rng.uniform(0, math.pi, count)
    tops = rng.uniform(min(0.2, top), top, count)
    for p in range(count):
        pu, pv = rad[p] * math.cos(ang[p]) * length / 2, rad[p] * math.sin(ang[p]) * width / 2
        piece = grid.rect_mask(_local(item.centre, yaw, pu, pv), sizes[p, 0], sizes[p, 1], yaw + yaws[p])
        if piece is not None:
            pwin, pmask, _, _ = piece
            grid.paint(pwin, pmask & _on(grid, pwin, region), base + float(tops[p]), clutter, mat, mode="max")


def _on(grid: WorldGrid, win: tuple[int, int, int, int], region: int) -> np.ndarray:
    i0, i1, j0, j1 = win
    out: np.ndarray = grid.region[i0:i1, j0:j1] == region
    return out


def _paint_text(grid: WorldGrid, item: ClutterSpec, region: int) -> None:
    """Letters in ``Material.PAINT_TEXT``, flat on the roof: read left to right along +east (at yaw 0)
    with the letters' tops toward north; ``letter_height_m`` is the cap height (7 font rows)."""
    text = (item.text or "").upper()
    cap = item.letter_height_m or 2.0
    px = cap / 7
    cols = 6 * len(text) - 1
    width = cols * px
    got = grid.rect_mask(item.centre, cap, width, math.radians(item.yaw_deg))
    if got is None:
        return
    win, mask, u, v = got
    bitmap = np.stack([FONT[ch] for ch in text])  # (chars, 7 rows, 6 columns)
    row = np.clip(np.floor((cap / 2 - u) / px).astype(np.int64), 0, 6)
    col = np.clip(np.floor((v + width / 2) / px).astype(np.int64), 0, cols - 1)
    ink = bitmap[col // 6, row, col % 6]
    i0, i1, j0, j1 = win
    flat = np.isin(grid.cls[i0:i1, j0:j1], _FLAT_TOPS) & (grid.region[i0:i1, j0:j1] == region)
    grid.paint(win, mask & ink & flat, None, None, Material.PAINT_TEXT)


def build_world(spec: ScenarioSpec, seed: int, path: Path) -> World:
    """Paint a validated spec into a grid and wrap it in a :class:`World` (``path`` names errors)."""
    ground_cls, ground_mat = _GROUND[spec.ground]
    grid = WorldGrid.empty(spec.extent.north, spec.extent.east, spec.resolution_m, ground_cls, ground_mat)
    for park in spec.parks:
        _fill(
            grid,
            park.centre,
            *park.size,
            math.radians(park.yaw_deg),
            height_m=0.0,
            cls=SurfaceClass.GRASS,
            mat=Material.GRASS,
        )
    for water in spec.water:
        _fill(
            grid,
            water.centre,
            *water.size,
            math.radians(water.yaw_deg),
            height_m=water.level_m,
            cls=SurfaceClass.WATER,
            mat=Material.WATER,
        )
    _paint_roads(grid, spec, seed)
    for pier in spec.piers:
        _fill(
            grid,
            pier.centre,
            *pier.size,
            math.radians(pier.yaw_deg),
            height_m=pier.height_m,
            cls=SurfaceClass.PIER,
            mat=Material.WOOD,
        )
    for hw in spec.highways:
        _paint_highway(grid, hw)
    for k, b in enumerate(spec.buildings):
        _paint_building(grid, b, k + 1, seed, k)
    _paint_trees(grid, spec, seed)
    for k, item in enumerate(spec.clutter):
        _paint_clutter(grid, item, k, seed, path)
    _check_safe_zones(grid, spec, path)
    return World(
        name=spec.name,
        seed=seed,
        grid=grid,
        launch_ne_m=(spec.launch.north, spec.launch.east),
        launch_height_m=spec.launch.height_m,
        launch_yaw_rad=math.radians(spec.launch.yaw_deg),
        sun=Sun(spec.sun.azimuth_deg, spec.sun.elevation_deg),
        safe_zones=tuple(
            SafeZone(z.centre, z.size[0], z.size[1], math.radians(z.yaw_deg), z.label)
            for z in spec.safe_zones
        ),
        lanes=tuple(
            Lane(ln.points, ln.speed_m_s, ln.arrivals_per_min, ln.deck_height_m) for ln in spec.lanes
        ),
        walkways=tuple(Walkway(w.points, w.count, w.surface_height_m, w.width_m) for w in spec.walkways),
        description=spec.description,
    )


def _check_safe_zones(grid: WorldGrid, spec: ScenarioSpec, path: Path) -> None:
    """A ground-truth landing zone must be clear: no forbidden or obstacle class inside it."""
    bad_classes = np.array(sorted(int(c) for c in FORBIDDEN_CLASSES | OBSTACLE_CLASSES))
    issues = []
    for k, zone in enumerate(spec.safe_zones):
        got = grid.rect_mask(zone.centre, *zone.size, math.radians(zone.yaw_deg))
        if got is None or not got[1].any():
            issues.append((f"safe_zones[{k}]", "covers no grid cell"))
            continue
        (i0, i1, j0, j1), mask, _, _ = got
        cls = grid.cls[i0:i1, j0:j1][mask]
        bad = np.isin(cls, bad_classes)
        if bad.any():
            names = ", ".join(SurfaceClass(int(c)).name.lower() for c in np.unique(cls[bad]))
            issues.append(
                (f"safe_zones[{k}]", f"covers {int(bad.sum())} cells of {names}; a safe zone must be clear")
            )
    if issues:
        raise ScenarioFileError(path, issues)
