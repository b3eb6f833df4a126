"""Every site a recovery measured, and how bad each is: where to land when nothing was accepted.

When the round budget runs out, the sensors are lost or the companion meets a defect of its own, the
vehicle still has to come down somewhere. "Here", blindly, has put it on water it had itself seen as
water and on a road it had refused as a road. The ledger keeps what each round learned instead: every
candidate Surface ID measured (with what its rank crop showed), every confirmation's verdict (what the
close-up and the LiDAR check found), and, on demand, the spot under the vehicle. :meth:`SiteLedger.least_bad`
then ranks them by :class:`Hazard`, worst kinds last:

==============  =======================================================================================
``ACCEPTED``    confirmed for descent: LiDAR clear and the reasoner's yes
``DOUBTED``     a roof whose LiDAR check was clear, refused only on the image's softer doubts (a hazard
                score, a lone "no"), or never confirmed but with nothing seen against it
``OFF_ROOF``    street level with no road markings or asphalt seen, judged as open ground: a lawn, a
                field, a yard, a car park in open country; or open ground too small or too near its edge
                (``cramped``)
``STREET``      street level among buildings, refused as such (``street_level``): a sidewalk, a plaza,
                where people and traffic come back
``OBSTRUCTED``  the LiDAR found an object in the rotor disc, rough ground or an edge; people, vehicles
                or rooftop objects, pipes, trees or a tree's canopy on it; or the image judgement is sure it
                is no clear roof (``not_clear``: clear-site confidence under 0.2), whatever it could name
``UNKNOWN``     nothing measured (no camera image and no LiDAR check)
``TRAFFIC``     lane markings or asphalt at street level, or an elevated strip: a road, a highway deck
``WATER``       water
==============  =======================================================================================

Within one kind, a site judged at confirmation (a close-up) comes before one only seen from afar, a
site farther from its edge before a nearer one, and then the nearer to the vehicle. So water or a
traffic lane is chosen only when nothing else was seen, a lawn or a field before a sidewalk among
buildings, and a sidewalk or a car park before a road. A site measured again (within
``same_site_m``) takes the newer verdict of the same or a closer look: a confirmation overrides what
the rank crop suggested, never the other way round.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any

__all__ = ["Hazard", "LedgerSite", "SiteLedger", "hazard_of"]


class Hazard(enum.IntEnum):
    """How bad a site is to land on (module docstring); lower is better."""

    ACCEPTED = 0
    DOUBTED = 1
    OFF_ROOF = 2
    STREET = 3
    OBSTRUCTED = 4
    UNKNOWN = 5
    TRAFFIC = 6
    WATER = 7

    @property
    def acceptable(self) -> bool:
        """Good enough to land on without looking further: a roof with nothing against it."""
        return self <= Hazard.DOUBTED

    @property
    def phrase(self) -> str:
        """How the kind is said to people: "off roof", "obstructed"."""
        return self.name.lower().replace("_", " ")


_TRAFFIC = {"markings", "street_asphalt"}
_OBSTRUCTED = {
    "lidar_obstacle",
    "lidar_rough",
    "lidar_slope",
    "lidar_edge",
    "raised",
    "raised_lines",
    "not_clear",
    "canopy",
}


def hazard_of(
    kinds: Iterable[str], *, accepted: bool, street_level: bool, strip: bool, judged: bool = True
) -> Hazard:
    """The :class:`Hazard` of a site from what was seen on it (``Decision.hazards`` kinds, or those
    of a rank crop) and where Surface ID measured it (``street_level``: under 3 m above its
    surroundings; ``strip``: an elevated deck). ``judged``: anything was measured at all."""
    seen = set(kinds)
    if "water" in seen:
        return Hazard.WATER
    if strip or seen & _TRAFFIC:
        return Hazard.TRAFFIC
    if accepted:
        return Hazard.ACCEPTED
    if not judged:
        return Hazard.UNKNOWN
    if seen & _OBSTRUCTED or ("vegetation" in seen and not street_level):
        return Hazard.OBSTRUCTED  # vegetation up on a roof: tree crowns
    if "street_level" in seen:
        return Hazard.STREET  # a sidewalk or a plaza among buildings: people come back
    if street_level or "cramped" in seen:
        return Hazard.OFF_ROOF  # a lawn at street level is vegetation: open ground
    return Hazard.DOUBTED


@dataclass
class LedgerSite:
    """One measured site: where it is (NED, metres), how bad (:class:`Hazard`) and why."""

    ned_m: tuple[float, float, float]
    hazard: Hazard
    why: str
    round: int
    closeup: bool  # judged on a confirmation close-up (not only a rank crop)
    edge_distance_m: float = math.nan  # Surface ID's distance from the site to its surface's edge
    label: str = ""  # how it is named to people: "site 2", "here"
    candidate: Any = field(default=None, repr=False)  # Surface ID's candidate, to confirm it later
    looked: bool = False  # a closer look was tried (flown to): not tried again
    kinds: tuple[str, ...] = ()  # what the onboard tier saw against it (``HAZARD_KINDS``), when it judged

    def to_json(self) -> dict[str, object]:
        return {
            "ned_m": [round(v, 2) for v in self.ned_m],
            "hazard": self.hazard.name.lower(),
            "why": self.why,
            "round": self.round,
            "closeup": self.closeup,
            "label": self.label,
        }


class SiteLedger:
    """The sites one recovery measured (module docstring)."""

    def __init__(self, same_site_m: float = 4.0) -> None:
        self.same_site_m = same_site_m
        self.sites: list[LedgerSite] = []

    def add(self, site: LedgerSite) -> LedgerSite:
        """Record ``site``; a site within ``same_site_m`` of it is replaced when the new look is as
        close or closer (a close-up over a rank crop), and otherwise kept (the new one is dropped)."""
        for k, old in enumerate(self.sites):
            if math.dist(old.ned_m[:2], site.ned_m[:2]) < self.same_site_m:
                if site.closeup or not old.closeup:
                    self.sites[k] = site
                    return site
                return old
        self.sites.append(site)
        return site

    def least_bad(
        self,
        here_ne_m: tuple[float, float] | None = None,
        *,
        allowed: Callable[[LedgerSite], bool] | None = None,
    ) -> LedgerSite | None:
        """The site to land on when nothing better will come (module docstring), among those
        ``allowed`` (all by default: e.g. not beyond the autopilot's fence), or None when there is none."""
        sites = [s for s in self.sites if allowed is None or allowed(s)]
        if not sites:
            return None

        def key(s: LedgerSite) -> tuple[float, ...]:
            edge = s.edge_distance_m if math.isfinite(s.edge_distance_m) else 0.0
            dist = math.dist(s.ned_m[:2], here_ne_m) if here_ne_m is not None else 0.0
            return (float(s.hazard), 0.0 if s.closeup else 1.0, -min(edge, 8.0), dist)

        return min(sites, key=key)

    def near(self, ne_m: tuple[float, float]) -> LedgerSite | None:
        """The site recorded within ``same_site_m`` of ``ne_m``, if any."""
        return next((s for s in self.sites if math.dist(s.ned_m[:2], ne_m) < self.same_site_m), None)

    def name(self, site: LedgerSite) -> str:
        """How ``site`` is named to people: its label, with its round when another site measured keeps
        the same label (Surface ID numbers each round's candidates from 0: "site 1, round 7")."""
        twins = [s for s in self.sites if s.label == site.label and s.round != site.round]
        return f"{site.label}, round {site.round}" if twins and site.label.startswith("site") else site.label

    def best_hazard(self) -> Hazard | None:
        return min((s.hazard for s in self.sites), default=None)
