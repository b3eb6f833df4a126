"""The onboard tier's judgement from LandNet-S's reading (``reasoner.onboard_judge = "landnet"``).

In place of the hand-written image cues (:mod:`companion.reasoning.image_cues`), the confirm stage and
both ranks read the image with :class:`companion.reasoning.landnet.LandNet` (the rank with Surface ID's
geometry subtracts the net's ``SceneReading.hazard`` from each candidate's geometry score, in
:class:`companion.reasoning.onboard.OnboardReasoner`). Everything that is not the image's business stays
as the onboard tier has it: the geometry score, the LiDAR veto, the street-level and built-up rules,
binding "no"s.

**Confirm.** The net reads the site window: the middle ``FRAME_WINDOW`` of each side of a whole camera
frame (16:9, ``FRAME_ASPECT``), else the middle ``CROP_WINDOW`` of a close-up cut around the site (or
``ConfirmParams.site_window``). Water over ``max_water`` of the window's cells, or painted markings over
``MAX_MARKING_SHARE`` (any at street level), veto it bindingly, as the cues' water and lane markings do
(but above street level on a window the net is firmly sure is a clear roof: those lines are its ridges);
so does a tree's crown above street level (:func:`canopy_share` over ``MAX_CANOPY_SHARE``: green and
textured, measured on the pixels, since the net's tree cells miss real canopy).
Otherwise the site is accepted when the net's clear-site probability reaches the sidecar's threshold
(calibrated on simbridge renders). That probability means a clear *roof*, which a surface Surface ID
measured at street level is not: there the window's road *and* roof-like cells count as paving (a plain
asphalt road looks like a tar roof from above; the height tells them apart), over
``max_street_asphalt`` a road or a car park. In open country (street level, no roof in view or measured near
the site: ``built_up`` false) only level ground with nothing on it passes, whatever the clear-site
probability: no object, person, vehicle, water or marking in the window, paving and trees within their
limits (a bare field, a yard, a lawn). Among buildings street level is a last resort, but for open ground:
a window mostly grass (``OPEN_GRASS_SHARE``) on a surface Surface ID measured at least
``ConfirmParams.open_ground_area_m2`` large, the site at least ``open_ground_edge_m`` from its edge (a
lawn, a sports field, a park's meadow, a pasture beside a farm; not a plaza, a street or a small garden,
whose edges carry people), judged then as open country is. So is the same wide grass measured above its
surroundings (a terrace or a meadow on a slope, where the ground falls away on one side, or a green
roof), which the clear-site probability, meaning a clear roof, would refuse. In open country too a site
on ground Surface ID measured must meet those two (the field's edge is a road or a path). A rejection
names what was seen where (objects, people, vehicles, vegetation, road surface, ...). With a critical
alarm and a clear LiDAR disc, one group of objects in view is tolerated, as the cues' one raised blob is.

**Rank (images only).** Score = crop size term - ``SceneReading.hazard`` (``HAZARD_SCALE`` x (half of
1 - clear probability, half the hazard peak: the likeliest hazard cell)): continuous, so ties are rare.
"""

from __future__ import annotations

import math
from typing import Any

import cv2
import numpy as np

from companion.perception.site_check import SiteCheck
from companion.reasoning.base import ConfirmRequest, RankRequest
from companion.reasoning.image_cues import CueParams, centre, check_rgb
from companion.reasoning.landnet import COUNTED, LandNet, SceneReading
from companion.reasoning.onboard_params import ConfirmParams, GeometryWeights

__all__ = ["confirm_reading", "rank_readings", "site_window", "unsure"]

