"""The module experiments of ``companion-bench modules`` (landfall_eval/modules.py): a two-iteration run on
scenario1 (schema, ranges, the onboard tier's choices, Jaccard against ``best_jaccard``, a short landing
distance, determinism), the in-process flight on flat ground, and the ground-truth helpers."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from landfall_eval.modules import (
    fly_and_land,
    in_safe_zone,
    roofs_of,
    run_modules,
    truth_point,
)
from landfall_eval.surfaces import best_jaccard, launch_frame
from simbridge.terrain import FlatTerrain
from simbridge.world.world import SafeZone

SEEDS = 2
CONTEXTS = ("crop", "full")


def _run(progress: list[str] | None = None) -> dict[str, Any]:
    return run_modules(
        "onboard",
        SEEDS,
        scenarios=("scenario1",),
        contexts=CONTEXTS,
        progress=None if progress is None else progress.append,
    )


@pytest.fixture(scope="module")
def run() -> tuple[dict[str, Any], list[str]]:
    lines: list[str] = []
    return _run(lines), lines


def _without_latency(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _without_latency(v) for k, v in value.items() if "latency" not in k}
    return value


def test_run_modules_schema_and_ranges(run: tuple[dict[str, Any], list[str]]) -> None:
    out, lines = run
    assert set(out) == {"surface_id", "landing_distance_m", "landing_distance", "reasoner", "reasoner_name"}
    assert out["reasoner_name"] == "onboard"
    sid = out["surface_id"]["scenario1"]
    assert sid["iterations"] == SEEDS
    assert sid["study"] == 0.871
    assert 0.0 <= sid["jaccard_min"] <= sid["jaccard_mean"] <= sid["jaccard_max"] <= 1.0
    landing = out["landing_distance"]["scenario1"]
    assert landing["iterations"] == SEEDS
    assert landing["study"] == 0.80
    assert landing["failures"] == []
    assert 0.0 <= landing["median_m"] <= landing["max_m"]
    assert out["landing_distance_m"]["scenario1"] == landing["mean_m"]
    assert set(out["reasoner"]["scenario1"]) == set(CONTEXTS)
    for entry in out["reasoner"]["scenario1"].values():
        assert entry["iterations"] == SEEDS
        for key in ("rank_success", "confirm_accept_clear", "confirm_reject_cluttered"):
            assert 0.0 <= entry[key] <= 1.0
        assert entry["rank_latency_s_median"] >= 0.0
        assert entry["confirm_latency_s_median"] >= 0.0
        assert isinstance(entry["failures"], list)
    assert len(lines) == SEEDS
    assert lines[-1].startswith(f"scenario1 {SEEDS}/{SEEDS}: jaccard ")


def test_run_modules_onboard_ranks_clear_roof_and_confirms_right(
    run: tuple[dict[str, Any], list[str]],
) -> None:
    entries = run[0]["reasoner"]["scenario1"]
    for context in CONTEXTS:
        assert entries[context]["rank_success"] == 1.0, entries[context]["failures"]
        assert entries[context]["confirm_accept_clear"] == 1.0, entries[context]["failures"]
        assert entries[context]["confirm_reject_cluttered"] == 1.0, entries[context]["failures"]
        assert entries[context]["failures"] == []


def test_run_modules_jaccard_equals_best_jaccard(run: tuple[dict[str, Any], list[str]]) -> None:
    scores = [best_jaccard(launch_frame("scenario1", seed))[0] for seed in range(SEEDS)]
    sid = run[0]["surface_id"]["scenario1"]
    assert sid["jaccard_mean"] == pytest.approx(sum(scores) / SEEDS, abs=1e-4)
    assert sid["jaccard_min"] == pytest.approx(min(scores), abs=1e-4)
    assert sid["jaccard_max"] == pytest.approx(max(scores), abs=1e-4)


def test_run_modules_landing_distance_small_on_scenario1(run: tuple[dict[str, Any], list[str]]) -> None:
    landing = run[0]["landing_distance"]["scenario1"]
    assert math.isfinite(landing["mean_m"])
    assert landing["max_m"] < 5.0
    assert landing["ipm_error_mean_m"] < 5.0


def test_run_modules_same_seeds_same_figures(run: tuple[dict[str, Any], list[str]]) -> None:
    assert _without_latency(_run()) == _without_latency(run[0])


def test_run_modules_bad_arguments_raise() -> None:
    with pytest.raises(ValueError, match="context"):
        run_modules(iterations=1, contexts=("pad25",))
    with pytest.raises(ValueError, match="iterations"):
        run_modules(iterations=0)
    with pytest.raises(ValueError, match="cluttered_roof"):
        run_modules(iterations=1, scenarios=(str(Path(__file__).with_name("onboard_scene.toml")),))


def test_fly_and_land_flat_ground_touches_down_at_target() -> None:
    touchdown, t_s = fly_and_land(FlatTerrain(), (0.0, 0.0, -30.0), 0.3, (0.0, 0.0, 0.0), (12.0, -7.0))
    assert math.hypot(touchdown[0] - 12.0, touchdown[1] + 7.0) < 0.5
    assert touchdown[2] == pytest.approx(-0.15, abs=0.1)  # resting on the gear
    assert 20.0 < t_s < 120.0


def test_truth_point_image_centre_is_below_the_camera() -> None:
    lf = launch_frame("scenario1", 0, hover=False)  # level, 110 m over Quay Street at the origin
    point = truth_point(lf, lf.camera.cx, lf.camera.cy)
    assert point is not None
    np.testing.assert_allclose(point, [0.0, 0.0, 0.0], atol=0.15)
    clear = roofs_of("scenario1").clear_ne  # the clear roof, 27 m west: seen left of the centre
    u = lf.camera.cx + clear[1] * lf.camera.fx / (-lf.pos_ned_m[2] - 22.0)
    roof = truth_point(lf, u, lf.camera.cy)
    assert roof is not None
    np.testing.assert_allclose(roof, [0.0, -27.0, -22.0], atol=0.15)
    assert truth_point(lf, -1.0, 10.0) is None


def test_in_safe_zone_rotated_rectangle() -> None:
    zone = SafeZone((10.0, 0.0), 20.0, 4.0, math.radians(90.0))  # long side along east
    assert in_safe_zone([zone], 10.0, 9.0)
    assert not in_safe_zone([zone], 19.0, 0.0)
    assert not in_safe_zone([], 10.0, 0.0)
