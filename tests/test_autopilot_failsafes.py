"""The autopilot's own failsafes in the middle of a recovery, on simbridge's emulation of
PX4 and ArduPilot: the companion sees the autopilot take over, stops commanding, says so, records it
and never fights the autopilot's choice; a failsafe that clears by itself (PX4's offboard-loss
fallback) hands the vehicle back; a warning that leaves room lets the recovery go on."""

from __future__ import annotations

import math
import struct
import time
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import pytest

from tests.conftest import Rig
from tests.test_companion_e2e import (
    _clean_relay,
    _events,
    _offboard_holds_s,
    _raise_alarm,
    _sim_port,
    _via,
    _wait_for_companion,
    _wait_touchdown,
)
from tests.test_sitl import _wait_event

pytestmark = pytest.mark.slow

INT8 = 2  # MAV_PARAM_TYPE_INT8
INT32 = 6  # MAV_PARAM_TYPE_INT32
REAL32 = 9


def _wire(value: float, kind: int, *, bytewise: bool) -> float:
    """A parameter's value as PARAM_SET carries it: PX4 puts an INT32's bytes in the float field
    (``bytewise``), ArduPilot casts it."""
    if kind == INT32 and bytewise:
        return float(struct.unpack("<f", struct.pack("<i", int(value)))[0])
    return value


def _emulated(start_rig: Callable[..., Rig], tmp_path: Path, *sim_args: str) -> tuple[Rig, Path]:
    """simbridge's emulation at 8x (``sim_args``) and a companion keeping a flight record."""
    record = tmp_path / "record"
    return start_rig([*sim_args, "--speed", "8"], ["--record", str(record)]), record


def _set_params(rig: Rig, params: dict[str, tuple[float, int]], *, bytewise: bool) -> None:
    """PARAM_SET from a ground station of its own, each confirmed by its PARAM_VALUE echo (:func:`_wire`)."""
    from pymavlink import mavutil

    gcs = mavutil.mavlink_connection(
        f"udpout:127.0.0.1:{_sim_port(rig)}", source_system=255, source_component=190
    )
    try:
        for name, (value, kind) in params.items():
            wire = _wire(value, kind, bytewise=bytewise)
            for _ in range(5):
                gcs.mav.param_set_send(1, 1, name.encode(), wire, kind)
                echo = gcs.recv_match(type="PARAM_VALUE", blocking=True, timeout=2)
                if echo is not None and echo.param_id == name and echo.param_value == pytest.approx(wire):
                    break
            else:
                raise AssertionError(f"{name} not set")
    finally:
        gcs.close()


def _modes_after(rig: Rig, mode: str) -> list[Any]:
    modes = [e["mode"] for e in rig.sim.events("mode")]
    assert mode in modes, modes
    return modes[modes.index(mode) :]


