"""The recovery's eyes: a frame (held for while none comes), Surface ID, the reasoner's rank and
confirmation, the LiDAR check of a site, and the chosen pixel placed in the world (IPM)."""

from __future__ import annotations

import asyncio
import dataclasses
import functools
import itertools
import math
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from companion.alarms import Criticality
from companion.guidance.frames import PinholeCamera, quat_to_matrix
from companion.guidance.ipm import IpmError, LidarPixelIndex, pixel_to_ned_flat, pixel_to_ned_surface
from companion.perception.appearance import appearance_candidates, clear_cells
from companion.perception.crops import crop, pad_of, rank_crops, site_box
from companion.perception.depth import DepthError
from companion.perception.image_extend import warm_up as warm_up_surface_id
from companion.perception.site_check import SiteCheck, check_site, world_points
from companion.perception.surface_id import (
    Candidate,
    propose,
    quadrant_fallback,
)
from companion.reasoning.base import ConfirmRequest, Decision, Ranking, RankRequest, Reasoner
from companion.reasoning.onboard import OnboardReasoner, lidar_kind
from companion.reasoning.people_watch import PeopleSeen, people_in_frame
from companion.recovery.core import (
    BUILT_UP_RADIUS_M,
    PULL_SPARE_M,
    PULLED_EDGE_M,
    SENSOR_RETRY_S,
    SITE_RETRIES,
    FrameUnavailable,
    RecoveryContext,
    SensorsLost,
    State,
)
from companion.recovery.search_plan import SearchPlanner
from companion.site_ledger import LedgerSite, hazard_of


def surface_id_ranking(candidates: Sequence[Candidate]) -> Ranking:
    """The ranking when a frame has no camera image: Surface ID's own order (its score), said so.
    Positions in ``candidates``, as a reasoner's order is, not the candidates' Surface ID indices:
    the candidates near a rejected site are no longer in the list, so the two differ."""
    return Ranking(
        tuple(range(len(candidates))),
        "no camera image: Surface ID's order (flat area, clearance, elevation)",
        "surface-id",
        0.0,
    )


def chosen_position(ranking: Ranking, candidates: Sequence[Candidate]) -> int | None:
    """The position in ``candidates`` of the one the vehicle flies to: the first in the ranking's order
    that is not a fallback crop (a quadrant has no measured site); None when there is none."""
    return next((k for k in ranking.order if 0 <= k < len(candidates) and not candidates[k].fallback), None)


def onboard_tier(reasoner: Reasoner) -> OnboardReasoner:
    """The onboard tier that judges every measured site for the ledger, whoever decides: the cascade's
    own (its judge, cues or LandNet-S, as configured) when there is one, else a default one."""
    onboard = getattr(reasoner, "onboard", None)
    return onboard if isinstance(onboard, OnboardReasoner) else OnboardReasoner()


def warm_up(reasoner: Reasoner) -> None:
    """Surface ID's image conversions and the onboard tier once each, so that the first alarm's round
    does not pay the libraries' first-call costs (measured in docs/performance.md). Blocking: the
    daemon runs it in a worker thread at start-up."""
    warm_up_surface_id()
    onboard_tier(reasoner).warm_up()


