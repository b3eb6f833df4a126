"""companion-bench flying real ArduCopter SITL (``--autopilot ardupilot-sitl``): a curated episode
graded as the emulation's are, and the firmware's own GPS glitch and drift followed onto the chosen
site. They run where ../shared/sitl/ardupilot holds the firmware (the ``arducopter`` fixture)."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import pytest

from tests.test_bench import EPISODE_KEYS, _episode_events, _log_tail, bench


@pytest.mark.slow
@pytest.mark.sitl
def test_curated_episode_flies_real_arducopter(arducopter: Path, tmp_path: Path) -> None:
    """``--autopilot ardupilot-sitl``: the harness waits out the firmware's initialisation and take-off
    (``ready``), raises the alarm, and grades the landing as with the emulation; the takeover is the
    alarm (the vehicle already holds in GUIDED), so the times are those of the companion's flight.
    scenario1's gravel roof: the companion follows the site down in the camera and the firmware's
    precision landing (PLND_TYPE 1) lands on its LANDING_TARGET (0.05-0.20 m from what the chosen
    pixel shows, three flights; 1.09 m median before, on the absolute target). At 4x, as the bench
    flies it: at 8x a look takes more than the 1.5 simulated seconds a find is sent for."""
    out = tmp_path / "sitl"
    res = bench(
        "curated", "--scenario", "scenario1", "--runs", "1", "--workers", "1", "--autopilot",
        "ardupilot-sitl", "--sitl", str(arducopter), "--speed", "4", "--quiet", "--out", str(out),
    )  # fmt: skip
    results = json.loads((out / "results.json").read_text())
    (e,) = results["episodes"]
    why = f"{e['error']}\n{_log_tail(out / 'episodes' / e['id'] / 'companion.log')}"
    assert res.returncode == 0, res.stderr[-3000:] + why
    assert e["id"] == "scenario1-r0-onboard-crop-clear-ardupilot-sitl"
    assert e["autopilot"] == "ardupilot-sitl"
    assert results["config"]["sitl"] == str(arducopter)
    assert e["outcome"] == "landed", why
    assert e["surface"] == "rooftop_clear", why
    assert e["safe"], e["reasons"]
    assert set(e) >= EPISODE_KEYS, EPISODE_KEYS - set(e)
    log = [json.loads(x) for x in (out / "episodes" / e["id"] / "episode.jsonl").read_text().splitlines()]
    ready = next(r for r in log if r["event"] == "ready")
    touchdown = next(r for r in log if r["event"] == "touchdown")
    assert ready["t_s"] > 30  # the firmware initialised and took off first
    # from the alarm (after ready) to the touchdown, not from simbridge's take-off
    assert 0 < e["time_to_touchdown_s"] < touchdown["t_s"] - ready["t_s"]
    assert e["kinematic_ratio"] >= 1.0
    assert math.dist(e["launch_ned_m"], ready["pos_ned_m"]) < 1.0  # control taken at the launch pose
    assert e["touchdown_to_site_m"] < 3.0
    # from the truth: the touchdown against what the chosen pixel showed from the frame's true pose
    assert e["landing_error"] is None
    assert e["landing_distance_m"] < 0.5, (e["landing_target_ned_m"], why)
    pl = e["precision_landing"]
    assert pl["used"], pl
    assert pl["why"] == "PLND_ENABLED 1, PLND_TYPE 1"  # read from the firmware
    assert pl["tracks_found"] >= 1, (pl, why)
    assert pl["targets_sent"] >= 1, (pl, why)
    # the targets go out ten times a second of the firmware's clock, whatever the simulation's speed:
    # its precision landing starts only after 2 s of targets none more than 0.5 s apart, and says
    # "PrecLand: Init Failed" (critical) each time they come slower (every target did, at 4x, when
    # they were paced in wall time)
    assert pl["looks_found"] >= 1, (pl, why)
    assert pl["targets_sent"] >= 20, (pl, why)
    texts = [x.get("text", "") for x in _episode_events(out, e)]
    assert not [t for t in texts if "PrecLand: Init Failed" in t], texts


def _fly_a_lying_gps(
    arducopter: Path, tmp_path: Path, scenario: str, *flags: str
) -> tuple[dict[str, Any], list[dict[str, Any]], str]:
    """One curated episode of ``scenario`` on real ArduCopter with ``flags`` (its GPS fault, its speed),
    landed on the clear roof: its results entry, its flight record's events and what to show on a
    failure."""
    out = tmp_path / "sitl"
    res = bench(
        "curated", "--scenario", scenario, "--runs", "1", "--workers", "1", "--autopilot",
        "ardupilot-sitl", "--sitl", str(arducopter), *flags, "--quiet", "--out", str(out),
    )  # fmt: skip
    (e,) = json.loads((out / "results.json").read_text())["episodes"]
    why = f"{e['error']}\n{_log_tail(out / 'episodes' / e['id'] / 'companion.log')}"
    assert res.returncode == 0, res.stderr[-3000:] + why
    assert e["outcome"] == "landed", why
    assert e["surface"] == "rooftop_clear", why
    return e, _episode_events(out, e), why


@pytest.mark.slow
@pytest.mark.sitl
def test_real_arducopters_gps_glitch_mid_descent_is_followed_onto_the_chosen_site(
    arducopter: Path, tmp_path: Path
) -> None:
    """``--gps-fault 15,10`` on real ArduCopter: 40 m above the ground simbridge sets the firmware's
    own SITL glitch (SIM_GPS1_GLTCH_X/Y); the EKF rejects it for some seconds, then resets onto it,
    and the vehicle, holding its target in that estimate, would fly 18 m off (18.3 m measured). The
    companion moves its target with the reset and lands on the chosen site (0.12-0.52 m measured)."""
    e, events, why = _fly_a_lying_gps(
        arducopter, tmp_path, "scenario1", "--gps-fault", "15,10", "--speed", "8"
    )
    (reset,) = [x for x in events if x["kind"] == "estimate_reset"]
    assert reset["shift_m"] == pytest.approx([15.0, 10.0], abs=1.0)
    texts = " ".join(x["text"] for x in events if x["kind"] == "autopilot_text")
    assert "GPS Glitch" in texts, texts  # the firmware's own account of it
    assert e["landing_distance_m"] < 1.0, (e["landing_target_ned_m"], why)


@pytest.mark.slow
@pytest.mark.sitl
def test_real_arducopters_gps_drifting_over_the_membrane_roof_is_waited_out_on_the_chosen_site(
    arducopter: Path, tmp_path: Path
) -> None:
    """``--gps-fault 15,10 --gps-fault-ramp 30`` on real ArduCopter over scenario2's plain membrane
    roof: from 40 m above the ground the firmware's own SITL glitch grows 18 m over 30 s; its EKF
    follows it with no step to see, and the vehicle, holding its target in that estimate, would drift
    off the site (9.4 and 1.2 m on 2026-11-28). The companion holds over the site while it drifts,
    its looks centred where the drift carries the site, until it stops; then looks for it against
    the frame it was chosen in and lands on it. The landing is as good as that one match against a
    frame from 85 m up (0.18 m cells on a roof with little texture): 0.07-0.41 m in nine flights on
    2026-12-06, median 0.31 m (the goal, 0.5 m, is a median: docs/sitl.md); one CI flight the same
    day landed 0.51 m off, on the site that gives the larger errors (0.32-0.41 m here). A flight
    that re-anchored nothing, the chain of references the drift built, left 0.45-0.75 m."""
    e, events, why = _fly_a_lying_gps(
        arducopter, tmp_path, "scenario2", "--gps-fault", "15,10", "--gps-fault-ramp", "30", "--speed", "4"
    )
    holds = [x for x in events if x["kind"] == "drift_hold"]
    assert holds, why
    assert holds[0]["drift_m_s"] >= 0.15, holds
    reanchors = [x for x in events if x["kind"] == "site_track" and x["phase"] == "reanchor"]
    assert reanchors, why
    assert reanchors[-1]["found"], (reanchors, why)
    assert e["landing_distance_m"] < 0.6, (e["landing_target_ned_m"], why)
