"""The onboard tier: deterministic, no network, a few milliseconds (DESIGN.md section 8).

**Rank.** Every crop is looked at (:func:`companion.reasoning.image_cues.analyse`): its ``hazard``
(water, vegetation, lane markings, raised objects and their shadows, ...) always counts against it.
When Surface ID's geometry comes with the request, each candidate also gets a geometry score
(:func:`geometry_score`): room to land (landable area, up to ``GeometryWeights.area_full_m2``), distance
to its edge, slope and roughness, and elevation: a surface ``roof_height_m`` or more above its
surroundings is a roof, away from traffic and people, and scores ``elevated``; a surface at street level
scores ``street_level`` (streets, plazas and car parks carry traffic even when they look empty). The
score is geometry minus hazard; candidates without geometry (the quadrant fallback) come after every
measured one. With images only (no depth: degraded mode) the hazard orders them, and a crop's size (the
boxes of one frame share a scale) breaks near-ties: a large clear roof before a clear sliver. The weights are
set so that a road's markings or water (2.5 to 3 hazard points) outweigh the elevation bonus, so an
elevated highway deck, geometrically a fine roof, loses to a clear roof: the reference study's smaller
models chose empty highways.

**Confirm.** The close-up is judged in site mode (``analyse(image, site=True)``: the surface under the image
centre, within the middle two thirds of a square close-up cut around the site, as the recovery loop sends,
or the middle 30 % of a whole camera frame; ``ConfirmParams.site_window`` overrides). Descend only when the
LiDAR check (when there is one) is clear and the image shows no veto on the site: water, vegetation, lane
markings, a site measured at street level that is mostly asphalt (``max_street_asphalt``: a road or a car
park, empty for now), more than ``max_raised`` raised objects (people, vehicles, clutter, or their shadows),
pipes or rails, or a total hazard over ``max_hazard``. When Surface ID measured the site ``roof_height_m``
or more above its surroundings (``ConfirmRequest.site_up_m``), its asphalt look and road texture do not
count: a dark, even tar roof looks like a road, but no road runs on a roof. An elevated *strip*
(``ConfirmRequest.site_strip``: Surface ID measured a long narrow band, a highway deck or a bridge) is
no roof: it is judged as street level is, where a single painted line (``lane_lines >= 1``) vetoes the
site whatever its texture. A "no" for water or lane markings, or any "no" for a site measured at street
level or on a strip (streets, plazas, car parks, decks), is *binding*: the cascade lets no remote
tier's "yes" overrule it. Among buildings (``ConfirmRequest.built_up``: a roof in view or measured
near the site) a site at street level is refused even when it looks clear: sidewalks and plazas look
empty between one pedestrian and the next, and the clear roofs are where no one walks. Such a site
stays in the recovery's ledger as a last resort (docs/recovery.md); in open country (none) a field is
judged on what is seen. ``Decision.hazards`` names the kinds of what vetoed the site (water,
markings, street_asphalt, raised, lidar_obstacle, ...): the recovery's ledger of measured sites ranks
them by it (docs/recovery.md). ``critical=True``
relaxes two things a little and never water or lane markings: the total hazard limit rises from
``max_hazard`` to ``max_hazard_critical`` (flat patches, asphalt-like texture, busy edges), and when the
LiDAR check is clear (nothing taller than 0.3 m inside the rotor disc) one raised object in view is
tolerated (``max_raised_critical``): it stands outside the disc, or is a false sighting. Without a LiDAR
check nothing about raised objects is relaxed.

**Judges.** ``judge="cues"`` (this class's default) reads images with the hand-written cues above;
``judge="landnet"`` (the companion's default, ``reasoner.onboard_judge``: far better on real aerial
photographs) reads them with the learned LandNet-S (:mod:`companion.reasoning.net_judge` says
how its reading replaces the cues in confirm and in images-only rank; in the rank with geometry its
``SceneReading.hazard`` takes the cues' place beside the geometry score); geometry, the LiDAR veto and the
binding rules are the same). Its weights load at construction: a missing or corrupt file is a
:class:`~companion.reasoning.landnet.LandNetError` naming it.

Rationales name the chosen site and what was seen on it and on the runner-up, e.g. ``site 0: elevated
flat roof 22 m up, 839 m2 landable, 14.3 m from its edge, no clutter, uniform gravel or tile texture
(not a hazard); site 1 rejected: HVAC-like blobs with shadows (6)``. The work is CPU-bound and takes a
few milliseconds; the async methods run it in a worker thread, off the event loop that streams setpoints.
"""