FRAME_ASPECT = 16.0 / 9.0  # a whole camera frame (the companion's camera), within ASPECT_TOL
ASPECT_TOL = 0.05
FRAME_WINDOW = CueParams().site_window_frame  # the image cues' site windows
CROP_WINDOW = CueParams().site_window_crop
MAX_MARKING_SHARE = 0.02  # of the window's cells: a painted line, not one stray cell
MAX_CANOPY_SHARE = 0.4  # of the window's pixels green and textured: a tree's crown, not a roof
CANOPY_EXG = 0.06  # excess green (2G - R - B) / (R + G + B) above which a pixel is vegetation ...
CANOPY_TEXTURE = 8.0  # ... and the grey levels' standard deviation over 7 x 7 pixels above which it is leaves
CANOPY_SIDE_PX = 192  # the window is judged at this size
TINT_MIN_SATURATION = 0.2  # HSV saturation from which a pixel is tinted: soil, crops, brick (asphalt,
#                            concrete and gravel are near grey: 0.06-0.09 in simbridge's renders)
TINT_MIN_CHROMA = 0.08  # ... or chroma (max - min of R, G, B) from which it is: haze adds a near-grey light
#                        that leaves chroma scaled by the transmission but lifts the value, so saturation
#                        falls under fog where chroma holds (a ploughed field 40 m below in simbridge's fog:
#                        saturation 0.1, chroma 0.1; grey paving stays under 0.06 in any weather)
TINT_MIN_VALUE = 0.1  # darker pixels have no hue to speak of
UNSURE_MARGIN = 0.15  # a clear-site probability this close to the threshold is a guess, either way ...
UNSURE_SPREAD = 0.35  # ... as is one whose mirror-image views differ by this much
FIRM_NOT_CLEAR_P = 0.2  # a clear-site probability under this: the net is sure it is no clear roof
OPEN_GRASS_SHARE = 0.5  # of the window's cells grass: open ground among buildings (_wide_grass)
TREE_MIN_M = 2.0  # the net's tree cells are trees when the LiDAR saw something this tall near the site


def unsure(r: SceneReading, threshold: float) -> str:
    """Why the net's clear-site verdict on ``r`` is a guess (empty: it is not): a probability within
    ``UNSURE_MARGIN`` of ``threshold``, or views of the image disagreeing by ``UNSURE_SPREAD``."""
    why = []
    if abs(r.clear_p - threshold) < UNSURE_MARGIN:
        why.append(f"clear-site confidence {r.clear_p:.2f} near its threshold {threshold:.2f}")
    if r.clear_spread >= UNSURE_SPREAD:
        why.append(f"its views disagree ({r.clear_spread:.2f} apart)")
    return "unsure: " + " and ".join(why) if why else ""


def canopy_share(window: np.ndarray) -> float:
    """Share of an RGB window that is green and textured: leaves. A tree's crown measured from above
    is an elevated surface like a roof, and on real photographs the net's tree cells miss it (a dense
    canopy read as "roof surface 100 %, clear-site confidence 0.89" on a held-out tile), so colour and
    texture say it: excess green over ``CANOPY_EXG`` where the grey levels vary over
    ``CANOPY_TEXTURE`` (a green metal roof is green but smooth: 9 % of its pixels)."""
    side = (CANOPY_SIDE_PX, CANOPY_SIDE_PX)
    small = cv2.resize(window, side, interpolation=cv2.INTER_AREA).astype(np.float32)
    r, g, b = small[..., 0], small[..., 1], small[..., 2]
    exg = (2 * g - r - b) / (r + g + b + 1.0)
    grey = 0.299 * r + 0.587 * g + 0.114 * b
    mean = cv2.blur(grey, (7, 7))
    sd = np.sqrt(np.maximum(cv2.blur(grey * grey, (7, 7)) - mean * mean, 0.0))
    return float(((exg > CANOPY_EXG) & (sd > CANOPY_TEXTURE)).mean())


def tinted_share(window: np.ndarray) -> float:
    """Share of an RGB window whose colour is tinted (HSV saturation from ``TINT_MIN_SATURATION`` or
    chroma from ``TINT_MIN_CHROMA``): bare soil, crops, brick, not asphalt or concrete. At street level
    the net's roof-like cells count as paving, since a plain road looks like a tar roof from above; a
    ploughed field or a crop's rows read so too (farmland's fields: "roof surface 88 %" from both
    packaged nets), but a road is grey and a field is not. Fog greys a field's saturation (haze adds
    light of its own, near grey) but not its chroma, which grey paving lacks in any weather. Judged at
    ``CANOPY_SIDE_PX``, as the canopy is."""
    side = (CANOPY_SIDE_PX, CANOPY_SIDE_PX)
    small = cv2.resize(window, side, interpolation=cv2.INTER_AREA)
    hsv = cv2.cvtColor(small, cv2.COLOR_RGB2HSV)
    sat, val = hsv[..., 1], hsv[..., 2]
    chroma = small.max(axis=2).astype(np.int16) - small.min(axis=2)
    tinted = (sat >= 255 * TINT_MIN_SATURATION) | (chroma >= 255 * TINT_MIN_CHROMA)
    return float((tinted & (val >= 255 * TINT_MIN_VALUE)).mean())


