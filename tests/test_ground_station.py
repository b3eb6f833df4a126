"""landfall-ground without a browser: payload checks, the station's bounded histories, replay of a flight
record written by the companion's own FlightRecord, the live feed against a real mosquitto (malformed
payloads, several vehicles, the broker going away and coming back), the HTTP side through a real
uvicorn, and the command line's errors."""

from __future__ import annotations

import asyncio
import base64
import contextlib
import json
import re
import subprocess
import sys
from collections.abc import AsyncIterator, Callable
from pathlib import Path
from typing import Any

import aiomqtt
import cv2
import httpx
import numpy as np
import pytest
import uvicorn

from companion.ground import annotated_thumbnail
from companion.record import FlightRecord
from landfall_ground.live import BrokerParams, LiveFeed
from landfall_ground.messages import MalformedPayload, parse
from landfall_ground.replay import NotARecord, Replay, load_record
from landfall_ground.server import create_app
from landfall_ground.station import TELEMETRY_KEPT, Station
from tests.conftest import Broker, free_tcp_port
from tests.test_ground import until

JPEG = base64.b64encode(
    annotated_thumbnail(np.zeros((54, 96, 3), np.uint8), [[1, 1, 50, 40]], 0, 32)
).decode()


def rank(**kw: Any) -> dict[str, Any]:
    body = {"stage": "rank", "round": 1, "chosen": 0, "rationale": "the gravel roof is clear",
            "tier": "onboard", "latency_s": 0.02, "candidates": [{"box": [1, 1, 50, 40]}],
            "thumbnail_jpeg_b64": JPEG}  # fmt: skip
    return {**body, **kw}


# ------------------------------------------------------------------ payload checks
def test_parse_accepts_the_feed_and_ignores_other_topics() -> None:
    msg = parse("landfall/d1/decision", json.dumps(rank(t=5.0)), "landfall", now=9.0)
    assert msg is not None
    assert (msg.vehicle, msg.leaf, msg.t) == ("d1", "decision", 5.0)
    assert msg.body["rationale"] == "the gravel roof is clear"
    telemetry = parse(
        "landfall/d1/telemetry", b'{"pos_ned_m": [1, 2, null], "mode": "OFFBOARD"}', "landfall", 9.0
    )
    assert telemetry is not None
    assert telemetry.t == 9.0  # no t of its own: when it arrived
    assert parse("landfall/d1/alarm/in", b"{}", "landfall", 0.0) is None  # alarms on their way to it
    assert parse("elsewhere/d1/status", b"garbage", "landfall", 0.0) is None
    assert parse("landfall/d1/status/extra", b"garbage", "landfall", 0.0) is None


@pytest.mark.parametrize(
    ("leaf", "payload", "problem"),
    [
        ("status", b"{not json", "not JSON"),
        ("status", b"\xff\xfe", "not JSON"),
        ("status", b"[1, 2]", "expected a JSON object, got list"),
        ("status", b"[" * 100_000 + b"]" * 100_000, "nested too deep"),
        ("status", b'{"state": "sleepy"}', 'state must be "online" or "offline"'),
        ("telemetry", b'{"agl_m": NaN}', "NaN is not JSON"),
        ("telemetry", b'{"agl_m": "high"}', "agl_m must be a number"),
        ("telemetry", b'{"pos_ned_m": [1, 2]}', "pos_ned_m must be [north, east, down]"),
        ("telemetry", b'{"battery_pct": true}', "battery_pct must be a number"),
        ("decision", json.dumps(rank(candidates=[{"box": [1, 2, 3]}])).encode(), "candidates must be"),
        ("decision", json.dumps(rank(thumbnail_jpeg_b64="not base64!")).encode(), "is not base64"),
        ("decision", json.dumps(rank(thumbnail_jpeg_b64="aGVsbG8=")).encode(), "is not a JPEG"),
        ("decision", json.dumps(rank(stage="guess")).encode(), 'stage must be "rank" or "confirm"'),
        ("decision", json.dumps(rank(frame_px=[0, 540])).encode(), "frame_px must be [width, height]"),
        ("state", b'{"round": 1}', "state must be text"),
        ("alarm/result", b'{"reason": "x"}', "result must be text"),
    ],
)
def test_parse_names_what_is_wrong(leaf: str, payload: bytes, problem: str) -> None:
    with pytest.raises(MalformedPayload, match=problem.replace("[", r"\[").replace("(", r"\(")) as caught:
        parse(f"landfall/d1/{leaf}", payload, "landfall", 0.0)
    assert caught.value.topic == f"landfall/d1/{leaf}"


