"""The module-level experiments of ``companion-bench modules`` (DESIGN.md sections 6 and 9).

Iteration ``k`` of a scenario uses seed ``k``: the seed moves the traffic, draws the LiDAR noise and
scatters the hovering drone's pose (:func:`landfall_eval.surfaces.launch_frame`). One launch frame per
iteration feeds all three experiments:

1. **Surface ID**: the Jaccard index of the best candidate's box against the safe zone's
   (:func:`~landfall_eval.surfaces.best_jaccard`, LiDAR depth).
2. **Landing distance**: the reasoner ranks the candidates (``crop`` context), the chosen candidate's
   centre pixel goes through the recovery's IPM (through the LiDAR, else flat ground at the
   rangefinder's distance), and simbridge's JSBSim F450 with its PX4-flavoured autopilot (the objects the
   ``simbridge`` process steps, here in-process, unpaced, without MAVLink) flies there at the launch
   altitude, descends over it in the recovery loop's steps (0.8 of the rangefinder distance per step,
   arrival by position and speed) and hands over to the autopilot's land mode at 5 m. The figure is
   the horizontal distance from the touchdown point to the world point the chosen pixel truly shows
   (its ray scaled by the rendered depth image): IPM error and flight error together.
3. **Reasoner stages**: rank, per context level (``crop``: the exact boxes; ``padNN``: boxes padded
   by NN %; ``full``: exact crops plus the whole frame as context), succeeds when the top-ranked
   candidate's centre pixel truly shows a point inside a ground-truth safe zone of the scenario (the
   clear roof inset by 2 m; graded by the depth image, not by the companion's own ``site_ned_m``).
   Confirm renders a close-up frame and a LiDAR sweep 30 m above the centre of the scenario file's
   ``clear_roof`` building and of its ``cluttered_roof`` (hover scatter seeded), runs the LiDAR site
   check and has the recovery confirm the site on its close-up; it succeeds when it accepts the clear
   roof and rejects the cluttered one. Confirm does not
   depend on the context level: it runs once per iteration and the same figures stand in every
   context's entry.

Surface ID, the rank, IPM and the confirmation are the recovery's own: its looker
(:class:`companion.recovery.looking.Looker`), on no vehicle, asked what a round asks of it.

The reasoner is the flight cascade ``companion-eval rank --reasoner NAME`` builds (the config's
profiles, deadlines and fallbacks; the onboard tier answers when the named tier cannot in time),
built afresh per iteration so the lone-"no" counts of one iteration do not carry into the next.
"""

from __future__ import annotations

import asyncio
import dataclasses
import math
import os
import statistics
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from pymavlink.dialects.v20 import common as mavlink2

from companion.alarms import Alarm, Criticality, ReasonCode
from companion.config import load_config
from companion.control import VehicleController
from companion.guidance.frames import PinholeCamera
from companion.perception.site_check import check_site
from companion.perception.surface_id import Candidate
from companion.reasoning.base import Decision, Ranking
from companion.reasoning.cascade import Cascade
from companion.reasoning.tiers import build_cascade
from companion.recovery import FrameUnavailable, RecoveryParams
from companion.recovery.core import RecoveryContext
from companion.recovery.looking import Looker, onboard_tier
from companion.recovery.search_plan import SearchPlanner
from companion.telemetry import TelemetryCache
from landfall_eval.landing import pixel_truth_ned
from landfall_eval.study import STUDY_JACCARD, STUDY_LANDING_DISTANCE_M
from landfall_eval.surfaces import (
    LaunchFrame,
    best_jaccard,
    hover_pose,
    launch_frame,
    sensor_frame,
)
from landfall_link.sensorstream import SensorFrame
from simbridge.autopilot.core import Autopilot
from simbridge.autopilot.flavours import MAV_RESULT_ACCEPTED, flavour_named
from simbridge.control import Setpoint
from simbridge.estimate import EstimateError, EstimateErrorConfig, estimate_preset
from simbridge.geo import GeoOrigin
from simbridge.scenarios import Scenario, load_scenario
from simbridge.terrain import Terrain
from simbridge.vehicle import Vehicle
from simbridge.world.live import LiveWorld
from simbridge.world.scenario_file import builtin_scenario_path, parse_scenario_file
from simbridge.world.world import SafeZone

