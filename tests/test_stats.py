"""Campaign statistics (landfall_eval/stats.py, compare.py, grading.summarise): the safe rate's 95 %
interval (Wilson; Clopper-Pearson when every launch or none was safe), Fisher's exact test between two
campaigns, the intervals in results.json's summary by kind of place, weather, autopilot and
criticality, and ``companion-bench compare``."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from landfall_eval.cli import main as bench_main
from landfall_eval.grading import summarise
from landfall_eval.stats import differ_p, safe_interval


def test_the_interval_is_wilsons_and_exact_at_the_ends() -> None:
    lo, hi = safe_interval(95, 100) or (0.0, 0.0)
    assert (round(lo, 4), round(hi, 4)) == (0.8882, 0.9785)  # Wilson's score interval, z = 1.96
    assert safe_interval(20, 20) == pytest.approx((0.025 ** (1 / 20), 1.0))  # "at least 83 %"
    lo300, _ = safe_interval(300, 300) or (0.0, 0.0)
    assert 0.987 < lo300 < 0.989
    assert safe_interval(0, 10) == pytest.approx((0.0, 1 - 0.025 ** (1 / 10)))
    assert safe_interval(0, 0) is None
    for bad in ((3, 2), (-1, 5), (1, -1)):
        with pytest.raises(ValueError, match="0 <= safe <= n"):
            safe_interval(*bad)
    with pytest.raises(ValueError, match="confidence"):
        safe_interval(1, 2, confidence=1.0)


def test_fisher_tells_a_real_difference_from_chance() -> None:
    assert differ_p(4, 4, 3, 4) == pytest.approx(1.0)
    assert differ_p(99, 100, 70, 100) < 1e-6
    assert differ_p(50, 100, 50, 100) == pytest.approx(1.0)
    with pytest.raises(ValueError, match="n > 0"):
        differ_p(0, 0, 1, 1)


def _episode(k: int, safe: bool, **extra: Any) -> dict[str, Any]:
    return {"id": f"e{k}", "safe": safe, "outcome": "landed", "surface": "rooftop_clear" if safe else "road",
            "rounds": 1, "reasoner": "onboard", "context": "crop", "weather": "clear", "city_seed": 0,
            "autopilot": "px4", "criticality": "high", "place": "downtown", **extra}  # fmt: skip


def test_the_summary_gives_each_rate_its_interval_by_place_weather_autopilot_and_criticality() -> None:
    episodes = [_episode(k, True) for k in range(18)] + [
        _episode(18, False),
        _episode(19, True, weather="fog"),
    ]
    episodes += [_episode(20 + k, True, place="suburb", weather="fog") for k in range(5)]
    s = summarise(episodes)
    assert s["safe_rate_interval_95"] == [round(v, 4) for v in safe_interval(24, 25) or ()]
    assert set(s["by"]) == {"place", "weather", "autopilot", "criticality"}
    assert s["by"]["place"]["suburb"] == {
        "episodes": 5, "safe": 5, "safe_rate": 1.0,
        "safe_rate_interval_95": [round(v, 4) for v in safe_interval(5, 5) or ()],
    }  # fmt: skip
    assert s["by"]["weather"]["clear"]["episodes"] == 19
    assert all("safe_rate_interval_95" in g for g in s["groups"])


def test_compare_prints_both_campaigns_and_the_verdict(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    a, b = tmp_path / "a", tmp_path / "b"
    a.mkdir()
    (a / "results.json").write_text(json.dumps({"episodes": [_episode(k, True) for k in range(100)]}))
    b_eps = [_episode(k, k >= 30) for k in range(100)]
    b_eps.append({**_episode(100, False), "error_kind": "infrastructure"})  # never reached its alarm
    b.mkdir()
    (b / "results.json").write_text(json.dumps({"episodes": b_eps}))
    assert bench_main(["compare", str(a), str(b / "results.json")]) == 0
    out = capsys.readouterr().out
    assert "100/100 safe (100.0 %, 95 % interval 96.4-100.0 %)" in out
    assert "70/100 safe" in out  # the infrastructure failure is not counted
    assert "they differ beyond chance" in out
    assert bench_main(["compare", str(a), str(tmp_path / "nothing.json")]) == 2
    assert "not a companion-bench results.json" in capsys.readouterr().err
