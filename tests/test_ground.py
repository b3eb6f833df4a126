"""The MQTT ground feed against a real mosquitto broker: topics and payloads, the retained status and
its last will, the bounded queue while the broker is away, reconnection, and alarm intake."""

from __future__ import annotations

import asyncio
import base64
import json
import math
import os
import signal
import subprocess
import sys
import time
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

import aiomqtt
import cv2
import numpy as np
import pytest

from companion.alarms import Alarm, Criticality, ReasonCode
from companion.ground import (
    GroundFeed,
    GroundParams,
    alarm_from_mqtt,
    annotated_thumbnail,
    mode_name,
    telemetry_snapshot,
)
from companion.telemetry import VehicleState
from tests.conftest import Broker, free_tcp_port, free_udp_port


class Inbox:
    """Everything a ground station subscribed to ``landfall/<vehicle>/#`` received, by topic leaf."""

    def __init__(self, client: aiomqtt.Client, prefix: str) -> None:
        self.client = client
        self.prefix = prefix
        self.got: list[tuple[str, dict[str, Any], bool]] = []

    async def pump(self) -> None:
        async for m in self.client.messages:
            leaf = str(m.topic)[len(self.prefix) :]
            if leaf != "alarm/in":  # what we ourselves send the vehicle, malformed on purpose at times
                assert isinstance(m.payload, bytes)
                self.got.append((leaf, json.loads(m.payload), bool(m.retain)))

    def of(self, leaf: str) -> list[dict[str, Any]]:
        return [body for t, body, _ in self.got if t == leaf]

    async def wait(self, cond: Callable[[], bool], timeout_s: float = 10.0) -> None:
        await until(cond, timeout_s)


async def until(cond: Callable[[], bool], timeout_s: float) -> None:
    """Poll ``cond``: what it watches is another task's or process's doing, with no event to await."""
    deadline = time.monotonic() + timeout_s
    while not cond():
        if time.monotonic() > deadline:
            raise TimeoutError(f"condition not met within {timeout_s} s")
        await asyncio.sleep(0.02)


@asynccontextmanager
async def ground_station(port: int, vehicle: str = "t1") -> AsyncIterator[Inbox]:
    prefix = f"landfall/{vehicle}/"
    async with aiomqtt.Client("127.0.0.1", port) as client:
        await client.subscribe(prefix + "#", qos=1)
        inbox = Inbox(client, prefix)
        task = asyncio.create_task(inbox.pump())
        try:
            yield inbox
        finally:
            task.cancel()


def params(port: int, **kw: Any) -> GroundParams:
    return GroundParams(host="127.0.0.1", port=port, vehicle_id="t1", **kw)


def candidates() -> list[dict[str, Any]]:
    return [
        {"index": 0, "box": [100, 100, 300, 250], "fallback": False, "geometry": {"area_m2": 500.0}},
        {"index": 1, "box": [500, 200, 700, 400], "fallback": False, "geometry": {"area_m2": 300.0}},
    ]


