"""The product end to end: simbridge and the companion as separate processes, an alarm from
trigger_alarm.py, and the verdict from simbridge's ground truth (its episode log)."""

from __future__ import annotations

import json
import re
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from tests.conftest import Rig
from tests.views import open_field_toml

pytestmark = pytest.mark.slow


def _wait_touchdown(rig: Rig, timeout_s: float) -> dict[str, object]:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        events = rig.sim.events("touchdown")
        if events:
            return events[0]
        assert rig.companion.poll() is None, rig.log_text()
        time.sleep(0.5)  # polling a file another process writes; no event to wait on
    raise AssertionError(f"no touchdown within {timeout_s} s\n{rig.log_text()[-3000:]}")


def _land_through_a_link_blackout(
    relays: list[Any],
    alarmed: Callable[[], Rig],
    *,
    first_step: str,
    step_timeout_s: float,
    touchdown_timeout_s: float,
) -> tuple[Rig, dict[str, object], str]:
    """``alarmed()`` starts a rig whose MAVLink goes through ``relays`` and raises an alarm; once the
    companion says ``first_step`` (its first descent step), the first relay's link goes dead for 5 s of
    wall time and comes back. The vehicle must land safe on the clear roof, the companion having said
    that the link was lost and came back. Every relay is closed, but only once the companion has said
    the recovery ended: the relay carries the autopilot's landed state after the touchdown. Returns
    the rig, the touchdown and the companion's log."""
    try:
        rig = alarmed()
        rig.wait_log(first_step, timeout_s=step_timeout_s)
        relays[0].blackout()
        time.sleep(5.0)
        relays[0].restore()
        td = _wait_touchdown(rig, timeout_s=touchdown_timeout_s)
        log = rig.wait_log("recovery ended: landed", timeout_s=120)
    finally:
        for r in relays:
            r.close()
    assert td["surface"] == "rooftop_clear", (td, rig.log_text()[-3000:])
    assert td["safe"] is True
    assert relays[0].counts["blacked_out"] > 0
    assert "link to the autopilot lost" in log
    assert "link back after" in log
    return rig, td, log


def _offboard_holds_s(rig: Rig) -> list[float]:
    """The simulated seconds of each offboard-loss hold, from PX4's failsafe to OFFBOARD given back
    (an unended hold is left out, so its count falls short of the failsafes')."""
    holds, since = [], None
    for e in rig.sim.events():
        if e.get("event") == "failsafe" and e.get("reason") == "offboard_loss":
            since = float(e["t_s"])  # type: ignore[arg-type]
        elif (
            e.get("event") == "failsafe_cleared" and e.get("reason") == "offboard_loss" and since is not None
        ):
            holds.append(float(e["t_s"]) - since)  # type: ignore[arg-type]
            since = None
    return holds


def _wait_for_companion(rig: Rig) -> None:
    """Until the companion accepts alarms, trigger_alarm.py reports 'refused for now' (exit 1)."""
    rig.wait_log("sensor stream connected", timeout_s=60)


def _via(relays: list[Any], make: Callable[[int], Any]) -> Callable[[int], int]:
    """A ``sensors_via`` / ``mavlink_via`` for ``start_rig``: a relay ``make(port)`` in front of the
    port, kept in ``relays`` for the test to drive and close."""

    def via(port: int) -> int:
        relays.append(make(port))
        return int(relays[-1].port)

    return via


def _clean_relay(port: int) -> Any:
    """A MAVLink relay with no losses, until blacked out."""
    from tests.relay import LossyUdpRelay

    return LossyUdpRelay(port, drop=0.0, duplicate=0.0, reorder=0.0, corrupt=0.0)


def _raise_alarm(rig: Rig, reason: str, criticality: str) -> None:
    """Once the companion takes alarms: one alarm, accepted."""
    _wait_for_companion(rig)
    out = rig.alarm_accepted("--reason", reason, "--criticality", criticality)
    assert out.returncode == 0, out.stdout + out.stderr


def _alarm_and_land(
    rig: Rig, reason: str, criticality: str, *, timeout_s: float, ended: str = "recovery ended"
) -> dict[str, object]:
    """Once the companion takes alarms: one alarm, accepted; simbridge's touchdown event; then the
    companion's own word that the recovery ended (``ended``: a prefix of that log line)."""
    _raise_alarm(rig, reason, criticality)
    td = _wait_touchdown(rig, timeout_s=timeout_s)
    rig.wait_log(ended, timeout_s=60)
    return td