def test_a_battery_failsafe_that_lands_keeps_the_vehicle_and_the_companion_stands_down(
    start_rig: Callable[..., Rig], tmp_path: Path
) -> None:
    """PX4 set to land at a critical battery (COM_LOW_BAT_ACT 2). Mid-descent the pack crosses the
    critical threshold: PX4 holds for COM_BAT_ACT_T (a command then would be a user takeover that
    cancels the action), then switches to AUTO.LAND. The companion commands nothing for its grace
    period; the failsafe does not clear, so it stops commanding, says so, watches the landing down and
    records how the flight ended."""
    rig, record = _emulated(
        start_rig, tmp_path, "--scenario", "scenario1", "--autopilot", "px4", "--battery", "40"
    )
    _wait_for_companion(rig)
    _set_params(rig, {"COM_LOW_BAT_ACT": (2, INT32)}, bytewise=True)
    _raise_alarm(rig, "GPS spoofing", "high")
    rig.wait_log("m, ", timeout_s=120)  # "descending 62 m, <rationale>": the first descent step
    # the thresholds raised above the charge left: the pack is now critical
    _set_params(rig, {"BAT_LOW_THR": (0.5, REAL32), "BAT_CRIT_THR": (0.45, REAL32)}, bytewise=True)
    td = _wait_touchdown(rig, timeout_s=200)
    log = rig.wait_log("recovery ended", timeout_s=60)
    # at 4x PX4's 1 s COM_OF_LOSS_T is 0.25 s of wall time: a loaded machine's stalled event loop can
    # cost a brief offboard loss, given back with the next setpoint; none is what this test is about
    losses = [f for f in rig.sim.events("failsafe") if f["reason"] == "offboard_loss"]
    holds = _offboard_holds_s(rig)
    assert len(holds) == len(losses), holds
    assert max(holds, default=0.0) < 3.0, holds
    failsafes = [f for f in rig.sim.events("failsafe") if f["reason"] != "offboard_loss"]
    # PX4 holds while its action waits (COM_BAT_ACT_T), then lands
    assert [(f["reason"], f["action"]) for f in failsafes] == [
        ("battery_critical", "AUTO.LOITER"),
        ("battery_critical", "AUTO.LAND"),
    ], failsafes
    assert "waiting 6 s for it to clear" in log
    assert "autopilot failsafe: AUTO.LAND; the autopilot keeps control" in log
    assert "re-engaging" not in log
    assert "recovery ended: aborted" not in log
    assert "(the autopilot's failsafe landed it (AUTO.LAND))" in log
    assert "OFFBOARD" not in _modes_after(rig, "AUTO.LAND")  # never taken back
    # COM_DISARM_LAND after the touchdown, in the simulation's time: it may not have passed yet
    assert _wait_event(rig.sim, "disarmed", 30)["reason"] == "landed"
    assert td["pos_ned_m"]
    events = _events(record)
    kinds = [e["kind"] for e in events]
    assert "autopilot_failsafe" in kinds
    assert any(e["kind"] == "released" and e["to"] == "AUTO.LAND" for e in events)
    texts = [e["text"] for e in events if e["kind"] == "autopilot_text"]
    assert any("Critical battery level" in t for t in texts), texts
    assert events[-1]["kind"] == "outcome"
    assert events[-1]["state"] == "landed"
    assert "failsafe" in events[-1]["reason"]


def test_an_offboard_loss_set_to_land_clears_when_the_link_returns_and_the_recovery_goes_on(
    start_rig: Callable[..., Rig], tmp_path: Path
) -> None:
    """PX4 set to land on a lost offboard stream (COM_OBL_RC_ACT 4). During the descent the companion's
    setpoints stop reaching PX4 (its telemetry still comes): PX4 falls back to AUTO.LAND, and the
    companion sees it. That fallback is a mode fallback: once setpoints flow again PX4 goes back to
    OFFBOARD by itself (failsafe.cpp, checkModeFallback). The companion holds off for its grace period,
    streaming a hold, rather than taking the failsafe for the end of the flight; the uplink returns
    within it, and the recovery lands on the roof it chose."""
    relays: list[Any] = []
    record = tmp_path / "record"
    try:
        rig = start_rig(
            # 4x, not 8x: PX4's 1 s offboard-loss timeout is 125 ms of wall time at 8x, which a loaded
            # two-core machine running the suite beside it has missed mid-descent (a second failsafe)
            ["--scenario", "scenario1", "--autopilot", "px4", "--speed", "4"],
            ["--record", str(record)],
            mavlink_via=_via(relays, _clean_relay),
        )
        _wait_for_companion(rig)
        _set_params(rig, {"COM_OBL_RC_ACT": (4, INT32)}, bytewise=True)
        _raise_alarm(rig, "GPS spoofing", "high")
        rig.wait_log("m, ", timeout_s=120)
        # the companion's setpoints stop reaching PX4, its telemetry still comes: PX4's fallback shows
        relays[0].blackout_uplink()
        rig.wait_log("autopilot failsafe: AUTO.LAND; waiting 6 s for it to clear", timeout_s=60)
        relays[0].restore()  # within the grace period: the hold setpoints reach PX4 again
        td = _wait_touchdown(rig, timeout_s=200)
        log = rig.wait_log("recovery ended", timeout_s=60)
    finally:
        for r in relays:
            r.close()
    # the uplink's blackout: PX4's AUTO.LAND, given back to OFFBOARD. At 4x PX4's 1 s COM_OF_LOSS_T is
    # 0.25 s of wall time: a loaded machine's stalled relay can add a brief loss, given back the same way
    actions = [f["action"] for f in rig.sim.events("failsafe")]
    holds = _offboard_holds_s(rig)
    assert set(actions) == {"AUTO.LAND"}, rig.sim.events("failsafe")
    assert [f["mode"] for f in rig.sim.events("failsafe_cleared")] == ["OFFBOARD"] * len(actions)
    assert max(holds[1:], default=0.0) < 3.0, holds
    assert "the autopilot keeps control" not in log
    assert "the autopilot's failsafe cleared (AUTO.LAND -> back to the companion): going on" in log
    assert "recovery ended: landed after" in log
    assert "failsafe landed it" not in log
    assert td["surface"] == "rooftop_clear", td
    assert td["safe"] is True
    events = _events(record)
    assert events[-1]["kind"] == "outcome"
    assert events[-1]["reason"] == "landed"


