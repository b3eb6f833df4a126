"""companion-bench: grading, the kinematic bound, Halton launches, and small real runs (2 episodes of
simbridge + companion processes) that check the results schema, the report and resumption."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from landfall_eval.cli import build_parser, episode_specs
from landfall_eval.episode import EpisodeSpec, EpisodeTimes, run_episode, simbridge_command
from landfall_eval.episode_grade import LogWatch, alarm_sim_time_s, grade, record_events, touchdown_to_site_m
from landfall_eval.grading import (
    SURFACES,
    kinematic_lower_bound_s,
    summarise,
    surface_class,
    trapezoid_time_s,
)
from landfall_eval.landing import chosen_pixel, landing_distance_m
from landfall_eval.launches import halton_launches
from landfall_eval.processes import ProcessSample
from simbridge.scenarios import load_scenario

EPISODE_KEYS = {
    "id", "kind", "scenario", "seed", "launch_index", "run", "reasoner", "context", "weather", "autopilot",
    "launch_ned_m", "touchdown_ned_m", "surface", "safe", "reasons", "outcome", "error", "rounds",
    "time_to_touchdown_s", "kinematic_lower_bound_s", "kinematic_ratio", "calls", "rationales",
    "trajectory_ne_m", "companion", "wall_s", "city_seed", "world_digest", "last_state",
    "touchdown_to_site_m", "landing_distance_m", "landing_target_ned_m", "landing_error", "precision_landing",
    "simbridge", "wall_phases_s",
}  # fmt: skip
LAST_STATE_KEYS = {
    "recovery_state", "round", "outcome_state", "outcome_reason", "vehicle_t_s", "vehicle_mode",
    "vehicle_armed", "vehicle_pos_ned_m", "vehicle_agl_m",
}  # fmt: skip


# ------------------------------------------------------------------------------------------ grading
def test_surface_class_refines_a_cluttered_roof_and_passes_the_rest_through() -> None:
    assert surface_class(None) == "no_landing"
    assert surface_class({"surface": "rooftop_clear", "safe": True, "reasons": []}) == "rooftop_clear"
    near_hvac = {"surface": "rooftop_clear", "safe": False, "reasons": ["rooftop object within 1.2 m"]}
    assert surface_class(near_hvac) == "rooftop_obstructed"
    # an edge is not an obstruction: the class stays, the verdict says unsafe
    edge = {"surface": "rooftop_clear", "safe": False, "reasons": ["0.6 m from an edge (20 m drop)"]}
    assert surface_class(edge) == "rooftop_clear"
    assert surface_class({"surface": "highway", "safe": False, "reasons": ["landed on highway"]}) == "highway"
    with pytest.raises(ValueError, match="unknown touchdown surface 'lava'"):
        surface_class({"surface": "lava"})


def test_trapezoid_time_is_the_bang_bang_optimum() -> None:
    assert trapezoid_time_s(0.0, 5.0, 3.0) == 0.0
    # too short to reach the speed limit: accelerate half way, brake the other half
    assert trapezoid_time_s(3.0, 5.0, 3.0) == pytest.approx(2.0)
    # long: 5/3 s up, 5/3 s down, the rest at 5 m/s (25/3 m used by the ramps)
    assert trapezoid_time_s(100.0, 5.0, 3.0) == pytest.approx(10 / 3 + (100 - 25 / 3) / 5)
    with pytest.raises(ValueError, match="dist >= 0"):
        trapezoid_time_s(-1.0, 5.0, 3.0)


def test_kinematic_bound_adds_the_straight_flight_and_the_descent() -> None:
    start, end = (0.0, 0.0, -110.0), (30.0, 40.0, -22.0)
    expect = trapezoid_time_s(50.0, 5.0, 3.0) + trapezoid_time_s(88.0, 1.5, 3.0)
    assert kinematic_lower_bound_s(start, end) == pytest.approx(expect)
    assert kinematic_lower_bound_s(end, end) == 0.0


def test_grade_reads_the_episode_log_and_the_flight_record(tmp_path: Path) -> None:
    session = tmp_path / "record" / "s1"
    session.mkdir(parents=True)
    events = [
        {"kind": "state", "state": "rank", "round": 1},
        {"kind": "rank", "round": 1, "tier": "onboard", "latency_s": 0.01, "rationale": "site 0: clear"},
        {"kind": "confirm", "round": 1, "tier": "gpt-5", "latency_s": 4.2, "rationale": "no: <birds>"},
        {"kind": "state", "state": "rank", "round": 2},
        {"kind": "confirm", "round": 2, "tier": "onboard", "latency_s": 0.02, "rationale": "site clear"},
        {"kind": "outcome", "state": "landed", "rounds": 2, "reason": "landed"},
    ]
    (session / "events.jsonl").write_text("".join(json.dumps(e) + "\n" for e in events))
    states = [
        {"t_s": t, "event": "state", "pos_ned_m": [0.5 * t, 0.0, -110.0 + t]}
        for t in (0.0, 0.5, 1.0, 2.0, 10.0)
    ]
    takeover = {"t_s": 1.0, "event": "mode", "mode": "OFFBOARD"}
    touchdown = {
        "t_s": 40.0,
        "pos_ned_m": [20.0, 0.0, -22.0],
        "surface": "rooftop_clear",
        "safe": True,
        "reasons": [],
    }
    got = grade(states, takeover, touchdown, record_events(tmp_path / "record"))
    assert got["launch_ned_m"] == [0.5, 0.0, -109.0]  # where the companion took control
    assert got["rounds"] == 2
    assert [c["tier"] for c in got["calls"]] == ["onboard", "gpt-5", "onboard"]
    assert got["rationales"][1] == {"stage": "confirm", "round": 1, "tier": "gpt-5", "text": "no: <birds>"}
    assert got["time_to_touchdown_s"] == 39.0
    bound = kinematic_lower_bound_s((0.5, 0.0, -109.0), (20.0, 0.0, -22.0))
    assert got["kinematic_ratio"] == pytest.approx(39.0 / bound, abs=1e-3)
    assert got["trajectory_ne_m"][0] == [0.5, 0.0]
    assert got["trajectory_ne_m"][-1] == [20.0, 0.0]
    none = grade(states, takeover, None, [])
    assert none["surface"] == "no_landing"
    assert not none["safe"]
    assert none["time_to_touchdown_s"] is None


def test_log_watch_takes_the_takeover_only_after_ready() -> None:
    """Real ArduCopter flies GUIDED to the launch pose before ``ready``: that switch is simbridge's
    take-off, not the companion taking control."""
    log = LogWatch()
    log.take([
        {"t_s": 0.0, "event": "start", "home_ned_m": [12.0, 8.0, 0.0]},
        {"t_s": 30.0, "event": "mode", "mode": "GUIDED"},
        {"t_s": 75.0, "event": "ready", "time_boot_ms": 74996},
        {"t_s": 75.1, "event": "state", "pos_ned_m": [12.0, 8.0, -110.0]},
    ])  # fmt: skip
    assert log.ready is not None
    assert log.takeover is None
    assert [s["t_s"] for s in log.states] == [75.1]
    log.take(
        [{"t_s": 80.0, "event": "mode", "mode": "GUIDED"}, {"t_s": 81.0, "event": "mode", "mode": "LAND"}]
    )
    assert log.takeover is not None
    assert log.takeover["t_s"] == 80.0
    log.take(
        [{"t_s": 99.0, "event": "touchdown", "pos_ned_m": [0, 0, 0]}, {"t_s": 99.1, "event": "state"}],
        final=True,
    )
    assert log.touchdown is None  # read after the processes were stopped: too late to grade
    assert log.last_vehicle == {"t_s": 99.1, "event": "state"}
    assert len(log.states) == 1


def test_alarm_time_is_placed_on_the_log_through_the_autopilot_clock() -> None:
    ready = {"t_s": 75.0, "event": "ready", "time_boot_ms": 74996}
    events = [{"kind": "state", "state": "idle"}, {"kind": "alarm", "vehicle_time_boot_ms": 80496}]
    assert alarm_sim_time_s(ready, events) == pytest.approx(80.5)
    assert alarm_sim_time_s(None, events) is None
    assert alarm_sim_time_s(ready, [{"kind": "alarm", "vehicle_time_boot_ms": None}]) is None
    assert alarm_sim_time_s({"t_s": 0.0}, events) is None  # a simbridge that does not say its clock


def test_touchdown_to_site_uses_the_last_confirmed_site_in_the_autopilot_frame() -> None:
    header = {"event": "start", "home_ned_m": [12.0, 8.0, 0.0]}  # the EKF origin in the scenario
    events = [
        {"kind": "confirm", "accept": True, "site_ned_m": [-40.0, 3.0, -20.0]},
        {"kind": "confirm", "accept": True, "site_ned_m": [3.0, 4.0, -20.0]},
        {"kind": "confirm", "accept": False, "site_ned_m": [90.0, 90.0, -20.0]},
    ]
    touchdown = {"pos_ned_m": [15.3, 12.4, -20.0]}
    assert touchdown_to_site_m(touchdown, header, events) == pytest.approx(0.5)
    assert touchdown_to_site_m(None, header, events) is None
    assert touchdown_to_site_m(touchdown, header, events[2:]) is None  # nothing confirmed
    assert touchdown_to_site_m(touchdown, None, events) is None


def _rank(rnd: int, chosen: int | None, stamp: int | None, *centres: tuple[float, float]) -> dict[str, Any]:
    cands = [{"index": k, "centre_px": list(c)} for k, c in enumerate(centres)]
    return {"kind": "rank", "round": rnd, "chosen": chosen, "candidates": cands, "frame_time_boot_ms": stamp}


def test_landing_distance_casts_the_chosen_pixel_from_the_true_pose() -> None:
    """A nadir frame 60 m over scenario2's clear roof (top 30 m up, centred N 0, E -39), level and
    facing north: with fx = fy = 480 px (960 px, 90 deg), pixel (cx - 80, cy + 48) looks 1/6 of the way
    west and 1/10 south, so it truly shows the roof at N -6, E -49. A touchdown at N -3, E -45 is 5 m
    from it. The companion's own estimate (the confirmed site) plays no part."""
    cx, cy = 480.0, 270.0
    events = [
        _rank(1, 0, 4_000, (10.0, 10.0)),  # an earlier round's site, rejected
        {"kind": "confirm", "round": 1, "accept": False, "site_ned_m": [50.0, 50.0, -20.0]},
        _rank(2, 1, 12_345, (900.0, 500.0), (cx - 80, cy + 48)),
        {"kind": "confirm", "round": 2, "accept": True, "site_ned_m": [99.0, 99.0, -30.0]},
        {"kind": "confirm", "round": 2, "accept": True, "site_ned_m": [99.0, 99.0, -30.0]},  # a descent step
    ]
    pick = chosen_pixel(events)
    assert pick is not None
    assert (pick.u, pick.v, pick.time_boot_ms, pick.round) == (cx - 80, cy + 48, 12_345, 2)
    log = LogWatch()
    log.take([
        {"t_s": 0.0, "event": "start", "scenario": "scenario2", "seed": 3, "city_seed": None,
         "world_digest": None},
        {"t_s": 4.0, "event": "frame", "time_boot_ms": 4_000, "pos_ned_m": [0.0, 0.0, -115.0],
         "quat_wxyz": [1.0, 0.0, 0.0, 0.0]},
        {"t_s": 12.345, "event": "frame", "time_boot_ms": 12_345, "pos_ned_m": [0.0, -39.0, -90.0],
         "quat_wxyz": [1.0, 0.0, 0.0, 0.0]},
    ])  # fmt: skip
    assert sorted(log.frames) == [4_000, 12_345]
    touchdown = {"pos_ned_m": [-3.0, -45.0, -30.0]}
    got = landing_distance_m(touchdown, log.header, log.frames, events)
    assert got is not None
    distance, target = got
    assert target == pytest.approx([-6.0, -49.0, -30.0], abs=0.05)
    assert distance == pytest.approx(5.0, abs=0.05)
    # nothing to measure: no touchdown, no confirmed site, no frame time (an older record), no frame
    assert landing_distance_m(None, log.header, log.frames, events) is None
    assert landing_distance_m(touchdown, log.header, log.frames, events[:2]) is None
    older = [{k: v for k, v in e.items() if k != "frame_time_boot_ms"} for e in events]
    assert landing_distance_m(touchdown, log.header, log.frames, older) is None
    assert landing_distance_m(touchdown, log.header, {4_000: log.frames[4_000]}, events) is None
    # a world that is not the one flown is an error, not a figure
    assert log.header is not None
    with pytest.raises(ValueError, match="not the flown world"):
        landing_distance_m(touchdown, {**log.header, "world_digest": "0" * 16}, log.frames, events)