async def test_a_round_reaches_the_ground_station(broker: Callable[..., Broker]) -> None:
    b = broker()
    feed = GroundFeed(params(b.port, telemetry_hz=10.0))
    async with ground_station(b.port) as inbox:
        task = asyncio.create_task(feed.run(lambda: {"pos_ned_m": [1.0, 2.0, -50.0]}))
        await inbox.wait(lambda: any(s["state"] == "online" for s in inbox.of("status")))
        frame = np.full((540, 960, 3), 90, np.uint8)
        feed.alarm(Alarm(ReasonCode.GPS_SPOOFING, Criticality.HIGH, "GPS spoofing", (255, 190), 0.0), 0)
        feed.record_event("state", {"state": "rank", "round": 1})
        feed.save_image("round01-acquire", frame)
        rank = {"round": 1, "order": [1, 0], "chosen": 1, "rationale": "site 1 is clear", "tier": "onboard",
                "latency_s": 0.01, "candidates": candidates()}  # fmt: skip
        feed.record_event("rank", rank)
        no_edge = {"edge_distance_m": math.inf, "roughness_m": 0.02}  # JSON has no inf: null
        feed.record_event("confirm", {"round": 1, "accept": True, "rationale": "clear", "check": no_edge})
        feed.record_event("outcome", {"state": "landed", "rounds": 1, "reason": "landed"})
        await inbox.wait(lambda: len(inbox.of("decision")) == 2 and len(inbox.of("telemetry")) >= 2)
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)
        await inbox.wait(lambda: inbox.of("status")[-1]["state"] == "offline")

    (alarm,) = inbox.of("alarm")
    assert alarm["reason"] == "GPS spoofing"
    assert (alarm["code"], alarm["criticality"], alarm["result"]) == ("gps_spoofing", "high", "accepted")
    assert [s.get("state") for s in inbox.of("state")] == ["rank", "landed"]
    rank, confirm = inbox.of("decision")
    assert rank["stage"] == "rank"
    assert rank["chosen"] == 1
    assert rank["rationale"] == "site 1 is clear"
    assert rank["frame_px"] == [960, 540]  # the boxes' pixels are of this frame
    jpeg = base64.b64decode(rank["thumbnail_jpeg_b64"])
    thumb = cv2.imdecode(np.frombuffer(jpeg, np.uint8), cv2.IMREAD_COLOR)
    assert thumb.shape == (180, 320, 3)
    # the chosen candidate (box 1, scaled by 1/3) is outlined in green, the other one is not
    _, g, r = (int(v) for v in thumb[200 // 3, (500 + 700) // 6])
    assert g > 150 > r
    _, g, r = (int(v) for v in thumb[100 // 3, 200 // 3])
    assert r > 150  # amber: the other candidate
    assert confirm["stage"] == "confirm"
    assert confirm["accept"] is True
    assert confirm["check"] == {"edge_distance_m": None, "roughness_m": 0.02}
    assert inbox.of("telemetry")[0]["pos_ned_m"] == [1.0, 2.0, -50.0]
    assert inbox.of("status")[0]["alarm_intake"] is False  # a ground station offers no alarm form
    assert feed.dropped == 0
    assert feed.published >= 6


async def test_without_a_broker_publishing_never_blocks_and_keeps_the_newest(
    broker: Callable[..., Broker],
) -> None:
    port = free_tcp_port()  # nobody listens here yet
    feed = GroundFeed(params(port, queue_size=50))
    task = asyncio.create_task(feed.run())
    for k in range(200):
        feed.publish("state", {"k": k})  # returns at once: a list append
    assert feed.dropped == 150
    await asyncio.sleep(1.5)  # a failed connection or two, with backoff
    assert not feed.connected
    b = broker(port)  # the broker comes up: the feed reconnects by itself and sends what it kept
    async with ground_station(b.port) as inbox:
        await inbox.wait(lambda: len(inbox.of("state")) == 50, timeout_s=20)
    task.cancel()
    await asyncio.gather(task, return_exceptions=True)
    assert [m["k"] for m in inbox.of("state")] == list(range(150, 200))  # the newest, in order


async def test_a_broker_restart_is_survived(broker: Callable[..., Broker]) -> None:
    b = broker()
    feed = GroundFeed(params(b.port))
    task = asyncio.create_task(feed.run())
    await until(lambda: feed.connected, 10)
    b.stop()
    feed.publish("state", {"after": "restart"})
    b2 = broker(b.port)
    async with ground_station(b2.port) as inbox:
        await inbox.wait(lambda: bool(inbox.of("state")), timeout_s=40)
    task.cancel()
    await asyncio.gather(task, return_exceptions=True)
    assert inbox.of("state") == [{"after": "restart"}]


async def test_alarm_intake_takes_good_alarms_and_answers_bad_ones(broker: Callable[..., Broker]) -> None:
    b = broker()
    taken: list[Alarm] = []

    def on_alarm(alarm: Alarm) -> int:
        taken.append(alarm)
        return 0

    feed = GroundFeed(params(b.port, alarm_intake=True))
    async with ground_station(b.port) as inbox:
        task = asyncio.create_task(feed.run(None, on_alarm))
        await inbox.wait(lambda: bool(inbox.of("status")))
        await asyncio.sleep(0.2)  # the feed subscribes right after saying online
        await inbox.client.publish(
            "landfall/t1/alarm/in", b'{"reason": "storm cell", "criticality": "critical"}'
        )
        await inbox.client.publish("landfall/t1/alarm/in", b"{not json")
        await inbox.client.publish("landfall/t1/alarm/in", b'{"reason": "x", "criticality": "apocalyptic"}')
        await inbox.wait(lambda: len(inbox.of("alarm/result")) == 3)
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)
    (alarm,) = taken
    assert (alarm.reason, alarm.criticality) == ("storm cell", Criticality.CRITICAL)
    results = inbox.of("alarm/result")
    assert results[0]["result"] == "accepted"
    assert [r["result"] for r in results[1:]] == ["malformed", "malformed"]
    assert "not JSON" in results[1]["error"]
    assert "criticality must be one of low, high, critical" in results[2]["error"]


def test_telemetry_names_the_mode_and_the_autopilot_link_age() -> None:
    state = VehicleState(autopilot=12, custom_mode=6 << 16, stamps={"heartbeat": time.monotonic() - 2.0})
    snap = telemetry_snapshot(state)
    assert snap["mode"] == "OFFBOARD"
    assert 1.9 <= snap["link_age_s"] <= 3.0
    assert telemetry_snapshot(VehicleState())["link_age_s"] is None  # never heard
    assert mode_name(3, 0, 9) == "LAND"  # ArduCopter
    assert mode_name(3, 0, 999) is None
    assert mode_name(0, 0, 0) is None  # before the first heartbeat


def test_alarm_payload_validation() -> None:
    good = alarm_from_mqtt(b'{"reason": " low battery ", "code": 3}')
    assert (good.reason, good.code, good.criticality) == (
        "low battery",
        ReasonCode.LOW_BATTERY,
        Criticality.HIGH,
    )
    assert alarm_from_mqtt(b'{"reason": "odd", "code": 99}').code == ReasonCode.OTHER
    for payload, problem in [
        (b"[1]", "must be a JSON object"),
        (b'{"reason": ""}', "reason must be text"),
        (b'{"reason": "' + b"x" * 51 + b'"}', "reason must be text"),
        (b'{"reason": "a", "code": "3"}', "code must be an integer"),
        (b"\xff\xfe", "not JSON"),
    ]:
        with pytest.raises(ValueError, match=problem):
            alarm_from_mqtt(payload)


def test_thumbnail_marks_the_chosen_candidate() -> None:
    frame = np.zeros((540, 960, 3), np.uint8)
    jpeg = annotated_thumbnail(frame, [[240, 135, 720, 405]], 0, 160)  # (40, 22)-(120, 68) scaled
    img = cv2.imdecode(np.frombuffer(jpeg, np.uint8), cv2.IMREAD_COLOR)
    assert img.shape == (90, 160, 3)
    assert img[45, 80].max() < 30  # inside the box: the frame, untouched
    assert img[45, 40][1] > 150  # its left edge: green


@pytest.mark.slow
async def test_a_killed_companion_is_announced_offline_by_its_last_will(
    broker: Callable[..., Broker], tmp_path: Path
) -> None:
    b = broker()
    env = {**os.environ, "LANDFALL_MQTT_ENABLED": "true", "LANDFALL_MQTT_PORT": str(b.port),
           "LANDFALL_MQTT_VEHICLE_ID": "t1", "LANDFALL_MQTT_KEEPALIVE_S": "5"}  # fmt: skip
    cmd = [sys.executable, "-m", "companion", "--mavlink", f"udp:{free_udp_port()}",
           "--sensors", f"127.0.0.1:{free_tcp_port()}"]  # fmt: skip
    log = tmp_path / "companion.log"
    async with ground_station(b.port) as inbox:
        with log.open("wb") as fh:
            proc = subprocess.Popen(cmd, env=env, stdout=fh, stderr=subprocess.STDOUT)  # noqa: ASYNC220
        try:
            await inbox.wait(lambda: any(s["state"] == "online" for s in inbox.of("status")), 60)
            await inbox.wait(lambda: len(inbox.of("telemetry")) >= 1, 10)
            t_kill = time.time()
            proc.send_signal(signal.SIGKILL)  # no goodbye: the broker speaks for it
            await inbox.wait(lambda: inbox.of("status")[-1]["state"] == "offline", 30)
        finally:
            proc.kill()
            proc.wait()
    offline = inbox.of("status")[-1]
    assert offline["t"] < t_kill  # the will was written at connection time, not by a live companion
    # a station that subscribes later still learns it: the will is retained
    async with ground_station(b.port) as late:
        await late.wait(lambda: bool(late.of("status")))
    assert late.of("status")[-1]["state"] == "offline"
    assert "MQTT connected" in log.read_text()


@pytest.mark.slow
async def test_a_landing_is_told_to_the_ground_station(
    broker: Callable[..., Broker], start_rig: Callable[..., Any], tmp_path: Path
) -> None:
    """simbridge + companion with the feed on: the ground station sees the alarm, the decision with
    its thumbnail, telemetry, the states and the landed outcome."""
    b = broker()
    env = {
        "LANDFALL_MQTT_ENABLED": "true",
        "LANDFALL_MQTT_PORT": str(b.port),
        "LANDFALL_MQTT_VEHICLE_ID": "t1",
    }
    async with ground_station(b.port) as inbox:
        rig = start_rig(["--scenario", "scenario1", "--speed", "4"], env=env)
        await until(lambda: "sensor stream connected" in rig.log_text(), 60)
        out = await asyncio.to_thread(rig.alarm_accepted, "--reason", "GPS spoofing", "--criticality", "high")
        assert out.returncode == 0, out.stdout + out.stderr
        await until(lambda: any(s.get("kind") == "outcome" for s in inbox.of("state")), 200)
    alarms = inbox.of("alarm")
    assert alarms[-1]["result"] == "accepted"
    assert alarms[-1]["reason"] == "GPS spoofing"
    rank = next(d for d in inbox.of("decision") if d["stage"] == "rank")
    assert rank["tier"] == "onboard"
    assert rank["chosen"] == rank["order"][0]
    thumb = cv2.imdecode(np.frombuffer(base64.b64decode(rank["thumbnail_jpeg_b64"]), np.uint8), 1)
    assert thumb.shape == (180, 320, 3)
    assert any(d["stage"] == "confirm" and d["accept"] for d in inbox.of("decision"))
    states = [s["state"] for s in inbox.of("state")]
    assert states[-1] == "landed"
    assert {"rank", "move", "confirm", "land"} <= set(states)
    telemetry = inbox.of("telemetry")
    assert len(telemetry) >= 5
    heights = [t["agl_m"] for t in telemetry if t["agl_m"] is not None]
    assert max(heights) > 50  # from the launch height ...
    assert min(heights) < 5  # ... down to the roof (1 Hz: the last sample may precede touchdown)