def site_window(h: int, w: int, override: float | None) -> float:
    """Share of each side of an (h, w) close-up the net judges."""
    if override is not None:
        return override
    return FRAME_WINDOW if abs(w / h - FRAME_ASPECT) <= ASPECT_TOL * FRAME_ASPECT else CROP_WINDOW


def confirm_reading(
    net: LandNet,
    request: ConfirmRequest,
    p: ConfirmParams,
    *,
    lidar_vetoes: list[tuple[str, str]],
    street_level: bool,
    where: str,
) -> tuple[list[tuple[str, str]], bool, str, SceneReading, bool]:
    """Vetoes from the reading of the site window (module docstring), after ``lidar_vetoes``.

    Returns (vetoes as (kind, text), categorical, a note for an acceptance, the reading, whether it was
    judged as open ground: a field, a lawn or a terrace, where people walk, not a roof).

    Raises:
        ValueError: an image that is not a non-empty (H, W, 3) uint8 array.
    """
    image = check_rgb(request.image)
    window = centre(image, site_window(image.shape[0], image.shape[1], p.site_window))
    r = net.confirmation(net.read(window, short_side=net.confirm_short_side_px), image)
    vetoes = list(lidar_vetoes)
    categorical = any(kind == "water" for kind, _ in vetoes)  # the LiDAR's water binds as the image's
    canopy = 0.0 if street_level else canopy_share(window)
    if canopy > MAX_CANOPY_SHARE:  # at street level the vegetation limits below judge lawns and parks
        vetoes.append(("canopy", f"tree canopy ({canopy:.0%} of the site green and textured)"))
        categorical = True
    if r.share("water") > p.max_water:
        vetoes.append(("water", f"{r.phrase('water')} on the site"))
        categorical = True
    marking = r.share("marking")
    ridges = _ridges(r, net.clear_threshold, street_level, marking)
    if (marking > MAX_MARKING_SHARE and not ridges) or (street_level and marking > 0.0):
        vetoes.append(("markings", f"{r.phrase('marking')} {where if street_level else ''}".rstrip()
                       + ": a road stays risky even when empty"))  # fmt: skip
        categorical = True
    tint = tinted_share(window) if street_level else 0.0
    paved = _paved(r, tint)
    if street_level and paved > p.max_street_asphalt:
        vetoes.append(("street_asphalt", f"{_paved_phrase(r, paved)} {where}: a road or a car park"))
    wide_grass = not vetoes and _wide_grass(r, request, p)
    open_among = street_level and request.built_up and wide_grass
    # level grass measured above its surroundings: a terrace or a meadow on a slope (the ground falls
    # away on one side), or a green roof; the clear-site probability means a clear roof, which it is not
    terrace = not street_level and wide_grass
    if street_level and request.built_up and not vetoes and not open_among:
        vetoes.append(
            ("street_level", f"{where} among buildings: people and traffic come back (a last resort only)")
        )
    note = f" (lines on it, {marking:.0%}, read as its ridges or seams: firmly clear)" if ridges else ""
    groups = sum(r.count(c) for c in COUNTED)
    vegetation = r.share("low_vegetation") + r.share("tree")
    open_country = street_level and not request.built_up
    if not vetoes and (open_country or open_among or terrace):
        # the net's clear site means a clear roof, which a surface measured at street level is not: there
        # only level ground with nothing on it passes, whatever the clear-site probability
        if not _open_ground(r, p, groups, tint, _nothing_tall(request.check)):
            vetoes.append(_not_open_ground(r, groups, vegetation, tint))
        elif (cramped := _cramped(request, p)) is not None:
            vetoes.append(("cramped", cramped))
        elif open_among:
            note = (
                f" (open ground among buildings: {request.site_area_m2:,.0f} m2 of it, "
                f"{request.site_edge_m:.0f} m from its edge)"
            )
        elif terrace:
            note = (
                f" (open ground {request.site_up_m or 0.0:.0f} m above its surroundings, a terrace or a "
                f"green roof: {request.site_area_m2:,.0f} m2 of it, {request.site_edge_m:.0f} m from its "
                "edge)"
            )
        else:
            note = " (open country: level ground with nothing on it)"
    elif not vetoes and r.clear_p < net.clear_threshold:
        lidar_clear = request.check is not None and request.check.clear
        tolerate = (
            request.critical
            and lidar_clear
            and groups <= p.max_raised_critical
            and vegetation <= p.max_vegetation
        )
        if tolerate and groups:
            note = " (critical: one object in view tolerated, LiDAR finds the rotor disc clear)"
        elif not tolerate:
            vetoes.append(_not_clear(r, net.clear_threshold, groups, vegetation, p.max_vegetation))
    return vetoes, categorical, note, r, open_country or open_among or terrace