def test_chosen_pixel_is_the_confirmed_candidates_in_the_frame_it_was_found_in() -> None:
    """A site looked at again rounds after it was seen (the budget's closer look) keeps the frame of
    the round that listed it; the candidate the confirm names decides, not the round's own choice."""
    a, b, c = (100.0, 100.0), (300.0, 200.0), (500.0, 250.0)
    events = [
        _rank(2, 0, 20_000, a, b),
        {"kind": "confirm", "round": 2, "accept": False, "candidate": _rank(0, 0, 0, a)["candidates"][0]},
        _rank(4, 0, 40_000, c),  # a later round, its own choice rejected
        {"kind": "confirm", "round": 4, "accept": False, "candidate": _rank(0, 0, 0, c)["candidates"][0]},
        {"kind": "confirm", "round": 5, "accept": True, "candidate": _rank(2, 0, 0, a, b)["candidates"][1]},
    ]
    pick = chosen_pixel(events)
    assert pick is not None
    assert (pick.u, pick.v, pick.time_boot_ms, pick.round) == (*b, 20_000, 2)
    # a candidate no rank listed: no frame to cast it from
    stray = {**events[-1], "candidate": {"index": 9, "centre_px": [1.0, 1.0]}}
    assert chosen_pixel([*events[:-1], stray]) is None
    # a rank after the confirm's round does not count
    assert chosen_pixel([*events[:-1], {**events[-1], "round": 1}]) is None


