"""The operator's controls (companion/operator.py): the RC inhibit switch keeps every alarm from starting
a recovery and each change of it is announced; cancel stops a running recovery, releases the vehicle
into the configured mode and says so, and is refused when nothing runs or the sender may not; and in
flight (simbridge's PX4 emulation) ``trigger_alarm.py --cancel`` leaves the vehicle holding where it was."""

from __future__ import annotations

import asyncio
import json
import time
from collections.abc import Callable
from pathlib import Path

import pytest
from pymavlink.dialects.v20 import common as mavlink2

from companion.alarms import Alarm, Criticality, ReasonCode
from companion.daemon import Companion
from companion.flavour import Mode
from companion.operator import RC_STALE_S, InhibitSwitch, cancel_mode
from tests.conftest import Rig
from tests.fake_link import FakeLink

RESULT_ACCEPTED, RESULT_DENIED = 0, 2
AUTOPILOT = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)


def _rc(channel: int, pwm: int) -> bytes:
    chans = [1500] * 18
    chans[channel - 1] = pwm
    return AUTOPILOT.rc_channels_encode(0, 18, *chans, 255).pack(AUTOPILOT)


def _heartbeat() -> bytes:
    return AUTOPILOT.heartbeat_encode(2, 12, 128 | 1, 6 << 16, 4).pack(AUTOPILOT)


def _text(msg: object) -> str:
    text = getattr(msg, "text", b"")
    return (text.decode() if isinstance(text, bytes) else str(text)).rstrip("\0")


def _alarm() -> Alarm:
    return Alarm.from_command(float(ReasonCode.OTHER), float(Criticality.HIGH), "test", (255, 190))


def test_the_switch_inhibits_within_its_band_only_while_rc_is_fresh_and_the_channel_used() -> None:
    switch = InhibitSwitch(7, (1800, 2200))
    chans = tuple([1500] * 6 + [1900] + [1500] * 11)
    assert switch.inhibits(chans, 0.1)
    assert not switch.inhibits(chans, RC_STALE_S + 0.1)  # RC lost: Landfall stays available
    assert not switch.inhibits(chans, float("inf"))  # never heard
    assert not switch.inhibits(tuple([1500] * 18), 0.1)
    assert not switch.inhibits(tuple([0] * 18), 0.1)  # a channel the receiver does not fill
    assert not switch.inhibits(tuple([65535] * 18), 0.1)
    assert not switch.inhibits((1900,) * 6, 0.1)  # fewer channels than the switch's
    with pytest.raises(ValueError, match=r"1\.\.18"):
        InhibitSwitch(19)
    with pytest.raises(ValueError, match="800 <= low <= high <= 2200"):
        InhibitSwitch(7, (2000, 1900))
    assert cancel_mode("rtl") is Mode.RTL
    with pytest.raises(ValueError, match="hold, land, rtl"):
        cancel_mode("orbit")
    with pytest.raises(ValueError, match="cancel mode"):
        Companion(link=FakeLink(), cancel_to="orbit")


def test_an_inhibited_companion_refuses_every_alarm_and_announces_each_change_of_the_switch() -> None:
    async def scenario() -> None:
        link = FakeLink()
        c = Companion(link=link, inhibit=InhibitSwitch(7, (1800, 2200)), watch_battery_pct=None)
        link.receive(_heartbeat())
        link.receive(_rc(7, 1950))
        c.watch_once()
        assert c.inhibited()
        assert c.raise_alarm(_alarm()) == RESULT_DENIED
        assert (c.alarms_inhibited, c.alarms_refused) == (1, 1)
        link.receive(_rc(7, 1100))
        c.watch_once()
        assert not c.inhibited()
        # no longer the switch: this alarm is refused for want of telemetry, and not counted inhibited
        assert c.raise_alarm(_alarm()) != RESULT_DENIED
        assert c.alarms_inhibited == 1
        said = [_text(m) for m in link.sent_of("STATUSTEXT")]
        assert said == ["Landfall inhibited (RC channel 7)", "Landfall enabled (RC channel 7)"]

    asyncio.run(scenario())


def test_cancel_stops_the_recovery_releases_the_vehicle_into_the_mode_and_says_so(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    async def scenario() -> None:
        link = FakeLink()
        c = Companion(link=link, cancel_to="land", accept_from=(255,))
        modes: list[Mode] = []

        async def set_mode(mode: Mode) -> None:  # the autopilot's side: takes the mode at once
            modes.append(mode)

        monkeypatch.setattr(c.ctl, "set_mode", set_mode)
        assert c.cancel((255, 190)) == RESULT_DENIED  # nothing to cancel
        running = asyncio.get_running_loop().create_task(asyncio.sleep(3600), name="recovery")
        c._recovery_task = running  # type: ignore[assignment]  # a recovery in flight, at the daemon's seam
        assert c.cancel((42, 190)) == RESULT_DENIED  # a system that may not raise alarms
        assert c.cancel((255, 190)) == RESULT_ACCEPTED
        assert c.operator.cancelling is not None
        await asyncio.wait_for(c.operator.cancelling, 5.0)
        assert running.cancelled()
        assert modes == [Mode.LAND]
        said = [_text(m) for m in link.sent_of("STATUSTEXT")]
        assert said == ["Landfall cancelled: LAND"]

    asyncio.run(scenario())


@pytest.mark.slow
def test_trigger_alarm_cancel_leaves_the_emulated_px4_holding_mid_recovery(
    start_rig: Callable[..., Rig], tmp_path: Path
) -> None:
    """In flight: an alarm, then ``trigger_alarm.py --cancel`` while the recovery runs; simbridge's PX4
    goes to AUTO.LOITER and never touches down, and the flight record says who cancelled."""
    record = tmp_path / "record"
    rig = start_rig(
        ["--autopilot", "px4", "--scenario", "scenario1", "--speed", "4"], ["--record", str(record)]
    )
    rig.wait_log("sensor stream connected", timeout_s=60)
    assert rig.alarm_accepted("--reason", "test", "--criticality", "high").returncode == 0
    rig.wait_log("site 0", timeout_s=60)  # the recovery is choosing and flying to a site
    out = rig.alarm("--cancel")
    assert out.returncode == 0, out.stdout + out.stderr
    assert "accepted: recovery cancelled" in out.stdout
    rig.wait_log("recovery cancelled by system 255: vehicle in HOLD", timeout_s=30)
    deadline = time.monotonic() + 10.0
    while time.monotonic() < deadline and not any(
        e.get("mode") == "AUTO.LOITER" for e in rig.sim.events("mode")
    ):
        time.sleep(0.2)  # simbridge's episode log, written by another process
    assert any(e.get("mode") == "AUTO.LOITER" for e in rig.sim.events("mode")), rig.sim.events("mode")
    time.sleep(3.0)
    assert not rig.sim.events("touchdown")
    again = rig.alarm("--cancel")
    assert again.returncode == 1  # nothing left to cancel
    events = [json.loads(x) for p in record.glob("*/events.jsonl") for x in p.read_text().splitlines()]
    (cancelled,) = [e for e in events if e.get("kind") == "cancelled"]
    assert cancelled["by"][0] == 255
    assert cancelled["mode"] == "hold"
