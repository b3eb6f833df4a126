"""The daemon's long-lived tasks under supervision: a task that fails is logged and started again,
a one-shot task that ends is done, cancellation ends them (companion/supervise.py)."""

from __future__ import annotations

import asyncio
import collections
import contextlib
import itertools
import logging
import socket
import threading

import pytest
from pymavlink.dialects.v20 import common as mavlink2

from companion.daemon import Companion
from companion.supervise import supervised

LOG = logging.getLogger("test.supervise")


def test_a_failing_task_is_logged_and_started_again_with_a_growing_back_off(
    caplog: pytest.LogCaptureFixture,
) -> None:
    runs: list[float] = []
    fourth = asyncio.Event()

    async def flaky() -> None:
        runs.append(asyncio.get_running_loop().time())
        if len(runs) == 4:
            fourth.set()
        if len(runs) <= 3:
            raise RuntimeError(f"fault {len(runs)}")
        await asyncio.sleep(10.0)  # then it runs as it should

    async def scenario() -> collections.Counter[str]:
        counts: collections.Counter[str] = collections.Counter()
        task = asyncio.create_task(
            supervised("watchers", flaky, LOG, restarts=counts, first_s=0.05, max_s=1.0)
        )
        await asyncio.wait_for(fourth.wait(), 5.0)
        task.cancel()
        with pytest.raises(asyncio.CancelledError):
            await task
        return counts

    with caplog.at_level(logging.ERROR, logger="test.supervise"):
        counts = asyncio.run(scenario())
    assert counts == {"watchers": 3}
    gaps = [b - a for a, b in itertools.pairwise(runs)]
    assert gaps[0] >= 0.05
    assert gaps[1] >= 0.1
    assert gaps[2] >= 0.2  # doubled each time
    failures = [r for r in caplog.records if "the watchers task failed" in r.getMessage()]
    assert len(failures) == 3
    assert all(r.exc_info is not None for r in failures)  # with the traceback
    assert "fault 3" in caplog.text


def test_a_task_meant_to_run_for_ever_that_returns_is_started_again_and_a_one_shot_is_done(
    caplog: pytest.LogCaptureFixture,
) -> None:
    calls = {"forever": 0, "once": 0}
    third = asyncio.Event()

    async def forever() -> None:
        calls["forever"] += 1
        if calls["forever"] > 2:
            third.set()
            await asyncio.sleep(10.0)

    async def once() -> None:
        calls["once"] += 1

    async def scenario() -> None:
        await asyncio.wait_for(supervised("sensors", once, LOG, forever=False), 1.0)
        task = asyncio.create_task(supervised("heartbeat", forever, LOG, first_s=0.01))
        await asyncio.wait_for(third.wait(), 5.0)
        task.cancel()
        with pytest.raises(asyncio.CancelledError):
            await task

    with caplog.at_level(logging.ERROR, logger="test.supervise"):
        asyncio.run(scenario())
    assert calls == {"forever": 3, "once": 1}
    assert caplog.text.count("the heartbeat task ended by itself") == 2