def test_curated_with_ekf_error_flies_the_emulation_on_its_estimate(tmp_path: Path) -> None:
    """``--ekf-error nominal`` reaches simbridge, names its episodes apart (resumption matches by id),
    and is refused with real firmware, which has its own estimator."""
    parse = build_parser().parse_args
    base = ["curated", "--scenario", "scenario2", "--runs", "2", "--out", str(tmp_path)]
    specs = episode_specs(parse([*base, "--autopilot", "ardupilot", "--ekf-error", "nominal"]))
    assert [s.id for s in specs] == [
        "scenario2-r0-onboard-crop-clear-ardupilot-ekf-nominal",
        "scenario2-r1-onboard-crop-clear-ardupilot-ekf-nominal",
    ]
    cmd = simbridge_command(specs[1], udp_port=1, sensors_port=2, episode_log=tmp_path / "e.jsonl", speed=4.0)
    assert cmd[cmd.index("--ekf-error") + 1] == "nominal"
    off = episode_specs(parse([*base, "--autopilot", "ardupilot"]))
    assert off[0].id == "scenario2-r0-onboard-crop-clear-ardupilot"  # the ids runs already hold
    cmd = simbridge_command(off[0], udp_port=1, sensors_port=2, episode_log=tmp_path / "e.jsonl", speed=4.0)
    assert "--ekf-error" not in cmd
    with pytest.raises(ValueError, match="real firmware has its own estimator"):
        episode_specs(parse([*base, "--autopilot", "ardupilot-sitl", "--ekf-error", "nominal"]))