@pytest.mark.parametrize(
    ("autopilot", "scenario", "roof_ne", "roof_height_m"),
    [("px4", "scenario1", (0.0, -27.0), 22.0), ("ardupilot", "scenario2", None, None)],
)
def test_alarm_lands_on_the_clear_roof(
    start_rig: Callable[..., Rig],
    autopilot: str,
    scenario: str,
    roof_ne: tuple[float, float] | None,
    roof_height_m: float | None,
) -> None:
    rig = start_rig(["--scenario", scenario, "--autopilot", autopilot, "--speed", "8"])
    _wait_for_companion(rig)
    out = rig.alarm_accepted(
        "--reason", "GPS spoofing detected", "--criticality", "high", "--code", "gps_spoofing"
    )
    assert out.returncode == 0, out.stdout + out.stderr
    assert "accepted: recovery started" in out.stdout
    td = _wait_touchdown(rig, timeout_s=150)
    assert td["surface"] == "rooftop_clear", (td, rig.log_text()[-2000:])
    assert td["safe"] is True
    # simbridge logs the touchdown before the companion has seen the landing in telemetry: wait for it.
    log = rig.wait_log("recovery ended: landed", timeout_s=60)
    rounds = int(log.split("recovery ended: landed after ")[1].split(" ")[0])
    assert rounds <= 6  # the budget of a 'high' alarm
    if roof_ne is not None and roof_height_m is not None:
        n, e, d = td["pos_ned_m"]  # type: ignore[misc]
        assert abs(n - roof_ne[0]) < 18
        assert abs(e - roof_ne[1]) < 13
        assert -d == pytest.approx(roof_height_m + 0.15, abs=0.1)


def test_repeated_alarm_merges_and_unsigned_alarm_is_refused(start_rig: Callable[..., Rig]) -> None:
    key = "ab" * 32
    rig = start_rig(
        ["--scenario", "scenario1", "--speed", "2", "--signing-key", key], env={"LANDFALL_SIGNING_KEY": key}
    )
    _wait_for_companion(rig)
    unsigned = rig.alarm("--reason", "spoofed", "--criticality", "critical", timeout_s=3)
    assert unsigned.returncode == 3  # silently dropped by the signed link: no acknowledgement
    first = rig.alarm_accepted("--reason", "low battery", "--signing-key", key)
    assert "recovery started" in first.stdout, first.stdout + first.stderr
    second = rig.alarm("--reason", "storm", "--criticality", "critical", "--signing-key", key)
    assert second.returncode == 0
    assert "merged into the running recovery" in second.stdout
    log = rig.log_text()
    assert "alarm raised to critical: 3 rounds" in log  # the repeat shortened the budget
    starts = re.findall(r"INFO companion: alarm '[^']*' \(\w+\), \d+ rounds", log)
    assert len(starts) == 1, starts  # and never started a second loop


def _sim_port(rig: Rig) -> int:
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        text = rig.sim.stderr_path.read_text()
        if "local UDP port" in text:
            return int(text.split("local UDP port ")[1].split(")")[0])
        time.sleep(0.2)
    raise AssertionError("simbridge did not log its port")


def test_operator_takeover_stops_the_companion(start_rig: Callable[..., Rig]) -> None:
    from pymavlink import mavutil

    rig = start_rig(["--scenario", "scenario1", "--autopilot", "ardupilot", "--speed", "2"])
    _raise_alarm(rig, "sensor failure", "low")
    deadline = time.monotonic() + 60
    while not [e for e in rig.sim.events("mode") if e["mode"] == "GUIDED"]:
        assert time.monotonic() < deadline, rig.log_text()
        time.sleep(0.2)
    # a ground station takes over: LOITER, sent straight to the autopilot
    gcs = mavutil.mavlink_connection(
        f"udpout:127.0.0.1:{_sim_port(rig)}", source_system=255, source_component=190
    )
    try:
        for _ in range(3):
            gcs.mav.command_long_send(1, 1, 176, 0, 1, 5, 0, 0, 0, 0, 0)
            if gcs.recv_match(type="COMMAND_ACK", blocking=True, timeout=2) is not None:
                break
    finally:
        gcs.close()
    log = rig.wait_log("recovery ended")
    assert "operator took over: stopped commanding" in log
    assert "recovery ended: aborted" in log
    modes = [e["mode"] for e in rig.sim.events("mode")]
    assert modes[-1] == "LOITER"  # nobody switched it back
    assert not rig.sim.events("touchdown")


