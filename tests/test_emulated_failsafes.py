"""The emulated autopilots' own failsafes, stepped without processes: the battery failsafe
of each flavour and the estimator without GPS. The same behaviour flown end to end, on the emulation
and on real ArduCopter and PX4: tests/test_autopilot_failsafes.py."""

from __future__ import annotations

from typing import Any

import pytest

from simbridge.autopilot.core import Autopilot
from simbridge.autopilot.flavours import (
    MAV_RESULT_ACCEPTED,
    MAV_RESULT_DENIED,
    MAV_RESULT_FAILED,
    MAV_RESULT_TEMPORARILY_REJECTED,
    flavour_named,
)
from simbridge.battery import BatteryConfig
from simbridge.geo import GeoOrigin
from simbridge.terrain import FlatTerrain
from simbridge.vehicle import Vehicle

STEPS_S = round(1 / Vehicle.DT_S)


class _Log:
    def __init__(self) -> None:
        self.events: list[tuple[str, dict[str, Any]]] = []
        self.texts: list[str] = []

    def failsafes(self) -> list[tuple[Any, Any]]:
        return [(f["reason"], f["action"]) for e, f in self.events if e == "failsafe"]


def _rig(flavour: str, charge: float = 1.0) -> tuple[Autopilot, Vehicle, _Log]:
    log = _Log()
    v = Vehicle(GeoOrigin(), FlatTerrain(), battery=BatteryConfig(initial_fraction=charge))
    ap = Autopilot(
        flavour_named(flavour), v, (0.0, 0.0, 0.0),
        lambda e, f: log.events.append((e, f)), lambda _sev, text: log.texts.append(text),
    )  # fmt: skip
    v.reset((0.0, 0.0, -40.0), 0.0)
    ap.spawn_in_air(v.state)
    return ap, v, log


def _fly(ap: Autopilot, v: Vehicle, seconds: float) -> None:
    for _ in range(round(seconds * STEPS_S)):
        v.step(ap.tick(v.state), ap.armed)


def test_px4_holds_then_lands_at_a_critical_battery_and_a_command_in_the_hold_cancels_it() -> None:
    ap, v, log = _rig("px4", charge=0.4)
    ap.set_param("COM_LOW_BAT_ACT", 2)
    ap.set_param("BAT_CRIT_THR", 0.45)
    _fly(ap, v, 1.0)
    assert ap.mode.name == "AUTO.LOITER"
    assert ap.failsafe
    assert "Critical battery level, landing advised" in log.texts
    _fly(ap, v, 5.0)  # COM_BAT_ACT_T
    assert ap.mode.name == "AUTO.LAND"
    assert log.failsafes() == [("battery_critical", "AUTO.LOITER"), ("battery_critical", "AUTO.LAND")]

    ap, v, log = _rig("px4", charge=0.4)
    ap.set_param("COM_LOW_BAT_ACT", 2)
    ap.set_param("BAT_CRIT_THR", 0.45)
    _fly(ap, v, 1.0)
    assert ap.set_mode(ap.flavour.mode("POSCTL")).result == MAV_RESULT_ACCEPTED  # a user takes over
    _fly(ap, v, 8.0)
    assert ap.mode.name == "POSCTL"
    assert not ap.failsafe


def test_px4_acts_only_on_a_battery_level_worse_than_at_arming() -> None:
    ap, v, log = _rig("px4", charge=0.06)  # critical already when armed (spawned in the air)
    ap.set_param("COM_LOW_BAT_ACT", 2)
    _fly(ap, v, 8.0)
    assert log.failsafes() == []
    assert ap.mode.name == "AUTO.LOITER"
    assert not ap.failsafe


def test_a_battery_warning_without_an_action_only_says_so() -> None:
    ap, v, log = _rig("px4", charge=0.14)  # PX4's default COM_LOW_BAT_ACT 0: warnings only
    ap.set_param("BAT_LOW_THR", 0.15)
    _fly(ap, v, 0.5)
    ap.set_param("BAT_CRIT_THR", 0.2)
    _fly(ap, v, 6.0)
    assert log.failsafes() == []
    assert [f["level"] for e, f in log.events if e == "battery_warning"] == ["critical"]