def test_curated_with_a_gps_fault_passes_it_to_simbridge_and_names_its_episodes_apart(tmp_path: Path) -> None:
    """``--gps-fault N,E`` (and a drift's ``--gps-fault-ramp``) reach simbridge with any autopilot,
    real firmware included, and name the episodes apart; simbridge's own flags are checked too."""
    from simbridge.cli import build_parser as sim_parser
    from simbridge.cli import config_from_args

    parse = build_parser().parse_args
    base = ["curated", "--scenario", "scenario1", "--runs", "1", "--out", str(tmp_path)]
    (spec,) = episode_specs(parse([*base, "--autopilot", "ardupilot-sitl", "--gps-fault=-15,10"]))
    assert spec.id == "scenario1-r0-onboard-crop-clear-ardupilot-sitl-gps-15,10"
    assert spec.gps_fault_entry == {"offset_ne_m": [-15.0, 10.0], "ramp_s": 0.0}
    cmd = simbridge_command(spec, udp_port=1, sensors_port=2, episode_log=tmp_path / "e.jsonl", speed=4.0)
    assert "--gps-fault=-15,10" in cmd
    assert cmd[cmd.index("--gps-fault-ramp") + 1] == "0"
    (drift,) = episode_specs(parse([*base, "--gps-fault", "20,0", "--gps-fault-ramp", "30"]))
    assert drift.id.endswith("-px4-gps20,0r30")
    plain = episode_specs(parse(base))[0]
    assert plain.gps_fault_entry is None
    assert "-gps" not in plain.id
    cmd = simbridge_command(plain, udp_port=1, sensors_port=2, episode_log=tmp_path / "e.jsonl", speed=4.0)
    assert not any(c.startswith("--gps-fault") for c in cmd)
    with pytest.raises(ValueError, match="--gps-fault-ramp goes with --gps-fault"):
        episode_specs(parse([*base, "--gps-fault-ramp", "30"]))
    config = config_from_args(sim_parser().parse_args(["--gps-fault", "15,10", "--gps-fault-ramp", "20"]))
    assert config.gps_fault is not None
    assert (config.gps_fault.offset_ne_m, config.gps_fault.below_m, config.gps_fault.ramp_s) == (
        (15.0, 10.0),
        40.0,
        20.0,
    )
    with pytest.raises(ValueError, match="only with --gps-fault"):
        config_from_args(sim_parser().parse_args(["--gps-fault-below", "30"]))
    with pytest.raises(ValueError, match="--gps-fault-ramp must be >= 0"):
        config_from_args(sim_parser().parse_args(["--gps-fault", "1,1", "--gps-fault-ramp", "-1"]))