__all__ = [
    "CONTEXTS",
    "FlightError",
    "Roofs",
    "fly_and_land",
    "in_safe_zone",
    "roofs_of",
    "run_modules",
    "truth_point",
]

CONTEXTS = ("crop", "pad20", "pad30", "pad40", "full")
CLOSEUP_HEIGHT_M = 30.0  # the confirm close-ups are taken this far above the roof
STREAM_EVERY_STEPS = 6  # the companion streams setpoints at 20 Hz; physics runs at 120 Hz
ENGAGE_STREAM_S = 0.05  # PX4 takes OFFBOARD once a setpoint is fresh (companion.control.engage)

Progress = Callable[[str], None]
Vec3 = tuple[float, float, float]


# --------------------------------------------------------------------------------------- ground truth
@dataclass(frozen=True, slots=True)
class Roofs:
    """The two roofs of a curated scenario: centres (north, east) and roof heights, metres."""

    clear_ne: tuple[float, float]
    clear_up_m: float
    cluttered_ne: tuple[float, float]
    cluttered_up_m: float


def roofs_of(scenario: str) -> Roofs:
    """The ``clear_roof`` and ``cluttered_roof`` buildings of a scenario file.

    Raises:
        ValueError: the scenario has no file, or the file lacks either building id.
    """
    path = Path(scenario) if scenario.endswith(".toml") else builtin_scenario_path(scenario)
    buildings = {b.id: b for b in parse_scenario_file(path).buildings}
    missing = [k for k in ("clear_roof", "cluttered_roof") if k not in buildings]
    if missing:
        raise ValueError(f"scenario {scenario!r} has no building with id {' or '.join(missing)}")
    clear, cluttered = buildings["clear_roof"], buildings["cluttered_roof"]
    return Roofs(
        (clear.centre[0], clear.centre[1]),
        clear.height_m,
        (cluttered.centre[0], cluttered.centre[1]),
        cluttered.height_m,
    )


def truth_point(lf: LaunchFrame, u: float, v: float) -> np.ndarray | None:
    """World NED point (3,) that pixel (u, v) of the launch frame truly shows, from the rendered depth
    image (:func:`landfall_eval.landing.pixel_truth_ned`); ``None`` for sky or outside the image."""
    return pixel_truth_ned(lf.depth_m, lf.camera, lf.pos_ned_m, lf.quat_wxyz, u, v)


def in_safe_zone(zones: Sequence[SafeZone], north_m: float, east_m: float) -> bool:
    """Whether (north, east) lies inside any of the (rotated) rectangles."""
    for z in zones:
        dn, de = north_m - z.centre_ne[0], east_m - z.centre_ne[1]
        c, s = math.cos(z.yaw_rad), math.sin(z.yaw_rad)
        if abs(dn * c + de * s) <= z.length_m / 2 and abs(-dn * s + de * c) <= z.width_m / 2:
            return True
    return False


# --------------------------------------------------------------------------------------- flight
class FlightError(Exception):
    """The in-process flight did not finish a phase within its simulated-time limit."""