class Looker:
    """Acquire, Surface ID, rank, confirm, the site check and IPM (DESIGN.md section 2, steps 1-5),
    and the onboard tier's view of every site for the ledger.

    Args:
        ctx: what the recovery's parts share.
        reasoner: ranks the candidates and confirms a site.
        onboard: judges every measured site for the ledger (:func:`onboard_tier`).
        plan: the search's map, whose roofs make a site's surroundings built-up (:meth:`built_up`).
    """

    def __init__(
        self, ctx: RecoveryContext, *, reasoner: Reasoner, onboard: OnboardReasoner, plan: SearchPlanner
    ) -> None:
        self.ctx = ctx
        self.reasoner = reasoner
        self.onboard = onboard
        self._plan = plan
        # this round's Surface ID measured a roof: a built-up area here (the round sets it)
        self.roofs_in_view = False

    async def acquire(self, *, first_round: bool = False) -> Any:
        """A frame; while none comes, the vehicle holds on its current setpoint and the request is
        repeated every ``SENSOR_RETRY_S``, each failure recorded. Raises ``SensorsLost`` after
        ``sensor_loss_s`` without one."""
        ctx = self.ctx
        ctx.set_state(State.ACQUIRE)
        ctx.fault.check("acquire", 1 if first_round else ctx.round)
        since = time.monotonic()
        for attempt in itertools.count():
            try:
                return await ctx.frames()
            except FrameUnavailable as exc:
                waited = time.monotonic() - since
                ctx.record.record_event(
                    "sensor_fault", {"round": ctx.round, "error": str(exc), "waited_s": round(waited, 2)}
                )
                if waited >= ctx.p.sensor_loss_s:
                    raise SensorsLost(f"no usable sensor frame for {waited:.0f} s ({exc})") from exc
                if attempt == 0:
                    ctx.say(4, f"no sensor frame ({exc}): holding, asking again")
                await asyncio.sleep(SENSOR_RETRY_S)
        raise AssertionError("unreachable")

    def surface_id(self, frame: Any, camera: PinholeCamera) -> list[Candidate]:
        """Candidates from the configured depth source; the quadrant fallback when it has nothing."""
        ctx = self.ctx
        ctx.fault.check("surface_id", ctx.round)
        try:
            cands, _depth = propose(
                ctx.p.depth_source,
                camera,
                image=frame.image_rgb,
                lidar_frd=frame.lidar_frd,
                quat_wxyz=frame.quat_wxyz,
                pos_ned_m=frame.pos_ned_m,
                ground_up_m=frame.pos_ned_m[2],
                params=ctx.p.surface,
            )
        except DepthError as exc:
            net = self.onboard.landnet
            if net is None or frame.image_rgb is None or frame.lidar_frd is not None:
                # a sweep that came empty is a gap (the next one is asked for), not a blind vehicle
                ctx.log.warning("Surface ID has no depth (%s): quadrant fallback", exc)
                return quadrant_fallback(camera)
            # no LiDAR at all (a camera alone, or a LiDAR that failed): surfaces by how they look
            # (companion.perception.appearance)
            clear = clear_cells(frame.image_rgb, net.presence, tuple(net.classes))
            cands = appearance_candidates(clear, camera.width, camera.height, max_candidates=5)
            ctx.log.info(
                "Surface ID has no depth (%s): %d clear roof surface%s by their look", exc, len(cands),
                "" if len(cands) == 1 else "s",
            )  # fmt: skip
            return cands or quadrant_fallback(camera)
        return cands

    async def rank(self, candidates: list[Candidate], frame: Any) -> tuple[Ranking, int | None]:
        """The reasoner's order of the candidates, from their crops (the configured context variant),
        and the one the vehicle flies to: the first in that order that is not a fallback crop (a
        quadrant has no measured site). Both go to the record's ``rank`` event (``order``, ``chosen``)."""
        ctx = self.ctx
        ctx.fault.check("rank", ctx.round)
        image = frame.image_rgb
        names: list[str] = []
        if image is None:
            ranking = surface_id_ranking(candidates)
        else:
            crops, cores, names = await asyncio.to_thread(self._rank_crops, image, candidates)
            request = RankRequest(
                crops,
                None if all(c.fallback for c in candidates) else tuple(candidates),
                context=image if ctx.p.context == "full" else None,
                critical=ctx.criticality == Criticality.CRITICAL,
                cores=cores if pad_of(ctx.p.context) > 0 else None,
            )
            ranking = await self.reasoner.rank(request)
        chosen = chosen_position(ranking, candidates)
        ctx.record.record_event(
            "rank",
            {
                "round": ctx.round,
                "order": list(ranking.order),
                "chosen": chosen,
                "rationale": ranking.rationale,
                "tier": ranking.tier,
                "latency_s": ranking.latency_s,
                "context": ctx.p.context,
                "images": names,
                "candidates": [c.to_json() for c in candidates],
                # the candidates' frame, on the autopilot's clock: where an evaluation finds what the
                # chosen pixel truly shows (the simulator's episode log holds the pose it was taken from)
                "frame_time_boot_ms": getattr(frame, "time_boot_ms", None),
            },
        )
        return ranking, chosen

    async def confirm(
        self, check: SiteCheck, frame: Any, target: tuple[float, float, float], choice: Candidate
    ) -> Decision:
        """Reasoner and geometric veto on a close-up of the site (the cascade arbitrates); the verdict
        goes to the ledger too, with what the onboard tier saw against the site whoever decided."""
        ctx = self.ctx
        ctx.fault.check("confirm", ctx.round)
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
                    critical=ctx.criticality == Criticality.CRITICAL,
                    site_ne_m=(target[0], target[1]),
                    site_up_m=choice.height_above_m if math.isfinite(choice.height_above_m) else None,
                    site_strip=choice.strip,
                    built_up=self.built_up((target[0], target[1])),
                    site_area_m2=_measured(choice.landable_area_m2),
                    site_edge_m=_measured(choice.edge_distance_m),
                )
            )
        up_m = choice.height_above_m if math.isfinite(choice.height_above_m) else None
        if decision.tier == self.onboard.name or image is None:
            kinds = decision.hazards or ((lidar_kind(check),) if check.measured and not check.clear else ())
        else:  # a remote tier decided: the ledger still wants the onboard tier's view of the site
            among = self.built_up((target[0], target[1]))
            kinds = await asyncio.to_thread(self.judge, frame, check, target, up_m, choice, among)
        hazard = hazard_of(
            kinds,
            accepted=decision.accept,
            street_level=not choice.elevated and not choice.strip,
            strip=choice.strip,
            judged=image is not None or check.measured,
        )
        why = decision.rationale[:160] if not decision.accept else "confirmed for descent"
        ctx.ledger.add(
            LedgerSite(
                target,
                hazard,
                why,
                ctx.round,
                True,
                choice.edge_distance_m,
                f"site {choice.index}",
                choice,
            )
        )
        ctx.record.record_event(
            "confirm",
            {
                "round": ctx.round,
                "accept": decision.accept,
                "unsure": decision.unsure,
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

    async def measure_site(self, target: tuple[float, float, float]) -> tuple[Any, SiteCheck]:
        """A frame and the LiDAR check of the site under it.

        Policy: a sweep that misses the site (empty, or too few returns in the rotor disc: a partial
        sweep) is a sensor gap, not a hazard. It is recorded as a ``sensor_fault`` and a new frame is
        asked for, ``SITE_RETRIES`` times at most; then the site goes to the reasoner unmeasured and is
        judged from the image, as with no LiDAR at all (a frame without one goes so at once). A gap
        never strikes a site off."""
        ctx = self.ctx
        for attempt in range(SITE_RETRIES + 1):
            frame = await self.acquire()
            ctx.set_state(State.CONFIRM)
            check = await asyncio.to_thread(
                check_site, frame.lidar_frd, frame.pos_ned_m, frame.quat_wxyz, (target[0], target[1])
            )
            if check.measured or frame.lidar_frd is None:
                return frame, check
            ctx.record.record_event(
                "sensor_fault",
                {
                    "round": ctx.round,
                    "error": f"site not measured: {check.points} LiDAR returns in the rotor disc",
                    "attempt": attempt,
                },
            )
            if attempt < SITE_RETRIES:
                await asyncio.sleep(SENSOR_RETRY_S)
        ctx.say(4, "the LiDAR keeps missing the site: judging it from the image")
        return frame, check

    def judge(
        self,
        frame: Any,
        check: SiteCheck,
        target: tuple[float, float, float],
        up_m: float | None,
        choice: Candidate | None,
        built_up: bool,
    ) -> tuple[str, ...]:
        """What the onboard tier sees against a site (``Decision.hazards``), from the close-up of
        ``frame`` around it and the LiDAR check, asked as a confirmation of it would be (among
        buildings or not, ``built_up``: :meth:`built_up`, read on the event loop; the surface's area and
        edge distance when Surface ID measured it, ``choice``); the LiDAR's kind alone without an image.
        A worker-thread job."""
        if frame.image_rgb is None:
            return (lidar_kind(check),) if check.measured and not check.clear else ()
        closeup = self.closeup(frame.image_rgb, frame, target)
        request = ConfirmRequest(
            closeup,
            check if check.measured else None,
            site_up_m=up_m,
            site_strip=choice is not None and choice.strip,
            built_up=built_up,
            site_area_m2=_measured(choice.landable_area_m2) if choice is not None else None,
            site_edge_m=_measured(choice.edge_distance_m) if choice is not None else None,
        )
        return self.onboard.confirm_sync(request).hazards

    def notes_job(self, candidates: list[Candidate], frame: Any, camera: PinholeCamera) -> Callable[[], None]:
        """:meth:`note_candidates` as a worker-thread job, whether each site lies among buildings
        decided now: the search's map is read on the event loop, never from a worker thread."""
        built = [c.site_ned_m is not None and self.built_up(c.site_ned_m[:2]) for c in candidates]
        return functools.partial(self.note_candidates, candidates, frame, camera, built)

    def note_candidates(
        self, candidates: list[Candidate], frame: Any, camera: PinholeCamera, built_up: list[bool]
    ) -> None:
        """Every measured candidate of a round into the ledger, judged from afar: the onboard tier's
        view of the frame around its site, as a confirmation would see it (a worker-thread job; each
        candidate's ``built_up`` from :meth:`notes_job`)."""
        for c, among in zip(candidates, built_up, strict=True):
            if c.fallback or c.site_ned_m is None:
                continue
            up_m = c.height_above_m if math.isfinite(c.height_above_m) else None
            kinds = self.judge(frame, UNMEASURED, c.site_ned_m, up_m, c, among)
            hazard = hazard_of(
                kinds, accepted=False, street_level=not c.elevated and not c.strip, strip=c.strip
            )
            why = ", ".join(kinds) or "nothing seen against it from afar"
            self.ctx.ledger.add(
                LedgerSite(
                    c.site_ned_m,
                    hazard,
                    why,
                    self.ctx.round,
                    False,
                    c.edge_distance_m,
                    f"site {c.index}",
                    c,
                    kinds=tuple(kinds),
                )
            )

    def built_up(self, site_ne_m: tuple[float, float]) -> bool:
        """Policy: whether a site at street level is among buildings, where streets and plazas carry people
        and traffic that come back (docs/recovery.md): a roof in this round's view, or roofs the LiDAR
        measured during the recovery (the search's map) within ``BUILT_UP_RADIUS_M`` of the site. The
        open fields past a town's last roofs are open country, judged on what is seen."""
        if self.roofs_in_view:
            return True
        return bool(self._plan.roof_groups(lambda c: math.dist(c, site_ne_m) < BUILT_UP_RADIUS_M))

    def _rank_crops(
        self, image: Any, candidates: list[Candidate]
    ) -> tuple[tuple[Any, ...], tuple[tuple[int, int, int, int], ...], list[str]]:
        """The crops the reasoner ranks (and their cores), saved to the record: a worker-thread job."""
        ctx = self.ctx
        crops, cores = rank_crops(image, [c.box_px for c in candidates], ctx.p.context)
        names = [
            self._saved_name(ctx.record.save_image(f"round{ctx.round:02d}-rank-crop{k}", c))
            for k, c in enumerate(crops)
        ]
        return crops, cores, names

    def _closeup_saved(self, image: Any, frame: Any, target: tuple[float, float, float]) -> tuple[Any, str]:
        closeup = self.closeup(image, frame, target)
        return closeup, self._saved_name(
            self.ctx.record.save_image(f"round{self.ctx.round:02d}-confirm", closeup)
        )

    @staticmethod
    def _saved_name(path: Any) -> str:
        return str(getattr(path, "name", path)) if path is not None else ""

    def closeup(self, image: Any, frame: Any, target: tuple[float, float, float]) -> Any:
        camera = PinholeCamera(frame.width, frame.height, frame.fx, frame.fy, frame.cx, frame.cy)
        return site_closeup(
            image, camera, frame.pos_ned_m, frame.quat_wxyz, target, self.ctx.p.closeup_half_m
        )

    async def watch_people(self, frame: Any, target: tuple[float, float, float]) -> PeopleSeen | None:
        """People the onboard net sees within ``people_margin_m`` of the site in this frame
        (:func:`~companion.reasoning.people_watch.people_near`, a worker-thread job); None when the
        watch cannot run: no image, the site out of view, no net (the cues judge) or a margin of 0."""
        margin = self.ctx.p.people_margin_m
        net = self.onboard.landnet
        if frame.image_rgb is None or net is None or margin <= 0:
            return None
        camera = PinholeCamera(frame.width, frame.height, frame.fx, frame.fy, frame.cx, frame.cy)
        seen = in_view(camera, frame.pos_ned_m, frame.quat_wxyz, target)
        if seen is None:
            return None
        u, v, dist = seen
        return await asyncio.to_thread(people_in_frame, net, frame, camera, (u, v), camera.fx / dist, margin)

    def pull_inside_fence(self, c: Candidate, frame: Any, camera: PinholeCamera) -> Candidate | None:
        """Policy: a candidate whose site lies beyond the circle the autopilot's fence leaves the
        recovery (:meth:`RecoveryContext.fence_bounds`) but whose surface reaches inside it: its site
        moved straight toward home until inside, where the disc Surface ID measured clear around the
        site (``edge_distance_m``) still leaves the moved site ``PULLED_EDGE_M`` from the surface's
        edge, so that it stays on the surface, as open ground must; its pixel moved with it (IPM places
        the pixel) and its edge distance less the move. None when it cannot be: too little of it
        inside, not measured, or out of the camera's view. A field cut by the fence's circle is a field
        a farmland flight may land on (docs/companion.md, "The autopilot's fence")."""
        bounds = self.ctx.fence_bounds()
        if bounds is None or c.site_ned_m is None or not math.isfinite(c.edge_distance_m):
            return None
        (hn, he), keep = bounds
        sn, se, sd = c.site_ned_m
        out = math.hypot(sn - hn, se - he)
        move = out - keep + PULL_SPARE_M
        if out <= 0 or move <= 0 or c.edge_distance_m - move < PULLED_EDGE_M:
            return None
        k = (out - move) / out
        site = (hn + k * (sn - hn), he + k * (se - he), sd)
        seen = in_view(camera, frame.pos_ned_m, frame.quat_wxyz, site)
        if seen is None:
            return None
        return dataclasses.replace(
            c, site_ned_m=site, centre_px=seen[:2], edge_distance_m=c.edge_distance_m - move
        )

    def ipm(self, c: Candidate, frame: Any, camera: PinholeCamera) -> tuple[float, float, float] | None:
        """The chosen pixel -> world point through the LiDAR; the flat-ground fallback without it;
        None when neither can place it."""
        ctx = self.ctx
        ctx.fault.check("ipm", ctx.round)
        u, v = c.centre_px
        try:
            index = LidarPixelIndex(frame.lidar_frd, camera)
            p = pixel_to_ned_surface(u, v, index, frame.pos_ned_m, frame.quat_wxyz)
        except IpmError as exc:
            ground_d = frame.pos_ned_m[2] + frame.rangefinder_m
            ctx.log.warning("IPM through the LiDAR failed (%s): flat ground at the rangefinder distance", exc)
            try:
                p = pixel_to_ned_flat(u, v, camera, frame.pos_ned_m, frame.quat_wxyz, ground_d)
            except IpmError as flat:  # e.g. a rangefinder reading 0: the ray never meets that plane
                ctx.log.warning("and flat ground failed too (%s): no world position", flat)
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
    seen = in_view(camera, pos_ned_m, quat_wxyz, target_ned_m)
    if seen is None:
        return image
    u, v, dist = seen
    half = int(camera.fx * half_m / dist)
    return crop(image, site_box(u, v, half, camera.width, camera.height))


def in_view(
    camera: PinholeCamera, pos_ned_m: Any, quat_wxyz: Any, point_ned_m: Any
) -> tuple[float, float, float] | None:
    """Where a world point (NED, metres) falls in a frame taken at ``pos_ned_m`` / ``quat_wxyz``: its
    pixel and its distance from the camera, or None when it is behind the camera, outside the image or
    at the camera itself."""
    rel = np.asarray(point_ned_m, dtype=float) - np.asarray(pos_ned_m, dtype=float)
    uv, front = camera.project_frd((rel @ quat_to_matrix(quat_wxyz))[None, :])
    dist = float(np.linalg.norm(rel))
    u, v = float(uv[0, 0]), float(uv[0, 1])
    if not front[0] or dist <= 0 or not (0 <= u < camera.width and 0 <= v < camera.height):
        return None
    return u, v, dist


UNMEASURED = SiteCheck(0, math.nan, math.nan, math.nan, math.nan, ("not measured",))


def height_above_surroundings(frame: Any, check: SiteCheck) -> float | None:
    """How far the measured surface under a site stands above the lowest tenth of the sweep's returns
    (what Surface ID calls elevation), or None without enough returns."""
    if frame.lidar_frd is None or len(frame.lidar_frd) < 20:
        return None
    up = -world_points(frame.lidar_frd, frame.pos_ned_m, frame.quat_wxyz)[:, 2]
    if len(up) < 20:
        return None
    return float(check.surface_up_m - np.percentile(up, 10))


def lidar_silent(lidar_frd: Any) -> bool:
    """A LiDAR sweep came and has no return with a finite position (a missing sweep is not silence)."""
    if lidar_frd is None:
        return False
    pts = np.asarray(lidar_frd, dtype=float)
    return pts.ndim != 2 or pts.shape[0] == 0 or not bool(np.isfinite(pts[:, :3]).all(axis=1).any())


def _measured(value: float) -> float | None:
    """A Surface ID measure for a request: None where it was not measured (NaN)."""
    return value if math.isfinite(value) else None
