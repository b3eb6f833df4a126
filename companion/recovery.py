"""The recovery loop (DESIGN.md section 2): acquire, Surface ID, rank, move, confirm, descend, land.

One :class:`Recovery` per alarm. Its state is explicit (:class:`State`); every decision is announced
(STATUSTEXT), recorded, and taken from telemetry, never from sleeps. A round that finds nothing
explores (climbs, or flies a search leg); a target never reached or a site rejected at confirmation
ends the round. When the round budget runs out with nothing acceptable seen, the vehicle searches on,
leg by leg (:mod:`companion.search`), while the battery holds more than the landing needs plus a
reserve and the alarm's window allows; then it lands at the least bad site it measured
(:mod:`companion.site_ledger`), never "here" blindly. The battery and the window also end the rounds
within the budget: a battery at its reserve lands at the least bad site after the first look. A
defect of the companion's own (any unexpected exception) never leaves the vehicle without a
commander: it is announced, recorded with its traceback, and the vehicle lands
(:meth:`Recovery._fail_safe`).
"""

from __future__ import annotations

import asyncio
import contextlib
import enum
import itertools
import logging
import math
import time
import traceback
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from companion.alarms import Alarm, Criticality
from companion.control import (
    AutopilotFailsafe,
    ControlError,
    OperatorTakeover,
    TargetTimeout,
    TelemetryLost,
    TouchedDown,
    VehicleController,
)
from companion.faults import FaultHook
from companion.guidance.descent import height_above_site
from companion.guidance.frames import PinholeCamera, quat_to_matrix
from companion.guidance.ipm import IpmError, LidarPixelIndex, pixel_to_ned, pixel_to_ned_flat
from companion.perception.crops import crop, pad_of, rank_crops, site_box
from companion.perception.depth import DepthError, DepthSource, LidarDepth
from companion.perception.site_check import SiteCheck, check_site, world_points
from companion.perception.surface_id import (
    ROOF_HEIGHT_M,
    Candidate,
    SurfaceParams,
    propose,
    quadrant_fallback,
)
from companion.reasoning.base import ConfirmRequest, Decision, Ranking, RankRequest, Reasoner
from companion.reasoning.onboard import OnboardReasoner, lidar_kind
from companion.search import Leg, SearchLimits, SearchPlanner, Verdict
from companion.site_ledger import Hazard, LedgerSite, SiteLedger, hazard_of
from companion.telemetry import TelemetryCache

MAX_REENGAGE = 2
SENSOR_RETRY_S = 1.0  # between two asks for a frame after one failed
SITE_RETRIES = 2  # more frames asked for when a LiDAR sweep misses the site before judging it unmeasured
SEVERITY_CRITICAL = 2  # MAV_SEVERITY_CRITICAL: a defect of the companion's own
MAX_REJECTED_RADIUS_M = 15.0  # water or traffic rules out at most this far around a rejected site


class FrameUnavailable(Exception):
    """No usable sensor frame this time (timed out, disconnected, too old): the round holds and asks
    again. What a ``FrameSource`` raises; anything else it raises is a defect and ends the recovery."""


class SensorsLost(Exception):
    """No usable frame for ``sensor_loss_s``: the recovery lands without its sensors."""


class State(enum.Enum):
    IDLE = "idle"
    ACQUIRE = "acquire"
    SURFACE_ID = "surface_id"
    RANK = "rank"
    MOVE = "move"
    CONFIRM = "confirm"
    DESCEND = "descend"
    EXPLORE = "explore"
    LAND = "land"
    LANDED = "landed"
    ABORTED = "aborted"


@dataclass(frozen=True, slots=True)
class RecoveryParams:
    rounds_by_criticality: dict[Criticality, int] = field(
        default_factory=lambda: {Criticality.LOW: 10, Criticality.HIGH: 6, Criticality.CRITICAL: 3}
    )
    descent_fraction: float = 0.8  # descend by this share of the rangefinder distance per step
    final_land_m: float = 5.0
    arrival_tolerance_m: float = 0.5
    arrival_speed_m_s: float = 0.3
    move_timeout_s: float = 60.0
    explore_climb_m: float = 15.0
    explore_max_alt_m: float = 90.0  # below the LiDAR's range (100 m): higher up it sees nothing
    blind_descent_agl_m: float = 70.0  # no LiDAR return at all and the ground farther: descend to this
    surface: SurfaceParams = field(default_factory=SurfaceParams)
    depth_source: DepthSource = field(default_factory=LidarDepth)
    rejected_radius_m: float = 4.0  # a rejected site rules out candidates this close to it
    context: str = "crop"  # what the reasoner sees per candidate: crop, pad20..pad60, or full (+ frame)
    closeup_half_m: float = 6.0  # the confirmation close-up shows this far around the site
    land_timeout_s: float = 120.0
    sensor_loss_s: float = 30.0  # wall seconds without a usable frame before landing without sensors
    link_loss_s: float = 60.0  # wall seconds without telemetry before leaving the vehicle to the autopilot
    search: SearchLimits = field(default_factory=SearchLimits)  # when searching on must stop
    search_agl_m: float = 75.0  # a search leg's least height above the ground


class Record(Protocol):
    def record_event(self, kind: str, fields: dict[str, Any]) -> None: ...

    def save_image(self, name: str, rgb: Any) -> Any: ...


class NoRecord:
    def record_event(self, kind: str, fields: dict[str, Any]) -> None:
        return None

    def save_image(self, name: str, rgb: Any) -> Any:
        return None


@dataclass
class Site:
    ned_m: tuple[float, float, float]
    candidate: Candidate


@dataclass(frozen=True, slots=True)
class Outcome:
    state: State
    rounds: int
    site_ned_m: tuple[float, float, float] | None
    reason: str


FrameSource = Callable[[], Awaitable[Any]]  # -> SensorFrame-like; raises FrameUnavailable