def fly_and_land(
    world: Terrain,
    start_ned_m: Vec3,
    start_yaw_rad: float,
    home_ned_m: Vec3,
    target_ne_m: tuple[float, float],
    params: RecoveryParams | None = None,
    estimate: EstimateError | None = None,
) -> tuple[Vec3, float]:
    """Fly simbridge's F450 from a hover at ``start_ned_m`` to ``target_ne_m`` at the start altitude,
    descend over it as the recovery loop does and land in the autopilot's land mode.

    The vehicle and the PX4-flavoured autopilot are the ones the ``simbridge`` process steps, driven
    in-process as fast as they run: setpoints go in as decoded MAVLink position targets (20 Hz), the
    companion's engage, goto and land (arrival within ``arrival_tolerance_m`` and slower than
    ``arrival_speed_m_s``) are followed in simulated time. No wind. With ``estimate`` the autopilot flies
    on its estimator's errors (its targets are in its estimated frame) and the companion's arrival and
    descent checks read the estimate, as over MAVLink.

    Returns:
        The touchdown position (NED metres, where the autopilot's land detector fired) and the
        simulated flight time in seconds.

    Raises:
        FlightError: a phase ran past its limit (the recovery loop's timeouts, in simulated seconds).
    """
    p = params or RecoveryParams()
    vehicle = Vehicle(GeoOrigin(), world)
    vehicle.reset(start_ned_m, start_yaw_rad)
    touchdown: list[Vec3] = []

    def on_event(name: str, fields: dict[str, Any]) -> None:
        if name == "touchdown":
            touchdown.append(vehicle.state.pos_ned_m)

    ap = Autopilot(
        flavour_named("px4"), vehicle, home_ned_m, on_event, lambda _sev, _text: None, estimate=estimate
    )
    ap.spawn_in_air(vehicle.state)
    steps = 0
    target: Setpoint | None = None

    def step() -> None:
        nonlocal steps
        if target is not None and steps % STREAM_EVERY_STEPS == 0:
            outcome = ap.external_setpoint(target, False)
            if outcome.result != MAV_RESULT_ACCEPTED:
                raise FlightError(f"setpoint {target} refused ({outcome.result})")
        vehicle.step(ap.tick(vehicle.state), ap.armed)
        steps += 1

    def goto(n: float, e: float, d: float, limit_s: float) -> None:
        nonlocal target
        target = Setpoint.hold((n, e, d), vehicle.state.euler_rad[2])
        t_end = vehicle.state.t_s + limit_s
        while True:
            step()
            s = ap.estimated_state  # what the companion hears
            if math.dist(s.pos_ned_m, (n, e, d)) < p.arrival_tolerance_m and (
                math.hypot(*s.vel_ned_m_s) < p.arrival_speed_m_s
            ):
                return
            if s.t_s > t_end:
                off = math.dist(s.pos_ned_m, (n, e, d))
                raise FlightError(f"target not reached in {limit_s:.0f} s ({off:.1f} m off)")

    # engage: one hold setpoint where the autopilot says the vehicle is, then OFFBOARD
    step()  # the autopilot's first estimate
    target = Setpoint.hold(ap.estimated_state.pos_ned_m, start_yaw_rad)
    while vehicle.state.t_s < ENGAGE_STREAM_S:
        step()
    mode = ap.set_mode(ap.flavour.mode("OFFBOARD"))
    if mode.result != MAV_RESULT_ACCEPTED:
        raise FlightError(f"OFFBOARD refused: {mode.text}")
    n0, e0, d0 = ap.estimated_state.pos_ned_m
    tn, te = target_ne_m
    goto(tn, te, d0, p.move_timeout(math.hypot(tn - n0, te - e0)))
    while True:
        s = vehicle.state
        rng_m = world.rangefinder_m(s.pos_ned_m, s.quat)  # a sensor: the truth measured
        if rng_m <= p.final_land_m:
            break
        d_now = ap.estimated_state.pos_ned_m[2]
        goto(tn, te, d_now + p.descent_fraction * rng_m, p.move_timeout_s + rng_m)
    target = None
    land = ap.land()
    if land.result != MAV_RESULT_ACCEPTED:
        raise FlightError(f"land mode refused: {land.text}")
    t_end = vehicle.state.t_s + p.land_timeout_s
    while not touchdown:
        step()
        if vehicle.state.t_s > t_end:
            raise FlightError(f"no touchdown within {p.land_timeout_s:.0f} s of land mode")
    return touchdown[0], vehicle.state.t_s