def _ridges(r: SceneReading, threshold: float, street_level: bool, marking: float) -> bool:
    """Whether the lines the net reads as painted markings (over ``MAX_MARKING_SHARE``) on a surface
    above street level are a roof's own: the ridges of corrugated metal, tile courses, seams. So when
    the net is firmly sure the window is a clear roof (its clear-site probability over ``threshold``,
    and not :func:`unsure`). On the real photographs every surface read with markings that was not a
    clear roof had a clear-site probability of 0.51 or less; corrugated clear roofs read 2-22 %
    markings at 0.87-0.99. At street level any marking is paint."""
    return (
        not street_level
        and marking > MAX_MARKING_SHARE
        and r.clear_p >= threshold
        and not unsure(r, threshold)
    )


def _paved(r: SceneReading, tint: float = 0.0) -> float:
    """Share of the window read as road or as roof surface. At street level both are paving where
    traffic runs: a plain asphalt road or car park looks like a tar roof from above (Surface ID's
    height tells them apart, not the image). Roof-like cells count in the share of the window that is
    not tinted (:func:`tinted_share` ``tint``): a brown field read as roof is no road."""
    return min(1.0, r.share("road") + r.share("roof") * (1.0 - tint))


def _paved_phrase(r: SceneReading, paved: float) -> str:
    where = ", ".join(list(dict.fromkeys([*r.where("road"), *r.where("roof")]))[:3])
    return f"road or tar-like paving ({100 * paved:.0f} %: {where})"


def _open_ground(
    r: SceneReading, p: ConfirmParams, groups: int, tint: float = 0.0, nothing_tall: bool = False
) -> bool:
    """A field, a yard or a lawn with nothing on it: no object, person, vehicle, water or marking seen,
    road or tar-like paving (:func:`_paved`) at most ``max_street_asphalt`` and trees at most
    ``max_vegetation`` of the window, unless the LiDAR found nothing tall near the site
    (``nothing_tall``, :func:`_nothing_tall`): a tree stands metres above the ground, and a lawn the
    net reads as trees is still a lawn."""
    hazards = r.share("water") + r.share("marking")
    return (
        groups == 0
        and hazards == 0.0
        and _paved(r, tint) <= p.max_street_asphalt
        and (r.share("tree") <= p.max_vegetation or nothing_tall)
    )


def _nothing_tall(check: SiteCheck | None) -> bool:
    """The close-up's LiDAR sweep measured the ground around the site as far as the close-up shows and
    nothing on it stands ``TREE_MIN_M`` tall: no tree there, whatever the image's cells say. Rain darkens
    a lawn into what the net reads as tree cover (suburb lawns 30 m below in simbridge's rain: 16-35 %
    of the window); a tree's crown is metres above the ground and in every sweep."""
    return check is not None and check.measured and check.tallest_near_m < TREE_MIN_M


def _wide_grass(r: SceneReading, request: ConfirmRequest, p: ConfirmParams) -> bool:
    """Open ground among buildings (module docstring): the window mostly grass (``OPEN_GRASS_SHARE``:
    a lawn, a sports field, a pasture; not a plaza, whose people come back), on a surface Surface ID
    measured at least ``open_ground_area_m2`` large with the site ``open_ground_edge_m`` from its edge."""
    area, edge = request.site_area_m2, request.site_edge_m
    return (
        area is not None
        and edge is not None
        and area >= p.open_ground_area_m2
        and edge >= p.open_ground_edge_m
        and r.share("low_vegetation") >= OPEN_GRASS_SHARE
    )


