"""Three defects found by reading the recovery and the controller, each pinned by a test that failed
before its fix: a ranking without an image read Surface ID's indices as positions in a filtered list;
a worker thread appended to the drift history that the event loop iterated; a crashed setpoint stream
stayed dead and its exception came out of ``release()``."""

from __future__ import annotations

import asyncio
import collections
import logging
import threading
import types
from typing import Any

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink2

from companion.perception.site_track import TrackResult
from companion.perception.surface_id import Candidate
from companion.recovery import following
from companion.recovery.following import FollowState, SiteFollower, look_for_site
from companion.recovery.looking import chosen_position, surface_id_ranking
from tests import recovery_fakes


def _candidate(index: int, fallback: bool = False) -> Candidate:
    return Candidate(index, (0, 0, 10, 10), (5.0, 5.0), fallback=fallback, score=10.0 - index)


# ---------------------------------------------------------------- 1: a ranking without an image
def test_without_an_image_the_ranking_orders_positions_in_the_list_left_after_rejected_sites() -> None:
    """Surface ID numbered five candidates 0-4; the ones near a rejected site (0 and 3) are gone. The
    ranking's order is positions in what is left, so the vehicle flies to the best one left (Surface
    ID's 1), never to another (position 1 is Surface ID's 2) or past the list's end (4)."""
    left = [_candidate(1), _candidate(2), _candidate(4)]
    ranking = surface_id_ranking(left)
    assert ranking.order == (0, 1, 2)
    assert ranking.tier == "surface-id"
    chosen = chosen_position(ranking, left)
    assert chosen == 0
    assert left[chosen].index == 1
    # a fallback crop is never flown to; none left but fallbacks: nothing chosen
    assert (
        chosen_position(
            surface_id_ranking([_candidate(2, True), _candidate(3)]), [_candidate(2, True), _candidate(3)]
        )
        == 1
    )
    assert chosen_position(surface_id_ranking([_candidate(2, True)]), [_candidate(2, True)]) is None


# ---------------------------------------------------------------- 2: the follower's state, one writer
def _frame(t_ms: int) -> Any:
    return types.SimpleNamespace(
        image_rgb=np.zeros((48, 64, 3), np.uint8), width=64, height=48, fx=50.0, fy=50.0, cx=32.0, cy=24.0,
        pos_ned_m=(0.0, 0.0, -20.0), quat_wxyz=(1.0, 0.0, 0.0, 0.0), lidar_frd=None, time_boot_ms=t_ms,
    )  # fmt: skip