def test_station_counts_malformed_keeps_the_rest_and_bounds_telemetry() -> None:
    station = Station("live")
    station.ingest("landfall/d1/status", b'{"state": "online", "alarm_intake": false}')
    station.ingest("landfall/d1/telemetry", b"{oops")
    station.ingest("landfall/d2/state", b'{"state": "rank", "round": 1}')
    for k in range(TELEMETRY_KEPT + 10):
        station.ingest("landfall/d1/telemetry", json.dumps({"pos_ned_m": [k, 0, -50]}).encode())
    hello = station.snapshot()
    assert hello["malformed"] == 1
    assert hello["recent"][0]["topic"] == "landfall/d1/telemetry"
    assert "not JSON" in hello["recent"][0]["problem"]
    assert sorted(hello["vehicles"]) == ["d1", "d2"]
    d1 = hello["vehicles"]["d1"]
    assert d1[0]["leaf"] == "status"  # the retained status outlives the telemetry that followed it
    telemetry = [m for m in d1 if m["leaf"] == "telemetry"]
    assert len(telemetry) == TELEMETRY_KEPT
    assert telemetry[-1]["body"]["pos_ned_m"][0] == TELEMETRY_KEPT + 9  # the newest kept


def test_a_slow_page_is_dropped_not_waited_for() -> None:
    station = Station("live")
    with station.watch() as w:
        for _ in range(w.queue.maxsize + 5):
            station.ingest("landfall/d1/state", b'{"state": "rank"}')
        assert w.dropped
        assert w.queue.full()


# ------------------------------------------------------------------ replay
def write_record(root: Path) -> Path:
    """A flight record as the companion writes it: an alarm, a round with its frame, a confirmation,
    a sensor fault, the landing; plus a torn last line (a killed writer)."""
    frame = np.full((540, 960, 3), 120, np.uint8)
    with FlightRecord(root, 50, "20261126T000000Z-1") as rec:
        rec.record_event("alarm", {"reason": "GPS spoofing", "code": "gps_spoofing", "criticality": "high"})
        rec.record_event("state", {"state": "acquire", "round": 1, "pos_ned_m": [0.0, 0.0, -110.0]})
        rec.save_image("round01-acquire", frame)
        rec.record_event(
            "rank",
            {"round": 1, "order": [1, 0], "chosen": 1, "rationale": "site 1: clear gravel", "tier": "onboard",
             "latency_s": 0.01, "candidates": [{"index": 0, "box": [90, 90, 300, 300]},
                                               {"index": 1, "box": [480, 150, 720, 390]}]},
        )  # fmt: skip
        rec.record_event("state", {"state": "move", "round": 1, "pos_ned_m": [0.0, 0.0, -110.0]})
        rec.record_event("sensor_fault", {"round": 1, "error": "stale frame", "waited_s": 0.4})
        rec.record_event(
            "confirm",
            {"round": 1, "accept": True, "rationale": "clear", "tier": "onboard", "latency_s": 0.01,
             "site_ned_m": [5.0, -28.0, -22.0], "check": {"points": 300, "roughness_m": 0.02,
                                                           "obstacle_m": 0.1, "edge_distance_m": None}},
        )  # fmt: skip
        rec.record_event("state", {"state": "landed", "round": 1, "pos_ned_m": [5.2, -28.1, -22.0]})
        rec.record_event("outcome", {"state": "landed", "rounds": 1, "reason": "landed"})
        rec.record_event("rank", {"round": 2, "candidates": "not a list"})
    with (rec.session_dir / "events.jsonl").open("ab") as fh:
        fh.write(b'{"a":' * 50_000 + b"\n")  # nested beyond any parser's patience
        fh.write(b'{"time_unix_s": 1, "kind": "sta')
    return rec.session_dir