def test_a_battery_warning_leaves_room_and_the_recovery_goes_on(
    start_rig: Callable[..., Rig], tmp_path: Path
) -> None:
    """ArduCopter's low-battery level with no action (BATT_FS_LOW_ACT 0, its default) crossed mid-descent:
    a warning only. The companion records the autopilot's words and lands where it chose."""
    rig, record = _emulated(start_rig, tmp_path, "--scenario", "scenario2", "--autopilot", "ardupilot")
    _raise_alarm(rig, "GPS spoofing", "high")
    rig.wait_log("m, ", timeout_s=120)
    _set_params(rig, {"BATT_LOW_MAH": (4999.0, REAL32)}, bytewise=False)  # less than that left: low
    td = _wait_touchdown(rig, timeout_s=200)
    log = rig.wait_log("recovery ended", timeout_s=60)
    warnings = rig.sim.events("battery_warning")
    assert [(w["level"], w["action"]) for w in warnings] == [("low", None)], warnings
    assert rig.sim.events("failsafe") == []
    assert "recovery ended: landed after" in log
    assert "autopilot failsafe" not in log
    assert td["safe"] is True
    events = _events(record)
    texts = [e["text"] for e in events if e["kind"] == "autopilot_text"]
    assert any(t.startswith("Battery 1 is low") for t in texts), texts
    assert events[-1]["kind"] == "outcome"
    assert events[-1]["reason"] == "landed"


def test_an_alarm_while_the_autopilots_failsafe_lands_does_not_take_the_vehicle(
    start_rig: Callable[..., Rig], tmp_path: Path
) -> None:
    """ArduCopter set to land at a critical battery (BATT_FS_CRT_ACT 1) before any alarm: its failsafe
    lands the vehicle and says so, which the companion's watcher takes as an alarm. The recovery that
    starts finds the autopilot's failsafe in charge and leaves the vehicle to it."""
    rig, record = _emulated(start_rig, tmp_path, "--scenario", "scenario2", "--autopilot", "ardupilot")
    _wait_for_companion(rig)
    _set_params(rig, {"BATT_FS_CRT_ACT": (1, INT32), "BATT_CRT_MAH": (4999.0, REAL32)}, bytewise=False)
    _wait_touchdown(rig, timeout_s=200)
    log = rig.wait_log("recovery ended", timeout_s=60)
    assert [(f["reason"], f["action"]) for f in rig.sim.events("failsafe")] == [("battery_critical", "LAND")]
    assert "watcher alarm 'Failsafe: battery critical, LAND'" in log
    assert "autopilot failsafe: LAND; the autopilot keeps control" in log
    assert "GUIDED" not in _modes_after(rig, "LAND")
    events = _events(record)
    assert events[-1]["kind"] == "outcome"
    assert events[-1]["state"] == "landed"
    assert events[-1]["rounds"] == 0