# --------------------------------------------------------------------------------------- one iteration
@dataclass(frozen=True, slots=True)
class RankTrial:
    ok: bool
    latency_s: float
    failure: str | None


@dataclass(frozen=True, slots=True)
class ConfirmTrial:
    accept_clear: bool
    reject_cluttered: bool
    latencies_s: tuple[float, float]
    failures: tuple[str, ...]


@dataclass(frozen=True, slots=True)
class Landing:
    distance_m: float | None  # None when the flight or the IPM failed
    ipm_error_m: float | None
    failure: str | None


@dataclass(frozen=True, slots=True)
class Iteration:
    seed: int
    jaccard: float
    ranks: dict[str, RankTrial]
    confirm: ConfirmTrial
    landing: Landing


# the site a confirmation close-up is taken over: the roof as a round would confirm it, without Surface
# ID's measurements (it is not chosen in a frame), so its height above the street is not given
ROOF_SITE = Candidate(0, (0, 0, 1, 1), (0.5, 0.5))
BENCH_ALARM = Alarm(ReasonCode.OTHER, Criticality.HIGH, "module bench", (0, 0), 0.0)


async def _no_frame() -> Any:
    raise FrameUnavailable("the module bench hands the looker its frames")


class _Silent:
    """A link that sends nothing: the module bench commands no vehicle."""

    def __init__(self) -> None:
        self.mav = mavlink2.MAVLink(None)

    def send_to(self, msg: Any, system: int, component: int) -> None:
        return None


def _looker(cascade: Cascade, context: str = "crop") -> Looker:
    """The recovery's looker for one context level of the rank, on no vehicle: a controller that sends
    nothing, telemetry never heard, no frame source (the bench hands it each frame) and no record."""
    tm = TelemetryCache()
    ctl = VehicleController(tm, _Silent())
    ctx = RecoveryContext(
        BENCH_ALARM, ctl, tm, _no_frame, lambda _sev, _text: None, RecoveryParams(context=context)
    )
    return Looker(ctx, reasoner=cascade, onboard=onboard_tier(cascade), plan=SearchPlanner(Criticality.HIGH))


def _rank_trial(
    lf: LaunchFrame, zones: Sequence[SafeZone], cands: list[Candidate], ranking: Ranking, chosen: int | None
) -> RankTrial:
    if chosen is None:
        return RankTrial(False, ranking.latency_s, f"seed {lf.seed}: no measured candidate ranked")
    choice = cands[chosen]
    point = truth_point(lf, *choice.centre_px)
    if point is None:
        return RankTrial(False, ranking.latency_s, f"seed {lf.seed}: site {choice.index} shows no surface")
    if in_safe_zone(zones, float(point[0]), float(point[1])):
        return RankTrial(True, ranking.latency_s, None)
    where = f"{point[0]:.0f} N {point[1]:.0f} E, {-point[2]:.0f} m up"
    return RankTrial(
        False, ranking.latency_s, f"seed {lf.seed}: site {choice.index} off the clear roof ({where})"
    )


async def _confirm_site(
    looker: Looker,
    world: LiveWorld,
    site_ne: tuple[float, float],
    roof_up_m: float,
    yaw_rad: float,
    rng: np.random.Generator,
    weather: str,
) -> Decision:
    """Close-up frame and LiDAR sweep 30 m above the site, checked and confirmed by the recovery's looker
    as a round does (the close-up: ``closeup_half_m`` around the site's pixel)."""
    pos, quat = hover_pose(rng, site_ne, -(roof_up_m + CLOSEUP_HEIGHT_M), yaw_rad)
    frame = world.camera_frame(pos, quat, 0.0, weather, rng)
    lidar = world.lidar_sweep(pos, quat, 0.0, rng)
    cm = world.camera
    camera = PinholeCamera.from_hfov(cm.width_px, cm.height_px, cm.hfov_deg)
    sensed = sensor_frame(world, camera, pos, quat, frame.rgb, lidar, weather)
    check = check_site(lidar, pos, quat, site_ne)  # what the looker's measure_site checks under the site
    return await looker.confirm(check, sensed, (site_ne[0], site_ne[1], -roof_up_m), ROOF_SITE)


