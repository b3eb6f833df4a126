"""The daemon's own alarm sources (battery, failsafe STATUSTEXT, GPS) and its rangefinder reading, fed
real MAVLink frames through the companion's receive path."""

from __future__ import annotations

import logging
import math

import pytest

from companion.daemon import Companion
from tests.autopilot_frames import AUTOPILOT, feed, on_fake_link


def _flying() -> Companion:
    c = on_fake_link(sensors=None, watch_battery_pct=None)
    feed(
        c,
        AUTOPILOT.heartbeat_encode(2, 12, 128 | 29, 6 << 16 | 4 << 24, 4),  # PX4, armed
        AUTOPILOT.extended_sys_state_encode(0, 2),  # in the air
    )
    return c


def test_a_failsafe_text_after_fifty_others_still_raises_an_alarm(caplog: pytest.LogCaptureFixture) -> None:
    """The autopilot's texts are kept 50 deep; the watcher used to index into that list and went deaf
    once it was full (found in review). Now it counts every text received."""
    c = _flying()
    caplog.set_level(logging.INFO)
    for k in range(120):
        feed(c, AUTOPILOT.statustext_encode(6, f"Mode change {k}".encode()))
        if k % 7 == 0:
            c.watch_once()
    c.watch_once()
    assert "watcher alarm" not in caplog.text
    raised: list[str] = []
    c.raise_alarm = lambda alarm: raised.append(alarm.reason) or 0  # type: ignore[method-assign]
    feed(c, AUTOPILOT.statustext_encode(2, b"Failsafe: offboard lost, AUTO.LOITER"))
    c.watch_once()
    assert "watcher alarm 'Failsafe: offboard lost, AUTO.LOITER'" in caplog.text
    c.watch_once()  # seen once, raised once
    assert raised == ["Failsafe: offboard lost, AUTO.LOITER"]


def test_arducopters_precision_landing_failsafe_text_raises_no_alarm() -> None:
    """ "PrecLand: Failsafe Measures" is ArduCopter's precision landing landing without a target, not
    the vehicle's failsafe: an alarm from it took a fence failsafe's landing back from the autopilot."""
    c = _flying()
    raised: list[str] = []
    c.raise_alarm = lambda alarm: raised.append(alarm.reason) or 0  # type: ignore[method-assign]
    feed(c, AUTOPILOT.statustext_encode(6, b"PrecLand: Failsafe Measures"))
    c.watch_once()
    assert raised == []
    feed(c, AUTOPILOT.statustext_encode(2, b"Failsafe: battery critical, LAND"))
    c.watch_once()
    assert raised == ["Failsafe: battery critical, LAND"]


def test_a_watcher_alarm_refused_for_now_is_asked_again_until_taken(monkeypatch: pytest.MonkeyPatch) -> None:
    """A failsafe's STATUSTEXT comes once: an alarm raised from it while the companion cannot take one
    yet (no fresh telemetry, no frame: TEMPORARILY_REJECTED) is asked again at each look, for
    ``OWN_ALARM_RETRY_S``, until taken (found in CI: the first telemetry after the companion's stream
    request came a moment after ArduCopter's battery failsafe had said so)."""
    import companion.daemon as daemon

    c = _flying()
    answers = [1, 1, 0]  # refused for now twice, then taken
    raised: list[str] = []
    c.raise_alarm = lambda alarm: raised.append(alarm.reason) or answers.pop(0)  # type: ignore[method-assign]
    feed(c, AUTOPILOT.statustext_encode(2, b"Failsafe: battery critical, LAND"))
    for _ in range(5):
        c.watch_once()
    assert raised == ["Failsafe: battery critical, LAND"] * 3

    c = _flying()
    clock = [1000.0]
    monkeypatch.setattr(daemon.time, "monotonic", lambda: clock[0])
    raised = []
    c.raise_alarm = lambda alarm: raised.append(alarm.reason) or 1  # type: ignore[method-assign]
    feed(c, AUTOPILOT.statustext_encode(2, b"Failsafe: battery critical, LAND"))
    c.watch_once()
    clock[0] += daemon.OWN_ALARM_RETRY_S / 2
    c.watch_once()
    clock[0] += daemon.OWN_ALARM_RETRY_S
    c.watch_once()  # too late: given up
    c.watch_once()
    assert len(raised) == 2


def test_texts_that_came_on_the_ground_are_passed_over(caplog: pytest.LogCaptureFixture) -> None:
    c = _flying()
    caplog.set_level(logging.INFO)
    feed(c, AUTOPILOT.extended_sys_state_encode(0, 1))  # landed
    feed(c, AUTOPILOT.statustext_encode(2, b"Failsafe: battery low"))
    c.watch_once()
    feed(c, AUTOPILOT.extended_sys_state_encode(0, 2))  # airborne again
    c.watch_once()
    assert "watcher alarm" not in caplog.text


def test_a_rangefinder_at_its_maximum_is_no_reading() -> None:
    """ArduCopter reports a rangefinder that sees nothing as its maximum (a 40 m sensor 100 m up says
    4000 cm): taken for the ground, it made the companion climb away from a LiDAR that was out of
    range (found flying real SITL). Beyond its range is no reading; in range is the distance."""
    c = _flying()
    down = 25  # MAV_SENSOR_ROTATION_PITCH_270

    def reading(cm: int) -> float:
        feed(c, AUTOPILOT.distance_sensor_encode(1000, 20, 4000, cm, 0, 0, down, 0))
        return c.tm.state.rangefinder_m

    assert reading(2091) == 20.91
    assert math.isnan(reading(4000))
    assert math.isnan(reading(4001))
    assert reading(15) == 0.15  # too close still says the ground is right there
    feed(c, AUTOPILOT.distance_sensor_encode(1000, 20, 0, 3000, 0, 0, down, 0))  # no maximum given
    assert c.tm.state.rangefinder_m == 30.0