def test_a_gps_loss_hands_the_vehicle_to_the_estimators_failsafe(
    start_rig: Callable[..., Rig], tmp_path: Path
) -> None:
    """ArduCopter's GPS switched off mid-descent (SITL's SIM_GPS1_ENABLE 0): its estimator dead-reckons,
    then has no position, and its EKF failsafe (FS_EKF_ACTION 1) lands where it is. The companion,
    whose position telemetry stops while heartbeats go on, leaves the vehicle to it and records why."""
    rig, record = _emulated(start_rig, tmp_path, "--scenario", "scenario2", "--autopilot", "ardupilot")
    _raise_alarm(rig, "GPS spoofing", "high")
    rig.wait_log("m, ", timeout_s=120)
    _set_params(rig, {"SIM_GPS1_ENABLE": (0, INT32)}, bytewise=False)
    _wait_touchdown(rig, timeout_s=200)
    log = rig.wait_log("recovery ended", timeout_s=60)
    assert [(f["reason"], f["action"]) for f in rig.sim.events("failsafe")] == [("position_lost", "LAND")]
    assert "autopilot failsafe: LAND; the autopilot keeps control" in log, log[-3000:]
    assert "(the autopilot's failsafe landed it (LAND))" in log
    assert "GUIDED" not in _modes_after(rig, "LAND")
    events = _events(record)
    texts = [e["text"] for e in events if e["kind"] == "autopilot_text"]
    assert any("position estimate lost" in t for t in texts), texts
    assert events[-1]["kind"] == "outcome"
    assert events[-1]["state"] == "landed"


# ------------------------------------------------------------------------------------- real firmware
def _gcs_frames(
    params: dict[str, tuple[float, int]],
    *,
    bytewise: bool,
    commands: Sequence[tuple[int, Sequence[float]]] = (),
    heartbeat: bool = False,
) -> list[bytes]:
    """PARAM_SET frames, then COMMAND_LONG ones (command, its first params), from a ground station
    (255/190) for the vehicle (1/1); first the ground station's HEARTBEAT with ``heartbeat`` (the
    autopilot then counts it as its ground link)."""
    from pymavlink.dialects.v20 import common as mavlink2

    mav = mavlink2.MAVLink(None, srcSystem=255, srcComponent=190)
    frames = []
    if heartbeat:
        gcs, invalid = mavlink2.MAV_TYPE_GCS, mavlink2.MAV_AUTOPILOT_INVALID
        frames.append(mav.heartbeat_encode(gcs, invalid, 0, 0, mavlink2.MAV_STATE_ACTIVE).pack(mav))
    for name, (value, kind) in params.items():
        wire = _wire(value, kind, bytewise=bytewise)
        frames.append(mav.param_set_encode(1, 1, name.encode(), wire, kind).pack(mav))
    for command, args in commands:
        p = [*args, *[0.0] * (7 - len(args))]
        frames.append(mav.command_long_encode(1, 1, command, 0, *p).pack(mav))
    return frames


FIRMWARE_ABORT = "Floating point exception - aborting"  # ArduCopter SITL's own words when it dies