def test_arducopter_returns_at_a_critical_battery_but_never_turns_a_landing_into_a_return() -> None:
    ap, v, log = _rig("ardupilot", charge=0.3)
    ap.set_param("BATT_FS_CRT_ACT", 2)
    ap.set_param("BATT_CRT_MAH", 4000)  # 1,500 mAh left
    _fly(ap, v, 0.5)
    assert ap.mode.name == "RTL"
    assert ap.failsafe
    assert any(t.startswith("Battery 1 is critical") for t in log.texts)

    ap, v, log = _rig("ardupilot", charge=0.3)
    assert ap.land().result == MAV_RESULT_ACCEPTED
    ap.set_param("BATT_FS_CRT_ACT", 2)
    ap.set_param("BATT_CRT_MAH", 4000)
    _fly(ap, v, 0.5)
    assert ap.mode.name == "LAND"
    assert log.failsafes() == []


@pytest.mark.parametrize("switch", ["SIM_GPS1_ENABLE", "GPS1_TYPE"])
def test_arducopter_without_gps_loses_its_position_and_its_ekf_failsafe_lands(switch: str) -> None:
    ap, v, log = _rig("ardupilot")
    assert ap.set_mode(ap.flavour.mode("GUIDED")).result == MAV_RESULT_ACCEPTED
    ap.set_param(switch, 0)
    _fly(ap, v, 1.0)
    assert ap.position_valid  # dead reckoning, for a while
    _fly(ap, v, 1.5)
    assert not ap.position_valid
    assert ap.mode.name == "LAND"
    assert ap.failsafe
    assert log.failsafes() == [("position_lost", "LAND")]
    assert ap.set_mode(ap.flavour.mode("GUIDED")).result == MAV_RESULT_FAILED  # needs a position
    _fly(ap, v, 60.0)
    assert ap.landed


def test_px4_without_gps_falls_back_to_altitude_control_and_refuses_offboard_and_land() -> None:
    ap, v, _log = _rig("px4")
    assert ap.inject_failure(4, 1).result == MAV_RESULT_DENIED  # SYS_FAILURE_EN 0
    ap.set_param("SYS_FAILURE_EN", 1)
    assert ap.inject_failure(4, 1).result == MAV_RESULT_ACCEPTED
    _fly(ap, v, 5.5)  # EKF2_NOAID_TOUT
    assert not ap.position_valid
    assert ap.mode.name == "ALTCTL"
    assert ap.failsafe
    for name in ("OFFBOARD", "AUTO.LAND", "AUTO.LOITER"):
        assert ap.set_mode(ap.flavour.mode(name)).result == MAV_RESULT_TEMPORARILY_REJECTED, name
    height = v.state.height_agl_m
    _fly(ap, v, 10.0)
    assert abs(v.state.height_agl_m - height) < 1.0  # holding its altitude
    assert ap.inject_failure(4, 0).result == MAV_RESULT_ACCEPTED  # the GPS back
    _fly(ap, v, 0.1)
    assert ap.position_valid
    assert ap.mode.name == "AUTO.LOITER"
    assert not ap.failsafe


def test_arducopter_lands_on_breaching_its_enabled_fence_and_reports_a_breach_once() -> None:
    ap, v, log = _rig("ardupilot")  # 40 m up
    ap.set_param("FENCE_ALT_MAX", 30)
    _fly(ap, v, 1.0)
    assert log.failsafes() == []  # FENCE_ENABLE 0: ArduCopter's default
    ap.set_param("FENCE_ACTION", 2)  # always land
    ap.set_param("FENCE_ENABLE", 1)
    _fly(ap, v, 1.0)
    assert ap.mode.name == "LAND"
    assert not ap.failsafe  # ArduCopter's heartbeat does not say critical for its fence
    assert log.failsafes() == [("geofence", "LAND")]
    assert "Max Alt fence breached" in log.texts
    assert [f["what"] for e, f in log.events if e == "fence_breach"] == ["altitude"]
    _fly(ap, v, 5.0)
    assert [e for e, _ in log.events].count("fence_breach") == 1