def test_curated_with_an_rtp_camera_streams_it_and_grades_by_the_video_frames(tmp_path: Path) -> None:
    """``--camera rtp`` reaches simbridge (its camera as H.264 over RTP, two frames a wall second, its
    calibration written out), names its episodes apart, is refused with real firmware; the landing
    distance takes each video frame's true pose by its presentation time."""
    from landfall_eval.episode_grade import video_frames_by_stamp

    parse = build_parser().parse_args
    base = ["curated", "--scenario", "scenario1", "--runs", "1", "--out", str(tmp_path), "--camera", "rtp"]
    (spec,) = episode_specs(parse(base))
    assert spec.id == "scenario1-r0-onboard-crop-clear-px4-rtp"
    info = tmp_path / "camera.yaml"
    cmd = simbridge_command(spec, udp_port=1, sensors_port=2, episode_log=tmp_path / "e.jsonl", speed=4.0,
                            video_port=5600, camera_info=info)  # fmt: skip
    assert cmd[cmd.index("--camera-stream") + 1] == "udp://127.0.0.1:5600"
    assert float(cmd[cmd.index("--camera-fps") + 1]) == 0.5  # 2 frames a wall second at 4 x
    assert cmd[cmd.index("--camera-info-out") + 1] == str(info)
    plain = episode_specs(parse(base[:-2]))[0]
    assert "--camera-stream" not in simbridge_command(
        plain, udp_port=1, sensors_port=2, episode_log=tmp_path / "e.jsonl", speed=4.0
    )
    with pytest.raises(ValueError, match="beside its own autopilots only"):
        episode_specs(parse([*base, "--autopilot", "px4-sitl"]))
    # simbridge sent six frames, one every 2 simulated (0.5 wall) seconds; the companion's decoder began
    # with the third, so its presentation times count from there, and each frame was decoded just after
    # the next one was sent (the parser's hold)
    sent = [{"pts_s": 2.0 * k, "t_s": 10.0 + 2 * k, "pos_ned_m": [k, 0, -50], "quat_wxyz": [1, 0, 0, 0],
             "sent_monotonic_s": 100.0 + 0.5 * k} for k in range(6)]  # fmt: skip
    used = [{"kind": "camera_frame", "pts_s": 0.0000111, "decoded_s": 101.51, "capture_boot_s": 13.9994},
            {"kind": "camera_frame", "pts_s": 2.0, "decoded_s": 102.02, "capture_boot_s": 15.0}]  # fmt: skip
    assert video_frames_by_stamp(sent, used) == {13999: sent[2], 15000: sent[3]}
    # by equal presentation times they would have been simbridge's first two, decoded 1 s before the
    # frames after them were sent; alone, a frame is the one whose next was sent just before its decoding
    assert video_frames_by_stamp(sent, [{**used[0], "pts_s": 7.0}]) == {13999: sent[2]}
    assert video_frames_by_stamp(sent, [{**used[0], "decoded_s": 100.2}]) == {}  # before any frame's next


def test_summary_counts_safe_landings_rounds_and_latency() -> None:
    def ep(safe: bool, rounds: int, surface: str, weather: str = "clear") -> dict[str, Any]:
        return {
            "safe": safe, "rounds": rounds, "surface": surface, "outcome": "landed", "reasoner": "onboard",
            "context": "crop", "weather": weather, "time_to_touchdown_s": 80.0, "kinematic_ratio": 1.2,
            "calls": [{"stage": "rank", "tier": "onboard", "latency_s": 0.01 * rounds}],
            "companion": {"peak_rss_mb": 100.0 + rounds, "peak_anon_mb": 50.0 + rounds, "cpu_s": 2.0},
        }  # fmt: skip

    s = summarise(
        [ep(True, 1, "rooftop_clear"), ep(True, 3, "rooftop_clear"), ep(False, 2, "highway", "fog")]
    )
    assert s["episodes"] == 3
    assert s["safe"] == 2
    assert s["safe_rate"] == pytest.approx(2 / 3, abs=1e-4)
    assert s["mean_rounds_safe"] == 2.0
    assert s["within_2_rounds_safe"] == 0.5
    assert s["by_surface"] == {"rooftop_clear": 2, "highway": 1}
    assert s["latency_s"]["rank"]["onboard"]["calls"] == 3
    assert s["companion_peak_rss_mb"] == 103.0
    assert s["companion_peak_anon_mb"] == 53.0
    older = ep(True, 1, "rooftop_clear")  # results written before the anonymous peak was recorded
    del older["companion"]["peak_anon_mb"]
    assert summarise([older])["companion_peak_anon_mb"] is None
    assert {(g["weather"], g["episodes"]) for g in s["groups"]} == {("clear", 2), ("fog", 1)}
    empty = summarise([])
    assert empty["episodes"] == 0
    assert empty["safe_rate"] is None
    assert empty["mean_rounds_safe"] is None
    assert set(SURFACES) >= set(s["by_surface"])


# ------------------------------------------------------------------------------------------ launches
def test_halton_launches_are_spread_stable_and_continue_from_an_index() -> None:
    first = halton_launches(20)
    assert [p.index for p in first] == list(range(20))
    assert all(-500 <= p.north_m <= 500 and -500 <= p.east_m <= 500 for p in first)
    assert all(100 <= p.height_m <= 120 for p in first)
    assert halton_launches(5, 15) == first[15:]  # --start-index continues the same sequence
    assert len({(p.north_m, p.east_m) for p in first}) == 20
    # quasi-random: every quadrant of the city gets its share of 20 points
    quadrants = [
        sum((p.north_m > 0) == n and (p.east_m > 0) == e for p in first) for n in (0, 1) for e in (0, 1)
    ]
    assert min(quadrants) >= 4
    with pytest.raises(ValueError, match=">= 0"):
        halton_launches(3, -1)