def _real_firmware_failsafe(
    start_rig: Callable[..., Rig],
    tmp_path: Path,
    sim_args: list[str],
    params: dict[str, tuple[float, int]],
    *,
    bytewise: bool,
    commands: Sequence[tuple[int, Sequence[float]]] = (),
    env: dict[str, str] | None = None,
    until_touchdown: bool = True,
    heartbeat: bool = False,
) -> tuple[Rig, str, list[dict[str, Any]], float]:
    """An alarm on real firmware; at the first descent step a failsafe is set up from a ground station
    sharing the companion's link (real firmware has no other MAVLink port here); then the recovery
    ends and (``until_touchdown``) the vehicle is on the ground, disarmed. Returns the rig, the
    companion's log, the flight record's events and the touchdown's simulated time (nan without).

    The rig's firmware itself has aborted mid-flight once (ArduCopter SITL, its GPS switched off: a
    floating point exception in the firmware, simbridge exits with its output): that flight is flown
    once more, with a warning saying so; any other failure, or a second abort, fails the test."""

    def fly(where: Path) -> tuple[Rig, str, list[dict[str, Any]], float]:
        relays: list[Any] = []
        record = where / "record"
        try:
            rig = start_rig(
                [*sim_args, "--speed", "8"],
                ["--record", str(record)],
                env=env,
                mavlink_via=_via(relays, _clean_relay),
            )
            _wait_event(rig.sim, "ready", 240)
            rig.wait_log("sensor stream connected", timeout_s=60)
            out = rig.alarm_accepted("--reason", "GPS spoofing detected", "--criticality", "high")
            assert out.returncode == 0, out.stdout + out.stderr
            rig.wait_log("m, site clear", timeout_s=300)  # "descending 70 m, site clear: ...": the first step
            for _ in range(3):  # a datagram may be lost; setting a parameter twice does no harm
                for frame in _gcs_frames(params, bytewise=bytewise, commands=commands, heartbeat=heartbeat):
                    relays[0].inject(frame)
                time.sleep(0.2)
            touchdown = math.nan
            if until_touchdown:
                touchdown = float(_wait_event(rig.sim, "touchdown", 400)["t_s"])
            log = rig.wait_log("recovery ended", timeout_s=120)
            if until_touchdown:
                _wait_event(rig.sim, "disarmed", 60)
        finally:
            for r in relays:
                r.close()
        events = _events(record)
        assert events[-1]["kind"] == "outcome"
        return rig, log, events, touchdown

    try:
        return fly(tmp_path / "first")
    except AssertionError as exc:
        if FIRMWARE_ABORT not in str(exc):
            raise
        warnings.warn(f"the firmware aborted by itself ({FIRMWARE_ABORT}): flying again", stacklevel=2)
    return fly(tmp_path / "again")


def _real_firmware_failsafe_lands(
    start_rig: Callable[..., Rig],
    tmp_path: Path,
    sim_args: list[str],
    params: dict[str, tuple[float, int]],
    *,
    bytewise: bool,
    land_mode: str,
    heartbeat: bool = False,
) -> list[dict[str, Any]]:
    """:func:`_real_firmware_failsafe` where the firmware's own failsafe lands the vehicle in
    ``land_mode`` (a return's landing included): the companion stood down and never took the
    vehicle back while it flew."""
    rig, log, events, touchdown = _real_firmware_failsafe(
        start_rig, tmp_path, sim_args, params, bytewise=bytewise, heartbeat=heartbeat
    )
    assert f"autopilot failsafe: {land_mode}; the autopilot keeps control" in log, log[-3000:]
    assert f"(the autopilot's failsafe landed it ({land_mode}))" in log
    assert "re-engaging" not in log
    # never taken back while it flew (once its land detector has the vehicle down, real PX4 ends the
    # failsafe and goes back to the mode its user chose, before it disarms: after the touchdown)
    timed = [(e["t_s"], e["mode"]) for e in rig.sim.events("mode")]
    landing = next(t for t, m in timed if m == land_mode)
    assert [m for t, m in timed if landing <= t <= touchdown] == [land_mode], timed
    assert any(e["kind"] == "released" and e["to"] == land_mode for e in events)
    assert events[-1]["state"] == "landed"
    return events


@pytest.mark.sitl
def test_real_arducopters_battery_failsafe_lands_and_the_companion_stands_down(
    arducopter: Path, start_rig: Callable[..., Rig], tmp_path: Path
) -> None:
    """Real ArduCopter: mid-descent its critical battery level is set above the charge left with the
    land action (BATT_CRT_MAH, BATT_FS_CRT_ACT 1). ArduCopter's own battery failsafe switches to LAND;
    the companion waits its grace period, leaves the vehicle to it, and records the landing."""
    events = _real_firmware_failsafe_lands(
        start_rig,
        tmp_path,
        ["--autopilot", "ardupilot-sitl", "--sitl", str(arducopter), "--scenario", "scenario2"],
        {"BATT_FS_CRT_ACT": (1, INT32), "BATT_CRT_MAH": (100000.0, REAL32)},
        bytewise=False,
        land_mode="LAND",
    )
    texts = [e["text"] for e in events if e["kind"] == "autopilot_text"]
    assert any("Battery 1 is critical" in t for t in texts), texts


