"""What a recovery is made of: its states, parameters, outcome and record protocol, and the context
the parts of :class:`~companion.recovery.Recovery` share (:class:`RecoveryContext`), given to each at
its construction."""

from __future__ import annotations

import contextlib
import enum
import logging
import math
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

from companion.alarms import Alarm, Criticality
from companion.config_schema import DEFAULTS, CompanionConfig
from companion.control import TargetTimeout, VehicleController
from companion.faults import FaultHook
from companion.perception.depth import DepthSource, LidarDepth
from companion.perception.sources import make_source
from companion.perception.surface_id import Candidate, SurfaceParams
from companion.recovery.search_plan import SearchLimits
from companion.site_ledger import Hazard, SiteLedger
from companion.telemetry import TelemetryCache

MAX_REENGAGE = 2
MAX_RESUMES = 3  # descents gone on with at the same site after a failsafe or a lost link, in a recovery
SENSOR_RETRY_S = 1.0  # between two asks for a frame after one failed
SITE_RETRIES = 2  # more frames asked for when a LiDAR sweep misses the site before judging it unmeasured
PEOPLE_LOOK_AGAIN_S = 2.0  # wall seconds between two looks at people near a site, held where it is
PEOPLE_WATCH_STEP_S = 1.0  # wall seconds between two looks at people near a site on the way down
TRANSIT_CLEARANCE_M = 10.0  # a level move flies at least this far above every roof measured near it
TRANSIT_NEAR_M = 100.0  # ... within this of where it starts or ends
TRANSIT_CORRIDOR_M = 15.0  # ... and over every LiDAR return measured this near its path (cell centres)
GO_AROUND_M = 15.0  # a final approach stopped for people climbs back this high above the site
GO_AROUND_MIN_M = 2.0  # below this height above the site the final approach is not stopped any more
QUIET_LOOKS = 2  # looks in a row without anyone before a site where people were seen is descended onto
ASIDE_CLEAR_M = 3.0  # a site stepped aside to lies this much beyond the people margin from everyone seen
ASIDE_EDGE_KEEP_M = 5.0  # and at least this far inside its surface's edge (from Surface ID's edge distance)
ASIDE_MAX = 3  # steps aside from people on one site before holding for them to go
FALLBACK_PEOPLE_WAIT_S = 60.0  # autopilot seconds a fallback landing holds for people in all, then lands
SEVERITY_CRITICAL = 2  # MAV_SEVERITY_CRITICAL: a defect of the companion's own
MAX_REJECTED_RADIUS_M = 15.0  # water or traffic rules out at most this far around a rejected site
# a site at street level with roofs measured this close is among buildings (people and traffic come back)
BUILT_UP_RADIUS_M = 200.0
# a site beyond the fence's circle whose surface reaches inside it is moved inside (Looker.pull_inside_fence)
# where it then stays this far from the surface's edge (the onboard tier's default open-ground edge) ...
PULLED_EDGE_M = DEFAULTS.reasoner.open_ground_edge_m
PULL_SPARE_M = 2.0  # ... and this far inside the circle


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
    """The recovery's parameters. A field named as a ``[recovery]`` key is that key: its default is the
    schema's (:data:`~companion.config_schema.DEFAULTS`) and :meth:`from_config` copies its value;
    ``deploy/companion.toml`` gives its unit and meaning. The fields no key sets say so."""

    rounds_by_criticality: dict[Criticality, int] = field(default_factory=DEFAULTS.recovery.rounds)
    descent_fraction: float = DEFAULTS.recovery.descent_fraction  # of the rangefinder distance, a step
    final_land_m: float = DEFAULTS.recovery.final_land_m
    arrival_tolerance_m: float = DEFAULTS.recovery.arrival_tolerance_m
    arrival_speed_m_s: float = DEFAULTS.recovery.arrival_speed_m_s
    move_timeout_s: float = DEFAULTS.recovery.move_timeout_s
    move_timeout_s_per_m: float = DEFAULTS.recovery.move_timeout_s_per_m  # on top of move_timeout_s
    explore_climb_m: float = DEFAULTS.recovery.explore_climb_m
    explore_max_alt_m: float = DEFAULTS.recovery.explore_max_alt_m  # below the LiDAR's range
    blind_descent_agl_m: float = DEFAULTS.recovery.blind_descent_agl_m  # no LiDAR return: descend to this
    surface: SurfaceParams = field(default_factory=SurfaceParams)  # [perception]
    depth_source: DepthSource = field(default_factory=LidarDepth)  # [perception]: depth = "lidar"
    rejected_radius_m: float = 4.0  # no key: a rejected site rules out candidates this close to it
    context: str = DEFAULTS.reasoner.context  # what the reasoner sees per candidate: crop, pad20..60, full
    closeup_half_m: float = 6.0  # no key: the confirmation close-up shows this far around the site
    land_timeout_s: float = DEFAULTS.recovery.land_timeout_s
    sensor_loss_s: float = DEFAULTS.recovery.sensor_loss_s  # wall seconds without a usable frame
    link_loss_s: float = DEFAULTS.recovery.link_loss_s  # wall seconds without telemetry
    # wall seconds the companion waits after the autopilot's own failsafe took its mode, streaming a
    # hold and commanding no mode: a failsafe may clear by itself (PX4's offboard-loss fallback) or
    # hold before it acts (PX4's COM_BAT_ACT_T, 5 s), and a command then would cancel it
    failsafe_grace_s: float = DEFAULTS.recovery.failsafe_grace_s
    search: SearchLimits = field(default_factory=SearchLimits)  # when searching on must stop
    search_agl_m: float = DEFAULTS.recovery.search_agl_m  # a search leg's least height above the ground
    lidar_range_m: float = DEFAULTS.perception.lidar_range_m  # how far a search leg's LiDAR reaches
    # a site off the roofs is watched for people this far around it before each descent step (0: not)
    people_margin_m: float = DEFAULTS.recovery.people_margin_m
    people_wait_s: float = DEFAULTS.recovery.people_wait_s  # autopilot seconds held for them to go

    @classmethod
    def from_config(cls, cfg: CompanionConfig) -> RecoveryParams:
        """The parameters ``cfg`` sets: ``[recovery]``, ``[perception]`` and ``reasoner.context``; what the
        daemon flies with (``companion.cli``).

        Raises:
            DepthError: the configured depth source cannot be built (a missing extra or network).
        """
        r, pc = cfg.recovery, cfg.perception
        built = {  # the fields not copied from [recovery] as they stand
            "rounds_by_criticality": r.rounds(),  # capped by max_rounds
            "surface": SurfaceParams(**pc.values_for(SurfaceParams)),
            "depth_source": make_source(
                pc.depth, cell_px=pc.cell_px, model=pc.depth_model, lidar_range_m=pc.lidar_range_m
            ),
            "lidar_range_m": pc.lidar_range_m,
            "context": cfg.reasoner.context,
            "search": SearchLimits.from_config(r),
        }
        return cls(**(r.values_for(cls) | built))

    def move_timeout(self, distance_m: float) -> float:
        """Wall seconds a move of ``distance_m`` may take before it counts as not reached."""
        return self.move_timeout_s + distance_m * self.move_timeout_s_per_m


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