# ------------------------------------------------------------------------------------------ real runs
def bench(*args: str, timeout: float = 600) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "landfall_eval.cli", *args],
        capture_output=True, text=True, timeout=timeout,
    )  # fmt: skip


def _log_tail(path: Path, lines: int = 60) -> str:
    """The end of an episode's companion log, for a failure message (CI keeps nothing else)."""
    if not path.exists():
        return f"({path} missing)"
    return "\n".join(path.read_text(errors="replace").splitlines()[-lines:])


@pytest.fixture(scope="module")
def curated_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, subprocess.CompletedProcess[str]]:
    """Two curated scenario1 episodes through the local executor, two at a time: flown once for the
    tests of the results file and of the Ray executor (which must give the same verdicts)."""
    out = tmp_path_factory.mktemp("curated") / "bench"
    # 8 x: what the two tests check (the results file, the verdicts) does not depend on the speed
    res = bench("curated", "--scenario", "scenario1", "--runs", "2", "--workers", "2", "--speed", "8",
                "--out", str(out))  # fmt: skip
    return out, res


@pytest.mark.slow
def test_curated_run_writes_results_and_report_then_resumes(
    curated_run: tuple[Path, subprocess.CompletedProcess[str]],
) -> None:
    out, res = curated_run
    assert res.returncode == 0, res.stderr[-3000:]
    results = json.loads((out / "results.json").read_text())
    assert results["schema"] == "landfall-bench/1"
    assert results["command"] == "curated"
    episodes = results["episodes"]
    assert [e["id"] for e in episodes] == [
        "scenario1-r0-onboard-crop-clear-px4",
        "scenario1-r1-onboard-crop-clear-px4",
    ]
    for e in episodes:
        assert set(e) >= EPISODE_KEYS, EPISODE_KEYS - set(e)
        why = f"{e['error']}\n{_log_tail(out / 'episodes' / e['id'] / 'companion.log')}"
        assert e["outcome"] == "landed", why
        assert e["error"] is None
        assert e["surface"] == "rooftop_clear", why  # the gravel roof
        assert e["safe"], e["reasons"]
        assert e["rounds"] >= 1
        assert e["calls"]
        assert e["rationales"]
        assert e["calls"][0] == {
            "stage": "rank",
            "tier": "onboard",
            "latency_s": e["calls"][0]["latency_s"],
            "round": 1,
        }
        assert e["kinematic_ratio"] >= 1.0  # nothing beats the vehicle's limits
        assert e["time_to_touchdown_s"] > e["kinematic_lower_bound_s"] > 0
        # the chosen pixel's true point on the roof, and the touchdown near it (0.76 m measured)
        assert e["landing_error"] is None
        assert e["landing_distance_m"] < 1.5, e["landing_target_ned_m"]
        # the distance, the target and the touchdown are each rounded to the centimetre: up to 0.005 m
        # on the distance and 0.007 m on each point's horizontal position (the CI run met 0.011)
        assert math.dist(e["landing_target_ned_m"][:2], e["touchdown_ned_m"][:2]) == pytest.approx(
            e["landing_distance_m"], abs=0.02
        )
        assert math.dist(e["trajectory_ne_m"][-1], e["touchdown_ned_m"][:2]) < 1e-6
        assert e["companion"]["peak_rss_mb"] > 20
        assert 10 < e["companion"]["peak_anon_mb"] <= e["companion"]["peak_rss_mb"]
        assert e["companion"]["cpu_s"] > 0
        assert e["simbridge"]["cpu_s"] > 0
        phases = e["wall_phases_s"]
        assert list(phases) == ["ready", "alarm", "touchdown", "stopped", "graded"]
        assert all(v is not None and v >= 0 for v in phases.values()), phases
        assert sum(phases.values()) == pytest.approx(e["wall_s"], abs=0.1)
        assert (out / "episodes" / e["id"] / "episode.jsonl").exists()
        # PX4's precision land where a landing target went out in time, else AUTO.LAND on the absolute
        # target: either way said in the record
        pl = e["precision_landing"]
        assert pl["mode"] == ("AUTO.PRECLAND" if pl["used"] else "AUTO.LAND"), pl
        said = "AUTO.PRECLAND, PLD_MAX_SRCH 0" if pl["used"] else "no landing target"
        assert pl["why"].startswith(said), pl
    s = results["summary"]
    assert s["episodes"] == 2
    assert s["safe_rate"] == 1.0
    assert s["mean_rounds_safe"] == pytest.approx(sum(e["rounds"] for e in episodes) / 2)
    assert s["mean_landing_distance_m"] == pytest.approx(
        sum(e["landing_distance_m"] for e in episodes) / 2, abs=1e-3
    )
    html = (out / "report.html").read_text()
    assert "scenario1" in html
    assert "figures/" in html
    assert all((out / src).exists() for src in _images(html))

    # the same command again: refused without --resume (a campaign is not mixed into another by
    # mistake); with it, nothing to fly and the file keeps its episodes
    refused = bench("curated", "--scenario", "scenario1", "--runs", "2", "--out", str(out))
    assert refused.returncode == 2
    assert "already holds 2 episodes: --resume" in refused.stderr
    again = bench("curated", "--scenario", "scenario1", "--runs", "2", "--out", str(out), "--resume")
    assert again.returncode == 0, again.stderr[-2000:]
    assert "resuming: 2 of 2 episodes" in again.stderr
    assert json.loads((out / "results.json").read_text())["episodes"] == episodes