@pytest.mark.sitl
def test_real_arducopters_low_battery_warning_leaves_room_and_the_recovery_lands_on_its_site(
    arducopter: Path, start_rig: Callable[..., Rig], tmp_path: Path
) -> None:
    """Real ArduCopter: mid-descent its low-battery level is set above the charge left with no action
    (BATT_LOW_MAH, BATT_FS_LOW_ACT 0, its default): a warning only. The companion records ArduCopter's
    words, takes nothing from it, and lands on the site it chose."""
    rig, log, events, _ = _real_firmware_failsafe(
        start_rig,
        tmp_path,
        ["--autopilot", "ardupilot-sitl", "--sitl", str(arducopter), "--scenario", "scenario2"],
        {"BATT_FS_LOW_ACT": (0, INT32), "BATT_LOW_MAH": (100000.0, REAL32)},
        bytewise=False,
    )
    texts = [e["text"] for e in events if e["kind"] == "autopilot_text"]
    assert any("Battery 1 is low" in t for t in texts), texts
    assert "recovery ended: landed after" in log, log[-3000:]
    assert not [e for e in events if e["kind"] in ("takeover", "released", "autopilot_failsafe")], events
    assert events[-1]["reason"] == "landed"
    (touchdown,) = rig.sim.events("touchdown")
    assert touchdown["surface"] == "rooftop_clear", touchdown


@pytest.mark.sitl
def test_real_px4s_low_battery_warning_leaves_room_and_the_recovery_lands_on_its_site(
    px4: Path, start_rig: Callable[..., Rig], tmp_path: Path
) -> None:
    """Real PX4 1.15: mid-descent its low-battery threshold is raised above the charge its battery
    simulator reports with no action (BAT_LOW_THR, COM_LOW_BAT_ACT 0, its default): a warning only.
    The companion keeps the vehicle and lands on the site it chose."""
    rig, log, events, _ = _real_firmware_failsafe(
        start_rig,
        tmp_path,
        ["--autopilot", "px4-sitl", "--px4", str(px4), "--scenario", "scenario1"],
        {"COM_LOW_BAT_ACT": (0, INT32), "BAT_LOW_THR": (0.99, REAL32)},
        bytewise=True,
    )
    assert "recovery ended: landed after" in log, log[-3000:]
    assert not [e for e in events if e["kind"] in ("takeover", "released")], events
    assert events[-1]["reason"] == "landed"
    (touchdown,) = rig.sim.events("touchdown")
    assert touchdown["surface"] == "rooftop_clear", touchdown


@pytest.mark.sitl
def test_real_arducopters_ground_link_loss_returns_it_home_and_the_companion_stands_down(
    arducopter: Path, start_rig: Callable[..., Rig], tmp_path: Path
) -> None:
    """Real ArduCopter: mid-descent a ground station sharing the companion's link sets the ground-link
    failsafe to return (FS_GCS_ENABLE 1), beats its heart a few times and falls silent. After
    FS_GCS_TIMEOUT (5 s) ArduCopter's GCS failsafe takes the vehicle out of GUIDED into RTL (GUIDED is
    not among the modes FS_OPTIONS lets go on by default); the companion stops commanding, never takes
    the vehicle back while it returns and lands at home, and the record says why it ended."""
    events = _real_firmware_failsafe_lands(
        start_rig,
        tmp_path,
        ["--autopilot", "ardupilot-sitl", "--sitl", str(arducopter), "--scenario", "scenario2"],
        {"FS_GCS_ENABLE": (1, INT32)},
        bytewise=False,
        land_mode="RTL",
        heartbeat=True,
    )
    texts = [e["text"] for e in events if e["kind"] == "autopilot_text"]
    assert "GCS Failsafe" in texts, texts  # ArduCopter's own account of it