@dataclass(eq=False)
class RecoveryContext:
    """What the parts of one recovery share, passed to each at its construction: the vehicle's
    controller and telemetry, the frames, the parameters, the record, the log and the announcement
    (what it works with), and the state more than one part reads or writes (the alarm's criticality,
    the state, the round, the accepted site, the rejected sites and the site ledger). One per alarm."""

    alarm: Alarm
    ctl: VehicleController
    tm: TelemetryCache
    frames: FrameSource
    announce: Callable[[int, str], None]
    p: RecoveryParams = field(default_factory=RecoveryParams)
    record: Record = field(default_factory=NoRecord)
    log: logging.Logger = field(default_factory=lambda: logging.getLogger("companion.recovery"))
    fault: FaultHook = field(default_factory=FaultHook)  # a test-only fault per stage (companion.faults)
    # the highest return the LiDAR measured within a corridor of a path (metres up; None: nothing
    # measured there): the search's map (SearchPlanner.highest_near_path), set by the recovery
    path_top: Callable[[tuple[float, float], tuple[float, float], float], float | None] | None = None
    state: State = State.IDLE
    round: int = 0
    best: Site | None = None  # the site confirmed for descent
    rejected: list[tuple[float, float, float]] = field(default_factory=list)  # north, east, radius (m)
    criticality: Criticality = field(init=False)  # the alarm's, raised by a repeated alarm
    ledger: SiteLedger = field(init=False)  # every site measured (companion.site_ledger)

    def __post_init__(self) -> None:
        self.criticality = self.alarm.criticality
        self.ledger = SiteLedger(self.p.rejected_radius_m)

    @property
    def budget(self) -> int:
        return self.p.rounds_by_criticality[self.criticality]

    def set_state(self, state: State) -> None:
        """The recovery's state, recorded with where the vehicle was."""
        self.state = state
        # where the vehicle was: a flight record's trajectory for a replay (the record keeps no telemetry)
        where = [round(v, 2) for v in self.tm.state.pos_ned_m]
        self.record.record_event("state", {"state": state.value, "round": self.round, "pos_ned_m": where})

    def say(self, severity: int, text: str) -> None:
        """Logged, and announced to the ground (STATUSTEXT)."""
        self.log.info("%s", text)
        self.announce(severity, f"Landfall: {text}")

    def site_ned(self) -> tuple[float, float, float] | None:
        return self.best.ned_m if self.best is not None else None

    def near_rejected(self, c: Candidate) -> bool:
        if c.site_ned_m is None:
            return False
        return any(math.dist(c.site_ned_m[:2], (n, e)) < r for n, e, r in self.rejected)

    def home_ne_m(self) -> tuple[float, float]:
        """Home in the local frame: where HOME_POSITION puts it, else the frame's origin."""
        home = self.tm.state.home_ned_m
        return (home[0], home[1]) if home is not None else (0.0, 0.0)

    def fence_bounds(self) -> tuple[tuple[float, float], float] | None:
        """(home north, east; radius) that search legs end within (:mod:`companion.fence`), or None."""
        fence = self.ctl.fence
        keep = fence.keep_in_m() if fence is not None else None
        return (self.home_ne_m(), keep) if keep is not None else None

    def outside_fence(self, c: Candidate) -> bool:
        """Whether ``c``'s site lies beyond what the autopilot's circular fence leaves the recovery
        (:mod:`companion.fence`): flying there would hand the vehicle to the fence's action."""
        return c.site_ned_m is not None and self.beyond_fence(c.site_ned_m)

    def beyond_fence(self, ned_m: tuple[float, float, float]) -> bool:
        """:meth:`outside_fence` for a place (NED metres): False without a known fence."""
        fence = self.ctl.fence
        return fence is not None and not fence.inside((ned_m[0], ned_m[1]), self.home_ne_m())

    def transit_d(self, to_ned: tuple[float, float, float]) -> float:
        """The height (NED down, metres) a level move from here to ``to_ned`` flies at: where the vehicle
        is, or higher where that is less than ``TRANSIT_CLEARANCE_M`` above a surface the recovery
        measured within ``TRANSIT_NEAR_M`` of either end (every roof in the ledger, the destination's
        own) or a return the LiDAR measured within ``TRANSIT_CORRIDOR_M`` of the path (``path_top``).
        A descent stopped low among taller buildings must not fly on level into their walls, nor into
        a tower between two sites (city 35 in fog: a fallback from one roof to the next, 41 m up,
        into the side of a 46 m building the ledger never held)."""
        n, e, d = self.tm.state.pos_ned_m
        ends = ((n, e), (to_ned[0], to_ned[1]))
        near = [
            s.ned_m[2]
            for s in self.ledger.sites
            if math.isfinite(s.ned_m[2])
            and min(math.dist(s.ned_m[:2], end) for end in ends) <= TRANSIT_NEAR_M
        ]
        if math.isfinite(to_ned[2]):
            near.append(to_ned[2])
        top = self.path_top(*ends, TRANSIT_CORRIDOR_M) if self.path_top is not None else None
        if top is not None and math.isfinite(top):
            near.append(-top)
        if not near or not math.isfinite(d):
            return d
        return min(d, min(near) - TRANSIT_CLEARANCE_M)

    async def climb_for_transit(self, to_ned: tuple[float, float, float]) -> float:
        """Climb straight up to :meth:`transit_d` when it is above the vehicle (said and recorded, a
        climb not finished in time goes on as the level move's own); the height to fly level at."""
        n, e, d = self.tm.state.pos_ned_m
        level = self.transit_d(to_ned)
        if not level < d - 1.0:
            return d
        self.say_transit_climb(d, level, "flying on")
        with contextlib.suppress(TargetTimeout):
            await self.ctl.goto(
                n, e, level, tolerance_m=self.p.arrival_tolerance_m, speed_m_s=self.p.arrival_speed_m_s,
                timeout_s=self.p.move_timeout(d - level),
            )  # fmt: skip
        return level

    def say_transit_climb(self, d: float, level: float, before: str) -> None:
        """Say and record a climb from ``d`` to ``level`` (NED down, metres) before a level move."""
        self.say(
            5, f"climbing {d - level:.0f} m before {before}: {TRANSIT_CLEARANCE_M:.0f} m over the roofs near"
        )
        self.record.record_event("transit_climb", {"from_d_m": round(d, 2), "to_d_m": round(level, 2)})

    def clock_s(self) -> float:
        """The autopilot's clock (seconds since its boot), so that a faster-than-real-time simulation
        keeps the alarm's window and the recovery's waits; the companion's monotonic clock before any
        telemetry."""
        t = self.tm.state.t_boot_s
        return t if t > 0 else time.monotonic()

    def strike_off(self, target: tuple[float, float, float], choice: Candidate) -> None:
        """:meth:`reject` the site, and forget it as the site confirmed for descent when it was."""
        self.reject(target, choice)
        if self.best is not None and math.dist(self.best.ned_m[:2], target[:2]) < self.p.rejected_radius_m:
            self.best = None

    def reject(self, target: tuple[float, float, float], choice: Candidate) -> None:
        """Rule out candidates around a rejected site: within ``rejected_radius_m``; for water or a
        traffic lane, within the surface's own size (half the side of a square of its area, up to
        ``MAX_REJECTED_RADIUS_M``): another point of the same harbour or street is no better."""
        site = self.ledger.near((target[0], target[1]))
        radius = self.p.rejected_radius_m
        if site is not None and site.hazard >= Hazard.TRAFFIC and math.isfinite(choice.area_m2):
            radius = max(radius, min(MAX_REJECTED_RADIUS_M, 0.5 * math.sqrt(choice.area_m2)))
        self.rejected.append((target[0], target[1], radius))