from __future__ import annotations

import asyncio
import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from companion.perception.site_check import SiteCheck
from companion.perception.surface_id import Candidate
from companion.reasoning.base import ConfirmRequest, Decision, Ranking, RankRequest, Reasoner
from companion.reasoning.image_cues import CueParams, ImageCues, analyse
from companion.reasoning.landnet import LandNet, SceneReading
from companion.reasoning.net_judge import confirm_reading, rank_readings, unsure
from companion.reasoning.onboard_params import ConfirmParams, GeometryWeights

__all__ = [
    "JUDGES",
    "ConfirmParams",
    "Decision",
    "GeometryWeights",
    "OnboardReasoner",
    "Ranking",
    "Reasoner",
    "geometry_score",
    "lidar_kind",
]


JUDGES = ("cues", "landnet")  # what reads the images (module docstring, "Judges")


@dataclass(frozen=True, slots=True)
class _Site:
    index: int
    score: float
    fallback: bool
    geometry: str  # what the geometry says, or "" without it
    cues: ImageCues | SceneReading = field(repr=False)  # what the judge saw in the crop


def geometry_score(c: Candidate, w: GeometryWeights | None = None) -> tuple[float, str]:
    """Points for a candidate's geometry (0 where unknown) and a phrase naming it.

    Relative depth (no metres) leaves area, heights and edges NaN: those terms count 0.
    """
    w = w or GeometryWeights()
    if c.fallback:
        return 0.0, "no flat surface measured there (quadrant fallback)"
    notes: list[str] = []
    s = 0.0
    h = c.height_above_m
    if math.isfinite(h):
        if h >= w.roof_height_m and c.strip:
            # long and narrow up in the air: a highway deck, a bridge or a ramp, where traffic runs
            s += w.street_level
            notes.append(
                f"elevated strip {h:.0f} m up, {c.length_m:.0f} x {c.width_m:.0f} m "
                "(a deck or a bridge: traffic)"
            )
        elif h >= w.roof_height_m:
            s += w.elevated
            notes.append(f"elevated flat roof {h:.0f} m up")
        else:
            s += w.street_level
            notes.append("at street level")
    room = c.landable_area_m2 if math.isfinite(c.landable_area_m2) else c.area_m2
    if math.isfinite(room):
        s += w.area * min(room, w.area_full_m2) / w.area_full_m2
        notes.append(f"{room:.0f} m2 landable")
    if math.isfinite(c.edge_distance_m):
        s += w.edge * min(c.edge_distance_m, w.edge_full_m) / w.edge_full_m
        notes.append(f"{c.edge_distance_m:.1f} m from its edge")
    if math.isfinite(c.slope_deg) and c.slope_deg > w.slope_free_deg:
        s -= w.slope_per_deg * (c.slope_deg - w.slope_free_deg)
        notes.append(f"sloped {c.slope_deg:.0f} deg")
    if math.isfinite(c.roughness_m) and c.roughness_m > w.roughness_free_m:
        s -= w.roughness_per_cm * 100.0 * (c.roughness_m - w.roughness_free_m)
        notes.append(f"rough {100 * c.roughness_m:.0f} cm")
    if c.measured_share < 1.0:
        s -= w.extended * (1.0 - c.measured_share)
    if not notes:
        notes.append("no metric geometry")
    return s, ", ".join(notes)


