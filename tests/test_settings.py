"""The recovery's runtime parameters have one source, the configuration schema: the defaults
of :class:`RecoveryParams`, :class:`SearchLimits`, :class:`SurfaceParams` and the depth sources are the
schema's, never a copy; and every key that sets a parameter reaches it through the function the daemon
uses (``companion.cli.params_from``)."""

from __future__ import annotations

import ast
import inspect
import tomllib
from collections.abc import Callable
from pathlib import Path

import pytest

from companion.alarms import Criticality
from companion.cli import params_from
from companion.config import load_config
from companion.config_schema import DEFAULTS, CompanionConfig, PerceptionConfig, RecoveryConfig
from companion.perception.depth import ArrayDepth, LidarDepth
from companion.perception.sources import make_source
from companion.perception.surface_id import SurfaceParams
from companion.recovery import RecoveryParams
from companion.recovery.search_plan import SearchLimits, SearchPlanner

# Every key that sets a runtime parameter, with a value other than its default, as TOML text.
NON_DEFAULT: dict[str, dict[str, str]] = {
    "recovery": {
        "max_rounds": "5",
        "rounds_by_criticality": "{ low = 8 }",
        "descent_fraction": "0.5",
        "final_land_m": "4.0",
        "arrival_tolerance_m": "0.25",
        "arrival_speed_m_s": "0.2",
        "move_timeout_s": "45.0",
        "move_timeout_s_per_m": "0.25",
        "explore_climb_m": "10.0",
        "explore_max_alt_m": "80.0",
        "blind_descent_agl_m": "60.0",
        "sensor_loss_s": "20.0",
        "link_loss_s": "40.0",
        "failsafe_grace_s": "3.0",
        "land_timeout_s": "90.0",
        "search_reserve_pct": "30.0",
        "search_window_s": "{ high = 200.0 }",
        "search_agl_m": "60.0",
        "search_max_legs": "20",
        "people_margin_m": "6.0",
        "people_wait_s": "8.0",
    },
    "perception": {
        "cell_px": "8",
        "window_cells": "7",
        "max_slope_deg": "6.0",
        "max_roughness_m": "0.04",
        "min_area_m2": "20.0",
        "edge_margin_m": "1.5",
        "max_candidates": "3",
        "lidar_range_m": "120.0",
        "extend_with_image": "false",
        "strip_min_length_m": "50.0",
        "strip_min_aspect": "3.0",
    },
    "reasoner": {"context": '"pad30"'},
}
# Keys whose value lands under another name, or in more than one place: what reads it, what it reads.
ELSEWHERE: dict[tuple[str, str], tuple[Callable[[RecoveryParams], object], object]] = {
    ("recovery", "max_rounds"): (lambda p: p.rounds_by_criticality[Criticality.LOW], 5),
    ("recovery", "rounds_by_criticality"): (lambda p: p.rounds_by_criticality[Criticality.LOW], 8),
    ("recovery", "search_reserve_pct"): (lambda p: p.search.reserve_pct, 30.0),
    ("recovery", "search_window_s"): (lambda p: p.search.window_s[Criticality.HIGH], 200.0),
    ("recovery", "search_max_legs"): (lambda p: p.search.max_legs, 20),
    ("perception", "cell_px"): (
        lambda p: (p.surface.cell_px, getattr(p.depth_source, "cell_px", None)),
        (8, 8),
    ),
    ("perception", "lidar_range_m"): (
        lambda p: (p.lidar_range_m, getattr(p.depth_source, "range_m", None)),
        (120.0, 120.0),
    ),
}
# Keys that choose the depth source object rather than a value (test_surface_id, test_mono_depth).
DEPTH_CHOICE = {("perception", "depth"), ("perception", "depth_model")}
# Dataclass fields that are keys of another section or under another name (the rest are named as a key
# of [recovery] or [perception]).
RENAMED = {
    RecoveryParams: {"context"},
    SearchLimits: {"reserve_pct", "window_s", "max_legs"},
    LidarDepth: {"range_m"},
}


def _reads(section: str, key: str) -> tuple[Callable[[RecoveryParams], object], object]:
    """Where a key's value lands in the parameters, and the value it should read there."""
    if (section, key) in ELSEWHERE:
        return ELSEWHERE[section, key]
    value = tomllib.loads(f"v = {NON_DEFAULT[section][key]}")["v"]
    if section == "perception":
        return (lambda p: getattr(p.surface, key)), value
    return (lambda p: getattr(p, key)), value


def test_non_default_covers_every_key_that_sets_a_parameter() -> None:
    """A new key of [recovery] or [perception] needs a value here, and so a test that it arrives."""
    keys = {
        (s, k)
        for s, model in (("recovery", RecoveryConfig), ("perception", PerceptionConfig))
        for k in model.model_fields
    }
    tested = {(s, k) for s, table in NON_DEFAULT.items() for k in table}
    assert keys - DEPTH_CHOICE - tested == set()
    assert tested - keys == {("reasoner", "context")}


def test_params_from_the_default_config_are_the_default_params() -> None:
    p = params_from(load_config(None, {}, {}))
    assert p == RecoveryParams()  # the search limits, the surface thresholds and the depth source too
    assert RecoveryParams.from_config(CompanionConfig()) == RecoveryParams()
    assert p.search == SearchLimits()
    assert p.surface == SurfaceParams()
    assert p.depth_source == LidarDepth() == make_source(DEFAULTS.perception.depth)


def test_search_planner_defaults_are_the_default_params() -> None:
    planner, p = SearchPlanner(Criticality.HIGH), RecoveryParams()
    assert planner.limits == p.search
    assert (planner.search_agl_m, planner.lidar_range_m) == (p.search_agl_m, p.lidar_range_m)


@pytest.mark.parametrize(
    ("section", "key"), [pytest.param(s, k, id=f"{s}.{k}") for s, table in NON_DEFAULT.items() for k in table]
)
def test_params_from_a_non_default_toml_value_reaches_the_params(
    section: str, key: str, tmp_path: Path
) -> None:
    read, expected = _reads(section, key)
    assert read(RecoveryParams()) != expected  # else this test could not fail
    path = tmp_path / "companion.toml"
    path.write_text(f"[{section}]\n{key} = {NON_DEFAULT[section][key]}\n")
    p = params_from(load_config(path, {}, {}))
    assert read(p) == expected
    assert p != RecoveryParams()


@pytest.mark.parametrize(
    "cls", [RecoveryParams, SearchLimits, SurfaceParams, LidarDepth, ArrayDepth], ids=lambda c: c.__name__
)
def test_a_field_that_is_a_key_takes_its_default_from_the_schema(cls: type) -> None:
    """No second copy of a default: a field that is a key reads it from ``DEFAULTS`` in its source."""
    keys = set(RecoveryConfig.model_fields) | set(PerceptionConfig.model_fields) | RENAMED.get(cls, set())
    tree = ast.parse(inspect.getsource(cls).lstrip())
    fields = [n for n in ast.walk(tree) if isinstance(n, ast.AnnAssign) and isinstance(n.target, ast.Name)]
    keyed = {n.target.id: ast.unparse(n.value) for n in fields if n.target.id in keys and n.value is not None}
    assert keyed, f"{cls.__name__} has no field that is a key"
    copied = {name: source for name, source in keyed.items() if "DEFAULTS." not in source}
    assert copied == {}
