"""Declarative scenario files: a validated TOML description of a city block, painted into a World.

The format is documented field by field in ``docs/scenario-format.md``. Coordinates are scenario NED
metres (``[north, east]``); heights are metres up from the scenario origin's ground level (ground = 0);
``yaw_deg`` turns a shape's length axis from north toward east. A file is parsed with :mod:`tomllib`,
validated by the pydantic models below (unknown keys are errors), checked against the extent, and then
painted into a :class:`~simbridge.world.model.WorldGrid` in a fixed order: ground, parks, water, roads
(parking, sidewalks, roads, crosswalks), piers, highways, buildings, trees, clutter.

Everything random (rubble, park trees, parked cars) draws from a generator seeded from the scenario seed
and the object's position in the file, so the same seed always gives the same grid.

Errors::

    ValueError
    └── ScenarioFileError   file, field path and problem, e.g.
                            "scenario1.toml: buildings[2].height_m: must be greater than 0 (got -3)"
"""

from __future__ import annotations

import difflib
import itertools
import math
import re
import tomllib
import types
import typing
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator
from pydantic_core import ErrorDetails

from simbridge.world.model import FORBIDDEN_CLASSES, OBSTACLE_CLASSES, Material, SurfaceClass, WorldGrid
from simbridge.world.world import Lane, SafeZone, Sun, Walkway, World

BUILTIN_SCENARIO_DIR = Path(__file__).resolve().parent / "scenarios"
"""Folder of the curated scenario files shipped with the package."""

MAX_GRID_CELLS = 40_000_000  # ~400 MB of rasters; beyond this the extent or resolution is a mistake


class ScenarioFileError(ValueError):
    """A scenario file that cannot be read, parsed, validated or built.

    ``issues`` holds ``(field_path, problem)`` pairs (an empty path for file-level problems); the
    message has one ``"<file name>: <field path>: <problem>"`` line per issue.
    """

    def __init__(self, path: Path, issues: Sequence[tuple[str, str]]) -> None:
        self.path = path
        self.issues = tuple(issues)
        lines = [
            f"{path.name}: {fld}: {problem}" if fld else f"{path.name}: {problem}" for fld, problem in issues
        ]
        super().__init__("\n".join(lines))

    @property
    def field(self) -> str:
        """Field path of the first issue, e.g. ``buildings[2].height_m``."""
        return self.issues[0][0] if self.issues else ""

    @property
    def problem(self) -> str:
        """What is wrong with the first issue's field."""
        return self.issues[0][1] if self.issues else ""


# ---------------------------------------------------------------------------------------------- schema
_Pos = Annotated[float, Field(gt=0)]
_Point = tuple[float, float]
_Size = tuple[_Pos, _Pos]
_Speed = Annotated[float, Field(ge=5.0, le=25.0)]
RoofName = Literal["gravel", "concrete", "tar", "membrane", "tiles"]
ClutterKind = Literal["hvac", "vent", "pipe", "dome", "antenna", "solar", "rubble", "text"]
RoadKind = Literal["road", "sidewalk", "crosswalk", "parking"]
GroundName = Literal["soil", "grass", "paving", "gravel"]