class Recovery:
    def __init__(
        self,
        alarm: Alarm,
        *,
        control: VehicleController,
        telemetry: TelemetryCache,
        frames: FrameSource,
        reasoner: Reasoner,
        announce: Callable[[int, str], None],
        params: RecoveryParams | None = None,
        record: Record | None = None,
        logger: logging.Logger | None = None,
    ) -> None:
        self.alarm = alarm
        self.ctl = control
        self.tm = telemetry
        self._frames = frames
        self.reasoner = reasoner
        self._announce = announce
        self.p = params or RecoveryParams()
        self.record: Record = record or NoRecord()
        self.log = logger or logging.getLogger("companion.recovery")
        self.state = State.IDLE
        self.criticality = alarm.criticality
        self.round = 0
        self.best: Site | None = None
        self.rejected: list[tuple[float, float, float]] = []  # north, east, radius (metres)
        self._reengaged = 0
        self._descending: tuple[tuple[float, float, float], Candidate] | None = None
        self.ledger = SiteLedger(self.p.rejected_radius_m)
        self.extra = 0  # rounds flown past the budget (nothing acceptable seen)
        self.search = SearchPlanner(
            alarm.criticality, self.p.search, search_agl_m=self.p.search_agl_m, lidar_range_m=100.0
        )
        self._ended: Verdict | None = None  # why the search stopped, when the battery or the window did
        # judges every measured site for the ledger, whoever decides: the cascade's own onboard tier (its
        # judge, cues or LandNet-S, as configured) when there is one
        onboard = getattr(reasoner, "onboard", None)
        self._onboard = onboard if isinstance(onboard, OnboardReasoner) else OnboardReasoner()
        self._fault = FaultHook.from_env()
        self._roofs_seen = False  # a roof measured during this recovery: a built-up area
        self._first_look: asyncio.Task[Any] | None = None  # the first frame, asked for while engaging

    @property
    def budget(self) -> int:
        return self.p.rounds_by_criticality[self.criticality]

    def raise_criticality(self, criticality: Criticality) -> None:
        """A repeated alarm can make the recovery more urgent (a shorter budget), never less."""
        if criticality > self.criticality:
            self.criticality = criticality
            self.search.raise_criticality(criticality)
            self._say(5, f"alarm raised to {criticality.name.lower()}: {self.budget} rounds")

    def _set(self, state: State) -> None:
        self.state = state
        # where the vehicle was: a flight record's trajectory for a replay (the record keeps no telemetry)
        where = [round(v, 2) for v in self.tm.state.pos_ned_m]
        self.record.record_event("state", {"state": state.value, "round": self.round, "pos_ned_m": where})

    def _say(self, severity: int, text: str) -> None:
        self.log.info("%s", text)
        self._announce(severity, f"Landfall: {text}")

    # ------------------------------------------------------------------ the loop
    async def run(self) -> Outcome:
        self._say(5, f"alarm '{self.alarm.reason}' ({self.criticality.name.lower()}), {self.budget} rounds")
        self.search.start(self._clock_s(), self.tm.state.battery_pct)
        try:
            await self._engage_and_look()
            resume: tuple[tuple[float, float, float], Candidate] | None = None
            while resume is not None or self._go_on():
                try:
                    if resume is not None:  # the link came back mid-descent: same site, confirm first
                        landed = await self._confirm_and_descend(*resume)
                    elif self.round >= self.budget:
                        landed = await self._extra_round()
                    else:
                        self.round += 1
                        self._descending = None
                        landed = await self._round()
                    resume = None
                except AutopilotFailsafe as exc:
                    resume = None
                    await self._reengage(exc)
                    continue
                except TelemetryLost as exc:
                    resume = self._descending
                    ended = await self._ride_out_link_loss(exc)
                    if ended is not None:
                        return ended
                    continue
                except SensorsLost as exc:
                    # policy: no sensors, no new site; the alarm still stands, so come down: at the
                    # best site measured so far (flown to on the autopilot's position hold), else here
                    self._say(3, f"{exc}: landing without them")
                    return await self._land_at_best("sensors lost", measure_here=False)
                if landed:
                    return Outcome(State.LANDED, self.round, self._site_ned(), "landed")
            if self._ended is not None:
                return await self._land_at_best(f"search ended ({self._ended.why})")
            return await self._land_at_best("round budget spent")
        except TouchedDown as exc:
            # the surface came sooner than measured: the vehicle is down, and says so
            self._set(State.LANDED)
            self._say(4, f"touched down before the final approach: {exc}")
            await self.ctl.release()
            return Outcome(State.LANDED, self.round, self._site_ned(), "touched down during a descent step")
        except OperatorTakeover as exc:
            self._set(State.ABORTED)
            self._say(4, "operator took over: stopped commanding")
            await self.ctl.release()
            return Outcome(State.ABORTED, self.round, None, str(exc))
        except ControlError as exc:
            self._set(State.ABORTED)
            self._say(2, f"aborted: {exc}")
            await self.ctl.release()
            return Outcome(State.ABORTED, self.round, None, str(exc))
        except Exception as exc:  # a defect of the companion's own: never leave the vehicle uncommanded
            return await self._fail_safe(exc)
        finally:
            if self._first_look is not None:  # ended before the first round used it
                self._first_look.cancel()
                with contextlib.suppress(asyncio.CancelledError, Exception):
                    await self._first_look
                self._first_look = None

    # ------------------------------------------------------------------ when nothing was accepted
    def _clock_s(self) -> float:
        """The autopilot's clock (seconds since its boot), so that a faster-than-real-time simulation
        keeps the alarm's window; the companion's monotonic clock before any telemetry."""
        t = self.tm.state.t_boot_s
        return t if t > 0 else time.monotonic()

    def _verdict(self) -> tuple[Verdict, LedgerSite | None]:
        """The search's verdict now (:meth:`SearchPlanner.verdict`), with the site the vehicle would
        land on were it to stop (whose distance the landing's need counts)."""
        s = self.tm.state
        n, e, _ = s.pos_ned_m
        site = self._fallback_site()
        to_site = math.dist(site.ned_m[:2], (n, e)) if site is not None else 0.0
        return self.search.verdict(self._clock_s(), s.battery_pct, s.rangefinder_m, to_site), site

    async def _search_instead(self, choice: Candidate) -> bool:
        """Policy: the best candidate in view, at street level or on an elevated strip, already looks
        like water or traffic from afar (the ledger's judgement of its rank crop): while the search
        may go on, it is struck off and a search leg flies instead of a round spent flying there to
        refuse it close up. A roof always gets its close look. True when it did so."""
        if choice.site_ned_m is None or (choice.elevated and not choice.strip):
            return False  # from afar a marking on a roof may be a shadow or a painted helipad
        seen = self.ledger.near((choice.site_ned_m[0], choice.site_ned_m[1]))
        if seen is None or seen.hazard < Hazard.TRAFFIC or not self._verdict()[0].search:
            return False
        what = seen.hazard.name.lower()
        self.rejected.append((seen.ned_m[0], seen.ned_m[1], self._rejected_radius(seen.ned_m, choice)))
        self.record.record_event(
            "search_instead",
            {"round": self.round, "candidate": choice.to_json(), "hazard": what, "why": seen.why},
        )
        self._say(5, f"site {choice.index} looks like {what} from afar ({seen.why[:60]}): searching instead")
        await self._search_leg()
        return True

    def _go_on(self) -> bool:
        """Policy: whether another round (or search leg and round) starts. The first look always does.
        Then the battery (what the landing needs plus a reserve) and the alarm's window may end the
        search, within the round budget too; past the budget it goes on only while nothing acceptable
        was judged close up (a roof with nothing against it)."""
        if self.round == 0:
            return True
        if self.round >= self.budget and not self._may_extend():
            return False
        verdict, site = self._verdict()
        if verdict.search:
            return True
        self._ended = verdict
        self._say(4, f"search ends: {verdict.why}")
        self.record.record_event(
            "search_end",
            {
                "note": f"search ends: {verdict.why}",
                "round": self.round,
                "reason": verdict.why,
                "battery_pct": round(verdict.battery_pct, 1) if math.isfinite(verdict.battery_pct) else None,
                "need_pct": round(verdict.need_pct, 1),
                "elapsed_s": round(verdict.elapsed_s, 1),
                "legs": len(self.search.legs),
                "best": None if site is None else site.to_json(),
            },
        )
        return False

    def _may_extend(self) -> bool:
        """Past the round budget: nothing acceptable was judged close up (a roof with nothing against
        it), so the search goes on (the battery and the window bound it, :meth:`_go_on`)."""
        if self.best is not None:
            return False
        site = self.ledger.least_bad()
        return not (site is not None and site.hazard.acceptable and site.closeup)

    async def _extra_round(self) -> bool:
        """A round past the budget: a closer look at the best roof seen only from afar (nothing seen
        against it: flown to and confirmed as any round would), or, with none, a step outward to a view
        not yet judged and a round there. True when it landed."""
        self.extra += 1
        self.round += 1
        self._descending = None
        n, e, _ = self.tm.state.pos_ned_m
        site = self.ledger.least_bad((n, e))
        battery = self.tm.state.battery_pct
        charge = f", battery {battery:.0f} %" if math.isfinite(battery) else ""
        count = f"{self.extra}{charge}"
        look = (
            site is not None
            and site.hazard.acceptable
            and not site.closeup
            and not site.looked
            and site.candidate is not None
        )
        self.record.record_event(
            "extend",
            {
                "round": self.round,
                "extra": self.extra,
                "best": None if site is None else site.to_json(),
                "action": "closer look" if look else "explore",
            },
        )
        if look:
            assert site is not None
            self._say(5, f"budget spent: a closer look at {site.label}, seen only from afar ({count})")
            site.looked = True  # once: a site the vehicle cannot reach is not tried again
            if not await self._fly_over(site, site.label, then="next round"):
                return False  # not over it: no confirmation, no descent from elsewhere
            return await self._confirm_and_descend(site.ned_m, site.candidate)
        seen = (
            "nothing measured"
            if site is None
            else f"the best seen is {site.hazard.name.lower().replace('_', ' ')}"
        )
        self._say(4, f"budget spent, {seen}: searching on ({count})")
        await self._search_leg()
        return await self._round()

    async def _search_leg(self) -> Leg:
        """Fly the planner's next leg (:meth:`SearchPlanner.next_leg`): climb first when the leg goes
        higher, descend last when it goes lower, so the level part flies at the safer height. Said,
        recorded (``search_leg``) and shown on the ground feed."""
        self._set(State.EXPLORE)
        s = self.tm.state
        n, e, d = s.pos_ned_m
        leg = await asyncio.to_thread(self.search.next_leg, (n, e, d), self.ledger, s.rangefinder_m)
        tn, te, td = leg.target_ned_m
        count = len(self.search.legs)
        note = f"search leg {count}: {leg.reason}"
        self._say(5, note)
        self.record.record_event(
            "search_leg",
            {
                "note": note,
                "round": self.round,
                "leg": count,
                "from_ned_m": [round(v, 1) for v in (n, e, d)],
                "battery_pct": round(s.battery_pct, 1) if math.isfinite(s.battery_pct) else None,
                **leg.to_json(),
            },
        )
        steps = [(n, e, td), (tn, te, td)] if td < d - 3.0 else [(tn, te, d), (tn, te, td)]
        for sn, se, sd in steps:
            with contextlib.suppress(TargetTimeout):
                await self.ctl.goto(
                    sn,
                    se,
                    sd,
                    tolerance_m=2.0,
                    speed_m_s=0.5,
                    timeout_s=self.p.move_timeout_s + math.dist((sn, se, sd), self.tm.state.pos_ned_m) / 2.0,
                )
        return leg

    async def _fail_safe(self, exc: Exception) -> Outcome:
        """Policy for a defect of the companion's own (an exception no stage expects): announce it
        (STATUSTEXT, critical), record it with its traceback, and land: at the best site already
        measured (accepted, else the ledger's least bad; nothing is measured anew), else with the
        autopilot's land mode where the vehicle is. Should that landing fail too, land mode once more,
        then the vehicle is left to the autopilot."""
        where = self.state.value
        text = f"{type(exc).__name__}: {exc}"
        self.log.error("defect in the recovery (%s): %s", where, text, exc_info=exc)
        self.record.record_event(
            "defect",
            {
                "round": self.round,
                "state": where,
                "error": text,
                "traceback": "".join(traceback.format_exception(exc)),
            },
        )
        # a STATUSTEXT holds 50 characters: what happened and what the vehicle does come first
        self._say(SEVERITY_CRITICAL, f"internal error, landing: {type(exc).__name__} in {where}: {exc}"[:150])
        site = self._fallback_site()
        try:
            try:
                if site is not None:
                    await self._fly_over(site, "best site measured")
                await self._final_land()
            except (TouchedDown, OperatorTakeover):
                raise
            except Exception as again:  # the landing itself failed: the autopilot's land mode, once more
                self.log.error("fail-safe landing failed (%r): autopilot land mode", again)
                self.record.record_event(
                    "defect", {"round": self.round, "state": "land", "error": repr(again)}
                )
                await self._final_land()
        except TouchedDown:
            self._set(State.LANDED)
        except OperatorTakeover as taken:
            self._set(State.ABORTED)
            await self.ctl.release()
            return Outcome(State.ABORTED, self.round, None, f"defect ({text}), then {taken}")
        except Exception as last:
            self._set(State.ABORTED)
            self._say(SEVERITY_CRITICAL, "fail-safe landing failed: the autopilot has the vehicle")
            with contextlib.suppress(Exception):
                await self.ctl.release()
            return Outcome(State.ABORTED, self.round, None, f"defect ({text}); landing failed ({last!r})")
        return Outcome(
            State.LANDED, self.round, site.ned_m if site is not None else None, f"defect ({text}): landed"
        )

    async def _reengage(self, exc: AutopilotFailsafe) -> None:
        """Policy: the autopilot's own failsafe (e.g. a lost setpoint stream) is re-engaged from where
        the vehicle is, ``MAX_REENGAGE`` times at most; then the autopilot keeps control."""
        self._reengaged += 1
        if self._reengaged > MAX_REENGAGE:
            raise ControlError(f"{exc}; not re-engaging again") from exc
        self._say(4, f"{exc}: re-engaging")
        await self.ctl.engage()

    async def _ride_out_link_loss(self, exc: TelemetryLost) -> Outcome | None:
        """Policy for a lost MAVLink link: keep streaming the last setpoint and wait up to
        ``link_loss_s`` for telemetry. Meanwhile the autopilot holds (PX4's offboard-loss failsafe
        after COM_OF_LOSS_T; ArduPilot's GUIDED keeps the last target). When the link returns: a
        vehicle that came down meanwhile ends the recovery; a failsafe is re-engaged from where the
        vehicle is; someone else's mode is a takeover. Then an interrupted descent goes on at the
        same site, confirmed again first; otherwise the next round starts. No telemetry within
        ``link_loss_s``: the companion stops commanding and leaves the vehicle to the autopilot."""
        self.record.record_event("link_lost", {"round": self.round, "state": self.state.value})
        self._say(3, f"link to the autopilot lost ({exc}): holding, waiting {self.p.link_loss_s:.0f} s")
        try:
            silent_s = await self.ctl.await_link(self.p.link_loss_s)
        except TelemetryLost as lost:
            raise ControlError(f"{lost}: leaving the vehicle to the autopilot") from lost
        s = self.tm.state
        self.record.record_event(
            "link_restored",
            {"round": self.round, "silent_s": round(silent_s, 2), "custom_mode": s.custom_mode},
        )
        self._say(5, f"link back after {silent_s:.1f} s")
        if s.on_ground:
            self._set(State.LANDED)
            self._say(4, "the vehicle came down while the link was lost")
            return Outcome(State.LANDED, self.round, None, "landed by the autopilot during a link loss")
        try:
            self.ctl.check_interruption()
        except AutopilotFailsafe as failsafe:
            await self._reengage(failsafe)
        return None

    def _site_ned(self) -> tuple[float, float, float] | None:
        return self.best.ned_m if self.best is not None else None

    async def _engage_and_look(self) -> None:
        """Take control and ask for the first round's frame at the same time: the frame (render,
        transfer) takes longer than the mode switch, and the vehicle holds either way."""
        look = asyncio.create_task(self._acquire(first_round=True), name="first-frame")
        try:
            await self.ctl.engage()
        except BaseException:
            look.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await look
            raise
        self._first_look = look

    async def _acquire(self, *, first_round: bool = False) -> Any:
        """A frame; while none comes, the vehicle holds on its current setpoint and the request is
        repeated every ``SENSOR_RETRY_S``, each failure recorded. Raises ``SensorsLost`` after
        ``sensor_loss_s`` without one."""
        self._set(State.ACQUIRE)
        self._fault.check("acquire", 1 if first_round else self.round)
        since = time.monotonic()
        for attempt in itertools.count():
            try:
                return await self._frames()
            except FrameUnavailable as exc:
                waited = time.monotonic() - since
                self.record.record_event(
                    "sensor_fault", {"round": self.round, "error": str(exc), "waited_s": round(waited, 2)}
                )
                if waited >= self.p.sensor_loss_s:
                    raise SensorsLost(f"no usable sensor frame for {waited:.0f} s ({exc})") from exc
                if attempt == 0:
                    self._say(4, f"no sensor frame ({exc}): holding, asking again")
                await asyncio.sleep(SENSOR_RETRY_S)
        raise AssertionError("unreachable")

    async def _round(self) -> bool:
        look, self._first_look = self._first_look, None
        frame = await (look if look is not None else self._acquire())
        self._set(State.SURFACE_ID)
        camera = PinholeCamera(frame.width, frame.height, frame.fx, frame.fy, frame.cx, frame.cy)
        candidates = await asyncio.to_thread(self._surface_id, frame, camera)
        await asyncio.to_thread(self._observe, frame)  # the search's map of what was seen
        # roofs the LiDAR saw beyond Surface ID's candidates make it a built-up area too
        self._roofs_seen = self._roofs_seen or bool(self.search.roof_groups())
        self._roofs_seen = self._roofs_seen or any(c.elevated for c in candidates)
        candidates = [c for c in candidates if not self._near_rejected(c)]
        if frame.image_rgb is not None:  # JPEG encoding off the event loop: the setpoint stream runs there
            await asyncio.to_thread(self.record.save_image, f"round{self.round:02d}-acquire", frame.image_rgb)
        if not candidates or all(c.fallback for c in candidates):
            await self._explore(blind=_lidar_silent(frame.lidar_frd))
            return False
        self._set(State.RANK)
        ranking, chosen = await self._rank(candidates, frame)
        if frame.image_rgb is not None:
            await asyncio.to_thread(self._note_candidates, candidates, frame, camera)
        choice = candidates[chosen] if chosen is not None else None
        if choice is None:
            await self._explore()
            return False
        if await self._search_instead(choice):
            return False
        target = await asyncio.to_thread(self._ipm, choice, frame, camera)
        if target is None:
            self._say(4, f"site {choice.index} cannot be placed in the world: next round")
            return False
        n, e, d = self.tm.state.pos_ned_m
        dist = math.hypot(target[0] - n, target[1] - e)
        bearing = _compass(math.degrees(math.atan2(target[1] - e, target[0] - n)))
        kind = "roof" if choice.height_above_m >= 3.0 else "ground"
        self._say(6, f"site {choice.index} {kind} {dist:.0f} m {bearing}")
        self._say(6, ranking.rationale[:200])
        self._set(State.MOVE)
        self._fault.check("move", self.round)
        try:
            await self.ctl.goto(
                target[0],
                target[1],
                d,
                tolerance_m=self.p.arrival_tolerance_m,
                speed_m_s=self.p.arrival_speed_m_s,
                timeout_s=self.p.move_timeout_s + dist / 2.0,
            )
        except TargetTimeout as exc:
            self._say(4, f"target not reached ({exc.error_m:.1f} m off): next round")
            return False
        return await self._confirm_and_descend(target, choice)

    async def _confirm_and_descend(self, target: tuple[float, float, float], choice: Candidate) -> bool:
        self._descending = (target, choice)  # what a link loss resumes: this site, confirmed again
        while True:
            frame, check = await self._measure_site(target)
            decision = await self._confirm(check, frame, target, choice)
            if not decision.accept and decision.contested:
                # a lone "no" on a clear site: ask again next round (the cascade's lone-"no" rule)
                self._say(4, f"site {choice.index} contested: {decision.rationale[:110]}")
                return False
            if not decision.accept:
                self.rejected.append((target[0], target[1], self._rejected_radius(target, choice)))
                if (
                    self.best is not None
                    and math.dist(self.best.ned_m[:2], target[:2]) < self.p.rejected_radius_m
                ):
                    self.best = None
                self._say(4, f"site {choice.index} {decision.rationale[:120]}")
                return False
            self.best = Site(target, choice)
            _n, _e, d = self.tm.state.pos_ned_m
            rng_m, rng_quat = frame.rangefinder_m, frame.quat_wxyz
            if not math.isfinite(rng_m):
                rng_m, rng_quat = self.tm.state.rangefinder_m, self.tm.state.quat_wxyz
            height_m = height_above_site(
                d,
                surface_up_m=check.surface_up_m,
                site_d_m=target[2],
                rangefinder_m=rng_m,
                quat_wxyz=rng_quat,
            )
            if not math.isfinite(height_m):
                self._say(4, "no height above the site measured: next round")
                return False
            if height_m <= self.p.final_land_m:
                return await self._land()
            self._set(State.DESCEND)
            self._fault.check("descend", self.round)
            step_m = self.p.descent_fraction * height_m
            new_d = d + step_m
            self._say(6, f"descending {step_m:.0f} m, {decision.rationale[:80]}")
            try:
                await self.ctl.goto(
                    target[0],
                    target[1],
                    new_d,
                    tolerance_m=self.p.arrival_tolerance_m,
                    speed_m_s=self.p.arrival_speed_m_s,
                    timeout_s=self.p.move_timeout_s + rng_m,
                )
            except TargetTimeout as exc:
                self._say(4, f"descent target not reached ({exc.error_m:.1f} m off): next round")
                return False

    async def _measure_site(self, target: tuple[float, float, float]) -> tuple[Any, SiteCheck]:
        """A frame and the LiDAR check of the site under it.

        Policy: a sweep that misses the site (empty, or too few returns in the rotor disc: a partial
        sweep) is a sensor gap, not a hazard. It is recorded as a ``sensor_fault`` and a new frame is
        asked for, ``SITE_RETRIES`` times at most; then the site goes to the reasoner unmeasured and is
        judged from the image, as with no LiDAR at all (a frame without one goes so at once). A gap
        never strikes a site off."""
        for attempt in range(SITE_RETRIES + 1):
            frame = await self._acquire()
            self._set(State.CONFIRM)
            check = await asyncio.to_thread(
                check_site, frame.lidar_frd, frame.pos_ned_m, frame.quat_wxyz, (target[0], target[1])
            )
            if check.measured or frame.lidar_frd is None:
                return frame, check
            self.record.record_event(
                "sensor_fault",
                {
                    "round": self.round,
                    "error": f"site not measured: {check.points} LiDAR returns in the rotor disc",
                    "attempt": attempt,
                },
            )
            if attempt < SITE_RETRIES:
                await asyncio.sleep(SENSOR_RETRY_S)
        self._say(4, "the LiDAR keeps missing the site: judging it from the image")
        return frame, check

    async def _land(self) -> bool:
        self._set(State.LAND)
        self._fault.check("land", self.round)
        await self._final_land()
        return True

    async def _final_land(self) -> None:
        self._set(State.LAND)
        self._say(5, "final approach: autopilot land mode")
        await self.ctl.land(self.p.land_timeout_s)
        self._set(State.LANDED)
        self._say(5, "landed")

    async def _land_at_best(self, reason: str, *, measure_here: bool = True) -> Outcome:
        """Land at the accepted site, else at the least bad one measured (:mod:`companion.site_ledger`),
        judging the spot under the vehicle too when sensors allow (``measure_here``); "here" only when
        nothing at all was measured, and said so."""
        if measure_here and self.best is None:
            await self._look_around()
            await self._measure_here()
        site = self._fallback_site()
        if site is None and not self.ledger.sites:
            self._say(4, f"{reason} with nothing measured: landing here")
        elif site is None:
            self._say(4, f"{reason}, only water or traffic measured elsewhere: landing here")
        else:
            where = "here" if site.label == "here" else f"at {site.label}"
            self._say(
                4, f"{reason}: landing {where} ({site.hazard.name.lower().replace('_', ' ')}: {site.why})"
            )
            self.record.record_event(
                "fallback_site",
                {
                    "round": self.round,
                    "reason": reason,
                    "chosen": site.to_json(),
                    "sites": [s.to_json() for s in self.ledger.sites],
                },
            )
            await self._fly_over(site, "the chosen site")
        await self._land()
        return Outcome(State.LANDED, self.round, site.ned_m if site is not None else None, reason)

    def _fallback_site(self) -> LedgerSite | None:
        """The accepted site, else the ledger's least bad, else None."""
        if self.best is not None:
            label = f"site {self.best.candidate.index}"
            return LedgerSite(
                self.best.ned_m, Hazard.ACCEPTED, "confirmed for descent", self.round, True, label=label
            )
        n, e, _ = self.tm.state.pos_ned_m
        site = self.ledger.least_bad((n, e))
        if site is not None and site.hazard > Hazard.UNKNOWN and not self.ledger.near((n, e)):
            return None  # only water or traffic measured, and not here: unknown beats known bad
        return site

    async def _fly_over(self, site: LedgerSite, what: str, then: str = "landing here") -> bool:
        """Fly over ``site`` at the current altitude; False (said, with what happens ``then``) when it
        was not reached in time."""
        n, e, _ = site.ned_m
        n0, e0, d = self.tm.state.pos_ned_m
        try:
            await self.ctl.goto(
                n,
                e,
                d,
                tolerance_m=self.p.arrival_tolerance_m,
                speed_m_s=self.p.arrival_speed_m_s,
                timeout_s=self.p.move_timeout_s + math.hypot(n - n0, e - e0) / 2.0,
            )
        except TargetTimeout as exc:
            self._say(4, f"{what} target not reached ({exc.error_m:.1f} m off): {then}")
            return False
        return True

    async def _look_around(self) -> None:
        """One look at what is in view now (Surface ID's candidates, judged from afar into the
        ledger), so that the least bad site is chosen among what can be reached at once, not only
        among what earlier rounds measured: a search that ends after a blind first look, a battery
        at its reserve. One frame, no waiting: a missing frame skips it."""
        try:
            frame = await self._frames()
        except FrameUnavailable:
            return
        camera = PinholeCamera(frame.width, frame.height, frame.fx, frame.fy, frame.cx, frame.cy)
        candidates = await asyncio.to_thread(self._surface_id, frame, camera)
        await asyncio.to_thread(self._note_candidates, candidates, frame, camera)

    async def _measure_here(self) -> None:
        """Judge the spot under the vehicle (one frame, no waiting: a missing frame skips it) into the
        ledger, so that "here" competes with the sites measured before on what is there."""
        try:
            frame = await self._frames()
        except FrameUnavailable:
            return
        n, e, d = self.tm.state.pos_ned_m
        check = await asyncio.to_thread(check_site, frame.lidar_frd, frame.pos_ned_m, frame.quat_wxyz, (n, e))
        rng = frame.rangefinder_m if math.isfinite(frame.rangefinder_m) else self.tm.state.rangefinder_m
        ground_d = -check.surface_up_m if check.measured else d + rng
        if not math.isfinite(ground_d):
            return
        target = (n, e, ground_d)
        up_m = _height_above_surroundings(frame, check) if check.measured else None
        kinds = await asyncio.to_thread(self._judge, frame, check, target, up_m, False)
        hazard = hazard_of(
            kinds,
            accepted=False,
            street_level=up_m is None or up_m < ROOF_HEIGHT_M,
            strip=False,
            judged=check.measured or frame.image_rgb is not None,
        )
        self.ledger.add(
            LedgerSite(
                target, hazard, ", ".join(kinds) or "nothing seen against it", self.round, True, label="here"
            )
        )

    def _judge(
        self,
        frame: Any,
        check: SiteCheck,
        target: tuple[float, float, float],
        up_m: float | None,
        strip: bool,
    ) -> tuple[str, ...]:
        """What the onboard tier sees against a site (``Decision.hazards``), from the close-up of
        ``frame`` around it and the LiDAR check; the LiDAR's kind alone without an image. A worker-
        thread job."""
        if frame.image_rgb is None:
            return (lidar_kind(check),) if check.measured and not check.clear else ()
        closeup = self._closeup(frame.image_rgb, frame, target)
        request = ConfirmRequest(closeup, check if check.measured else None, site_up_m=up_m, site_strip=strip)
        return self._onboard.confirm_sync(request).hazards

    def _note_candidates(self, candidates: list[Candidate], frame: Any, camera: PinholeCamera) -> None:
        """Every measured candidate of a round into the ledger, judged from afar: the onboard tier's
        view of the frame around its site, as a confirmation would see it (a worker-thread job)."""
        for c in candidates:
            if c.fallback or c.site_ned_m is None:
                continue
            up_m = c.height_above_m if math.isfinite(c.height_above_m) else None
            kinds = self._judge(frame, _UNMEASURED, c.site_ned_m, up_m, c.strip)
            hazard = hazard_of(
                kinds, accepted=False, street_level=not c.elevated and not c.strip, strip=c.strip
            )
            why = ", ".join(kinds) or "nothing seen against it from afar"
            self.ledger.add(
                LedgerSite(
                    c.site_ned_m, hazard, why, self.round, False, c.edge_distance_m, f"site {c.index}", c
                )
            )

    async def _explore(self, blind: bool = False) -> None:
        """Nothing survived screening: climb for a wider view, else fly a search leg
        (:meth:`_search_leg`) to roofs the LiDAR saw or to ground not yet seen.

        ``blind``: the LiDAR returned nothing at all. When the rangefinder agrees that the ground is
        far (beyond ``blind_descent_agl_m``), everything below is out of the LiDAR's range: climbing
        or moving would not help, so descend to ``blind_descent_agl_m`` first. The LiDAR's silence
        says nothing stands within its range below, so the descent has nothing to hit. A silent
        LiDAR with the ground near is a failed LiDAR: no blind descent then.

        Whenever the rangefinder puts the ground more than ``explore_max_alt_m`` below (a roof left
        behind, low ground), the step is a descent to ``explore_max_alt_m`` above it: from higher up
        the LiDAR reaches nothing flat."""
        self._set(State.EXPLORE)
        n, e, d = self.tm.state.pos_ned_m
        alt = self.tm.state.rangefinder_m
        beyond = math.isfinite(alt) and alt > self.p.explore_max_alt_m + 5.0
        if blind and math.isfinite(alt) and alt > self.p.blind_descent_agl_m + 5.0:
            drop = alt - self.p.blind_descent_agl_m
            target = (n, e, d + drop)
            self._say(6, f"LiDAR sees nothing, ground {alt:.0f} m below: descending {drop:.0f} m")
        elif beyond:
            # the rangefinder measured the column below clear all the way down: descend within reach
            drop = alt - self.p.explore_max_alt_m
            target = (n, e, d + drop)
            self._say(6, f"ground {alt:.0f} m below, beyond the LiDAR's reach: descending {drop:.0f} m")
        elif math.isfinite(alt) and alt + self.p.explore_climb_m <= self.p.search_agl_m:
            # low down a climb widens the view; at the search height the LiDAR's reach would shrink
            target = (n, e, d - self.p.explore_climb_m)
            self._say(6, f"no flat site in view: climbing {self.p.explore_climb_m:.0f} m")
        else:
            await self._search_leg()
            return
        with contextlib.suppress(TargetTimeout):
            await self.ctl.goto(*target, tolerance_m=1.0, speed_m_s=0.5, timeout_s=self.p.move_timeout_s)

    def _observe(self, frame: Any) -> None:
        """The frame into the search's map: the LiDAR's sweep, and with LandNet-S as the onboard judge
        what the camera shows beyond it (water and traffic). A worker-thread job."""
        self.search.observe(frame)
        net = self._onboard.landnet
        if net is not None and frame.image_rgb is not None:
            self.search.observe_camera(frame, net.presence, tuple(net.classes))

    def _surface_id(self, frame: Any, camera: PinholeCamera) -> list[Candidate]:
        """Candidates from the configured depth source; the quadrant fallback when it has nothing."""
        self._fault.check("surface_id", self.round)
        try:
            cands, _depth = propose(
                self.p.depth_source,
                camera,
                image=frame.image_rgb,
                lidar_frd=frame.lidar_frd,
                quat_wxyz=frame.quat_wxyz,
                pos_ned_m=frame.pos_ned_m,
                ground_up_m=frame.pos_ned_m[2],
                params=self.p.surface,
            )
        except DepthError as exc:
            self.log.warning("Surface ID has no depth (%s): quadrant fallback", exc)
            return quadrant_fallback(camera)
        return cands

    async def _rank(self, candidates: list[Candidate], frame: Any) -> tuple[Ranking, int | None]:
        """The reasoner's order of the candidates, from their crops (the configured context variant),
        and the one the vehicle flies to: the first in that order that is not a fallback crop (a
        quadrant has no measured site). Both go to the record's ``rank`` event (``order``, ``chosen``)."""
        self._fault.check("rank", self.round)
        image = frame.image_rgb
        names: list[str] = []
        if image is None:
            # no camera image this frame: Surface ID's own order (its score), said so in the record
            ranking = Ranking(
                tuple(c.index for c in candidates),
                "no camera image: Surface ID's order (flat area, clearance, elevation)",
                "surface-id",
                0.0,
            )
        else:
            crops, cores, names = await asyncio.to_thread(self._rank_crops, image, candidates)
            request = RankRequest(
                crops,
                None if all(c.fallback for c in candidates) else tuple(candidates),
                context=image if self.p.context == "full" else None,
                critical=self.criticality == Criticality.CRITICAL,
                cores=cores if pad_of(self.p.context) > 0 else None,
            )
            ranking = await self.reasoner.rank(request)
        chosen = next((k for k in ranking.order if not candidates[k].fallback), None)
        self.record.record_event(
            "rank",
            {
                "round": self.round,
                "order": list(ranking.order),
                "chosen": chosen,
                "rationale": ranking.rationale,
                "tier": ranking.tier,
                "latency_s": ranking.latency_s,
                "context": self.p.context,
                "images": names,
                "candidates": [c.to_json() for c in candidates],
                # the candidates' frame, on the autopilot's clock: where an evaluation finds what the
                # chosen pixel truly shows (the simulator's episode log holds the pose it was taken from)
                "frame_time_boot_ms": getattr(frame, "time_boot_ms", None),
            },
        )
        return ranking, chosen

    async def _confirm(
        self, check: SiteCheck, frame: Any, target: tuple[float, float, float], choice: Candidate
    ) -> Decision:
        """Reasoner and geometric veto on a close-up of the site (the cascade arbitrates); the verdict
        goes to the ledger too, with what the onboard tier saw against the site whoever decided."""
        self._fault.check("confirm", self.round)
        image = frame.image_rgb
        if image is None and not check.measured:
            # neither sensor judged the site: not a reason to strike it off (contested: asked again)
            decision = Decision(
                False, "no camera image, and the LiDAR missed the site: not judged", "site-check", 0.0, True
            )
            closeup_name = ""
        elif image is None:
            decision = Decision(
                check.clear,
                "no camera image: LiDAR check only: "
                + ("clear" if check.clear else "; ".join(check.reasons)),
                "site-check",
                0.0,
            )
            closeup_name = ""
        else:
            closeup, closeup_name = await asyncio.to_thread(self._closeup_saved, image, frame, target)
            decision = await self.reasoner.confirm(
                ConfirmRequest(
                    closeup,
                    check if check.measured else None,
                    critical=self.criticality == Criticality.CRITICAL,
                    site_ne_m=(target[0], target[1]),
                    site_up_m=choice.height_above_m if math.isfinite(choice.height_above_m) else None,
                    site_strip=choice.strip,
                    built_up=self._roofs_seen,
                )
            )
        up_m = choice.height_above_m if math.isfinite(choice.height_above_m) else None
        if decision.tier == self._onboard.name or image is None:
            kinds = decision.hazards or ((lidar_kind(check),) if check.measured and not check.clear else ())
        else:  # a remote tier decided: the ledger still wants the onboard tier's view of the site
            kinds = await asyncio.to_thread(self._judge, frame, check, target, up_m, choice.strip)
        hazard = hazard_of(
            kinds,
            accepted=decision.accept,
            street_level=not choice.elevated and not choice.strip,
            strip=choice.strip,
            judged=image is not None or check.measured,
        )
        why = decision.rationale[:160] if not decision.accept else "confirmed for descent"
        self.ledger.add(
            LedgerSite(
                target, hazard, why, self.round, True, choice.edge_distance_m, f"site {choice.index}", choice
            )
        )
        self.record.record_event(
            "confirm",
            {
                "round": self.round,
                "accept": decision.accept,
                "rationale": decision.rationale,
                "tier": decision.tier,
                "latency_s": decision.latency_s,
                "site_ned_m": list(target),
                "candidate": choice.to_json(),  # whose pixel the site is (its rank event has its frame)
                "hazard": hazard.name.lower(),
                "image": closeup_name,
                "check": {
                    "points": check.points,
                    "roughness_m": check.roughness_m,
                    "obstacle_m": check.obstacle_m,
                    "edge_distance_m": check.edge_distance_m,
                    "reasons": list(check.reasons),
                },
            },
        )
        return decision

    def _rank_crops(
        self, image: Any, candidates: list[Candidate]
    ) -> tuple[tuple[Any, ...], tuple[tuple[int, int, int, int], ...], list[str]]:
        """The crops the reasoner ranks (and their cores), saved to the record: a worker-thread job."""
        crops, cores = rank_crops(image, [c.box_px for c in candidates], self.p.context)
        names = [
            self._saved_name(self.record.save_image(f"round{self.round:02d}-rank-crop{k}", c))
            for k, c in enumerate(crops)
        ]
        return crops, cores, names

    def _closeup_saved(self, image: Any, frame: Any, target: tuple[float, float, float]) -> tuple[Any, str]:
        closeup = self._closeup(image, frame, target)
        return closeup, self._saved_name(self.record.save_image(f"round{self.round:02d}-confirm", closeup))

    @staticmethod
    def _saved_name(path: Any) -> str:
        return str(getattr(path, "name", path)) if path is not None else ""

    def _closeup(self, image: Any, frame: Any, target: tuple[float, float, float]) -> Any:
        camera = PinholeCamera(frame.width, frame.height, frame.fx, frame.fy, frame.cx, frame.cy)
        return site_closeup(image, camera, frame.pos_ned_m, frame.quat_wxyz, target, self.p.closeup_half_m)

    def _near_rejected(self, c: Candidate) -> bool:
        if c.site_ned_m is None:
            return False
        return any(math.dist(c.site_ned_m[:2], (n, e)) < r for n, e, r in self.rejected)

    def _rejected_radius(self, target: tuple[float, float, float], choice: Candidate) -> float:
        """How far a rejected site rules out candidates: ``rejected_radius_m``; for water or a traffic
        lane, the surface's own size (half the side of a square of its area, up to
        ``MAX_REJECTED_RADIUS_M``): another point of the same harbour or street is no better."""
        site = self.ledger.near((target[0], target[1]))
        radius = self.p.rejected_radius_m
        if site is not None and site.hazard >= Hazard.TRAFFIC and math.isfinite(choice.area_m2):
            radius = max(radius, min(MAX_REJECTED_RADIUS_M, 0.5 * math.sqrt(choice.area_m2)))
        return radius

    def _ipm(self, c: Candidate, frame: Any, camera: PinholeCamera) -> tuple[float, float, float] | None:
        """The chosen pixel -> world point through the LiDAR; the flat-ground fallback without it;
        None when neither can place it."""
        self._fault.check("ipm", self.round)
        u, v = c.centre_px
        try:
            index = LidarPixelIndex(frame.lidar_frd, camera)
            p = pixel_to_ned(u, v, index, frame.pos_ned_m, frame.quat_wxyz)
        except IpmError as exc:
            ground_d = frame.pos_ned_m[2] + frame.rangefinder_m
            self.log.warning(
                "IPM through the LiDAR failed (%s): flat ground at the rangefinder distance", exc
            )
            try:
                p = pixel_to_ned_flat(u, v, camera, frame.pos_ned_m, frame.quat_wxyz, ground_d)
            except IpmError as flat:  # e.g. a rangefinder reading 0: the ray never meets that plane
                self.log.warning("and flat ground failed too (%s): no world position", flat)
                return None
        return (float(p[0]), float(p[1]), float(p[2]))