async def _confirm_trial(
    looker: Looker, sc: Scenario, world: LiveWorld, roofs: Roofs, seed: int, weather: str
) -> ConfirmTrial:
    """Both close-ups, each with its own seeded hover scatter."""
    yaw = sc.launch_yaw_rad
    clear = await _confirm_site(
        looker, world, roofs.clear_ne, roofs.clear_up_m, yaw, np.random.default_rng([seed, 1]), weather
    )
    cluttered_rng = np.random.default_rng([seed, 2])
    cluttered = await _confirm_site(
        looker, world, roofs.cluttered_ne, roofs.cluttered_up_m, yaw, cluttered_rng, weather
    )
    failures = []
    if not clear.accept:
        failures.append(f"seed {seed}: clear roof rejected ({clear.rationale[:90]})")
    if cluttered.accept:
        failures.append(f"seed {seed}: cluttered roof accepted ({cluttered.rationale[:90]})")
    latencies = (clear.latency_s, cluttered.latency_s)
    return ConfirmTrial(clear.accept, not cluttered.accept, latencies, tuple(failures))


def _landing(
    looker: Looker,
    lf: LaunchFrame,
    frame: SensorFrame,
    choice: Candidate | None,
    sc: Scenario,
    world: LiveWorld,
    ekf: EstimateErrorConfig | None = None,
) -> Landing:
    """Fly to the IPM point of the chosen candidate and land; the distance to what its pixel shows.
    With ``ekf``, the frame is placed with the autopilot's estimate (bias, noise and attitude error at
    capture) and the flight follows targets in the estimated frame while its bias drifts."""
    if choice is None:
        return Landing(None, None, f"seed {lf.seed}: no measured candidate to fly to")
    u, v = choice.centre_px
    truth = truth_point(lf, u, v)
    if truth is None:
        return Landing(None, None, f"seed {lf.seed}: site {choice.index} shows no surface")
    estimate = EstimateError(ekf, np.random.default_rng([lf.seed, 7])) if ekf is not None else None
    if estimate is not None:
        pos, quat = estimate.perturb(lf.pos_ned_m, lf.quat_wxyz)
        frame = dataclasses.replace(frame, pos_ned_m=pos, quat_wxyz=quat)
    ipm = looker.ipm(choice, frame, lf.camera)
    if ipm is None:
        return Landing(None, None, f"seed {lf.seed}: IPM placed nothing (neither the LiDAR nor flat ground)")
    n, e = sc.launch_ne_m
    home = (n, e, -world.height_m(n, e))
    w, x, y, z = lf.quat_wxyz
    yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    try:
        touchdown, _t = fly_and_land(world, lf.pos_ned_m, yaw, home, (ipm[0], ipm[1]), estimate=estimate)
    except FlightError as exc:
        return Landing(None, None, f"seed {lf.seed}: {exc}")
    ipm_error = math.hypot(ipm[0] - truth[0], ipm[1] - truth[1])
    distance = math.hypot(touchdown[0] - truth[0], touchdown[1] - truth[1])
    return Landing(distance, ipm_error, None)


