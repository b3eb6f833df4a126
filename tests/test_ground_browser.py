"""landfall-ground in a real browser: headless Chromium (Debian's ``chromium``) driven by Playwright,
against a real mosquitto and a real landing (simbridge + companion, scenario1 at 4x). One landing serves
every test here: the live page while it happens, the alarm form, several vehicles and a malformed
payload, the replay of its flight record, and the broker going away and coming back (last: it stops
the broker). Set ``LANDFALL_GROUND_SCREENSHOTS=DIR`` to keep the pages' screenshots there (README).

Without chromium these tests skip and say how to get it; under CI (``CI`` set) that is a failure.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import httpx
import pytest
from paho.mqtt import publish

from companion.record import EVENTS_FILE
from landfall_ground.cli import PASSWORD_ENV
from tests.conftest import Broker, Rig, free_tcp_port, rig_starter, sim_starter

pytestmark = [pytest.mark.slow, pytest.mark.timeout(600)]

playwright_sync = pytest.importorskip("playwright.sync_api", reason="pip install 'landfall[ground]'")
expect = playwright_sync.expect
VEHICLE = "sim1"
LANDING_S = 300.0  # wall seconds allowed for the whole landing at 4x on a busy CI machine


@pytest.fixture(scope="module")
def chromium() -> str:
    exe = shutil.which("chromium") or shutil.which("chromium-browser")
    if exe is None:
        why = "the browser tests need Debian's chromium: sudo apt-get install chromium (make test does so)"
        if os.environ.get("CI"):
            pytest.fail(f"CI: {why}")
        pytest.skip(why)
    return exe


class Ground:
    """A ``landfall-ground`` process on a free loopback port."""

    def __init__(self, log: Path, *args: str, env: dict[str, str] | None = None) -> None:
        self.port = free_tcp_port()
        self.url = f"http://127.0.0.1:{self.port}/"
        self.log = log
        cmd = [sys.executable, "-m", "landfall_ground", *args, "--http", f"127.0.0.1:{self.port}"]
        with log.open("wb") as fh:
            self.proc = subprocess.Popen(
                cmd, stdout=fh, stderr=subprocess.STDOUT, env={**os.environ, **(env or {})}
            )
        deadline = time.monotonic() + 30
        while True:  # until it serves
            try:
                if httpx.get(self.url + "api/state", timeout=1).status_code == 200:
                    break
            except httpx.HTTPError:
                pass
            if self.proc.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"landfall-ground did not start: {log.read_text()}")
            time.sleep(0.1)

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            self.proc.wait(timeout=10)


@dataclass
class Flight:
    tmp: Path
    broker: Broker
    ground: Ground
    rig: Rig
    record: Path
    page: Any  # playwright's Page, opened on the live view before the alarm
    browser: Any
    seen_before_alarm: str


def shot(page: Any, tmp: Path, name: str) -> None:
    page.screenshot(path=str(tmp / name))
    keep = os.environ.get("LANDFALL_GROUND_SCREENSHOTS")
    if keep:
        Path(keep).mkdir(parents=True, exist_ok=True)
        shutil.copy(tmp / name, Path(keep) / name)


@pytest.fixture(scope="module")
def flight(chromium: str, tmp_path_factory: pytest.TempPathFactory) -> Iterator[Flight]:
    tmp = tmp_path_factory.mktemp("ground")
    record = tmp / "record"
    broker = Broker(tmp)
    env = {
        "LANDFALL_MQTT_ENABLED": "true",
        "LANDFALL_MQTT_PORT": str(broker.port),
        "LANDFALL_MQTT_VEHICLE_ID": VEHICLE,
        "LANDFALL_MQTT_TELEMETRY_HZ": "2",
        "LANDFALL_MQTT_ALARM_INTAKE": "true",
    }
    ground = Ground(
        tmp / "ground.log",
        *("--mqtt", f"127.0.0.1:{broker.port}", "--mqtt-user", "operator", "--basemap", "scenario1"),
        env={PASSWORD_ENV: "not-checked-by-this-broker"},
    )
    with (
        playwright_sync.sync_playwright() as pw,
        sim_starter(tmp) as start_sim,
        rig_starter(start_sim, tmp) as start_rig,
    ):
        browser = pw.chromium.launch(executable_path=chromium, args=["--no-sandbox"])
        brokers = [broker]  # the last test restarts it
        try:
            page = browser.new_page(viewport={"width": 1366, "height": 768})
            page.goto(ground.url)
            rig = start_rig(["--scenario", "scenario1", "--speed", "4"], ["--record", str(record)], env=env)
            expect(page.locator("#st-status")).to_have_text("online", timeout=60_000)
            rig.wait_log("sensor stream connected", 60)
            seen = page.locator("#rounds-section").inner_text()
            out = rig.alarm_accepted("--reason", "GPS spoofing", "--criticality", "high")
            assert out.returncode == 0, out.stdout + out.stderr
            expect(page.locator("#outcome")).to_contain_text("landed", timeout=LANDING_S * 1000)
            f = Flight(tmp, broker, ground, rig, record, page, browser, seen)
            yield f
            brokers.append(f.broker)
        finally:
            browser.close()
            ground.stop()
            for b in brokers:
                b.stop()


def recorded(flight: Flight, kind: str) -> list[dict[str, Any]]:
    (events,) = flight.record.glob(f"*/{EVENTS_FILE}")
    rows = [json.loads(line) for line in events.read_text().splitlines()]
    return [r for r in rows if r["kind"] == kind]


def test_live_page_shows_the_landing_as_it_happens(flight: Flight) -> None:
    page = flight.page
    assert "no round yet" in flight.seen_before_alarm  # the rounds below came over the WebSocket, live
    expect(page.locator("#link")).to_have_text("broker connected")
    expect(page.locator("#vehicle-name")).to_have_text(VEHICLE)
    expect(page.locator("#st-status")).to_have_text("online")
    expect(page.locator("#st-mode")).not_to_have_text("-")
    expect(page.locator("#st-alt")).to_have_text(re.compile(r"\d+\.\d m "))  # rangefinder, else local frame
    expect(page.locator("#st-battery")).to_contain_text("%")
    expect(page.locator("#st-link")).to_have_text("telemetry ok")
    assert [a["reason"] for a in recorded(flight, "alarm")] == ["GPS spoofing"]
    # the page shows the newest alarm: the operator's, or the autopilot's failsafe when one came after it
    # and the companion merged it into the recovery (at 4x a setpoint stream stalled 0.33 s on a loaded
    # machine is 1.3 s of PX4's clock: "Failsafe: offboard lost, POSCTL")
    failsafes = [r["text"] for r in recorded(flight, "autopilot_text") if r["text"].startswith("Failsafe")]
    newest = (
        re.compile(re.escape(failsafes[-1]) + r" \(high\): in_progress at ")
        if failsafes
        else re.compile(r"^GPS spoofing \(high\): accepted at ")
    )
    expect(page.locator("#alarm-current")).to_have_text(newest)
    # each round: its frame, its candidates boxed, exactly one of them the chosen one, and the rationale
    ranks = recorded(flight, "rank")
    rounds = page.locator(".round")
    expect(rounds).to_have_count(len({r["round"] for r in ranks}))
    first = page.locator(f'.round[data-round="{ranks[0]["round"]}"]')
    expect(first.locator("img")).to_be_visible()
    assert first.locator("img").evaluate("img => img.naturalWidth") == 320
    expect(first.locator("rect.candidate")).to_have_count(len(ranks[0]["candidates"]))
    expect(first.locator("rect.chosen")).to_have_count(1)
    assert first.locator("rect.chosen").get_attribute("data-k") == str(ranks[0]["chosen"])
    stroke = first.locator("rect.chosen").evaluate("r => getComputedStyle(r).stroke")
    assert stroke == "rgb(60, 200, 40)"  # green
    expect(first.locator(".meta > .rationale")).to_have_text(ranks[0]["rationale"])
    expect(first.locator(".meta")).to_contain_text(f"tier {ranks[0]['tier']}")
    confirms = recorded(flight, "confirm")
    assert any(c["accept"] for c in confirms)
    expect(page.locator(".confirm.accept").first).to_contain_text("LiDAR")
    # the recovery's timeline, the touchdown on the trajectory
    timeline = page.locator("#timeline")
    for state in ("rank", "move", "confirm", "land"):
        expect(timeline).to_contain_text(state)
    expect(page.locator("#outcome")).to_have_text("landed: landed")
    expect(page.locator("#touchdown")).to_have_count(1)
    assert len(page.locator("#track polyline").get_attribute("points").split()) > 10
    expect(page.locator("#track image")).to_have_count(1)  # over simbridge's top view of the world
    # in one evaluation: the track is drawn afresh with each telemetry message, and a handle resolved
    # before a redraw points at a detached element (whose box is empty)
    width = page.evaluate("() => document.querySelector('#track image').getBBox().width")
    assert width > 400  # metres: the world
    expect(page.locator("#track-scale")).to_contain_text("over scenario1")
    shot(page, flight.tmp, "ground-live.png")


def test_an_alarm_from_the_page_gets_the_companion_answer(flight: Flight) -> None:
    page = flight.page
    expect(page.locator("#alarm-form")).to_be_visible()
    page.fill("#alarm-reason", "operator check")
    page.select_option("#alarm-criticality", "critical")
    page.click("#alarm-form button")
    # the vehicle is on the ground now: the companion says no, and the page shows its answer
    expect(page.locator("#alarm-answers")).to_contain_text("operator check: denied", timeout=20_000)
    expect(page.locator("#alarm-sent")).to_contain_text("sent 'operator check' (critical)")


def test_a_second_vehicle_is_listed_and_garbage_is_counted(flight: Flight) -> None:
    page = flight.page
    port = flight.broker.port
    publish.multiple(
        [
            {"topic": "landfall/sim2/status", "payload": '{"state": "offline"}', "retain": True},
            {"topic": f"landfall/{VEHICLE}/decision", "payload": '{"stage": "rank", "candidates": 7}'},
            {"topic": f"landfall/{VEHICLE}/telemetry", "payload": b"\xff not json"},
        ],
        hostname="127.0.0.1",
        port=port,
    )
    expect(page.locator("#malformed")).to_have_text("2 malformed")
    expect(page.locator("#malformed-list")).to_contain_text("candidates must be a list of boxes")
    expect(page.locator("#vehicles option")).to_have_count(2)
    page.select_option("#vehicles", "sim2")
    expect(page.locator("#st-status")).to_have_text("offline")
    expect(page.locator("#rounds-empty")).to_be_visible()
    page.select_option("#vehicles", VEHICLE)
    expect(page.locator("#st-status")).to_have_text("online")  # the page still draws, the landing intact
    expect(page.locator("#outcome")).to_have_text("landed: landed")


def test_the_record_replays_with_a_time_slider(flight: Flight) -> None:
    ground = Ground(flight.tmp / "replay.log", "--replay", str(flight.record), "--speed", "8")
    try:
        page = flight.browser.new_page(viewport={"width": 1366, "height": 768})
        page.goto(ground.url)
        expect(page.locator("#source")).to_have_text("replay")
        expect(page.locator("#alarm-off")).to_have_text("a replay: alarms go to live vehicles only")
        expect(page.locator("#outcome")).to_contain_text("landed", timeout=120_000)
        ranks = recorded(flight, "rank")
        first = page.locator(f'.round[data-round="{ranks[0]["round"]}"]')
        expect(first.locator("img")).to_be_visible()
        expect(first.locator("rect.chosen")).to_have_count(1)
        expect(first.locator(".meta > .rationale")).to_have_text(ranks[0]["rationale"])
        expect(page.locator("#touchdown")).to_have_count(1)
        expect(page.locator("#play")).to_have_text("play")  # played to its end
        shot(page, flight.tmp, "ground-replay.png")
        # back to the start with the slider: the alarm only, no round yet
        page.locator("#slider").fill("0")
        expect(page.locator("#rounds-empty")).to_be_visible()
        expect(page.locator("#outcome")).to_have_text("no outcome yet")
        expect(page.locator("#timeline li")).to_have_count(1)
        page.click("#forward")  # event by event
        expect(page.locator("#timeline li")).to_have_count(2)
        page.click("#back")
        expect(page.locator("#timeline li")).to_have_count(1)
        # and to the end again: the landing
        page.locator("#slider").fill(str(page.locator("#slider").get_attribute("max")))
        expect(page.locator("#outcome")).to_contain_text("landed")
        expect(page.locator(".round")).to_have_count(len({r["round"] for r in ranks}))
    finally:
        ground.stop()


def test_the_broker_going_away_is_shown_and_survived(flight: Flight) -> None:
    page = flight.page
    flight.broker.stop()
    expect(page.locator("#link")).to_have_text("broker down", timeout=20_000)
    expect(page.locator("#banner")).to_contain_text(f"127.0.0.1:{flight.broker.port}")
    expect(page.locator("#st-link")).to_contain_text("no telemetry for", timeout=20_000)
    flight.broker = Broker(flight.tmp, flight.broker.port)
    expect(page.locator("#link")).to_have_text("broker connected", timeout=30_000)
    expect(page.locator("#banner")).to_be_hidden()
    # the companion comes back too (its own backoff): its telemetry flows to the page again
    expect(page.locator("#st-link")).to_have_text("telemetry ok", timeout=60_000)