def _images(html: str) -> list[str]:
    return [part.split('"', 1)[0] for part in html.split('src="')[1:]]


@pytest.mark.slow
def test_city_episode_starts_at_its_halton_point(tmp_path: Path) -> None:
    """Launch 2 (a one-round landing: launch 3 explores for eight rounds, which tests/test_search_e2e.py
    covers, and took a minute of the suite)."""
    out = tmp_path / "city"
    res = bench(
        "city", "--seeds", "1", "--start-index", "2", "--workers", "1", "--speed", "8", "--out", str(out)
    )  # fmt: skip
    assert res.returncode == 0, res.stderr[-3000:]
    (e,) = json.loads((out / "results.json").read_text())["episodes"]
    launch = halton_launches(1, 2)[0]
    assert e["id"] == "city0-i2-onboard-crop-clear-px4"
    assert e["kind"] == "city"
    assert e["launch_index"] == 2
    assert math.dist(e["launch_ned_m"][:2], (launch.north_m, launch.east_m)) < 2.0
    assert e["outcome"] == "landed", (
        f"{e['error']}\n{_log_tail(out / 'episodes' / e['id'] / 'companion.log')}"
    )
    assert e["surface"] in SURFACES
    assert e["surface"] != "no_landing"
    assert isinstance(e["safe"], bool)
    assert e["rounds"] >= 1
    assert set(e) >= EPISODE_KEYS, EPISODE_KEYS - set(e)
    assert e["city_seed"] == 0  # --city-seed's default: the city every episode of the run flies
    assert e["world_digest"] == load_scenario("city", 2, city_seed=0).world_digest
    assert set(e["last_state"]) == LAST_STATE_KEYS
    assert e["last_state"]["outcome_state"] == "landed"
    assert e["last_state"]["round"] == e["rounds"]


def test_a_companion_that_cannot_start_is_an_error_and_leaves_no_simulator_behind(tmp_path: Path) -> None:
    """The companion exits at once (its configuration is not TOML): the episode is an infrastructure
    error saying so, and simbridge is stopped with it (nothing of the episode left running)."""
    from landfall_eval.processes import running

    bad = tmp_path / "bad.toml"
    bad.write_text("[reasoner\nonboard_model = ")
    spec = EpisodeSpec("curated", "scenario1", 0)
    e = run_episode(spec, tmp_path / "ep", times=EpisodeTimes(speed=2.0), config_path=bad)
    assert e["outcome"] == "error"
    assert e["error"].startswith("the companion exited before the vehicle was ready"), e["error"]
    assert e["error_kind"] == "infrastructure"
    assert running() == 0
    assert "bad.toml" in (tmp_path / "ep" / "companion.log").read_text()  # the companion said why


def test_line_tail_reads_each_line_once_and_waits_for_a_line_being_written(tmp_path: Path) -> None:
    from landfall_eval.episode_grade import recorded
    from landfall_eval.processes import JsonlTail, LineTail

    path = tmp_path / "companion.log"
    tail = LineTail(path)
    assert tail.text_lines() == []  # not there yet
    with path.open("w") as fh:
        fh.write("companion up on udp:1\nsensor str")
        fh.flush()
        assert tail.text_lines() == ["companion up on udp:1"]
        fh.write("eam connected\n\nrecovery ended\n")
        fh.flush()
        assert tail.text_lines() == ["sensor stream connected", "", "recovery ended"]
        assert tail.text_lines() == []
    tail.close()
    jl = tmp_path / "e.jsonl"
    jl.write_text('{"a": 1}\n{"torn": \n{"b": 2}\n')
    jt = JsonlTail(jl)
    assert jt.lines() == [{"a": 1}, {"b": 2}]
    jt.close()
    record = tmp_path / "record" / "session"
    record.mkdir(parents=True)
    (record / "events.jsonl").write_text('{"kind": "state"}\n{"kind": "sensors"}\n')
    assert recorded(tmp_path / "record", "sensors")
    assert not recorded(tmp_path / "record", "outcome", "recovery_failed")