async def _iteration(
    scenario: str,
    seed: int,
    roofs: Roofs,
    contexts: Sequence[str],
    cascade: Cascade,
    weather: str,
    ekf: EstimateErrorConfig | None = None,
) -> Iteration:
    lf = launch_frame(scenario, seed, weather, hover=True)
    sc = load_scenario(scenario, seed)  # the same seeded world, for the close-ups and the flight
    world = sc.terrain
    assert isinstance(world, LiveWorld)  # launch_frame has checked it
    jaccard, _box = best_jaccard(lf)
    frame = sensor_frame(world, lf.camera, lf.pos_ned_m, lf.quat_wxyz, lf.image, lf.lidar_frd, weather)
    looker = _looker(cascade)
    cands = looker.surface_id(frame, lf.camera)
    ranks: dict[str, RankTrial] = {}
    flown: Candidate | None = None
    for context in dict.fromkeys(("crop", *contexts)):  # the flight follows the crop ranking
        ranking, chosen = await _looker(cascade, context).rank(cands, frame)
        if context == "crop":
            flown = cands[chosen] if chosen is not None else None
        if context in contexts:
            ranks[context] = _rank_trial(lf, world.world.safe_zones, cands, ranking, chosen)
    confirm = await _confirm_trial(looker, sc, world, roofs, seed, weather)
    return Iteration(seed, jaccard, ranks, confirm, _landing(looker, lf, frame, flown, sc, world, ekf))


# --------------------------------------------------------------------------------------- the run
def _median(values: Sequence[float], nd: int = 4) -> float | None:
    return round(statistics.median(values), nd) if values else None


def _mean(values: Sequence[float], nd: int = 3) -> float | None:
    return round(statistics.fmean(values), nd) if values else None


def _summary(its: Sequence[Iteration], scenario: str, contexts: Sequence[str]) -> dict[str, Any]:
    """The figures of one scenario: surface_id, landing_distance and reasoner entries."""
    scores = [it.jaccard for it in its]
    surface = {
        "jaccard_mean": round(statistics.fmean(scores), 4),
        "jaccard_min": round(min(scores), 4),
        "jaccard_max": round(max(scores), 4),
        "iterations": len(scores),
        "study": STUDY_JACCARD.get(scenario),
    }
    flown = [it.landing for it in its if it.landing.distance_m is not None]
    dist = [lg.distance_m for lg in flown if lg.distance_m is not None]
    ipm = [lg.ipm_error_m for lg in flown if lg.ipm_error_m is not None]
    landing = {
        "mean_m": _mean(dist),
        "median_m": _median(dist, 3),
        "max_m": round(max(dist), 3) if dist else None,
        "ipm_error_mean_m": _mean(ipm),
        "iterations": len(dist),
        "study": STUDY_LANDING_DISTANCE_M.get(scenario),
        "failures": [it.landing.failure for it in its if it.landing.failure is not None],
    }
    n = len(its)
    confirm_failures = [f for it in its for f in it.confirm.failures]
    confirm = {
        "confirm_accept_clear": round(sum(it.confirm.accept_clear for it in its) / n, 4),
        "confirm_reject_cluttered": round(sum(it.confirm.reject_cluttered for it in its) / n, 4),
        "confirm_latency_s_median": _median([lat for it in its for lat in it.confirm.latencies_s]),
    }
    reasoner: dict[str, Any] = {}
    for context in contexts:
        trials = [it.ranks[context] for it in its]
        reasoner[context] = {
            "rank_success": round(sum(t.ok for t in trials) / n, 4),
            **confirm,
            "iterations": n,
            "rank_latency_s_median": _median([t.latency_s for t in trials]),
            "failures": [t.failure for t in trials if t.failure is not None] + confirm_failures,
        }
    return {"surface_id": surface, "landing_distance": landing, "reasoner": reasoner}