class OnboardReasoner:
    """The onboard tier (module docstring). ``rank_sync``/``confirm_sync`` do the work; the async
    methods of the :class:`~companion.reasoning.base.Reasoner` protocol call them."""

    name: str = "onboard"

    def __init__(
        self,
        weights: GeometryWeights | None = None,
        confirm: ConfirmParams | None = None,
        *,
        judge: str = "cues",
        landnet: LandNet | None = None,
        cues: CueParams | None = None,
    ) -> None:
        """``judge``: ``"cues"`` or ``"landnet"``; with ``"landnet"``, ``landnet`` (default: the packaged
        model, loaded now); with ``"cues"``, ``cues`` the image cues' thresholds (default: ``CueParams()``).

        Raises:
            ValueError: an unknown judge.
            LandNetError: ``"landnet"`` without a loadable model (the message names the file).
        """
        if judge not in JUDGES:
            raise ValueError(f"unknown onboard judge {judge!r}; expected one of {', '.join(JUDGES)}")
        self.weights = weights or GeometryWeights()
        self.confirm_params = confirm or ConfirmParams()
        self.judge = judge
        self.cue_params = cues if cues is not None else CueParams()
        self.landnet = (landnet or LandNet.load()) if judge == "landnet" else None

    # the work runs in a worker thread: the daemon's event loop also streams the setpoints, and a
    # 4x-speed simulation leaves it 250 ms of wall time before PX4's offboard-loss failsafe
    async def rank(self, request: RankRequest) -> Ranking:
        return await asyncio.to_thread(self.rank_sync, request)

    async def confirm(self, request: ConfirmRequest) -> Decision:
        return await asyncio.to_thread(self.confirm_sync, request)

    def warm_up(self) -> None:
        """A rank of two plain grey crops and a confirmation of a plain grey close-up, answers dropped:
        the first reading pays ONNX Runtime's first run and OpenCV's first conversions, which a start-up
        pays better than the first alarm. Holds no state: later answers are the same."""
        grey = np.full((96, 128, 3), 128, np.uint8)
        self.rank_sync(RankRequest((grey, grey)))
        self.confirm_sync(ConfirmRequest(np.full((540, 960, 3), 128, np.uint8)))

    # ------------------------------------------------------------------ rank
    def rank_sync(self, request: RankRequest) -> Ranking:
        """Every candidate, best first; ties keep the given order.

        Raises:
            ValueError: a crop that is not a non-empty (H, W, 3) uint8 image.
        """
        t0 = time.perf_counter()
        if self.landnet is not None and request.candidates is None:
            order, text, body = rank_readings(
                self.landnet, request, [_core(request, k) for k in range(len(request.crops))], self.weights
            )
            if request.transcript is not None:
                request.transcript.append({"tier": self.name, "judge": self.judge, **body})
            return Ranking(order, text, self.name, time.perf_counter() - t0)
        cores = [_core(request, k) for k in range(len(request.crops))]
        # what reads the crops: the net when it is the judge (its reading replaces the cues' hazard terms
        # beside the geometry too), else the image cues; both validate the crops first
        all_cues: list[ImageCues | SceneReading] = (
            [self.landnet.read_rank(c) for c in cores]
            if self.landnet is not None
            else [analyse(c, params=self.cue_params) for c in cores]
        )
        largest = max(c.size_px[0] * c.size_px[1] for c in all_cues)
        sites: list[_Site] = []
        for k, cues in enumerate(all_cues):
            cand = None if request.candidates is None else request.candidates[k]
            if cand is None:
                # Images only: a crop's size is all there is to say about room to land (Surface ID's
                # boxes of one frame share one scale); a light tie-breaker, not a reason.
                share = cues.size_px[0] * cues.size_px[1] / largest
                g, geometry = self.weights.crop_size * math.sqrt(share), ""
            else:
                g, geometry = geometry_score(cand, self.weights)
            fallback = cand is not None and cand.fallback
            sites.append(_Site(k, g - cues.hazard, fallback, geometry, cues))
        ranked = sorted(sites, key=lambda s: (s.fallback, -s.score, s.index))
        threshold = None if self.landnet is None else self.landnet.net_clear_threshold
        rationale = _rank_rationale(ranked, request.candidates is None, threshold)
        if request.transcript is not None:
            request.transcript.append(
                {
                    "tier": self.name,
                    "judge": self.judge,
                    "scores": {str(s.index): round(s.score, 3) for s in sites},
                    "readings" if self.landnet is not None else "cues": [s.cues.to_json() for s in sites],
                }
            )
        order = tuple(s.index for s in ranked)
        return Ranking(order, rationale, self.name, time.perf_counter() - t0)

    # ------------------------------------------------------------------ confirm
    def confirm_sync(self, request: ConfirmRequest) -> Decision:
        """Descend or not (module docstring).

        Raises:
            ValueError: an image that is not a non-empty (H, W, 3) uint8 image.
        """
        t0 = time.perf_counter()
        if self.landnet is not None:
            return self._confirm_net(request, self.landnet, t0)
        p = self.confirm_params
        cues = analyse(request.image, site=True, window=p.site_window, params=self.cue_params)
        check = request.check
        lidar_clear = check is not None and check.clear
        relax = request.critical
        max_raised = p.max_raised_critical if relax and lidar_clear else p.max_raised
        vetoes = _lidar_vetoes(check)  # (kind, what was seen)
        # water or a road's markings: no other tier's yes overrules them
        categorical = any(kind == "water" for kind, _ in vetoes)
        if cues.water_share > p.max_water:
            vetoes.append(("water", f"water ({100 * cues.water_share:.0f} % of the site)"))
            categorical = True
        if cues.vegetation_share > p.max_vegetation:
            vetoes.append(("vegetation", f"vegetation ({100 * cues.vegetation_share:.0f} %)"))
        elevated, street_level, where = self._level(request)
        if cues.line_length > p.max_markings:
            vetoes.append(
                ("markings", f"lane markings ({cues.lane_lines}): a road stays risky even when empty")
            )
            categorical = True
        elif street_level and cues.lane_lines >= 1:
            # Off a roof a single painted line is a road's (or a car park's): no texture outvotes it.
            vetoes.append(("markings", f"a painted line {where}: a road stays risky even when empty"))
            categorical = True
        if street_level and cues.asphalt_share > p.max_street_asphalt:
            vetoes.append(
                (
                    "street_asphalt",
                    f"asphalt {where} ({100 * cues.asphalt_share:.0f} %): a road or a car park, "
                    "where traffic comes back",
                )
            )
        if street_level and request.built_up and not vetoes:
            # Among buildings the clear roofs are where no one walks; sidewalks and plazas look clear
            # from above between one pedestrian and the next. Open country (no roof measured) keeps
            # its fields.
            vetoes.append(
                (
                    "street_level",
                    f"{where} among buildings: people and traffic come back (a last resort only)",
                )
            )
        if cues.raised_blobs > max_raised:
            vetoes.append(("raised", cues.phrase("raised")))
        if cues.raised_line_length > p.max_raised_lines:
            vetoes.append(("raised_lines", cues.phrase("lines_raised")))
        limit = p.max_hazard_critical if relax else p.max_hazard
        # A surface measured well above its surroundings is a roof: a dark, even tar roof looks like
        # asphalt, but no road runs there. (Lane markings still veto: an elevated highway deck.)
        street = ("asphalt", "road_texture") if elevated else ()
        terms = [(name, v) for name, v in cues.terms if name not in street]
        hazard = sum(v for _name, v in terms)
        if not vetoes and hazard > limit:
            seen = ", ".join(cues.phrase(name) for name, _v in terms[:3])
            vetoes.append(("hazard", f"hazard {hazard:.1f} over {limit:.1f}: {seen}"))
        why = f"site clear: {_geometry_phrase(check)}; image: {', '.join(cues.observations()[:3])}"
        if relax and cues.raised_blobs:
            why += " (critical: one object in view tolerated, LiDAR finds the rotor disc clear)"
        if elevated and any(name in street for name, _v in cues.terms):
            why += f" (dark asphalt-like surface {request.site_up_m:.0f} m up: a tar roof, not a road)"
        body = {"cues": cues.to_json()}
        return self._decision(request, t0, vetoes, categorical or street_level, why, body)

    def _confirm_net(self, request: ConfirmRequest, net: LandNet, t0: float) -> Decision:
        """``confirm_sync`` with LandNet-S's reading in place of the image cues (net_judge)."""
        _elevated, street_level, where = self._level(request)
        vetoes, categorical, note, reading, open_ground = confirm_reading(
            net,
            request,
            self.confirm_params,
            lidar_vetoes=_lidar_vetoes(request.check),
            street_level=street_level,
            where=where,
        )
        seen = ", ".join(reading.observations()[:3])
        why = f"site clear: {_geometry_phrase(request.check)}; image: {seen}{note}"
        body = {"judge": self.judge, "reading": reading.to_json()}
        # the clear-site probability decided (a roof, no binding veto): say how sure it was
        guess = "" if categorical or street_level or open_ground else unsure(reading, net.clear_threshold)
        return self._decision(
            request, t0, vetoes, categorical or street_level, why, body, guess, open_ground=open_ground
        )

    def _level(self, request: ConfirmRequest) -> tuple[bool, bool, str]:
        """(elevated, street level, where in words) of the site. A roof is a surface measured well
        above its surroundings that is not a long narrow strip (a highway deck, a bridge: traffic
        runs there). Streets and decks are judged alike."""
        roof = request.site_up_m is not None and request.site_up_m >= self.weights.roof_height_m
        elevated = roof and not request.site_strip
        street_level = request.site_up_m is not None and not elevated
        where = "on an elevated strip (a deck)" if roof and request.site_strip else "at street level"
        return elevated, street_level, where

    def _decision(
        self,
        request: ConfirmRequest,
        t0: float,
        vetoes: list[tuple[str, str]],
        binds: bool,
        clear_why: str,
        body: dict[str, Any],
        guess: str = "",
        *,
        open_ground: bool = False,
    ) -> Decision:
        """The confirm stage's Decision from its vetoes (none: accepted, with ``clear_why``); a
        rejection is binding when ``binds``; ``open_ground``: judged as open ground, not a roof.
        Appends the transcript entry (``body`` and the verdict)."""
        accept = not vetoes
        if accept:
            why = clear_why
        else:
            why = "rejected: " + "; ".join(text for _kind, text in vetoes)
            if request.check is None:
                why += " (no LiDAR: judged from the image alone)"
        if guess:
            why += f" ({guess})"
        binding = not accept and binds
        kinds = tuple(dict.fromkeys(kind for kind, _text in vetoes))
        if request.transcript is not None:
            request.transcript.append(
                {"tier": self.name, **body, "accept": accept, "binding": binding, "hazards": kinds,
                 "unsure": bool(guess)}
            )  # fmt: skip
        spent = time.perf_counter() - t0
        return Decision(
            accept,
            why,
            self.name,
            spent,
            binding=binding,
            hazards=kinds,
            unsure=bool(guess),
            open_ground=accept and open_ground,
        )