def test_replay_turns_a_record_into_the_feed(tmp_path: Path) -> None:
    session = write_record(tmp_path / "rec")
    flight = load_record(tmp_path / "rec")  # the record root: its newest session
    assert flight.session == session.name
    leaves = [m.leaf for m in flight.messages]
    assert leaves == ["alarm", "state", "decision", "state", "fault", "decision", "state", "state"]
    assert flight.messages[0].body["result"] == "accepted"
    decision = flight.messages[2].body
    assert decision["frame_px"] == [960, 540]
    thumb = cv2.imdecode(np.frombuffer(base64.b64decode(decision["thumbnail_jpeg_b64"]), np.uint8), 1)
    assert thumb.shape == (180, 320, 3)
    _, g, r = (int(v) for v in thumb[150 // 3, 600 // 3])  # the chosen box's top edge: green
    assert g > 150 > r
    assert flight.messages[-1].body["kind"] == "outcome"
    problems = sorted(e.problem for e in flight.rejected)  # the bad rank, the deep and the torn line
    assert len(problems) == 3
    assert any("nested too deep" in p for p in problems)
    assert any("candidates must be a list of boxes" in p for p in problems)
    assert any("not JSON" in p for p in problems)


async def test_replay_plays_seeks_and_pauses(tmp_path: Path) -> None:
    write_record(tmp_path / "rec")
    flight = load_record(tmp_path / "rec")
    station = Station("replay")
    replay = Replay(flight, station, speed=1000.0)
    assert station.malformed == 3
    player = asyncio.create_task(replay.run())
    try:
        await until(lambda: not replay.playing, 10)  # played to the end, then stopped
        outcome = [m for m in station.vehicles[flight.session].messages() if m.body.get("kind") == "outcome"]
        assert len(outcome) == 1
        assert station.clock is not None
        assert station.clock["t"] == flight.t1
        replay.seek(flight.t0)  # back to the alarm: only it is shown
        assert [m.leaf for m in station.vehicles[flight.session].messages()] == ["alarm"]
        with pytest.raises(ValueError, match="finite"):
            replay.seek(float("nan"))
        replay.step(2)  # event by event: the alarm, then its first state, then the ranking
        assert [m.leaf for m in station.vehicles[flight.session].messages()] == ["alarm", "state", "decision"]
        replay.step(-1)
        assert [m.leaf for m in station.vehicles[flight.session].messages()] == ["alarm", "state"]
        replay.step(-10)  # never before the first event
        assert [m.leaf for m in station.vehicles[flight.session].messages()] == ["alarm"]
        replay.play()
        await until(lambda: not replay.playing, 10)
        assert len(station.vehicles[flight.session].messages()) == len(flight.messages)
    finally:
        player.cancel()
        await asyncio.gather(player, return_exceptions=True)


def test_replay_says_when_the_fallback_left_a_site_for_another(tmp_path: Path) -> None:
    """The fallback's choice, then a site seen from afar that proved worse from overhead: two notes,
    the second naming both sites."""
    site0 = {"ned_m": [30.0, 0.0, 0.0], "hazard": "off_roof", "label": "site 0", "closeup": False}
    with FlightRecord(tmp_path / "rec", 50, "20261203T000000Z-1") as rec:
        rec.record_event("alarm", {"reason": "low battery", "code": "battery_low", "criticality": "high"})
        rec.record_event(
            "fallback_site", {"round": 4, "reason": "search ended", "chosen": site0, "sites": []}
        )
        rec.record_event(
            "fallback_site",
            {"round": 4, "reason": "search ended", "chosen": {**site0, "label": "site 3"}, "sites": [],
             "instead_of": {**site0, "hazard": "obstructed", "closeup": True}},
        )  # fmt: skip
    notes = [m.body["state"] for m in load_record(tmp_path / "rec").messages if m.leaf == "state"]
    assert notes == [
        "landing at the best site seen: search ended",
        "site 0 from overhead: obstructed; landing at site 3 instead",
    ]


@pytest.mark.parametrize("what", ["missing", "file", "empty", "no-events"])
def test_replay_of_what_is_not_a_record_says_so(tmp_path: Path, what: str) -> None:
    path = tmp_path / "x"
    if what == "file":
        path.write_text("hello")
    elif what in ("empty", "no-events"):
        path.mkdir()
        if what == "no-events":
            (path / "events.jsonl").write_bytes(b"")
    with pytest.raises(NotARecord, match=str(path)):
        load_record(path)


def test_the_command_line_refuses_a_non_record_with_one_line(tmp_path: Path) -> None:
    out = subprocess.run(
        [sys.executable, "-m", "landfall_ground", "--replay", str(tmp_path), "--http", "127.0.0.1:0"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert out.returncode == 2
    assert f"landfall-ground: {tmp_path} is not a flight record: no events.jsonl" in out.stderr
    assert out.stderr.count("\n") == 1


# ------------------------------------------------------------------ live, against a real mosquitto
async def publish(port: int, *messages: tuple[str, bytes, bool]) -> None:
    async with aiomqtt.Client("127.0.0.1", port) as client:
        for topic, payload, retain in messages:
            await client.publish(topic, payload, qos=1, retain=retain)


async def test_live_feed_takes_vehicles_counts_garbage_and_survives_the_broker(
    broker: Callable[..., Broker],
) -> None:
    b = broker()
    await publish(b.port, ("landfall/d1/status", b'{"state": "online", "alarm_intake": true}', True))
    station = Station("live")
    feed = LiveFeed(BrokerParams("127.0.0.1", b.port), station)
    task = asyncio.create_task(feed.run())
    try:
        await until(lambda: "d1" in station.vehicles, 10)  # the retained status, on subscribing
        await publish(
            b.port,
            ("landfall/d2/telemetry", b'{"agl_m": 12.5, "mode": "OFFBOARD"}', False),
            ("landfall/d2/decision", b'{"stage": "rank", "candidates": 3}', False),
            ("landfall/d2/state", b"\x00\x01", False),
        )
        await until(lambda: station.malformed == 2, 10)
        assert station.link["state"] == "connected"
        assert [m.body["agl_m"] for m in station.vehicles["d2"].messages()] == [12.5]
        b.stop()  # the broker goes away: the page is told, the feed keeps trying
        await until(lambda: station.link["state"] in ("down", "connecting") and feed.connections == 1, 10)
        await until(lambda: station.link["state"] == "down", 10)
        assert f"127.0.0.1:{b.port}" in station.link["detail"]
        b2 = broker(b.port)
        await until(lambda: station.link["state"] == "connected", 30)
        assert feed.connections == 2
        await publish(b2.port, ("landfall/d1/state", b'{"state": "land"}', False))
        await until(lambda: any(m.leaf == "state" for m in station.vehicles["d1"].messages()), 10)
    finally:
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)


async def test_a_broker_down_at_start_is_shown_until_it_comes(broker: Callable[..., Broker]) -> None:
    port = free_tcp_port()  # nobody listens here yet
    station = Station("live")
    feed = LiveFeed(BrokerParams("127.0.0.1", port), station)
    task = asyncio.create_task(feed.run())
    try:
        await until(lambda: station.link["state"] == "down", 10)
        assert "refused" in station.link["detail"].lower()
        assert feed.connections == 0
        broker(port)
        await until(lambda: station.link["state"] == "connected", 30)
    finally:
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)


@contextlib.asynccontextmanager
async def serving(station: Station, source: LiveFeed | Replay) -> AsyncIterator[str]:
    """The app on a real uvicorn on loopback; its base URL."""
    port = free_tcp_port()
    server = uvicorn.Server(
        uvicorn.Config(create_app(station, source), "127.0.0.1", port, log_level="warning")
    )
    task = asyncio.create_task(server.serve())
    await until(lambda: server.started, 20)
    try:
        yield f"http://127.0.0.1:{port}"
    finally:
        server.should_exit = True
        await asyncio.wait_for(task, 20)


async def test_alarms_from_the_page_go_only_where_allowed(broker: Callable[..., Broker]) -> None:
    b = broker()
    await publish(
        b.port,
        ("landfall/open/status", b'{"state": "online", "alarm_intake": true}', True),
        ("landfall/shut/status", b'{"state": "online", "alarm_intake": false}', True),
    )
    received: list[tuple[str, dict[str, Any]]] = []

    async def vehicle_side() -> None:
        async with aiomqtt.Client("127.0.0.1", b.port) as client:
            await client.subscribe("landfall/+/alarm/in", qos=1)
            async for m in client.messages:
                assert isinstance(m.payload, bytes)
                received.append((str(m.topic), json.loads(m.payload)))

    listener = asyncio.create_task(vehicle_side())
    station = Station("live", alarms={"enabled": True, "why": ""})
    feed = LiveFeed(BrokerParams("127.0.0.1", b.port, "operator", "secret"), station)
    try:
        async with serving(station, feed) as url, httpx.AsyncClient(base_url=url) as http:
            await until(lambda: {"open", "shut"} <= set(station.vehicles), 10)
            page = await http.get("/")
            assert page.status_code == 200
            assert "<title>Landfall ground</title>" in page.text
            sent = await http.post(
                "/api/alarm", json={"vehicle": "open", "reason": "storm", "criticality": "critical"}
            )
            assert sent.status_code == 202, sent.text
            shut = await http.post(
                "/api/alarm", json={"vehicle": "shut", "reason": "storm", "criticality": "high"}
            )
            assert shut.status_code == 403
            assert "alarm_intake is off" in shut.json()["error"]
            bad = await http.post(
                "/api/alarm", json={"vehicle": "open", "reason": "x", "criticality": "apocalyptic"}
            )
            assert bad.status_code == 400
            assert "criticality must be one of low, high, critical" in bad.json()["error"]
            await until(lambda: len(received) == 1, 10)
            form = json.dumps({"vehicle": "open", "reason": "storm", "criticality": "high"})
            plain = await http.post("/api/alarm", content=form, headers={"content-type": "text/plain"})
            assert plain.status_code == 415  # what another site's page could send without a preflight
            foreign = await http.post(
                "/api/alarm", json=json.loads(form), headers={"origin": "http://evil.test"}
            )
            assert foreign.status_code == 403
            assert "own page only" in foreign.json()["error"]
            station.alarms = {"enabled": False, "why": "alarms are off: no broker credentials"}
            off = await http.post(
                "/api/alarm", json={"vehicle": "open", "reason": "storm", "criticality": "high"}
            )
            assert (off.status_code, off.json()["error"]) == (403, "alarms are off: no broker credentials")
            state = (await http.get("/api/state")).json()
            assert state["type"] == "hello"
            assert state["link"]["state"] == "connected"
    finally:
        listener.cancel()
        await asyncio.gather(listener, return_exceptions=True)
    await asyncio.sleep(0.2)  # nothing else arrives: the refused alarms never left
    assert received == [("landfall/open/alarm/in", {"reason": "storm", "criticality": "critical"})]


def test_page_bundle_is_shipped_whole_and_needs_no_network() -> None:
    static = Path(__file__).resolve().parents[1] / "landfall_ground" / "static"
    names = sorted(p.name for p in static.iterdir())
    assert names == ["app.js", "index.html", "style.css"]
    total = sum(p.stat().st_size for p in static.iterdir())
    assert total < 60_000
    for p in static.iterdir():
        text = p.read_text()
        assert "http://" not in text.replace("http://www.w3.org/2000/svg", "")
        assert "https://" not in text


def test_the_companion_imports_nothing_of_the_ground_station() -> None:
    """The web server stays on the ground: no companion module imports it or its web stack, even lazily."""
    root = Path(__file__).resolve().parents[1]
    pattern = re.compile(
        r"^\s*(from|import)\s+(landfall_ground|starlette|uvicorn|websockets)\b", re.MULTILINE
    )
    offenders = [
        str(p.relative_to(root)) for p in (root / "companion").rglob("*.py") if pattern.search(p.read_text())
    ]
    assert offenders == []


async def test_the_websocket_starts_with_the_picture_and_answers_bad_controls(tmp_path: Path) -> None:
    from websockets.asyncio.client import connect

    write_record(tmp_path / "rec")
    flight = load_record(tmp_path / "rec")
    station = Station("replay")
    replay = Replay(flight, station, speed=1000.0)
    async with serving(station, replay) as url, connect(url.replace("http", "ws") + "/ws") as ws:
        hello = json.loads(await ws.recv())
        assert hello["type"] == "hello"
        assert hello["malformed"] == 3
        await until(lambda: not replay.playing, 10)
        for bad, says in [
            ("not json", "must be JSON"),
            ('{"type": "rewind"}', "unknown control 'rewind'"),
            ('{"type": "seek"}', "bad seek control"),
            ('{"type": "speed", "speed": -1}', "speed must be > 0"),
            ("[" * 100_000, "must be JSON"),
        ]:
            await ws.send(bad)
            while (event := json.loads(await ws.recv()))["type"] != "error":
                pass  # the clock and messages of the replay's play-through
            assert says in event["detail"]
        await ws.send(json.dumps({"type": "seek", "t": flight.t0}))
        while (event := json.loads(await ws.recv()))["type"] != "hello":
            pass
        (messages,) = event["vehicles"].values()
        assert [m["leaf"] for m in messages] == ["alarm"]
        assert event["clock"]["t"] == flight.t0


def test_alarms_are_off_without_credentials_and_say_how() -> None:
    from landfall_ground.cli import PASSWORD_ENV, _alarm_policy, _parser, parse_hostport

    live = _parser().parse_args(["--mqtt", "broker.local"])
    off = _alarm_policy(live, None)
    assert off["enabled"] is False
    assert f"--mqtt-user USER and the password in ${PASSWORD_ENV}" in str(off["why"])
    with_user = _parser().parse_args(["--mqtt", "broker.local", "--mqtt-user", "op"])
    assert _alarm_policy(with_user, None)["enabled"] is False  # a user without its password
    assert _alarm_policy(with_user, "pw") == {"enabled": True, "why": ""}
    replay = _parser().parse_args(["--replay", "somewhere"])
    assert _alarm_policy(replay, "pw")["enabled"] is False
    assert parse_hostport("broker.local", 1883) == ("broker.local", 1883)
    assert parse_hostport("10.0.0.2:8883", 1883) == ("10.0.0.2", 8883)
    assert parse_hostport("[::1]:1884", 1883) == ("::1", 1884)
    for bad in ("host:port", ":1883", "h:70000", "[::1]x"):
        with pytest.raises(ValueError, match=re.escape(repr(bad))):
            parse_hostport(bad, 1883)
