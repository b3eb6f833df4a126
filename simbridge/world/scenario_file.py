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
import math
import re
import tomllib
import types
import typing
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ValidationError
from pydantic_core import ErrorDetails

from simbridge.world.scenario_paint import _local, build_world
from simbridge.world.scenario_schema import (
    BUILTIN_SCENARIO_DIR,
    MAX_GRID_CELLS,
    Point,
    ScenarioFileError,
    ScenarioSpec,
)
from simbridge.world.world import World

__all__ = [
    "BUILTIN_SCENARIO_DIR",
    "MAX_GRID_CELLS",
    "ScenarioFileError",
    "ScenarioSpec",
    "build_world",
    "builtin_scenario_names",
    "builtin_scenario_path",
    "load_scenario_file",
    "parse_scenario_file",
]


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
def _rect_corners(centre: Point, size: tuple[float, float], yaw_deg: float) -> list[Point]:
    half_l, half_w, yaw = size[0] / 2, size[1] / 2, math.radians(yaw_deg)
    return [_local(centre, yaw, su * half_l, sv * half_w) for su, sv in ((1, 1), (1, -1), (-1, -1), (-1, 1))]


def _check_placement(spec: ScenarioSpec) -> list[tuple[str, str]]:
    """Everything that must lie inside the extent, unique ids and the grid size."""
    (n_lo, n_hi), (e_lo, e_hi) = spec.extent.north, spec.extent.east
    where = f"the extent (north {n_lo:g}..{n_hi:g}, east {e_lo:g}..{e_hi:g})"
    issues: list[tuple[str, str]] = []
    eps = 1e-6

    def inside(p: Point) -> bool:
        return n_lo - eps <= p[0] <= n_hi + eps and e_lo - eps <= p[1] <= e_hi + eps

    def check_points(field: str, pts: Sequence[Point], what: str) -> None:
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