async def _run(
    reasoner: str,
    iterations: int,
    scenarios: Sequence[str],
    contexts: Sequence[str],
    progress: Progress | None,
    config_path: Path | None,
    weather: str,
    ekf: EstimateErrorConfig | None = None,
) -> dict[str, Any]:
    cfg = load_config(config_path, os.environ, {"reasoner.name": reasoner}).reasoner
    out: dict[str, Any] = {"surface_id": {}, "landing_distance_m": {}, "landing_distance": {}, "reasoner": {}}
    for scenario in scenarios:
        roofs = roofs_of(scenario)
        its: list[Iteration] = []
        for seed in range(iterations):
            cascade = build_cascade(cfg)  # fresh per iteration: no lone-"no" counts carried over
            try:
                it = await _iteration(scenario, seed, roofs, contexts, cascade, weather, ekf)
            finally:
                await cascade.aclose()
            its.append(it)
            if progress is not None:
                ranked = sum(t.ok for t in it.ranks.values())
                land = it.landing.distance_m
                progress(
                    f"{scenario} {seed + 1}/{iterations}: jaccard {it.jaccard:.3f}, "
                    f"landing {'failed' if land is None else f'{land:.2f} m'}, "
                    f"rank {ranked}/{len(it.ranks)}, "
                    f"confirm {'ok' if it.confirm.accept_clear and it.confirm.reject_cluttered else 'wrong'}"
                )
        figures = _summary(its, scenario, contexts)
        out["surface_id"][scenario] = figures["surface_id"]
        out["landing_distance"][scenario] = figures["landing_distance"]
        out["landing_distance_m"][scenario] = figures["landing_distance"]["mean_m"]
        out["reasoner"][scenario] = figures["reasoner"]
    out["reasoner_name"] = cfg.name
    return out


def run_modules(
    reasoner: str = "onboard",
    iterations: int = 20,
    *,
    scenarios: Sequence[str] = ("scenario1", "scenario2"),
    contexts: Sequence[str] = CONTEXTS,
    progress: Progress | None = None,
    config_path: Path | None = None,
    weather: str = "clear",
    ekf_error: str = "off",
) -> dict[str, Any]:
    """Run the three module experiments (module docstring) and return the ``modules`` section of
    results.json.

    Args:
        reasoner: the first tier of the cascade: ``onboard`` or an LVLM profile name.
        iterations: seeded iterations per scenario (iteration k uses seed k).
        scenarios: curated scenarios (their files must name a ``clear_roof`` and a ``cluttered_roof``).
        contexts: context levels of the rank stage: ``crop``, ``pad20`` .. ``pad60``, ``full``.
        progress: called after each iteration with a one-line status.
        config_path: companion TOML with the reasoner's profiles, deadlines and fallbacks.
        weather: ``clear``, ``fog`` or ``rain`` for every render.
        ekf_error: the autopilot's estimator errors for the landing flights (``simbridge.estimate``
            presets: ``off``, ``nominal``).

    Returns:
        ``surface_id.<scenario>``: ``jaccard_mean``/``_min``/``_max``, ``iterations``, ``study``;
        ``landing_distance_m.<scenario>``: the mean distance in metres; ``landing_distance.<scenario>``:
        ``mean_m``, ``median_m``, ``max_m``, ``ipm_error_mean_m`` (the IPM point against the truth,
        before flying), ``iterations`` (flights measured), ``study``, ``failures``;
        ``reasoner.<scenario>.<context>``: ``rank_success``, ``confirm_accept_clear``,
        ``confirm_reject_cluttered`` (shares of iterations; confirm is the same figure in every
        context), ``iterations``, ``rank_latency_s_median``, ``confirm_latency_s_median`` (seconds,
        over both close-ups), ``failures`` (one short line per failed rank or confirm);
        ``reasoner_name``.

    Raises:
        ValueError: no iterations, an unknown context level, or a scenario without the two roofs.
        companion.config.ConfigError: an unknown reasoner or a bad config file.
    """
    if iterations < 1:
        raise ValueError(f"iterations must be >= 1, got {iterations}")
    allowed = ("crop", "pad20", "pad30", "pad40", "pad50", "pad60", "full")
    bad = [c for c in contexts if c not in allowed]
    if bad or not contexts:
        raise ValueError(
            f"unknown context level(s) {bad or contexts!r}; expected some of {', '.join(allowed)}"
        )
    for scenario in scenarios:
        roofs_of(scenario)  # fail before any work
    ekf = estimate_preset(ekf_error)
    return asyncio.run(_run(reasoner, iterations, scenarios, contexts, progress, config_path, weather, ekf))