def site_closeup(
    image: np.ndarray,
    camera: PinholeCamera,
    pos_ned_m: Any,
    quat_wxyz: Any,
    target_ned_m: Any,
    half_m: float,
) -> np.ndarray:
    """The part of a camera frame within ``half_m`` of the site, centred on it (``site_box``), or the
    whole frame when the site is not in view: what the confirm stage judges."""
    rel = np.asarray(target_ned_m, dtype=float) - np.asarray(pos_ned_m, dtype=float)
    uv, front = camera.project_frd((rel @ quat_to_matrix(quat_wxyz))[None, :])
    dist = float(np.linalg.norm(rel))
    if not front[0] or not (0 <= uv[0, 0] < camera.width and 0 <= uv[0, 1] < camera.height) or dist <= 0:
        return image
    half = int(camera.fx * half_m / dist)
    return crop(image, site_box(uv[0, 0], uv[0, 1], half, camera.width, camera.height))


_UNMEASURED = SiteCheck(0, math.nan, math.nan, math.nan, math.nan, ("not measured",))


def _height_above_surroundings(frame: Any, check: SiteCheck) -> float | None:
    """How far the measured surface under a site stands above the lowest tenth of the sweep's returns
    (what Surface ID calls elevation), or None without enough returns."""
    if frame.lidar_frd is None or len(frame.lidar_frd) < 20:
        return None
    up = -world_points(frame.lidar_frd, frame.pos_ned_m, frame.quat_wxyz)[:, 2]
    if len(up) < 20:
        return None
    return float(check.surface_up_m - np.percentile(up, 10))


def _lidar_silent(lidar_frd: Any) -> bool:
    """A LiDAR sweep came and has no return with a finite position (a missing sweep is not silence)."""
    if lidar_frd is None:
        return False
    pts = np.asarray(lidar_frd, dtype=float)
    return pts.ndim != 2 or pts.shape[0] == 0 or not bool(np.isfinite(pts[:, :3]).all(axis=1).any())


def _compass(bearing_deg: float) -> str:
    names = ["N", "NE", "E", "SE", "S", "SW", "W", "NW"]
    return names[round((bearing_deg % 360) / 45) % 8]