@pytest.mark.sitl
def test_real_px4s_battery_failsafe_lands_and_the_companion_stands_down(
    px4: Path, start_rig: Callable[..., Rig], tmp_path: Path
) -> None:
    """Real PX4 1.15: mid-descent the critical battery threshold is raised above the charge its battery
    simulator reports, with the land action (BAT_CRIT_THR, COM_LOW_BAT_ACT 2). PX4 holds in AUTO.LOITER
    for COM_BAT_ACT_T, then its failsafe switches to AUTO.LAND; the companion commands nothing in its
    grace period (a command in PX4's hold would cancel the action), leaves the vehicle to it, and records
    the landing."""
    events = _real_firmware_failsafe_lands(
        start_rig,
        tmp_path,
        ["--autopilot", "px4-sitl", "--px4", str(px4), "--scenario", "scenario1"],
        {"COM_LOW_BAT_ACT": (2, INT32), "BAT_LOW_THR": (0.99, REAL32), "BAT_CRIT_THR": (0.98, REAL32)},
        bytewise=True,
        land_mode="AUTO.LAND",
    )
    assert any(e["kind"] == "autopilot_failsafe" for e in events)


@pytest.mark.sitl
def test_real_px4s_ground_link_loss_returns_it_and_the_companion_stands_down(
    px4: Path, start_rig: Callable[..., Rig], tmp_path: Path
) -> None:
    """Real PX4 1.15: mid-descent a ground station sharing the companion's link sets the data-link-loss
    action to return (NAV_DLL_ACT 2; simbridge boots PX4 with 0), beats its heart a few times and
    falls silent. After COM_DL_LOSS_T (10 s) PX4's failsafe takes the vehicle out of OFFBOARD into
    AUTO.RTL; the companion stops commanding and never takes it back while it returns and lands."""
    events = _real_firmware_failsafe_lands(
        start_rig,
        tmp_path,
        ["--autopilot", "px4-sitl", "--px4", str(px4), "--scenario", "scenario1"],
        {"NAV_DLL_ACT": (2, INT32)},
        bytewise=True,
        land_mode="AUTO.RTL",
        heartbeat=True,
    )
    texts = [e["text"] for e in events if e["kind"] == "autopilot_text"]
    assert any(t.startswith("Failsafe activated") for t in texts), texts


@pytest.mark.sitl
def test_real_px4s_geofence_breach_lands_and_the_companion_stands_down(
    px4: Path, start_rig: Callable[..., Rig], tmp_path: Path
) -> None:
    """Real PX4 1.15: mid-descent its geofence gets a ceiling below the vehicle (GF_MAX_VER_DIST 10 m
    above home) with the land action (GF_ACTION 5). PX4's geofence failsafe takes the vehicle out of
    OFFBOARD into AUTO.LAND; the companion stops commanding, never takes it back, and the record says
    why the recovery ended."""
    _real_firmware_failsafe_lands(
        start_rig,
        tmp_path,
        ["--autopilot", "px4-sitl", "--px4", str(px4), "--scenario", "scenario1"],
        {"GF_ACTION": (5, INT32), "GF_MAX_VER_DIST": (10.0, REAL32)},
        bytewise=True,
        land_mode="AUTO.LAND",
    )


@pytest.mark.sitl
def test_real_arducopters_gps_loss_hands_the_vehicle_to_its_ekf_failsafe(
    arducopter: Path, start_rig: Callable[..., Rig], tmp_path: Path
) -> None:
    """Real ArduCopter: its GPS driver switched off mid-descent (GPS1_TYPE 0, which ArduCopter reads at
    every update: no GPS from then on). Its EKF failsafe lands the vehicle; the companion stands down
    and records it. (SITL's own switch, SIM_GPS1_ENABLE 0, made this firmware abort with a floating
    point exception in most CI flights.)"""
    events = _real_firmware_failsafe_lands(
        start_rig,
        tmp_path,
        ["--autopilot", "ardupilot-sitl", "--sitl", str(arducopter), "--scenario", "scenario2"],
        {"GPS1_TYPE": (0, INT8)},
        bytewise=False,
        land_mode="LAND",
    )
    texts = [e["text"] for e in events if e["kind"] == "autopilot_text"]
    assert "EKF Failsafe: changed to LAND Mode" in texts, texts