@pytest.mark.slow
def test_episode_that_never_lands_says_where_it_stood(tmp_path: Path) -> None:
    spec = EpisodeSpec("city", "city", 5, launch_index=5, city_seed=2)
    e = run_episode(spec, tmp_path / "ep", times=EpisodeTimes(speed=2.0, sim_s=1.0))
    why = f"{e['error']}\n{_log_tail(tmp_path / 'ep' / 'companion.log')}"
    assert e["outcome"] == "timeout", why
    assert e["error"] == "no touchdown within 1 simulated seconds"
    assert e["touchdown_ned_m"] is None
    assert (e["seed"], e["city_seed"]) == (5, 2)
    assert e["world_digest"] == load_scenario("city", 0, city_seed=2).world_digest
    last = e["last_state"]
    assert set(last) == LAST_STATE_KEYS
    mid_recovery = {"acquire", "surface_id", "rank", "move", "confirm", "explore", "descend"}
    assert last["recovery_state"] in mid_recovery
    assert last["round"] >= 0
    assert last["vehicle_mode"] == "OFFBOARD"  # the companion had control, px4
    assert last["vehicle_armed"] is True
    assert last["vehicle_agl_m"] > 50.0  # still up near the launch height
    assert last["vehicle_t_s"] > 0.0
    assert len(last["vehicle_pos_ned_m"]) == 3


def test_bad_arguments_and_a_foreign_results_file_are_refused(tmp_path: Path) -> None:
    res = bench("curated", "--scenario", "scenario1", "--runs", "0", "--out", str(tmp_path))
    assert res.returncode == 2
    assert "--runs must be > 0" in res.stderr
    res = bench("curated", "--scenario", "scenario1", "--sitl", "/bin/true", "--out", str(tmp_path))
    assert res.returncode == 2
    assert "--sitl goes with --autopilot ardupilot-sitl" in res.stderr
    missing = tmp_path / "no-arducopter"
    res = bench("curated", "--scenario", "scenario1", "--autopilot", "ardupilot-sitl", "--sitl", str(missing),
                "--out", str(tmp_path / "sitl"))  # fmt: skip
    assert res.returncode == 2
    assert f"{missing} is not a file" in res.stderr
    assert not (tmp_path / "sitl").exists()  # refused before anything was written
    (tmp_path / "results.json").write_text('{"something": "else"}')
    res = bench("city", "--seeds", "1", "--out", str(tmp_path))
    assert res.returncode == 2
    assert "not a companion-bench results file" in res.stderr
    (tmp_path / "results.json").write_text("{broken")
    res = bench("city", "--seeds", "1", "--out", str(tmp_path))
    assert res.returncode == 2
    assert "is not valid JSON" in res.stderr
    assert (tmp_path / "results.json").read_text() == "{broken"  # never overwritten


def _episode_events(out: Path, e: dict[str, Any]) -> list[dict[str, Any]]:
    """The flight record's events of episode ``e`` of the campaign in ``out``."""
    (record,) = (out / "episodes" / e["id"] / "record").glob("*/events.jsonl")
    return [json.loads(x) for x in record.read_text().splitlines()]


@pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="reads Linux /proc")
def test_process_sample_peak_counts_memory_freed_between_samples() -> None:
    """The companion's peak RSS is the kernel's high-water mark: 200 MB touched and freed before the
    first sample still count."""
    code = (
        "import sys; b = bytearray(200 * 1024 * 1024); b[::4096] = b'x' * len(b[::4096]); del b; "
        "print('freed', flush=True); sys.stdin.read()"
    )
    child = subprocess.Popen(
        [sys.executable, "-c", code], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
    )
    try:
        assert child.stdout is not None
        assert child.stdout.readline().strip() == "freed"
        usage = ProcessSample(child.pid)
        usage.sample()
        status = Path(f"/proc/{child.pid}/status").read_text()
        now_mb = next(int(x.split()[1]) for x in status.splitlines() if x.startswith("VmRSS:")) / 1024
        assert usage.peak_rss_mb >= 200.0
        assert now_mb < 150.0  # the memory is gone now: only the high-water mark remembers it
        assert 0.0 < usage.peak_anon_mb < 150.0  # its own memory at the sample, freed already
        assert usage.cpu_s >= 0.0
    finally:
        child.communicate("")


def test_wall_phases_count_each_phase_from_the_last_one_reached() -> None:
    from landfall_eval.episode import wall_phases

    marks = {
        "start": 100.0,
        "ready": 104.5,
        "alarm": 104.75,
        "touchdown": 125.0,
        "stopped": 126.0,
        "graded": 127.5,
    }
    assert wall_phases(marks) == {
        "ready": 4.5,
        "alarm": 0.25,
        "touchdown": 20.25,
        "stopped": 1.0,
        "graded": 1.5,
    }
    # the alarm refused: no flight; the stop counts from the last phase reached
    cut = {"start": 0.0, "ready": 3.0, "stopped": 4.0, "graded": 4.5}
    assert wall_phases(cut) == {"ready": 3.0, "alarm": None, "touchdown": None, "stopped": 1.0, "graded": 0.5}