def test_unreachable_target_ends_the_round_and_the_budget_still_lands(start_rig: Callable[..., Rig]) -> None:
    from pymavlink import mavutil

    # ArduPilot's geofence (10 m) refuses every target toward the roofs and the vehicle holds:
    # each move times out (after 6 s of wall clock and 0.1 s a metre, 8x faster than real time)
    env = {"LANDFALL_RECOVERY_MOVE_TIMEOUT_S": "6", "LANDFALL_RECOVERY_MOVE_TIMEOUT_S_PER_M": "0.1"}
    rig = start_rig(["--scenario", "scenario1", "--autopilot", "ardupilot", "--speed", "8"], env=env)
    gcs = mavutil.mavlink_connection(
        f"udpout:127.0.0.1:{_sim_port(rig)}", source_system=255, source_component=190
    )
    try:
        for _ in range(5):
            gcs.mav.param_set_send(1, 1, b"FENCE_RADIUS", 10.0, mavutil.mavlink.MAV_PARAM_TYPE_REAL32)
            echo = gcs.recv_match(type="PARAM_VALUE", blocking=True, timeout=2)
            if echo is not None and echo.param_value == 10.0:
                break
        else:
            raise AssertionError("geofence parameter not set")
    finally:
        gcs.close()
    _raise_alarm(rig, "storm", "critical")
    _wait_touchdown(rig, timeout_s=200)
    log = rig.wait_log("recovery ended")
    # the round's target is not reached (a move of 6 s wall plus its distance allowance, 8x faster
    # than real time: over a minute of the autopilot's clock), and the critical alarm's window
    # (60 s) has closed by then: no more rounds, the least bad site measured, not reached either
    assert "site 0 roof 28 m W" in log  # the chosen pixel's own point (29 m: its nearest LiDAR return)
    assert "target not reached (28" in log
    assert "search ends: the critical alarm's 60 s to search have passed" in log
    assert "landing at site 0 (doubted: nothing seen against it from afar)" in log
    assert "the chosen site target not reached" in log
    assert "recovery ended: landed after 1 rounds (search ended (the critical alarm's" in log


def test_autopilot_failsafe_text_raises_an_alarm_by_itself(start_rig: Callable[..., Rig]) -> None:
    from pymavlink import mavutil

    rig = start_rig(["--scenario", "scenario1", "--autopilot", "px4", "--speed", "2"])
    _wait_for_companion(rig)
    gcs = mavutil.mavlink_connection(
        f"udpout:127.0.0.1:{_sim_port(rig)}", source_system=255, source_component=190
    )
    try:
        # a ground station flies offboard for a moment, then its stream stops: PX4's offboard-loss
        # failsafe announces itself by STATUSTEXT, and the companion's watcher takes it as an alarm
        end = time.monotonic() + 1.5
        while time.monotonic() < end:
            gcs.mav.set_position_target_local_ned_send(0, 1, 1, 1, 3576, 0, 0, -110, 0, 0, 0, 0, 0, 0, 0, 0)
            time.sleep(0.05)
        gcs.mav.command_long_send(1, 1, 176, 0, 1, 6, 0, 0, 0, 0, 0)
        ack = gcs.recv_match(type="COMMAND_ACK", blocking=True, timeout=5)
        assert ack is not None
        assert ack.result == 0
    finally:
        gcs.close()
    log = rig.wait_log("watcher alarm")
    assert "watcher alarm 'Failsafe" in log
    assert "-> MAV_RESULT 0" in log  # it started a recovery


PITCHED_WORLD = """
name = "nothing_flat"
description = "one vast gable roof pitched about 25 deg: no flat surface anywhere in view"
extent = { north = [-250.0, 250.0], east = [-250.0, 250.0] }
resolution_m = 0.5
ground = "soil"
launch = { north = 0.0, east = 20.0, height_m = 70.0, yaw_deg = 0.0 }

[[buildings]]
id = "gable"
centre = [0.0, 0.0]
size = [496.0, 496.0]
height_m = 2.0
roof = "tiles"
pitched = { ridge_m = 118.0 }
"""