@pytest.mark.sitl
def test_real_px4s_gps_failure_leaves_it_to_px4_which_takes_no_landing_command(
    px4: Path, start_rig: Callable[..., Rig], tmp_path: Path
) -> None:
    """Real PX4 1.15: its GPS failed mid-descent by PX4's own failure injection (SYS_FAILURE_EN 1,
    MAV_CMD_INJECT_FAILURE: GPS off; its simulator_mavlink then drops simbridge's HIL_GPS). EKF2
    dead-reckons for EKF2_NOAID_TOUT, then OFFBOARD cannot run and PX4 falls back to ALTCTL (with no
    stick input here: in two flights one descended blind within 140 s simulated, the other drifted
    1.6 km and came down after 700 s). After its grace period the companion cannot have OFFBOARD back
    (refused without a position); it asks for PX4's land mode where the vehicle is, which PX4 refuses
    too, so it leaves the vehicle to PX4 and watches for a landing (``recovery.land_timeout_s``, 10 s
    here), then records why it ended."""
    rig, log, events, _ = _real_firmware_failsafe(
        start_rig,
        tmp_path,
        ["--autopilot", "px4-sitl", "--px4", str(px4), "--scenario", "scenario1"],
        {"SYS_FAILURE_EN": (1, INT32)},
        bytewise=True,
        commands=[(420, (4.0, 1.0))],  # MAV_CMD_INJECT_FAILURE: FAILURE_UNIT_SENSOR_GPS, FAILURE_TYPE_OFF
        env={"LANDFALL_RECOVERY_LAND_TIMEOUT_S": "10"},
        until_touchdown=False,
    )
    assert "autopilot failsafe: ALTCTL; waiting 6 s for it to clear" in log, log[-3000:]
    assert "asking it to land where it is" in log
    assert "land mode refused as well" in log
    assert "autopilot failsafe: ALTCTL; the autopilot keeps control" in log
    assert any(e["kind"] == "land_in_place" for e in events)
    assert any(e["kind"] == "released" and e["to"] == "ALTCTL" for e in events)
    assert "ALTCTL" in events[-1]["reason"]
    assert _modes_after(rig, "ALTCTL")[:2] != ["ALTCTL", "OFFBOARD"]  # never taken back in flight


@pytest.mark.sitl
def test_real_arducopters_fence_breach_reads_as_a_takeover_that_the_record_explains(
    arducopter: Path, start_rig: Callable[..., Rig], tmp_path: Path
) -> None:
    """Real ArduCopter: mid-descent its fence is enabled with a ceiling below the vehicle and the land
    action (FENCE_ALT_MAX 10, FENCE_ACTION 2, FENCE_ENABLE 1). Its fence switches to LAND without the
    critical status its other failsafes set, so to the companion it is someone else's mode: it stops
    commanding at once, and the record and the outcome carry what ArduCopter said ("Max Alt fence
    breached"); ArduCopter lands the vehicle."""
    rig, log, events, touchdown = _real_firmware_failsafe(
        start_rig,
        tmp_path,
        ["--autopilot", "ardupilot-sitl", "--sitl", str(arducopter), "--scenario", "scenario2"],
        {"FENCE_ALT_MAX": (10.0, REAL32), "FENCE_ACTION": (2, INT32), "FENCE_ENABLE": (1, INT32)},
        bytewise=False,
    )
    assert "mode changed to LAND by someone else: operator takeover" in log, log[-3000:]
    assert "Max Alt fence breached" in log
    takeover = next(e for e in events if e["kind"] == "takeover")
    assert "Max Alt fence breached" in takeover["autopilot_said"]
    assert events[-1]["state"] == "aborted"
    timed = [(e["t_s"], e["mode"]) for e in rig.sim.events("mode")]
    landing = next(t for t, m in timed if m == "LAND")
    assert [m for t, m in timed if landing <= t <= touchdown] == ["LAND"], timed
