"""benchmarks/time_beyond_bound.py: a campaign's time beyond the kinematic bound split into the
companion's looks, the final approach and the rest, from a run folder written as companion-bench writes
one."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "benchmarks" / "time_beyond_bound.py"


def _episode(run: Path, eid: str, *, safe: bool = True, record: bool = True) -> dict[str, Any]:
    folder = run / "episodes" / eid
    folder.mkdir(parents=True)
    if record:
        (folder / "record" / "20261205T100000Z-1").mkdir(parents=True)
        steps = [(0.0, "acquire"), (0.25, "surface_id"), (0.5, "rank"), (0.75, "move"), (2.0, "acquire"),
                 (2.5, "confirm"), (3.0, "descend"), (10.0, "land")]  # fmt: skip
        rows = [{"time_mono_s": 100 + t, "kind": "state", "state": s} for t, s in steps]
        rows.append({"time_mono_s": 112.0, "kind": "outcome", "state": "landed"})
        (folder / "record" / "20261205T100000Z-1" / "events.jsonl").write_text(
            "".join(json.dumps(r) + "\n" for r in rows)
        )
    log = [
        {"t_s": 40.0, "event": "state", "agl_m": 3.4},
        {"t_s": 41.0, "event": "state", "agl_m": 3.0},  # hovering where the land mode is asked for
        {"t_s": 41.05, "event": "mode", "mode": "AUTO.PRECLAND"},
        {"t_s": 48.0, "event": "state", "agl_m": 0.1},
    ]
    (folder / "episode.jsonl").write_text("".join(json.dumps(r) + "\n" for r in log))
    return {"id": eid, "safe": safe, "rounds": 2, "time_to_touchdown_s": 100.0,
            "kinematic_lower_bound_s": 80.0, "kinematic_ratio": 1.25}  # fmt: skip


def _run(tmp_path: Path, *extra: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, str(SCRIPT), str(tmp_path), *extra],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=60,
    )


def test_the_excess_is_split_into_looks_final_approach_and_the_rest(tmp_path: Path) -> None:
    episodes = [
        _episode(tmp_path, "a"),
        _episode(tmp_path, "b", safe=False),
        _episode(tmp_path, "c", record=False),
    ]
    (tmp_path / "results.json").write_text(json.dumps({"config": {"speed": 4.0}, "episodes": episodes}))
    out = _run(tmp_path, "--json")
    assert out.returncode == 0, out.stderr
    got = json.loads(out.stdout)
    assert [r["id"] for r in got["episodes"]] == [
        "a"
    ]  # the unsafe landing and the one without a record left out
    row = got["episodes"][0]
    # looks: acquire, Surface ID and rank 0.75 wall s, acquire and confirm 1.0 more, at 4x
    assert row["looks_s"] == 7.0
    # the land state's 2 wall s at 4x, less 3 m at 1.5 m/s and 3 m/s^2 (1 s of ramps and 1.5 s cruising)
    assert row["land_height_m"] == 3.0
    assert row["final_approach_s"] == 5.5
    assert row["rest_s"] == 20.0 - 7.0 - 5.5
    assert got["median"]["excess_s"] == 20.0
    table = _run(tmp_path)
    assert table.returncode == 0, table.stderr
    assert "1 safe landings with records" in table.stdout


def test_a_run_without_a_usable_landing_says_so(tmp_path: Path) -> None:
    episodes = [_episode(tmp_path, "a", record=False)]
    (tmp_path / "results.json").write_text(json.dumps({"config": {"speed": 1.0}, "episodes": episodes}))
    out = _run(tmp_path)
    assert out.returncode == 1
    assert "no safe landing with a flight record and an episode log" in out.stderr