def _cramped(request: ConfirmRequest, p: ConfirmParams) -> str | None:
    """Why open ground Surface ID measured is too small, or the site too near its edge (the road, path
    or fence where people pass), for ``open_ground_area_m2`` and ``open_ground_edge_m``; None when it
    is neither, or was not measured."""
    area, edge = request.site_area_m2, request.site_edge_m
    if edge is not None and edge < p.open_ground_edge_m:
        return f"open ground, but {edge:.0f} m from its edge (at least {p.open_ground_edge_m:.0f} m)"
    if area is not None and area < p.open_ground_area_m2:
        return f"open ground, but {area:,.0f} m2 of it (at least {p.open_ground_area_m2:,.0f} m2)"
    return None


def _not_open_ground(r: SceneReading, groups: int, vegetation: float, tint: float = 0.0) -> tuple[str, str]:
    seen = [r.phrase(c) for c in ("person", "vehicle", "object") if r.count(c)]
    if r.share("water") > 0.0:  # under the water veto's share, but open ground has none
        seen.append(r.phrase("water"))
    if r.share("tree") > 0.0:
        seen.append(r.phrase("tree"))
    paved = _paved(r, tint)
    if paved > 0.0:
        seen.append(_paved_phrase(r, paved))
    what = ", ".join(seen[:4]) if seen else "nothing named"
    kind = "raised" if groups else "vegetation" if vegetation > 0.0 and not paved else "street_asphalt"
    return kind, f"not level open ground with nothing on it: {what}"


def _not_clear(
    r: SceneReading, threshold: float, groups: int, vegetation: float, max_vegetation: float
) -> tuple[str, str]:
    seen = [r.phrase(c) for c in ("person", "vehicle", "object") if r.count(c)]
    if vegetation > 0.0:
        seen.append(f"vegetation ({100 * vegetation:.0f} %)")
    seen.extend(r.phrase(c) for c in ("road", "edge", "ground") if r.share(c) >= 0.1)
    what = ", ".join(seen[:4]) if seen else "nothing named, but it does not look like a clear roof"
    text = (
        f"not a clear roof surface (clear-site confidence {r.clear_p:.2f} under {threshold:.2f}; "
        f"roof surface {100 * r.share('roof'):.0f} %): {what}"
    )
    # sure it is no clear roof (an edge or a wall it cannot count, say), it is not a soft doubt: a site
    # the search would otherwise settle for (city 0 on real ArduCopter: a parapet 1.9 m away, clear-site
    # confidence 0.11, "edges or walls 26 %")
    firm = r.clear_p < FIRM_NOT_CLEAR_P
    kind = (
        "raised"
        if groups
        else "vegetation"
        if vegetation > max_vegetation
        else "not_clear"
        if firm
        else "hazard"
    )
    return kind, text


def rank_readings(
    net: LandNet, request: RankRequest, crops: list[Any], w: GeometryWeights
) -> tuple[tuple[int, ...], str, dict[str, Any]]:
    """Images-only rank (no candidates): order, rationale and the transcript entry's body.

    Raises:
        ValueError: a crop that is not a non-empty (H, W, 3) uint8 array.
    """
    readings = [net.read_rank(c) for c in crops]
    largest = max(r.size_px[0] * r.size_px[1] for r in readings)
    scores = [w.crop_size * math.sqrt(r.size_px[0] * r.size_px[1] / largest) - r.hazard for r in readings]
    order = tuple(sorted(range(len(readings)), key=lambda k: (-scores[k], k)))
    best = order[0]
    text = f"site {best}: {_describe(readings[best], net.net_clear_threshold, 3)}"
    if len(order) > 1:
        nxt = order[1]
        verdict = "rejected" if readings[nxt].clear_p < net.net_clear_threshold else "next"
        text += f"; site {nxt} {verdict}: {_describe(readings[nxt], net.net_clear_threshold, 2)}"
    text += " (no geometry: LandNet-S reading only)"
    body = {
        "scores": {str(k): round(s, 3) for k, s in enumerate(scores)},
        "readings": [r.to_json() for r in readings],
    }
    return order, text, body


def _describe(r: SceneReading, threshold: float, limit: int) -> str:
    """The rank's words for one reading: up to ``limit`` things seen, then the roof surface's share and
    the net's confidence, which are always said."""
    head = "looks like a clear roof" if r.clear_p >= threshold else "not a clear roof"
    seen = r.observations()
    return f"{head}, " + ", ".join([*seen[:-2][:limit], *seen[-2:]])