def _lidar_vetoes(check: SiteCheck | None) -> list[tuple[str, str]]:
    """The LiDAR's veto of a site, as the one (kind, text) pair of a list (empty: no check, or clear)."""
    if check is None or check.clear:
        return []
    return [(lidar_kind(check), "LiDAR: " + "; ".join(check.reasons))]


def lidar_kind(check: SiteCheck) -> str:
    """The ``Decision.hazards`` kind of a LiDAR veto: water (returns as dark as water) before an
    object in the rotor disc before roughness before a slope before an edge (the worst of what the
    check found)."""
    text = " ".join(check.reasons)
    if "dark as water" in text:
        return "water"
    if "object" in text:
        return "lidar_obstacle"
    if "rough" in text:
        return "lidar_rough"
    if "sloped" in text:
        return "lidar_slope"
    return "lidar_edge"


def _geometry_phrase(check: SiteCheck | None) -> str:
    if check is None:
        return "no LiDAR (judged from the image alone)"
    edge = (
        "no edge in view"
        if math.isinf(check.edge_distance_m)
        else f"{check.edge_distance_m:.1f} m to an edge"
    )
    slope = f", sloped {check.slope_deg:.0f} deg" if check.slope_deg >= 1.5 else ""  # NaN: not fitted
    return f"LiDAR {check.points} returns, {100 * check.roughness_m:.0f} cm rough{slope}, {edge}"


def _describe(site: _Site, limit: int) -> str:
    parts = [site.geometry] if site.geometry else []
    parts.extend(site.cues.observations()[:limit])
    return ", ".join(parts)


def _rank_rationale(ranked: list[_Site], images_only: bool, clear_threshold: float | None = None) -> str:
    """``clear_threshold``: the net's, when it read the crops (a runner-up under it is "rejected")."""
    best = ranked[0]
    text = f"site {best.index}: {_describe(best, 3)}"
    if len(ranked) > 1:
        nxt = ranked[1]
        seen = nxt.cues
        poor = (
            seen.clear_p < clear_threshold
            if isinstance(seen, SceneReading) and clear_threshold is not None
            else seen.hazard >= 1.0
        )
        verdict = "rejected" if poor or nxt.fallback else "next"
        text += f"; site {nxt.index} {verdict}: {_describe(nxt, 2)}"
    if images_only:
        text += " (no geometry: image cues only)"
    return text


def _core(request: RankRequest, k: int) -> Any:
    """Crop ``k`` without its context padding: the onboard tier judges where it would land."""
    crop = request.crops[k]
    if request.cores is None:
        return crop
    x0, y0, x1, y1 = request.cores[k]
    return crop[y0:y1, x0:x1]
