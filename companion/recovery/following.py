"""Following the chosen site down: the site found again in each newer frame
(:mod:`companion.perception.site_track`), the descent's target moved onto it, and during the
autopilot's land mode LANDING_TARGET for its precision landing (docs/companion.md, "Precision
landing").

A frame where the site is not found keeps the last target (the absolute one, placed by the estimate)
and the record says why; a later frame may find it again. During each descent step the site is looked
for twice a second as well, and the step's target follows it: a GPS that jumps mid-step moves the
vehicle's whole frame of reference (and the vehicle, which holds its target in that frame), while the
site stays where the camera sees it. The estimate's resets (``TelemetryCache.position_resets``: a
jump its velocity does not explain) move the target and the followed site at once, camera or not;
a site that drifts steadily in the estimate (a GPS drifting) is held over until it stops
(docs/companion.md, "Under a lying GPS").
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import dataclasses
import math
import time
from collections.abc import AsyncIterator
from typing import Any

import cv2
import numpy as np

from companion.flavour import Mode
from companion.guidance.frames import PinholeCamera, quat_to_matrix
from companion.memory import trim_malloc
from companion.perception.site_track import SiteView, TrackParams, TrackResult, centre_down, track_site
from companion.precision import PrecisionLanding
from companion.recovery.core import FrameUnavailable, RecoveryContext
from companion.recovery.drift import (
    DRIFT_BLIND_S,
    DRIFT_MIN_M_S,
    DRIFT_WAIT_S,
    drift_prediction,
    site_drift_line,
    site_drift_m_s,
)

LAND_FEED_PERIOD_S = 0.2  # a look for the site at most five times a second (wall time: the processor's pace)
LAND_SEND_PERIOD_S = 0.1  # LANDING_TARGET ten times a second of the autopilot's clock: ArduPilot's
# precision landing starts only after 2 s of targets none more than 0.5 s apart ("PrecLand: Init Failed")
LAND_TARGET_MAX_AGE_S = 1.5  # from a look at most this old (autopilot seconds), placed from the pose now
PRECLAND_FIRST_S = 1.5  # PX4's AUTO.PRECLAND is asked for once a target went out, within this long
STEP_FOLLOW_PERIOD_S = 0.5  # during a descent step, a look for the site twice a second
STEP_FOLLOW_MIN_M = 0.3  # and the step's target moved when it is this far from where the site is seen
RESET_CHECK_PERIOD_S = 0.1  # and for the estimate's resets ten times a second
ADOPT_SHIFT_M = 1.0  # a look that finds the site moved this far becomes the reference all the same
# a frame's pose is the estimate at its capture time, which is uncertain by some tens of milliseconds
# (the estimator's lag behind the airframe, the clocks' offsets): while the vehicle turns, its
# attitude then is that much uncertain, and the site it places that many times its distance
POSE_TIMING_S = 0.05
TURN_BLUR_MAX_M = 0.3  # a frame whose pose may place the site further off than this is not looked in


def site_view(frame: Any) -> SiteView | None:
    """A sensor frame as the tracker reads it (None without a camera image)."""
    if frame.image_rgb is None:
        return None
    camera = PinholeCamera(frame.width, frame.height, frame.fx, frame.fy, frame.cx, frame.cy)
    view = SiteView(frame.image_rgb, camera, tuple(frame.pos_ned_m), tuple(frame.quat_wxyz))
    return dataclasses.replace(view, centre_down_m=centre_down(getattr(frame, "lidar_frd", None), view))


def _frame_time(frame: Any) -> float:
    """A frame's capture time on the autopilot's boot clock (seconds; -inf when it has none)."""
    t = getattr(frame, "time_boot_ms", None)
    return float(t) / 1000.0 if t is not None else -math.inf


def _moved(
    track: tuple[SiteView, tuple[float, float, float]] | None, dn: float, de: float
) -> tuple[SiteView, tuple[float, float, float]] | None:
    """A followed site and its frame, both moved north ``dn`` and east ``de`` (an estimate's reset)."""
    if track is None:
        return None
    view, (n, e, d) = track
    p = view.pos_ned_m
    return dataclasses.replace(view, pos_ned_m=(p[0] + dn, p[1] + de, p[2])), (n + dn, e + de, d)


@dataclasses.dataclass(frozen=True)
class FollowState:
    """What a look for the site reads (a copy: the worker thread that looks never writes the
    follower's state). ``resets``: the estimate's resets the follower has taken, (boot time,
    (north, east) shift) as :class:`~companion.telemetry.TelemetryCache` keeps them."""

    track: tuple[SiteView, tuple[float, float, float]]  # the frame looked against, the site in it
    anchor: tuple[SiteView, tuple[float, float, float]] | None  # the frame the site was chosen in
    seen: tuple[tuple[float, float, float], ...]  # (t_boot_s, north, east) of the recent finds
    resets: tuple[tuple[float, tuple[float, float]], ...] = ()


@dataclasses.dataclass(frozen=True)
class Look:
    """A look's outcome: the match, the frame to look against next when it becomes that (else None),
    and the find for the drift's history ((t_boot_s, north, east); None when not found or untimed)."""

    result: TrackResult
    track: tuple[SiteView, tuple[float, float, float]] | None
    seen: tuple[float, float, float] | None


def look_for_site(
    frame: Any, state: FollowState, params: TrackParams, adopt: bool = True, reanchor: bool = False
) -> Look | None:
    """The site in ``frame`` (a worker-thread job: it reads ``state`` and writes nothing); None when
    the frame has no usable view. Looked for against the last frame it was found in, else against the
    one it was chosen in (from higher up, it saw more: what a jump of the estimate took out of the last
    one's view). Found, ``frame`` becomes the one to look against next when ``adopt``: each such link
    adds its match's error to the chain, so the looks during a descent step, twice a second, do not,
    unless the site lies ``ADOPT_SHIFT_M`` or more from where it was expected (the estimate moved: the
    next search from the older frame might not reach it). Where the site drifts steadily in the
    estimate (:func:`drift_prediction`), the search is centred where the drift carried it: a drift
    needs no chain of references then, and no look rate to keep up with it; else where the newest
    look found it.

    ``reanchor``: looked for against the frame it was chosen in first, about where the last frame puts
    it, and found there, that frame becomes the one to look against: one link from the choice instead
    of the chain a drift built (each of its links added its match's error; scenario2's plain membrane
    roof on real ArduCopter, 18 m of drift over 30 s: 0.4-0.75 m)."""
    view = site_view(frame)
    if view is None:
        return None
    # a frame placed before a reset the follower has taken: into the follower's frame
    taken = _frame_time(frame)
    later = [r for t, r in state.resets if t > taken]
    if later:
        (n, e, d), dn, de = view.pos_ned_m, sum(r[0] for r in later), sum(r[1] for r in later)
        view = dataclasses.replace(view, pos_ned_m=(n + dn, e + de, d))
    ref, site = state.track
    # a steady drift of the estimate carried forward: the search is centred where it puts the site;
    # else where it was last found (a look that did not become the reference still saw where the
    # estimate has moved it since: 0.6-0.75 m in the 7 s from 13 m over a roof to 3.5 m, with the
    # search 0.8 m wide there)
    predicted = drift_prediction(site_drift_line(list(state.seen)), taken)
    if predicted is None and state.seen:
        predicted = (state.seen[-1][1], state.seen[-1][2])
    expected = predicted if predicted is not None else (site[0], site[1])
    anchor = state.anchor
    if reanchor and anchor is not None and anchor[0] is not ref:
        result = track_site(anchor[0], anchor[1], view, params, expected)
        if result.found:
            adopt = True
        else:
            result = track_site(ref, site, view, params, predicted)
    else:
        result = track_site(ref, site, view, params, predicted)
        if not result.found and anchor is not None and anchor[0] is not ref:
            again = track_site(anchor[0], anchor[1], view, params, predicted)
            result = again if again.found else result
    if not result.found:
        return Look(result, None, None)
    surprise = math.dist(result.site_ned_m[:2], expected)
    track = (view, result.site_ned_m) if adopt or surprise >= ADOPT_SHIFT_M else None
    seen = (taken, result.site_ned_m[0], result.site_ned_m[1]) if math.isfinite(taken) else None
    return Look(result, track, seen)


def _look_then_trim(
    frame: Any, state: FollowState, params: TrackParams, adopt: bool, reanchor: bool
) -> Look | None:
    """:func:`look_for_site`, then what it freed handed back to the system (:func:`trim_malloc`, a
    tenth of a millisecond when there is little). Twice a second in a descent, each look resamples the
    frames around the site on grids that grow as the ground comes closer; glibc kept the larger blocks
    freed, and the daemon's memory climbed a step with each look (town city 21, launch 44 at 8x, two
    flights at once: 215 to 263 MB in the 7 s of one descent; 240 MB with the trim)."""
    try:
        return look_for_site(frame, state, params, adopt, reanchor)
    finally:
        trim_malloc()


class SiteFollower:
    """The site kept in view from its choice to the touchdown (module docstring): its last view and
    where it was then (``track``), the frame it was chosen in, the estimate's resets taken and its
    drift. Only the event loop writes this state; the looks run in worker threads on a copy
    (:func:`look_for_site`)."""

    def __init__(self, ctx: RecoveryContext, params: TrackParams | None = None) -> None:
        self.ctx = ctx
        self.track_params = params or TrackParams()
        # the site being followed: the last frame it was found in, and where it was then
        self.track: tuple[SiteView, tuple[float, float, float]] | None = None
        # the frame the site was chosen in: the widest view of it, looked in when the last frame fails
        self._anchor: tuple[SiteView, tuple[float, float, float]] | None = None
        self._resets_seen = 0  # the estimate's resets (``tm.position_resets``) the follower has taken
        # (t_boot_s, north, east) of the recent finds: the site's drift in the estimate
        self._site_seen: collections.deque[tuple[float, float, float]] | None = None
        self._drift_budget_s = DRIFT_WAIT_S  # the round's time left for holding over a drifting site
        self._reanchor = False  # the next look is against the frame the site was chosen in (after a hold)

    def forget(self) -> None:
        """Nothing to follow (a new round, or a landing elsewhere): no camera view of a site."""
        self.track = None

    def follow_from(self, frame: Any, target: tuple[float, float, float]) -> None:
        """The frame the site was chosen in, and where inverse perspective mapping put it."""
        view = site_view(frame)
        self.track = (view, target) if view is not None else None
        self._anchor = self.track
        taken = _frame_time(frame)
        self._resets_seen = sum(1 for t, _ in self.ctx.tm.position_resets.resets if t <= taken)
        self._site_seen = collections.deque(maxlen=64)
        self._drift_budget_s = DRIFT_WAIT_S
        self._reanchor = False

    def _catch_up(self) -> tuple[float, float]:
        """The estimate's resets not taken yet, added up (north, east): the followed site and the frames
        it is looked for in move by them into the estimate's frame now. The caller moves its target
        alike (a reset moves the vehicle's frame of reference, not the site)."""
        ctx = self.ctx
        resets = ctx.tm.position_resets.resets
        new, self._resets_seen = resets[self._resets_seen :], len(resets)
        if not new:
            return (0.0, 0.0)
        dn, de = sum(r[1][0] for r in new), sum(r[1][1] for r in new)
        self.track = _moved(self.track, dn, de)
        self._anchor = _moved(self._anchor, dn, de)
        if self._site_seen is not None:  # a reset is not a drift
            moved = [(t, n + dn, e + de) for t, n, e in self._site_seen]
            self._site_seen.clear()
            self._site_seen.extend(moved)
        shift = [round(dn, 3), round(de, 3)]
        when = round(new[-1][0], 2)
        ctx.record.record_event("estimate_reset", {"round": ctx.round, "t_boot_s": when, "shift_m": shift})
        ctx.log.info(
            "the autopilot's position estimate jumped %.1f m (north %.1f, east %.1f): the site and the "
            "target move with it",
            math.hypot(dn, de), dn, de,
        )  # fmt: skip
        return (dn, de)

    async def _track_once(self, frame: Any, adopt: bool = True, reanchor: bool = False) -> TrackResult | None:
        """The site in ``frame``; None when there is nothing to follow. The look runs in a worker thread
        on a copy of the follower's state (:func:`look_for_site`), and what it found is taken into that
        state here, on the event loop, which alone writes it (a worker appending to the drift's history
        while a hold iterated it ended recoveries with "deque mutated during iteration"). A reset of
        the estimate taken while the look ran, which the frame predates, moves what it found into the
        estimate's frame now.

        Raises:
            ValueError, cv2.error: a malformed frame (the callers say so and try the next)."""
        if self.track is None:
            return None
        turning = self._turning(frame)
        if turning is not None:
            return turning
        state = FollowState(
            self.track, self._anchor, tuple(self._site_seen or ()),
            tuple(self.ctx.tm.position_resets.resets[: self._resets_seen]),
        )  # fmt: skip
        resets_before = self._resets_seen
        look = await asyncio.to_thread(_look_then_trim, frame, state, self.track_params, adopt, reanchor)
        if look is None:
            return None
        # resets taken while it ran: the find moves with those the frame predates (a frame taken after
        # a reset is already in the estimate's new frame)
        taken = _frame_time(frame)
        new = [
            r for t, r in self.ctx.tm.position_resets.resets[resets_before : self._resets_seen] if t > taken
        ]
        dn, de = sum(r[0] for r in new), sum(r[1] for r in new)
        if look.track is not None and self.track is not None:
            self.track = _moved(look.track, dn, de)
        if look.seen is not None and self._site_seen is not None:
            t, n, e = look.seen
            self._site_seen.append((t, n + dn, e + de))
        return look.result

    def _turning(self, frame: Any) -> TrackResult | None:
        """A refusal when the vehicle turned so fast about the frame's capture that its pose could place
        the site more than ``TURN_BLUR_MAX_M`` off; None otherwise, or when the rate is not known.
        Without it, a vehicle that pitched to move onto a corrected target saw the site metres off in
        the next frame, moved again, and so on (the emulated ArduCopter, whose estimate is 50 ms late,
        rocking 15-35 degrees a second; its touchdowns 0.04-1.6 m from the site)."""
        assert self.track is not None
        taken = _frame_time(frame)
        rate = self.ctx.tm.poses.turn_rate_at(taken) if math.isfinite(taken) else math.nan
        site = self.track[1]
        off_m = math.dist(tuple(frame.pos_ned_m), site) * rate * POSE_TIMING_S
        if not off_m > TURN_BLUR_MAX_M:  # NaN: not known
            return None
        why = f"the vehicle was turning {math.degrees(rate):.0f} deg/s: its pose may place the site"
        why += f" {off_m:.1f} m off"
        return TrackResult(False, site, (0.0, 0.0), math.nan, math.nan, math.nan, why)

    async def follow(self, frame: Any, target: tuple[float, float, float]) -> tuple[float, float, float]:
        """The descent's target after looking for the site in ``frame``: moved onto it when found,
        kept when not; recorded either way. After a hold over a drifting site the frame the site was
        chosen in is looked against first (:meth:`_track_once`'s ``reanchor``)."""
        dn, de = self._catch_up()
        target = (target[0] + dn, target[1] + de, target[2])
        reanchor, self._reanchor = self._reanchor, False
        result = await self._track_once(frame, True, reanchor)
        if result is None:
            return target
        self.ctx.record.record_event(
            "site_track", self._track_fields(result, "reanchor" if reanchor else "descent", frame)
        )
        if not result.found:
            self.ctx.log.info("site not found in the frame (%s): keeping the target", result.reason)
            return target
        return (result.site_ned_m[0], result.site_ned_m[1], target[2])

    async def goto_following(
        self, target: tuple[float, float, float], down_m: float, *, timeout_s: float
    ) -> tuple[float, float, float]:
        """A descent step: to ``target``'s north and east at ``down_m``, the site followed meanwhile
        (module docstring). Returns the target as it ended, down at the step's start."""
        ctx = self.ctx
        moved = [target]
        async with self._following(moved, adopt=False):
            await ctx.ctl.goto(
                target[0],
                target[1],
                down_m,
                tolerance_m=ctx.p.arrival_tolerance_m,
                speed_m_s=ctx.p.arrival_speed_m_s,
                timeout_s=timeout_s,
            )
        return moved[-1]

    @contextlib.asynccontextmanager
    async def _following(
        self, moved: list[tuple[float, float, float]], *, adopt: bool
    ) -> AsyncIterator[None]:
        """:meth:`_follow_during_step` for as long as the block runs."""
        follower = asyncio.create_task(self._follow_during_step(moved, adopt), name="site-follow")
        try:
            yield
        finally:
            follower.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await follower

    async def _follow_during_step(self, moved: list[tuple[float, float, float]], adopt: bool = False) -> None:
        """Twice a second: a frame, the site in it, and the step's target onto it when it moved
        (appended to ``moved``); the estimate's resets at once. Frames missing or unusable are
        skipped: the next one is tried. ``adopt``: see :meth:`_track_once`."""
        ctx = self.ctx
        while self.track is not None:
            started = time.monotonic()
            while time.monotonic() - started < STEP_FOLLOW_PERIOD_S:
                await asyncio.sleep(RESET_CHECK_PERIOD_S)
                dn, de = self._catch_up()
                if dn or de:  # the estimate jumped: the target with it, at once
                    n, e, d = moved[-1]
                    moved.append((n + dn, e + de, d))
                    ctx.ctl.retarget(n + dn, e + de)
            try:
                frame = await ctx.frames()
                result = await self._track_once(frame, adopt)
            except (FrameUnavailable, ValueError, cv2.error) as exc:
                ctx.log.debug("site not looked for during the step: %s", exc)
                continue
            if result is None or not result.found:
                continue
            n, e, d = moved[-1]
            if math.hypot(result.site_ned_m[0] - n, result.site_ned_m[1] - e) < STEP_FOLLOW_MIN_M:
                continue
            moved.append((result.site_ned_m[0], result.site_ned_m[1], d))
            ctx.ctl.retarget(result.site_ned_m[0], result.site_ned_m[1])
            ctx.record.record_event("site_track", self._track_fields(result, "step", frame))
            if result.reacquired:
                ctx.log.info(
                    "site found %.1f m from where the estimate had it: the target follows it",
                    math.hypot(result.shift_m[0], result.shift_m[1]),
                )

    def _site_drift_m_s(self, since_s: float = -math.inf) -> float:
        return site_drift_m_s(list(self._site_seen or ()), since_s)

    async def settle(self, target: tuple[float, float, float]) -> tuple[float, float, float]:
        """Before a descent step or the final approach: while the site drifts in the estimate
        (``DRIFT_MIN_M_S``), hold over it, following it, until it stops; the autopilot holds its own
        estimate, which would carry the vehicle off the site as it drifts, and from lower down the
        site is harder to follow. A round holds ``DRIFT_WAIT_S`` in all at most, and a hold ends
        when no frame has found the site for ``DRIFT_BLIND_S``. Returns the target then."""
        ctx = self.ctx
        drift = self._site_drift_m_s()
        if not drift >= DRIFT_MIN_M_S or self._drift_budget_s <= 0:  # NaN: too few frames to say
            return target
        ctx.say(
            5, f"the site drifts {drift:.1f} m/s in the autopilot's estimate (a GPS drifting?): "
            "holding over it until it stops",
        )  # fmt: skip
        start = ctx.tm.state.t_boot_s
        moved = [target]
        why = "it stopped"
        # the looks search where the drift carries the site (:meth:`_track_once`), against the last
        # frame the site was found in before the hold: a chain of references, one per look, would
        # add each match's error to where the vehicle lands
        async with self._following(moved, adopt=False):
            while True:
                await asyncio.sleep(STEP_FOLLOW_PERIOD_S)
                ctx.ctl.check_interruption()
                now = ctx.tm.state.t_boot_s
                seen = [p for p in (self._site_seen or ()) if p[0] > start]
                if self._site_drift_m_s(since_s=start) < DRIFT_MIN_M_S:  # False while NaN
                    break
                if now - (seen[-1][0] if seen else start) > DRIFT_BLIND_S:
                    why = "the site is not found from here"
                    break
                if now - start >= self._drift_budget_s:
                    why = "the round's time for holding is spent"
                    break
        waited = ctx.tm.state.t_boot_s - start
        self._drift_budget_s -= waited
        self._reanchor = True
        still = self._site_drift_m_s(since_s=start)
        ctx.record.record_event(
            "drift_hold",
            {"round": ctx.round, "drift_m_s": round(drift, 3), "waited_s": round(waited, 1), "why": why,
             "drift_after_m_s": round(still, 3) if math.isfinite(still) else None},
        )  # fmt: skip
        ctx.say(5, f"held {waited:.0f} s over the site ({why}): going on")
        return moved[-1]

    def _track_fields(self, result: TrackResult, phase: str, frame: Any) -> dict[str, Any]:
        def r(v: float) -> float | None:
            return round(v, 3) if math.isfinite(v) else None

        return {
            "round": self.ctx.round,
            "phase": phase,
            "t_boot_s": r(_frame_time(frame)),
            "found": result.found,
            "site_ned_m": [round(v, 3) for v in result.site_ned_m],
            "shift_m": [round(v, 3) for v in result.shift_m],
            "score": r(result.score),
            "margin": r(result.margin),
            "cell_m": r(result.cell_m),
            "reason": result.reason,
            "reacquired": result.reacquired,
        }

    async def _first_target(self, stats: dict[str, Any]) -> bool:
        """Wait (holding the descent's last target) until the feed has sent a landing target, at most
        ``PRECLAND_FIRST_S``; True if one went out."""
        deadline = time.monotonic() + PRECLAND_FIRST_S
        while stats["sent"] == 0:
            self.ctx.ctl.check_interruption()
            if time.monotonic() > deadline:
                return False
            await asyncio.sleep(0.05)
        return True

    async def _feed_landing_target(self, stats: dict[str, Any], local_ned: bool) -> None:
        """While the autopilot lands: frames, the site in each, and LANDING_TARGET toward where it was
        last found (:meth:`_send_landing_targets`); until the task is cancelled. A frame without the
        site changes nothing (the targets stop once the last find is ``LAND_TARGET_MAX_AGE_S`` old:
        the autopilot keeps its estimate of the target a while, then lands where it is), and each
        change of the reason goes into ``stats["lost"]`` with its time."""
        sender = asyncio.create_task(self._send_landing_targets(stats, local_ned), name="landing-target-send")
        last_reason = ""
        try:
            while True:
                started = time.monotonic()
                reason, score = await self._one_landing_look(stats, local_ned)
                if reason and reason != last_reason:
                    stats["lost"].append(
                        {
                            "t_boot_s": round(self.ctx.tm.state.t_boot_s, 2),
                            "why": reason,
                            "score": round(score, 3) if math.isfinite(score) else None,
                        }
                    )
                    self.ctx.log.info("precision landing: the site not found (%s)", reason)
                last_reason = reason
                await asyncio.sleep(max(0.0, LAND_FEED_PERIOD_S - (time.monotonic() - started)))
        finally:
            sender.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await sender

    async def _one_landing_look(self, stats: dict[str, Any], local_ned: bool) -> tuple[str, float]:
        """One frame of the final approach: the site found in it (``stats["seen"]``: the frame's time
        and the site in the estimate; ``("", score)``), or why not and the match's score (NaN when no
        match was tried). ``local_ned`` (PX4): the looks are not chained into references."""
        try:
            frame = await self.ctx.frames()
        except FrameUnavailable as exc:
            return f"no frame: {exc}", math.nan
        dn, de = self._catch_up()
        if (dn or de) and stats["seen"] is not None:  # the estimate jumped: the newest find with it
            t, (n, e, d) = stats["seen"]
            stats["seen"] = (t, np.array([n + dn, e + de, d]))
        try:
            result = await self._track_once(frame, not local_ned)
        except (ValueError, cv2.error) as exc:  # a malformed frame: said, and the next one tried
            return f"frame not usable: {exc}", math.nan
        if result is None:
            return "no camera image", math.nan
        if not result.found:
            return result.reason, result.score
        taken = _frame_time(frame)
        stats["seen"] = (
            taken if math.isfinite(taken) else self.ctx.tm.state.t_boot_s,
            np.asarray(result.site_ned_m),
        )
        stats["looks_found"] += 1
        return "", result.score

    async def _send_landing_targets(self, stats: dict[str, Any], local_ned: bool) -> None:
        """LANDING_TARGET every ``LAND_SEND_PERIOD_S`` of the autopilot's clock toward the site where
        the newest look found it (at most ``LAND_TARGET_MAX_AGE_S`` old): in the autopilot's local
        frame (PX4), else in the vehicle's body axes from where it is now (ArduPilot). The looks come
        at the processor's pace; the targets at the autopilot's, whatever the simulation's speed."""
        ctx = self.ctx
        last = -math.inf
        while True:
            await asyncio.sleep(0.02)
            s = ctx.tm.state
            now = s.t_boot_s
            seen = stats.get("seen")
            if seen is None or now - last < LAND_SEND_PERIOD_S or now - seen[0] > LAND_TARGET_MAX_AGE_S:
                continue
            site = seen[1]
            if local_ned:  # PX4: where the site is in its local frame
                ctx.ctl.send_landing_target_local(
                    (float(site[0]), float(site[1]), float(site[2])), int(now * 1e6)
                )
            else:  # from where the vehicle is now (it moved since the frame), in its body axes then,
                # stamped with that time: the attitude is the estimate's at the position's time
                pose = ctx.tm.poses.at(now)
                quat = pose.quat_wxyz if pose is not None else s.quat_wxyz
                frd = quat_to_matrix(quat).T @ (site - np.asarray(s.pos_ned_m))
                if frd[2] <= 0.05:  # level with the vehicle: no line of sight to give
                    continue
                ctx.ctl.send_landing_target((float(frd[0]), float(frd[1]), float(frd[2])), int(now * 1e6))
            last = now
            stats["sent"] += 1
            stats["last_site_ned_m"] = [round(float(v), 3) for v in site]

    async def land_on_site(self, setup: PrecisionLanding | None) -> None:
        """The autopilot's land mode; with its precision landing fed from the camera when it is set up
        for one and the site is in view; recorded as ``precision_landing``."""
        ctx = self.ctx
        if setup is None:
            why, ready = "the autopilot's parameters were not read", False
        else:
            why, ready = setup.why, setup.ready
        if ready and self.track is None:
            why, ready = "no camera view of the site to follow: the absolute target", False
        stats: dict[str, Any] = {
            "sent": 0,
            "looks_found": 0,
            "lost": [],
            "last_site_ned_m": None,
            "seen": None,
        }
        feed = None
        if ready and setup is not None:
            feed = asyncio.create_task(
                self._feed_landing_target(stats, setup.local_ned), name="landing-target"
            )
        mode = Mode.LAND
        try:
            if feed is not None and setup is not None and setup.own_mode:
                # PX4's AUTO.PRECLAND searches (or lands where it is) a second after it starts without a
                # target: it is asked for only once a target went out, else the land mode it is
                if await self._first_target(stats):
                    mode = Mode.PRECLAND
                else:
                    why = f"no landing target within {PRECLAND_FIRST_S:g} s: the absolute target"
                    ready = False
                    feed.cancel()  # AUTO.LAND reads no target
            await ctx.ctl.land(ctx.p.land_timeout_s, mode)
        finally:
            if feed is not None:
                feed.cancel()
                with contextlib.suppress(asyncio.CancelledError):
                    await feed
            ctx.record.record_event(
                "precision_landing",
                {
                    "round": ctx.round,
                    "used": ready,
                    "why": why,
                    "mode": ctx.ctl.flavour.mode_name(ctx.ctl.flavour.modes[mode]),
                    "targets_sent": stats["sent"],
                    "looks_found": stats["looks_found"],
                    "lost": stats["lost"],
                    "last_site_ned_m": stats["last_site_ned_m"],
                },
            )
