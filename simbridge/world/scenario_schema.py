"""The scenario file's schema: pydantic models of every table (unknown keys are errors), and the
error a bad file raises. The format is documented field by field in ``docs/scenario-format.md``."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Annotated, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from simbridge.world.model import Material

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
Point = tuple[float, float]
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


def _nonzero_path(v: tuple[Point, ...]) -> tuple[Point, ...]:
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
    centre: Point
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
CLUTTER_KINDS: dict[str, tuple[Material, tuple[float, float] | None, float | None, float | None]] = {
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
    centre: Point
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
            bad = sorted({ch for ch in self.text.upper() if ch not in FONT})
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
        default = CLUTTER_KINDS[self.kind][1]
        return default if default is not None else (1.0, 1.0)

    def radius(self) -> float:
        """Radius in metres for the round kinds (vent, dome, antenna)."""
        default = CLUTTER_KINDS[self.kind][2]
        return self.radius_m if self.radius_m is not None else (default or 0.5)

    def rise_m(self) -> float:
        """Height of the top above the surface under the centre, metres."""
        default = CLUTTER_KINDS[self.kind][3]
        return self.height_m if self.height_m is not None else (default or 0.0)


class RoadSpec(_Spec):
    kind: RoadKind = "road"
    points: tuple[Point, ...] = Field(min_length=2)
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
    start: Point
    end: Point
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
    points: tuple[Point, ...] = Field(min_length=2)
    width_m: float = Field(gt=0.0, le=100.0)
    deck_height_m: float = Field(gt=0.0, le=100.0)
    lanes: int = Field(default=4, ge=1, le=12)
    guard_rail: bool = True
    markings: bool = True
    ramps: tuple[RampSpec, ...] = ()

    _path = field_validator("points")(_nonzero_path)


class WaterSpec(_Spec):
    centre: Point
    size: _Size
    yaw_deg: float = 0.0
    level_m: float = Field(default=-0.8, ge=-20.0, lt=0.0)


class PierSpec(_Spec):
    centre: Point
    size: _Size
    yaw_deg: float = 0.0
    height_m: float = Field(default=0.6, gt=0.0, le=10.0)


class ParkSpec(_Spec):
    centre: Point
    size: _Size
    yaw_deg: float = 0.0
    trees: int = Field(default=0, ge=0, le=5000)
    tree_radius_m: tuple[_Pos, _Pos] = (2.0, 4.5)
    tree_height_m: tuple[_Pos, _Pos] = (5.0, 12.0)

    _ordered = field_validator("tree_radius_m", "tree_height_m")(_ordered_pair)


class TreeSpec(_Spec):
    centre: Point
    radius_m: float = Field(default=3.0, gt=0.0, le=20.0)
    height_m: float = Field(default=8.0, gt=0.0, le=60.0)


class LaneSpec(_Spec):
    points: tuple[Point, ...] = Field(min_length=2)
    speed_m_s: tuple[_Speed, _Speed] = (8.0, 14.0)
    arrivals_per_min: float = Field(default=6.0, gt=0.0, le=120.0)
    deck_height_m: float = Field(default=0.0, ge=0.0, le=100.0)

    _ordered = field_validator("speed_m_s")(_ordered_pair)

    _path = field_validator("points")(_nonzero_path)


class WalkwaySpec(_Spec):
    points: tuple[Point, ...] = Field(min_length=2)
    count: int = Field(default=4, ge=0, le=500)
    surface_height_m: float = Field(default=0.0, ge=0.0, le=400.0)
    width_m: float = Field(default=2.0, gt=0.0, le=50.0)

    _path = field_validator("points")(_nonzero_path)


class SafeZoneSpec(_Spec):
    centre: Point
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


# A 5x7 stencil font: each glyph is seven rows of five bits (bit 4 = leftmost column), as hex pairs.
FONT_HEX = {
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
FONT: dict[str, np.ndarray] = {
    ch: np.array(
        [[c < 5 and bool(int(h[2 * r : 2 * r + 2], 16) >> (4 - c) & 1) for c in range(6)] for r in range(7)]
    )
    for ch, h in FONT_HEX.items()
}