class _Spec(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


def _ordered_pair(v: tuple[float, float]) -> tuple[float, float]:
    if v[0] > v[1]:
        raise ValueError(f"the first value must not exceed the second (got [{v[0]}, {v[1]}])")
    return v


def _nonzero_path(v: tuple[_Point, ...]) -> tuple[_Point, ...]:
    if all(p == v[0] for p in v):
        raise ValueError("all points coincide; a path needs length")
    return v


class ExtentSpec(_Spec):
    """The modelled area: ``[min, max]`` metres along north and east."""

    north: tuple[float, float] = (-250.0, 250.0)
    east: tuple[float, float] = (-250.0, 250.0)

    @field_validator("north", "east")
    @classmethod
    def _min_below_max(cls, v: tuple[float, float]) -> tuple[float, float]:
        if not v[0] < v[1]:
            raise ValueError(f"min must be less than max (got [{v[0]}, {v[1]}])")
        return v


class LaunchSpec(_Spec):
    """Where the vehicle starts: metres north/east, height above the ground, heading."""

    north: float = 0.0
    east: float = 0.0
    height_m: float = Field(default=110.0, ge=20.0, le=200.0)
    yaw_deg: float = 0.0


class SunSpec(_Spec):
    azimuth_deg: float = Field(default=135.0, ge=0.0, le=360.0)
    elevation_deg: float = Field(default=50.0, ge=5.0, le=90.0)


class ParapetSpec(_Spec):
    """A low wall around a roof's edge, ``height_m`` above the roof, ``width_m`` thick."""

    height_m: float = Field(default=1.0, gt=0.0, le=3.0)
    width_m: float = Field(default=0.4, gt=0.0, le=2.0)
    material: Literal["concrete", "brick", "metal"] = "concrete"


class PitchedSpec(_Spec):
    """A gable roof: eaves at the building's ``height_m``, ridge along its length at ``ridge_m``."""

    ridge_m: float = Field(gt=0.0, le=400.0)


class BuildingSpec(_Spec):
    id: str = Field(min_length=1)
    centre: _Point
    size: _Size
    yaw_deg: float = 0.0
    height_m: float = Field(gt=0.0, le=400.0)
    roof: RoofName = "concrete"
    parapet: ParapetSpec | None = None
    pitched: PitchedSpec | None = None
    parking_structure: bool = False
    parked_fraction: float = Field(default=0.0, ge=0.0, le=1.0)

    @model_validator(mode="after")
    def _consistent(self) -> BuildingSpec:
        if self.pitched is not None:
            if self.parking_structure:
                raise ValueError("pitched: a parking structure has a flat deck; drop one of the two")
            if self.parapet is not None:
                raise ValueError("parapet: a pitched roof has no parapet; drop one of the two")
            if self.pitched.ridge_m <= self.height_m:
                raise ValueError(
                    f"pitched.ridge_m: must be above the eaves at height_m {self.height_m} "
                    f"(got {self.pitched.ridge_m})"
                )
        if self.parking_structure and self.roof != "concrete":
            raise ValueError(f"roof: a parking structure's deck is 'concrete' (got {self.roof!r})")
        if self.parked_fraction > 0 and not self.parking_structure:
            raise ValueError("parked_fraction: only a parking_structure has parking bays")
        if self.parapet is not None and 2 * self.parapet.width_m >= min(self.size):
            raise ValueError(
                f"parapet.width_m: twice the width must be less than the building's smaller side "
                f"{min(self.size)} m (got {self.parapet.width_m})"
            )
        return self


# kind -> (material, default size [l, w] or None, default radius or None, default height above roof)
_CLUTTER_KINDS: dict[str, tuple[Material, tuple[float, float] | None, float | None, float | None]] = {
    "hvac": (Material.METAL, (3.0, 2.0), None, 1.6),
    "pipe": (Material.METAL, None, None, 0.5),
    "solar": (Material.SOLAR, (4.0, 2.0), None, 0.4),
    "rubble": (Material.RUBBLE, (5.0, 4.0), None, 0.6),
    "vent": (Material.METAL, None, 0.4, 0.9),
    "dome": (Material.METAL, None, 2.0, 1.5),
    "antenna": (Material.METAL, None, 0.15, 4.0),
    "text": (Material.PAINT_TEXT, None, None, None),
}
_ROUND_KINDS = frozenset({"vent", "dome", "antenna"})


class ClutterSpec(_Spec):
    kind: ClutterKind
    centre: _Point
    size: _Size | None = None
    radius_m: float | None = Field(default=None, gt=0.0, le=20.0)
    yaw_deg: float = 0.0
    height_m: float | None = Field(default=None, gt=0.0, le=30.0)
    count: int | None = Field(default=None, ge=1, le=500)
    text: str | None = None
    letter_height_m: float | None = Field(default=None, gt=0.0, le=20.0)

    @model_validator(mode="after")
    def _kind_fields(self) -> ClutterSpec:
        kind = self.kind
        if kind in _ROUND_KINDS:
            if self.size is not None:
                raise ValueError(f"size: not used by kind {kind!r}, which is round; give radius_m")
        elif self.radius_m is not None:
            raise ValueError(f"radius_m: not used by kind {kind!r}; give size [length, width]")
        if kind == "pipe" and self.size is None:
            raise ValueError("size: required for kind 'pipe' ([length, diameter] in metres)")
        if kind == "text":
            if not self.text:
                raise ValueError("text: required for kind 'text' (the letters to paint)")
            bad = sorted({ch for ch in self.text.upper() if ch not in _FONT})
            if bad:
                raise ValueError(
                    f"text: unsupported characters {''.join(bad)!r}; allowed: A-Z, 0-9, space and ! - ."
                )
            for name in ("size", "height_m", "count"):
                if getattr(self, name) is not None:
                    raise ValueError(f"{name}: not used by kind 'text' (letters are painted flat)")
        else:
            if self.text is not None or self.letter_height_m is not None:
                name = "text" if self.text is not None else "letter_height_m"
                raise ValueError(f"{name}: only used by kind 'text'")
        if self.count is not None and kind != "rubble":
            raise ValueError(f"count: only used by kind 'rubble' (got kind {kind!r})")
        return self

    def box(self) -> tuple[float, float]:
        """Footprint ``(length, width)`` in metres for the rectangular kinds."""
        if self.size is not None:
            return self.size
        default = _CLUTTER_KINDS[self.kind][1]
        return default if default is not None else (1.0, 1.0)

    def radius(self) -> float:
        """Radius in metres for the round kinds (vent, dome, antenna)."""
        default = _CLUTTER_KINDS[self.kind][2]
        return self.radius_m if self.radius_m is not None else (default or 0.5)

    def rise_m(self) -> float:
        """Height of the top above the surface under the centre, metres."""
        default = _CLUTTER_KINDS[self.kind][3]
        return self.height_m if self.height_m is not None else (default or 0.0)


class RoadSpec(_Spec):
    kind: RoadKind = "road"
    points: tuple[_Point, ...] = Field(min_length=2)
    width_m: float = Field(gt=0.0, le=200.0)
    lanes: int = Field(default=2, ge=1, le=10)
    markings: bool = True
    parked_fraction: float = Field(default=0.0, ge=0.0, le=1.0)

    _path = field_validator("points")(_nonzero_path)

    @model_validator(mode="after")
    def _kind_fields(self) -> RoadSpec:
        if self.parked_fraction > 0 and self.kind != "parking":
            raise ValueError(f"parked_fraction: only used by kind 'parking' (got kind {self.kind!r})")
        return self


class RampSpec(_Spec):
    start: _Point
    end: _Point
    width_m: float = Field(gt=0.0, le=50.0)
    start_height_m: float = Field(ge=0.0, le=100.0)
    end_height_m: float = Field(ge=0.0, le=100.0)
    guard_rail: bool = True

    @model_validator(mode="after")
    def _has_length(self) -> RampSpec:
        if self.start == self.end:
            raise ValueError(f"end: must differ from start (both {list(self.start)})")
        return self


class HighwaySpec(_Spec):
    points: tuple[_Point, ...] = Field(min_length=2)
    width_m: float = Field(gt=0.0, le=100.0)
    deck_height_m: float = Field(gt=0.0, le=100.0)
    lanes: int = Field(default=4, ge=1, le=12)
    guard_rail: bool = True
    markings: bool = True
    ramps: tuple[RampSpec, ...] = ()

    _path = field_validator("points")(_nonzero_path)


class WaterSpec(_Spec):
    centre: _Point
    size: _Size
    yaw_deg: float = 0.0
    level_m: float = Field(default=-0.8, ge=-20.0, lt=0.0)


class PierSpec(_Spec):
    centre: _Point
    size: _Size
    yaw_deg: float = 0.0
    height_m: float = Field(default=0.6, gt=0.0, le=10.0)


class ParkSpec(_Spec):
    centre: _Point
    size: _Size
    yaw_deg: float = 0.0
    trees: int = Field(default=0, ge=0, le=5000)
    tree_radius_m: tuple[_Pos, _Pos] = (2.0, 4.5)
    tree_height_m: tuple[_Pos, _Pos] = (5.0, 12.0)

    _ordered = field_validator("tree_radius_m", "tree_height_m")(_ordered_pair)


class TreeSpec(_Spec):
    centre: _Point
    radius_m: float = Field(default=3.0, gt=0.0, le=20.0)
    height_m: float = Field(default=8.0, gt=0.0, le=60.0)


class LaneSpec(_Spec):
    points: tuple[_Point, ...] = Field(min_length=2)
    speed_m_s: tuple[_Speed, _Speed] = (8.0, 14.0)
    arrivals_per_min: float = Field(default=6.0, gt=0.0, le=120.0)
    deck_height_m: float = Field(default=0.0, ge=0.0, le=100.0)

    _ordered = field_validator("speed_m_s")(_ordered_pair)

    _path = field_validator("points")(_nonzero_path)


class WalkwaySpec(_Spec):
    points: tuple[_Point, ...] = Field(min_length=2)
    count: int = Field(default=4, ge=0, le=500)
    surface_height_m: float = Field(default=0.0, ge=0.0, le=400.0)
    width_m: float = Field(default=2.0, gt=0.0, le=50.0)

    _path = field_validator("points")(_nonzero_path)


class SafeZoneSpec(_Spec):
    centre: _Point
    size: _Size
    yaw_deg: float = 0.0
    label: str = ""


class ScenarioSpec(_Spec):
    """The whole file. Tables are painted in the order given in the module docstring."""

    name: str = Field(min_length=1)
    description: str = ""
    extent: ExtentSpec = ExtentSpec()
    resolution_m: float = Field(default=0.2, ge=0.05, le=1.0)
    ground: GroundName = "soil"
    launch: LaunchSpec = LaunchSpec()
    sun: SunSpec = SunSpec()
    buildings: tuple[BuildingSpec, ...] = ()
    clutter: tuple[ClutterSpec, ...] = ()
    roads: tuple[RoadSpec, ...] = ()
    highways: tuple[HighwaySpec, ...] = ()
    water: tuple[WaterSpec, ...] = ()
    piers: tuple[PierSpec, ...] = ()
    parks: tuple[ParkSpec, ...] = ()
    trees: tuple[TreeSpec, ...] = ()
    lanes: tuple[LaneSpec, ...] = ()
    walkways: tuple[WalkwaySpec, ...] = ()
    safe_zones: tuple[SafeZoneSpec, ...] = ()


# ---------------------------------------------------------------------------------------------- loading
def builtin_scenario_names() -> list[str]:
    """Names (file stems) of the curated scenarios, sorted."""
    return sorted(p.stem for p in BUILTIN_SCENARIO_DIR.glob("*.toml"))


def builtin_scenario_path(name: str) -> Path:
    """The file of a curated scenario; ``ScenarioFileError`` naming the known ones if there is none."""
    path = BUILTIN_SCENARIO_DIR / f"{name}.toml"
    if not path.is_file():
        known = ", ".join(builtin_scenario_names())
        raise ScenarioFileError(path, [("", f"no built-in scenario {name!r}; known: {known}")])
    return path


def load_scenario_file(path: Path, seed: int = 0) -> World:
    """Parse, validate and build the scenario in ``path`` (TOML) into a :class:`World`.

    Args:
        path: the ``.toml`` file.
        seed: seeds everything random in the file (rubble, park trees, parked cars).

    Raises:
        ScenarioFileError: the file cannot be read, is not valid TOML, does not match the schema, or
            describes something that cannot be built (clutter off any roof, an obstructed safe zone).
    """
    spec = parse_scenario_file(path)
    return build_world(spec, seed, path)


def parse_scenario_file(path: Path) -> ScenarioSpec:
    """Read and validate ``path`` without painting anything."""
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise ScenarioFileError(path, [("", f"cannot read the file: {exc.strerror or exc}")]) from exc
    try:
        data = tomllib.loads(raw.decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise ScenarioFileError(path, [("", f"not UTF-8 text: {exc.reason} at byte {exc.start}")]) from exc
    except tomllib.TOMLDecodeError as exc:
        m = re.search(r"line (\d+)", str(exc))
        where = f"line {m.group(1)}" if m else ""
        raise ScenarioFileError(path, [(where, f"TOML syntax error: {exc}")]) from exc
    try:
        spec = ScenarioSpec.model_validate(data)
    except ValidationError as exc:
        raise ScenarioFileError(path, [_describe(err) for err in exc.errors()]) from exc
    issues = _check_placement(spec)
    if issues:
        raise ScenarioFileError(path, issues)
    return spec


def _field_path(loc: Sequence[int | str]) -> str:
    out = ""
    for part in loc:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else str(part))
    return out


def _model_in(tp: Any) -> type[BaseModel] | None:
    if isinstance(tp, type) and issubclass(tp, BaseModel):
        return tp
    if isinstance(tp, types.UnionType) or typing.get_origin(tp) is not None:
        for arg in typing.get_args(tp):
            found = _model_in(arg)
            if found is not None:
                return found
    return None


def _allowed_keys(loc: Sequence[int | str]) -> list[str]:
    model: type[BaseModel] = ScenarioSpec
    for part in loc:
        if isinstance(part, int):
            continue
        info = model.model_fields.get(part)
        sub = None if info is None else _model_in(info.annotation)
        if sub is None:
            return []
        model = sub
    return list(model.model_fields)


def _describe(err: ErrorDetails) -> tuple[str, str]:
    """One pydantic error as ``(field path, problem)`` in our words."""
    loc = list(err["loc"])
    typ, msg, got = err["type"], err["msg"], err.get("input")
    if typ == "extra_forbidden":
        allowed = _allowed_keys(loc[:-1])
        hint = difflib.get_close_matches(str(loc[-1]), allowed, n=1)
        mean = f" (did you mean {hint[0]!r}?)" if hint else ""
        return _field_path(loc), f"unknown key{mean}; allowed keys: {', '.join(allowed)}"
    if typ == "missing":
        return _field_path(loc), "required, but missing"
    if msg.startswith("Value error, "):
        msg = msg.removeprefix("Value error, ")
        # model validators name the field they object to as "field: problem"
        m = re.match(r"([a-z_]+(?:\.[a-z_]+)*): (.*)", msg, re.DOTALL)
        if m is not None and typ == "value_error" and isinstance(got, dict):
            loc += m.group(1).split(".")
            msg = m.group(2)
        return _field_path(loc), msg
    if msg.startswith("Input should be "):
        msg = "must be " + msg.removeprefix("Input should be ")
    if isinstance(got, bool | int | float | str):
        msg += f" (got {got!r})"
    return _field_path(loc), msg


# ---------------------------------------------------------------------------------------------- placement
def _rect_corners(centre: _Point, size: tuple[float, float], yaw_deg: float) -> list[_Point]:
    half_l, half_w, yaw = size[0] / 2, size[1] / 2, math.radians(yaw_deg)
    return [_local(centre, yaw, su * half_l, sv * half_w) for su, sv in ((1, 1), (1, -1), (-1, -1), (-1, 1))]


def _check_placement(spec: ScenarioSpec) -> list[tuple[str, str]]:
    """Everything that must lie inside the extent, unique ids and the grid size."""
    (n_lo, n_hi), (e_lo, e_hi) = spec.extent.north, spec.extent.east
    where = f"the extent (north {n_lo:g}..{n_hi:g}, east {e_lo:g}..{e_hi:g})"
    issues: list[tuple[str, str]] = []
    eps = 1e-6

    def inside(p: _Point) -> bool:
        return n_lo - eps <= p[0] <= n_hi + eps and e_lo - eps <= p[1] <= e_hi + eps

    def check_points(field: str, pts: Sequence[_Point], what: str) -> None:
        for p in pts:
            if not inside(p):
                issues.append((field, f"{what} ({p[0]:g}, {p[1]:g}) lies outside {where}"))
                return

    cells = ((n_hi - n_lo) / spec.resolution_m) * ((e_hi - e_lo) / spec.resolution_m)
    if cells > MAX_GRID_CELLS:
        issues.append(
            (
                "resolution_m",
                f"the extent at {spec.resolution_m} m gives {cells:.3g} cells; at most "
                f"{MAX_GRID_CELLS:.3g} (coarsen the resolution or shrink the extent)",
            )
        )
    check_points("launch", [(spec.launch.north, spec.launch.east)], "the launch point")
    rects: list[tuple[str, Sequence[Any]]] = [
        ("buildings", spec.buildings),
        ("water", spec.water),
        ("piers", spec.piers),
        ("parks", spec.parks),
        ("safe_zones", spec.safe_zones),
    ]
    for table, items in rects:
        for k, item in enumerate(items):
            check_points(
                f"{table}[{k}].centre", _rect_corners(item.centre, item.size, item.yaw_deg), "corner"
            )
    for k, tree in enumerate(spec.trees):
        check_points(f"trees[{k}].centre", [tree.centre], "the centre")
    for k, clutter in enumerate(spec.clutter):
        check_points(f"clutter[{k}].centre", [clutter.centre], "the centre")
    paths: list[tuple[str, Sequence[Any]]] = [
        ("roads", spec.roads),
        ("highways", spec.highways),
        ("lanes", spec.lanes),
        ("walkways", spec.walkways),
    ]
    for table, items in paths:
        for k, item in enumerate(items):
            check_points(f"{table}[{k}].points", item.points, "point")
    for k, hw in enumerate(spec.highways):
        for r, ramp in enumerate(hw.ramps):
            check_points(f"highways[{k}].ramps[{r}]", [ramp.start, ramp.end], "end point")
    seen: dict[str, int] = {}
    for k, b in enumerate(spec.buildings):
        if b.id in seen:
            issues.append((f"buildings[{k}].id", f"duplicate id {b.id!r} (also buildings[{seen[b.id]}])"))
        seen.setdefault(b.id, k)
    return issues


# ---------------------------------------------------------------------------------------------- painting
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


def _local(centre: _Point, yaw: float, u: float, v: float) -> _Point:
    """Scenario (north, east) of the point ``u`` along and ``v`` across a frame at ``centre``."""
    c, s = math.cos(yaw), math.sin(yaw)
    return (centre[0] + u * c - v * s, centre[1] + u * s + v * c)


def _segments(points: Sequence[_Point]) -> Iterator[tuple[_Point, float, float]]:
    """``(midpoint, length, yaw_rad)`` of each non-degenerate segment."""
    for (n1, e1), (n2, e2) in itertools.pairwise(points):
        length = math.hypot(n2 - n1, e2 - e1)
        if length > 0:
            yield ((n1 + n2) / 2, (e1 + e2) / 2), length, math.atan2(e2 - e1, n2 - n1)


def _mark_width(grid: WorldGrid) -> float:
    return max(0.15, grid.res * 1.01)


def _tiles(
    grid: WorldGrid, centre: _Point, length_m: float, width_m: float, yaw: float
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
    centre: _Point,
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
    points: Sequence[_Point],
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
    points: Sequence[_Point],
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


def _paint_lane_markings(grid: WorldGrid, points: Sequence[_Point], width_m: float, lanes: int) -> None:
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


def _paint_zebra(grid: WorldGrid, points: Sequence[_Point], width_m: float) -> None:
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
    centre: _Point,
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
    centre: _Point,
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
    mat = _CLUTTER_KINDS[item.kind][0]
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


# A 5x7 stencil font: each glyph is seven rows of five bits (bit 4 = leftmost column), as hex pairs.
_FONT_HEX = {
    "A": "0E11111F111111", "B": "1E11111E11111E", "C": "0E11101010110E", "D": "1E11111111111E",
    "E": "1F10101E10101F", "F": "1F10101E101010", "G": "0E11101711110F", "H": "1111111F111111",
    "I": "0E04040404040E", "J": "0702020202120C", "K": "11121418141211", "L": "1010101010101F",
    "M": "111B1515111111", "N": "11111915131111", "O": "0E11111111110E", "P": "1E11111E101010",
    "Q": "0E11111115120D", "R": "1E11111E141211", "S": "0F10100E01011E", "T": "1F040404040404",
    "U": "1111111111110E", "V": "11111111110A04", "W": "1111111515150A",
    "X": "11110A040A1111", "Y": "1111110A040404", "Z": "1F01020408101F", "0": "0E11131519110E",
    "1": "040C040404040E", "2": "0E11010204081F", "3": "1F02040201110E",
    "4": "02060A121F0202", "5": "1F101E0101110E", "6": "0608101E11110E", "7": "1F010204080808",
    "8": "0E11110E11110E", "9": "0E11110F01020C", " ": "00000000000000", "!": "04040404040004",
    "-": "0000001F000000", ".": "00000000000C0C",
}  # fmt: skip
# (7 rows, 6 columns) booleans; the sixth column is the gap before the next letter
_FONT: dict[str, np.ndarray] = {
    ch: np.array(
        [[c < 5 and bool(int(h[2 * r : 2 * r + 2], 16) >> (4 - c) & 1) for c in range(6)] for r in range(7)]
    )
    for ch, h in _FONT_HEX.items()
}


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
    bitmap = np.stack([_FONT[ch] for ch in text])  # (chars, 7 rows, 6 columns)
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