def test_the_daemon_starts_a_failed_watcher_again_and_keeps_its_heartbeat(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """A fault in the alarm watchers (here: the first check raises) costs one check, not the
    watchers: the daemon starts them again, keeps sending its heartbeat and says so when it stops."""
    gcs = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    gcs.bind(("127.0.0.1", 0))
    gcs.settimeout(5.0)
    c = Companion(
        mavlink_url=f"udpout:127.0.0.1:{gcs.getsockname()[1]}", sensors=None, watch_battery_pct=None
    )
    checks = {"n": 0}
    again = threading.Event()

    def watch_once() -> None:
        checks["n"] += 1
        if checks["n"] == 2:
            again.set()
        if checks["n"] == 1:
            raise KeyError("a telemetry field the watcher expected")

    c.watch_once = watch_once  # type: ignore[method-assign]

    with caplog.at_level(logging.INFO):
        asyncio.run(_run_until(c, again, gcs))
    gcs.close()
    assert c.restarts == {"watchers": 1}
    assert "the watchers task failed" in caplog.text
    assert "tasks started again after a failure: {'watchers': 1}" in caplog.text


async def _run_until(c: Companion, event: threading.Event, gcs: socket.socket) -> None:
    """Run the daemon until ``event`` is set, hear its heartbeat on ``gcs`` after that, stop it."""
    run = asyncio.create_task(c.run())
    assert await asyncio.to_thread(event.wait, 10.0)
    heard = await asyncio.to_thread(_heartbeat, gcs)
    assert heard.type == mavlink2.MAV_TYPE_ONBOARD_CONTROLLER
    c.stop()
    await asyncio.wait_for(run, 10.0)


def _heartbeat(sock: socket.socket) -> mavlink2.MAVLink_heartbeat_message:
    mav = mavlink2.MAVLink(None)
    while True:
        for msg in mav.parse_buffer(sock.recv(65536)) or []:
            if msg.get_type() == "HEARTBEAT":
                return msg


@pytest.mark.parametrize("fails", [False, True])
def test_the_daemon_warms_up_once_at_start_and_a_failed_warm_up_only_costs_its_time(
    fails: bool, caplog: pytest.LogCaptureFixture, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The start-up warm-up (Surface ID's conversions, the onboard tier) runs once in a worker thread
    with the reasoner the daemon flies with; when it raises, a warning says so, it is not started
    again and the heartbeat goes on."""
    import companion.daemon as daemon

    gcs = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    gcs.bind(("127.0.0.1", 0))
    gcs.settimeout(5.0)
    c = Companion(
        mavlink_url=f"udpout:127.0.0.1:{gcs.getsockname()[1]}", sensors=None, watch_battery_pct=None
    )
    seen: list[tuple[object, str]] = []
    done = threading.Event()

    def warm_up(reasoner: object) -> None:
        seen.append((reasoner, threading.current_thread().name))
        done.set()
        if fails:
            raise RuntimeError("no model file")

    monkeypatch.setattr(daemon, "warm_up", warm_up)

    with caplog.at_level(logging.INFO):
        asyncio.run(_run_until(c, done, gcs))
    gcs.close()
    assert len(seen) == 1
    assert seen[0][0] is c.reasoner
    assert seen[0][1] != threading.main_thread().name  # off the event loop's thread
    assert not c.restarts
    if fails:
        assert "warm-up failed (RuntimeError: no model file)" in caplog.text
    else:
        assert "warmed up in" in caplog.text


def test_a_sensor_stream_not_up_yet_is_dialled_again_soon_then_once_a_second(
    caplog: pytest.LogCaptureFixture, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Both processes start at boot and the stream is usually up moments after the daemon: it is dialled
    again after 0.2 s, then twice as long each time up to a second; said once, connected in the end."""
    from landfall_link.sensorstream import SensorStreamError

    attempts = itertools.count()

    class LateStream:
        def __init__(self, host: str, port: int, *, timeout_s: float) -> None:
            if next(attempts) < 6:
                raise SensorStreamError(f"sensor stream {host}:{port}: cannot connect")

        async def __aenter__(self) -> LateStream:
            return self

        async def __aexit__(self, *exc: object) -> None:
            return None

    waits: list[float] = []
    real_sleep = asyncio.sleep

    async def sleep(seconds: float) -> None:
        waits.append(seconds)
        await real_sleep(0)

    c = Companion(mavlink_url="udpout:127.0.0.1:9", sensors=("127.0.0.1", 9), watch_battery_pct=None)

    async def connect() -> None:
        monkeypatch.setattr(asyncio, "sleep", sleep)
        async with contextlib.AsyncExitStack() as stack:
            await c._connect_sensors(stack, LateStream)

    with caplog.at_level(logging.INFO):
        asyncio.run(connect())
    assert waits == [0.2, 0.4, 0.8, 1.0, 1.0, 1.0]
    assert caplog.text.count("sensor stream not available yet") == 1
    assert "sensor stream connected: 127.0.0.1:9" in caplog.text