def test_nothing_flat_explores_then_lands_when_the_budget_runs_out(
    start_rig: Callable[..., Rig], tmp_path: Path
) -> None:
    scenario = tmp_path / "nothing_flat.toml"
    scenario.write_text(PITCHED_WORLD)
    # 70 m up, nothing flat anywhere: search legs to ground not yet seen, until the critical alarm's
    # window (recovery.search_window_s.critical, 60 s of the autopilot's clock) closes
    rig = start_rig(["--scenario", str(scenario), "--autopilot", "ardupilot", "--speed", "8"])
    _raise_alarm(rig, "storm", "critical")
    td = _wait_touchdown(rig, timeout_s=200)
    log = rig.log_text()
    assert "search leg 1: " in log
    assert "to ground not yet seen" in log  # a whole view's width onward, never the same ground
    assert "search ends: the critical alarm's 60 s to search have passed" in log
    assert "landing here (" in log  # never just give up: the spot below, judged
    assert td["safe"] is False  # and the ground truth agrees that a gable roof was no place to land


def test_out_of_lidar_range_descends_into_it_instead_of_climbing(
    start_rig: Callable[..., Rig], tmp_path: Path
) -> None:
    """125 m above a bare field the 100 m LiDAR returns nothing; the rangefinder (200 m) sees the
    ground. Climbing or moving would keep it blind: the companion descends to 70 m, then finds the
    field flat and lands on it."""
    scenario = tmp_path / "open_field.toml"
    scenario.write_text(open_field_toml(250.0, 125.0))
    rig = start_rig(["--scenario", str(scenario), "--autopilot", "px4", "--speed", "8"])
    _raise_alarm(rig, "GPS spoofing", "high")
    td = _wait_touchdown(rig, timeout_s=200)
    log = rig.log_text()
    assert "LiDAR sees nothing, ground 125 m below: descending 55 m" in log
    assert "climbing" not in log
    assert td["safe"] is True, td


def test_past_the_budget_a_descent_to_see_is_followed_by_a_look_from_there(
    start_rig: Callable[..., Rig], tmp_path: Path
) -> None:
    """A round budget of one (``recovery.max_rounds``), 125 m above a bare field, out of the 100 m
    LiDAR's reach: the first round ends descending to 70 m to see; the next, past the budget, looks
    from there before it flies any search leg, finds the field flat and lands on it. (City 5, launch
    47: past the budget each such descent was followed by a leg climbing back out of the LiDAR's
    reach, until the alarm's window closed with nothing seen and it landed where it was.)"""
    scenario = tmp_path / "open_field.toml"
    scenario.write_text(open_field_toml(250.0, 125.0))
    rig = start_rig(
        ["--scenario", str(scenario), "--autopilot", "px4", "--speed", "8"],
        env={"LANDFALL_RECOVERY_MAX_ROUNDS": "1"},
    )
    _raise_alarm(rig, "GPS spoofing", "high")
    td = _wait_touchdown(rig, timeout_s=200)
    log = rig.log_text()
    assert "LiDAR sees nothing, ground 125 m below: descending 55 m" in log
    assert "budget spent, nothing measured: looking again from here (1, battery" in log
    assert "search leg" not in log
    assert td["safe"] is True, td


TOWER = """
[[buildings]]
id = "tower"
centre = [0.0, 40.0]
size = [20.0, 20.0]
height_m = 55.0
roof = "tiles"
pitched = { ridge_m = 59.7 }
"""