class _LoopOnlyDeque(collections.deque):  # type: ignore[type-arg]
    """A deque that notes the thread of every append."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.threads: list[threading.Thread] = []

    def append(self, item: Any) -> None:
        self.threads.append(threading.current_thread())
        super().append(item)


def _follower(frame: Any) -> SiteFollower:
    me = SiteFollower(recovery_fakes.context())
    me.follow_from(frame, (4.0, 3.0, 0.0))
    me._site_seen = _LoopOnlyDeque(maxlen=64)
    return me


@pytest.mark.parametrize(("reset_t_s", "moved"), [(12.5, True), (11.5, False)])
def test_a_look_runs_on_a_copy_and_only_the_event_loop_writes_what_it_found(
    monkeypatch: pytest.MonkeyPatch, reset_t_s: float, moved: bool
) -> None:
    """The look (a worker thread) reads a copy of the follower's state and returns what it found; the
    event loop takes it in. A hold over a drifting site iterates the drift history on the event loop
    while the step's looks run: an append from the worker thread raised "deque mutated during
    iteration" there. A reset of the estimate taken while the look ran moves its find with it when
    the frame predates the reset (12.5 s after a frame of 12.0 s); a frame taken after it (11.5 s)
    is in the new frame already."""
    found = TrackResult(True, (5.0, 6.0, 0.0), (1.0, 3.0), 0.9, 0.3, 0.1)
    in_look = threading.Event()
    go_on = threading.Event()

    def slow_match(*_a: Any) -> TrackResult:
        in_look.set()
        assert go_on.wait(5.0)
        return found

    monkeypatch.setattr(following, "track_site", slow_match)
    frame = _frame(12_000)
    me = _follower(frame)

    async def scenario() -> Any:
        look = asyncio.create_task(me._track_once(frame, True))
        assert await asyncio.to_thread(in_look.wait, 5.0)
        assert list(me._site_seen) == []  # the loop iterates freely while the look runs
        # the estimate resets while the look runs: the loop takes it (as _catch_up does)
        me.ctx.tm.position_resets.resets.append((reset_t_s, (2.0, -1.0)))
        me._catch_up()
        go_on.set()
        return await look

    result = asyncio.run(scenario())
    assert result is found
    assert me._site_seen.threads == [threading.main_thread()]  # appended on the event loop only
    expected = (7.0, 5.0) if moved else (5.0, 6.0)  # the find, moved by the reset taken meanwhile
    assert list(me._site_seen) == [(12.0, *expected)]
    assert me.track is not None
    assert me.track[1] == (*expected, 0.0)
    # the look itself: a pure function of its copy
    state = FollowState(me.track, me._anchor, ((11.0, 6.0, 5.0),))
    go_on.set()
    look = look_for_site(frame, state, me.track_params)
    assert look is not None
    assert look.seen == (12.0, 5.0, 6.0)
    assert state.seen == ((11.0, 6.0, 5.0),)


def test_each_look_hands_back_what_it_freed_in_its_own_worker_thread(monkeypatch: pytest.MonkeyPatch) -> None:
    """Twice a second in a descent a look resamples the frames around the site; glibc kept what each
    freed and the daemon's memory climbed with every look. The look's worker thread hands it back
    (``trim_malloc``) once the look is done, found or failed, before the event loop goes on."""
    events: list[tuple[str, threading.Thread]] = []
    found = TrackResult(True, (5.0, 6.0, 0.0), (1.0, 3.0), 0.9, 0.3, 0.1)
    outcome: list[Any] = [found]

    def match(*_a: Any) -> TrackResult:
        events.append(("look", threading.current_thread()))
        if isinstance(outcome[0], Exception):
            raise outcome[0]
        return found

    monkeypatch.setattr(following, "track_site", match)
    monkeypatch.setattr(following, "trim_malloc", lambda: events.append(("trim", threading.current_thread())))
    frame = _frame(12_000)
    me = _follower(frame)
    assert asyncio.run(me._track_once(frame, True)) is found
    outcome[0] = ValueError("a malformed frame")
    with pytest.raises(ValueError, match="malformed"):
        asyncio.run(me._track_once(frame, True))
    assert [what for what, _t in events] == ["look", "trim", "look", "trim"]
    assert all(t is not threading.main_thread() for _w, t in events)  # in the look's worker thread
    assert events[0][1] is events[1][1]
    assert events[2][1] is events[3][1]


# ---------------------------------------------------------------- 3: the setpoint stream
def test_a_setpoint_stream_survives_a_failing_send_and_release_never_raises(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """A send that fails (the link gone for a moment) is logged once and the setpoints go on; the
    controller releases cleanly; engaged again, it streams again."""
    from companion.control import VehicleController
    from companion.telemetry import TelemetryCache
    from tests.autopilot_frames import accept_commands
    from tests.fake_link import FakeLink

    class FlakyLink(FakeLink):
        """The third to fifth setpoints fail as a link gone for a moment does."""

        failures = 3

        def send_to(self, msg: Any, system: int, component: int) -> None:
            if msg.get_type() == "SET_POSITION_TARGET_LOCAL_NED" and len(setpoints()) >= 2 and self.failures:
                self.failures -= 1
                raise OSError("Network is unreachable")
            super().send_to(msg, system, component)

    def setpoints() -> list[Any]:
        return link.sent_of("SET_POSITION_TARGET_LOCAL_NED")

    tm = TelemetryCache(1)
    tm.state.pos_ned_m = (0.0, 0.0, -10.0)  # a PX4 hovering 10 m up
    tm.state.autopilot = mavlink2.MAV_AUTOPILOT_PX4
    link = FlakyLink(answer=accept_commands)  # the autopilot accepts the mode change
    ctl = VehicleController(tm, link)
    link.attach(lambda msg, _addr: ctl.on_command_ack(msg))

    async def scenario() -> tuple[int, int]:
        await ctl.engage()
        await asyncio.sleep(0.6)
        during = len(setpoints())
        await ctl.release()
        after_release = len(setpoints())
        await asyncio.sleep(0.2)
        assert len(setpoints()) == after_release  # released: nothing more sent
        await ctl.engage()
        await asyncio.sleep(0.3)
        again = len(setpoints()) - after_release
        await ctl.release()
        return during, again

    with caplog.at_level(logging.ERROR, logger="companion.control"):
        during, again = asyncio.run(scenario())
    assert link.failures == 0
    assert during >= 8  # 20 Hz for 0.6 s, three ticks lost to the failing link
    assert again >= 3
    said = [r.getMessage() for r in caplog.records if "setpoint not sent" in r.getMessage()]
    assert len(said) == 1  # once until a tick succeeds again