def test_high_above_the_ground_with_nothing_flat_in_reach_it_descends_before_it_moves(
    start_rig: Callable[..., Rig], tmp_path: Path
) -> None:
    """125 m above a bare field, a tower with a pitched roof 40 m east: the LiDAR (100 m) reaches only the
    tower's roof, nothing flat. Moving on level (as the exploring spiral did) would keep the field out
    of reach; the rangefinder measured the column below clear, so the companion descends to 90 m above
    the field, finds it flat and lands on it. (A campaign's city 2 launch 18 spent four extra
    rounds 130 m up, seeing nothing flat.)"""
    scenario = tmp_path / "tower_field.toml"
    scenario.write_text(open_field_toml(250.0, 125.0) + TOWER)
    rig = start_rig(["--scenario", str(scenario), "--autopilot", "px4", "--speed", "8"])
    _raise_alarm(rig, "GPS spoofing", "high")
    td = _wait_touchdown(rig, timeout_s=200)
    log = rig.log_text()
    assert "beyond the LiDAR's reach: descending 35 m" in log, log[-3000:]
    assert "moving" not in log.split("beyond the LiDAR's reach")[0]  # no level step out of reach first
    assert td["safe"] is True, td


def test_an_lvlm_tier_flies_the_loop_and_a_lone_no_is_overridden(
    start_rig: Callable[..., Rig], tmp_path: Path
) -> None:
    """The companion asks a vision-language model over real HTTP (a scripted local OpenAI-compatible
    server): it ranks the first candidate first, and at every confirmation sees "birds on the roof".
    The LiDAR and the onboard cues find the clear roof clear, so the first "no" is a lone no (the site
    is not struck off), the second is overridden (reasoner.override_lone_no_after = 2), and the vehicle
    lands on the clear roof. The flight record keeps every exchange."""
    from tests.lvlm_server import ScriptedServer, answer

    server = ScriptedServer()
    try:
        server.script("vlm", answer({"explanation": "candidate 0 is a clear gravel roof", "ranking": [0]}),
                      stage="rank")  # fmt: skip
        server.script("vlm", answer({"explanation": "birds on the roof", "decision": 0}), stage="confirm")
        record = tmp_path / "record"
        rig = _lvlm_rig(start_rig, tmp_path, server.base_url, record)
        _raise_alarm(rig, "sensor failure", "high")
        td = _wait_touchdown(rig, timeout_s=200)
        assert td["surface"] == "rooftop_clear", (td, rig.log_text()[-3000:])
        assert td["safe"] is True
        log = rig.wait_log("recovery ended: landed", timeout_s=60)
        assert "contested" in log
        assert len(server.seen("vlm")) >= 4  # ranks and confirmations went over HTTP
    finally:
        server.close()
    events = _events(record)
    exchanges = [e for e in events if e["kind"] == "exchange"]
    assert {e["tier"] for e in exchanges} == {"edge"}  # the model always answered validly
    assert any(t.get("raw") and "birds" in t["raw"] for e in exchanges for t in e["transcript"])
    confirms = [e for e in events if e["kind"] == "confirm"]
    assert confirms[0]["accept"] is False
    assert any(c["accept"] and "accepted over 2 lone no" in c["rationale"] for c in confirms)
    ranks = [e for e in events if e["kind"] == "rank"]
    assert all(r["tier"] == "edge" and r["images"] for r in ranks)
    # the first round's frame goes into the search's map once the vehicle moves, not before its setpoint
    move = next(k for k, e in enumerate(events) if e["kind"] == "state" and e["state"] == "move")
    observed = next(k for k, e in enumerate(events) if e["kind"] == "observed")
    assert events[move]["round"] == events[observed]["round"] == 1
    assert move < observed
    assert events[observed]["jobs"] == 1  # a roof chosen: the candidates' notes waited for the move too


def _events(record: Path) -> list[dict[str, Any]]:
    """The events of the one session under ``record``."""
    (events_file,) = record.glob("*/events.jsonl")
    return _events_in(events_file.parent)


def _lvlm_rig(start_rig: Callable[..., Rig], tmp_path: Path, base_url: str, record: Path) -> Rig:
    """scenario1, PX4, 8x; the companion's reasoner is the model "vlm" at ``base_url``, recorded."""
    config = tmp_path / "companion.toml"
    config.write_text(
        f'[reasoner]\nname = "edge"\n[reasoner.profiles.edge]\nbase_url = "{base_url}"\n'
        'model = "vlm"\napi_key_env = ""\n'
    )
    return start_rig(
        ["--scenario", "scenario1", "--autopilot", "px4", "--speed", "8"],
        ["--config", str(config), "--record", str(record)],
    )


def _events_in(session: Path) -> list[dict[str, Any]]:
    return [json.loads(line) for line in (session / "events.jsonl").read_text().splitlines()]
