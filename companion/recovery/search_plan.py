"""The search for a landing site once the rounds in view have found nothing acceptable.

A launch over a river, a highway or a wide street sees only water and traffic. Accepting them while the
battery still holds most of its charge is what a pilot would never do: a pilot flies to the nearest block
of roofs. Two questions, two parts:

**May the vehicle go on searching?** (:class:`SearchLimits`, :meth:`SearchPlanner.verdict`) Searching
ends when the battery holds no more than what the landing needs plus a reserve, or when the alarm's
window has passed (a critical alarm has little time, a GPS-spoofing alarm at high criticality minutes).
Time is the autopilot's clock (``time_boot_ms``), so a simulation run faster than real time keeps its
meaning; the battery drain is measured in flight since the alarm (a default rate until enough has been
seen). The round budget stays the unit the study reports in; it no longer ends the search.

**Where next?** (:meth:`SearchPlanner.next_leg`) Every frame the recovery judges goes into a coarse map
of the ground (``cell_m`` cells, world NE): which cells the LiDAR has measured and which returns stand
3 m or more above the sweep's ground and are level (roof evidence), and where each look was taken and how
far it saw (its footprint). A leg is then, in this order:

1. **roofs seen but not judged**: a group of level elevated cells outside every earlier look's judged
   core (the inner part of its footprint, where Surface ID proposes all that is flat and large enough)
   and away from sites the ledger holds as water, traffic or obstructed: fly there and look;
2. **new ground**: a step of at least one view's width (the footprint at the search altitude: the smaller
   of the camera's half-width and the LiDAR's reach on the ground) in the heading that shows the most
   ground not yet seen, leans toward roof evidence and away from the water and traffic measured so far,
   and keeps to the previous heading where all else is equal. Headings whose footprint is mostly
   ground already seen are never taken while another is open.

Each leg says why (``Leg.reason``); the recovery announces it, records it (``search_leg``) and the
ground feed shows it. The altitude of a leg keeps ``clearance_m`` above the highest return the LiDAR has
measured near its path, and at least ``search_agl_m`` above the ground, where a 100 m LiDAR's reach on the
ground matches the camera's view.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from companion.alarms import Criticality
from companion.config_schema import DEFAULTS, RecoveryConfig
from companion.guidance.frames import PinholeCamera, compass_point, quat_to_matrix
from companion.perception.site_check import world_points
from companion.site_ledger import Hazard, SiteLedger

__all__ = ["Leg", "SearchLimits", "SearchPlanner", "Verdict"]

ROOF_UP_M = 3.0  # a return this far above the sweep's ground is elevated (Surface ID's roof height)
LEVEL_STD_M = 0.6  # elevated returns in one cell within this spread: a level surface, not a tree crown
MIN_CELL_RETURNS = 3
HEADINGS = 12  # candidate headings of a new-ground leg, evenly spaced
CAMERA_BAD = ("water", "road", "marking")  # LandNet-S classes that make ground no place to look for roofs
LEG_CORRIDOR_M = 30.0  # a leg keeps clearance_m over every return measured this near its path
CAMERA_TILES = (3, 2)  # columns, rows: the frame is read in tiles near the scale the net learnt


@dataclass(frozen=True, slots=True)
class SearchLimits:
    """When searching must stop. Percent of the battery; seconds of the autopilot's clock.

    ``reserve_pct``, ``window_s`` and ``max_legs`` are the ``[recovery]`` keys ``search_reserve_pct``,
    ``search_window_s`` and ``search_max_legs``: their defaults are the schema's and :meth:`from_config`
    copies them. No key sets the others.
    """

    reserve_pct: float = DEFAULTS.recovery.search_reserve_pct  # on top of what the landing itself needs
    window_s: dict[Criticality, float] = field(
        default_factory=DEFAULTS.recovery.search_window_s.per_criticality
    )
    default_drain_pct_s: float = 0.1  # before enough flight was seen to measure it
    descent_m_s: float = 1.0  # the staged descent's pace, confirmations included
    cruise_m_s: float = 3.0  # the pace of a flight to the chosen site
    landing_margin_s: float = 60.0  # spare time in the landing's need (a missed approach, a re-look)
    max_legs: int = DEFAULTS.recovery.search_max_legs  # whatever the battery says (a broken battery gauge)

    @classmethod
    def from_config(cls, r: RecoveryConfig) -> SearchLimits:
        """The limits ``[recovery]`` sets."""
        return cls(
            reserve_pct=r.search_reserve_pct,
            window_s=r.search_window_s.per_criticality(),
            max_legs=r.search_max_legs,
        )


@dataclass(frozen=True, slots=True)
class Verdict:
    """Whether searching may go on, and why (said to people and recorded)."""

    search: bool
    why: str
    battery_pct: float
    need_pct: float
    elapsed_s: float


@dataclass(frozen=True, slots=True)
class Leg:
    """One search leg: where to fly (world NED, metres) and why."""

    target_ned_m: tuple[float, float, float]
    aim: str  # "roofs" (evidence seen, not judged) or "new ground"
    reason: str
    distance_m: float
    bearing_deg: float

    def to_json(self) -> dict[str, Any]:
        return {
            "target_ned_m": [round(v, 1) for v in self.target_ned_m],
            "aim": self.aim,
            "reason": self.reason,
            "distance_m": round(self.distance_m, 1),
            "bearing_deg": round(self.bearing_deg, 1),
        }


@dataclass(slots=True)
class _Look:
    ne_m: tuple[float, float]
    reach_m: float  # how far from below the vehicle the LiDAR measured the ground (80th percentile)


class SearchPlanner:
    """The search's map of what was seen, its limits and its legs (module docstring).

    Args:
        criticality: the alarm's; :meth:`raise_criticality` shortens the window.
        limits: when searching stops.
        search_agl_m: a leg's least height above the ground.
        clearance_m: a leg's height above the highest structure measured near its path.
        lidar_range_m: the LiDAR's range (what it can reach on the ground from the leg's height).
        cell_m: the map's cell size.
    """

    def __init__(
        self,
        criticality: Criticality,
        limits: SearchLimits | None = None,
        *,
        search_agl_m: float = DEFAULTS.recovery.search_agl_m,
        clearance_m: float = 20.0,
        lidar_range_m: float = DEFAULTS.perception.lidar_range_m,
        cell_m: float = 10.0,
    ) -> None:
        self.criticality = criticality
        self.limits = limits or SearchLimits()
        self.search_agl_m = search_agl_m
        self.clearance_m = clearance_m
        self.lidar_range_m = lidar_range_m
        self.cell_m = cell_m
        self.looks: list[_Look] = []
        self.legs: list[Leg] = []
        # per cell (i, j): [returns, elevated returns, sum of elevated up, sum of squares, highest up]
        self._cells: dict[tuple[int, int], list[float]] = {}
        self.ground_up_m: float | None = None  # the latest sweep's ground level, metres up
        # per cell: [camera cells seen there, of which water or traffic] (LandNet-S on whole frames)
        self._camera: dict[tuple[int, int], list[int]] = {}
        self.half_fov_rad = math.radians(45.0)
        self._start: tuple[float, float] | None = None  # autopilot clock (s), battery (%) at the alarm
        self._heading: float | None = None
        # (home north, east; radius): the circle legs end inside (the autopilot's fence, companion.fence)
        self.bounds: tuple[tuple[float, float], float] | None = None
        # where legs were aimed that made no headway (the autopilot refused or could not fly them)
        self.blocked: list[tuple[float, float]] = []

    def _within(self, ne_m: tuple[float, float]) -> bool:
        return self.bounds is None or math.dist(ne_m, self.bounds[0]) <= self.bounds[1] + 1e-6

    def _reach_within(self, here: tuple[float, float], u: tuple[float, float], step: float) -> float:
        """How far along heading ``u`` from ``here`` a leg may go, up to ``step``, and stay inside
        :attr:`bounds` (0 when ``here`` is outside it and ``u`` does not lead back in)."""
        if self.bounds is None:
            return step
        (cn, ce), r = self.bounds
        dn, de = here[0] - cn, here[1] - ce
        # |d + s u| = r: s^2 + 2 (d.u) s + |d|^2 - r^2 = 0, the larger root
        b = dn * u[0] + de * u[1]
        disc = b * b - (dn * dn + de * de - r * r)
        if disc < 0:
            return 0.0
        return max(0.0, min(step, -b + math.sqrt(disc)))

    # ------------------------------------------------------------------ limits
    def start(self, t_boot_s: float, battery_pct: float) -> None:
        """The alarm came now (autopilot clock, seconds) with this charge (percent, nan: unknown)."""
        self._start = (t_boot_s, battery_pct)

    def raise_criticality(self, criticality: Criticality) -> None:
        self.criticality = max(self.criticality, criticality)

    def verdict(self, t_boot_s: float, battery_pct: float, agl_m: float, to_site_m: float = 0.0) -> Verdict:
        """May the vehicle go on searching now?

        Args:
            t_boot_s: the autopilot's clock now.
            battery_pct: the charge now (nan: unknown; then only the window and ``max_legs`` bound it).
            agl_m: height above the ground (the descent's length).
            to_site_m: how far the site it would land on lies (the flight there).
        """
        lim = self.limits
        t0, b0 = self._start if self._start is not None else (t_boot_s, battery_pct)
        elapsed = max(0.0, t_boot_s - t0)
        drain = lim.default_drain_pct_s
        if elapsed >= 30.0 and math.isfinite(b0) and math.isfinite(battery_pct) and b0 > battery_pct:
            drain = max(drain * 0.25, (b0 - battery_pct) / elapsed)
        height = agl_m if math.isfinite(agl_m) else 120.0
        need_s = height / lim.descent_m_s + to_site_m / lim.cruise_m_s + lim.landing_margin_s
        need = drain * need_s
        window = lim.window_s[self.criticality]
        if math.isfinite(battery_pct) and battery_pct <= lim.reserve_pct + need:
            why = (
                f"battery {battery_pct:.0f} %: the landing needs about {need:.0f} % "
                f"and {lim.reserve_pct:.0f} % stays in reserve"
            )
            return Verdict(False, why, battery_pct, need, elapsed)
        if elapsed >= window:
            why = f"the {self.criticality.name.lower()} alarm's {window:.0f} s to search have passed"
            return Verdict(False, why, battery_pct, need, elapsed)
        if len(self.legs) >= lim.max_legs:
            return Verdict(False, f"{lim.max_legs} search legs flown", battery_pct, need, elapsed)
        charge = f"battery {battery_pct:.0f} %" if math.isfinite(battery_pct) else "battery unknown"
        why = f"{charge}, {window - elapsed:.0f} s of the alarm's window left"
        return Verdict(True, why, battery_pct, need, elapsed)

    # ------------------------------------------------------------------ the map
    def observe(self, frame: Any) -> None:
        """Add one frame's LiDAR sweep (and its camera's field of view) to the map. A frame without a
        sweep adds the look with no reach."""
        pn, pe, pd = (float(v) for v in frame.pos_ned_m)
        pos = (pn, pe, pd)
        if getattr(frame, "fx", None) and getattr(frame, "width", None):
            self.half_fov_rad = math.atan(0.5 * float(frame.width) / float(frame.fx))
        lidar = getattr(frame, "lidar_frd", None)
        if lidar is None or len(lidar) == 0:
            self.looks.append(_Look((pos[0], pos[1]), 0.0))
            return
        pts = world_points(np.asarray(lidar), pos, frame.quat_wxyz)
        if len(pts) < 20:
            self.looks.append(_Look((pos[0], pos[1]), 0.0))
            return
        up = -pts[:, 2]
        # the sweep's low returns are the ground, unless the ground lies beyond the LiDAR's reach and
        # only roofs came back: the rangefinder's column then says where the ground is
        ground = float(np.percentile(up, 10))
        rng = float(getattr(frame, "rangefinder_m", math.nan))
        if math.isfinite(rng) and rng > 0:
            ground = min(ground, -(pos[2] + rng))
        self.ground_up_m = ground
        horiz = np.hypot(pts[:, 0] - pos[0], pts[:, 1] - pos[1])
        on_ground = up < ground + ROOF_UP_M
        reach = float(np.percentile(horiz[on_ground], 80)) if on_ground.sum() >= 20 else 0.0
        self.looks.append(_Look((pos[0], pos[1]), reach))
        i = np.floor(pts[:, 0] / self.cell_m).astype(np.int64)
        j = np.floor(pts[:, 1] / self.cell_m).astype(np.int64)
        elev = ~on_ground
        key = i * 1_000_003 + j
        order = np.argsort(key, kind="stable")
        key, up_s, elev_s, i_s, j_s = key[order], up[order], elev[order], i[order], j[order]
        starts = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
        ends = np.r_[starts[1:], len(key)]
        for a, b in zip(starts, ends, strict=True):
            cell = (int(i_s[a]), int(j_s[a]))
            e_up = up_s[a:b][elev_s[a:b]]
            acc = self._cells.setdefault(cell, [0.0, 0.0, 0.0, 0.0, -math.inf])
            acc[0] += b - a
            acc[1] += len(e_up)
            acc[2] += float(e_up.sum())
            acc[3] += float((e_up**2).sum())
            acc[4] = max(acc[4], float(up_s[a:b].max()))

    def observe_camera(self, frame: Any, presence: Any, classes: tuple[str, ...]) -> int:
        """Add what the camera shows beyond the LiDAR's reach: the frame read in ``CAMERA_TILES`` tiles by
        ``presence`` (LandNet-S's :meth:`~companion.reasoning.landnet.LandNet.presence`: per class and
        cell, present or not; ``classes`` its class names), each cell placed on the ground (flat, at the
        latest sweep's ground level or the rangefinder's) and marked water or traffic or not. Returns
        the number of cells placed (0 without an image or a ground level)."""
        image = getattr(frame, "image_rgb", None)
        pn, pe, pd = (float(v) for v in frame.pos_ned_m)
        rng = float(getattr(frame, "rangefinder_m", math.nan))
        ground_d = -self.ground_up_m if self.ground_up_m is not None else pd + rng
        if image is None or not math.isfinite(ground_d) or ground_d <= pd + 1.0:
            return 0
        bad_rows = [classes.index(c) for c in CAMERA_BAD if c in classes]
        h, w = image.shape[:2]
        cols, rows = CAMERA_TILES
        th, tw = h // rows, w // cols
        uv_all, bad_all = [], []
        for r in range(rows):
            for c in range(cols):
                pres = np.asarray(presence(image[r * th : (r + 1) * th, c * tw : (c + 1) * tw]))
                _k, gh, gw = pres.shape
                vv, uu = np.meshgrid(
                    (np.arange(gh) + 0.5) * th / gh, (np.arange(gw) + 0.5) * tw / gw, indexing="ij"
                )
                uv_all.append(np.column_stack([c * tw + uu.ravel(), r * th + vv.ravel()]))
                bad_all.append(pres[bad_rows].any(axis=0).ravel() if bad_rows else np.zeros(gh * gw, bool))
        uv, bad = np.concatenate(uv_all), np.concatenate(bad_all)
        camera = PinholeCamera(w, h, frame.fx, frame.fy, frame.cx, frame.cy)
        rays = camera.pixel_rays_frd(uv) @ quat_to_matrix(frame.quat_wxyz).T
        down = rays[:, 2] > 0.05
        t = (ground_d - pd) / rays[down, 2]
        ne = np.column_stack([pn + t * rays[down, 0], pe + t * rays[down, 1]])
        for (n, e), b in zip(ne, bad[down], strict=True):
            acc = self._camera.setdefault(self._cell_of((float(n), float(e))), [0, 0])
            acc[0] += 1
            acc[1] += int(b)
        return int(down.sum())

    def camera_bad(self, ne_m: tuple[float, float]) -> float | None:
        """Share of the camera's cells placed in the map cell of ``ne_m`` that showed water or traffic
        (None: the camera placed none there)."""
        acc = self._camera.get(self._cell_of(ne_m))
        return None if acc is None or acc[0] == 0 else acc[1] / acc[0]

    def _bad_ground(self, ne_m: tuple[float, float], radius_m: float) -> float:
        """Share of a disc of ``radius_m`` around ``ne_m`` the camera showed as water or traffic, among
        the parts of it the camera saw (0 where it saw none)."""
        seen = bad = 0.0
        for r in (0.0, 0.35, 0.7, 1.0):
            for k in range(8 if r > 0 else 1):
                a = k * math.pi / 4 + r
                share = self.camera_bad(
                    (ne_m[0] + r * radius_m * math.cos(a), ne_m[1] + r * radius_m * math.sin(a))
                )
                if share is not None:
                    seen += 1.0
                    bad += share
        return bad / seen if seen else 0.0

    def seen(self, ne_m: tuple[float, float]) -> bool:
        """The LiDAR measured the cell holding ``ne_m``."""
        return self._cell_of(ne_m) in self._cells

    def _cell_of(self, ne_m: tuple[float, float]) -> tuple[int, int]:
        return (math.floor(ne_m[0] / self.cell_m), math.floor(ne_m[1] / self.cell_m))

    def _centre(self, cell: tuple[int, int]) -> tuple[float, float]:
        return ((cell[0] + 0.5) * self.cell_m, (cell[1] + 0.5) * self.cell_m)

    def roof_cells(self) -> list[tuple[int, int]]:
        """Cells whose elevated returns are many and level: roof evidence (not tree crowns)."""
        out = []
        for cell, (_n, ne, s, ss, _top) in self._cells.items():
            if ne < MIN_CELL_RETURNS:
                continue
            mean = s / ne
            if ss / ne - mean * mean <= LEVEL_STD_M**2:
                out.append(cell)
        return out

    def _judged(self, ne_m: tuple[float, float]) -> bool:
        """Inside the core of an earlier look: Surface ID saw it whole there."""
        return any(
            look.reach_m > 0 and math.dist(ne_m, look.ne_m) < 0.6 * look.reach_m for look in self.looks
        )

    def _covered(self, ne_m: tuple[float, float], radius_m: float) -> float:
        """Share of a disc of ``radius_m`` around ``ne_m`` whose cells the LiDAR has measured."""
        hits = total = 0
        for r in (0.3, 0.65, 1.0):
            for k in range(8):
                a = k * math.pi / 4 + r
                p = (ne_m[0] + r * radius_m * math.cos(a), ne_m[1] + r * radius_m * math.sin(a))
                total += 1
                hits += self.seen(p)
        hits += self.seen(ne_m)
        return hits / (total + 1)

    def footprint_m(self, agl_m: float) -> float:
        """How far from below the vehicle, at ``agl_m`` over flat ground, both the camera and the
        LiDAR see the ground: the radius a look judges."""
        cam = agl_m * math.tan(self.half_fov_rad)
        lidar = math.sqrt(max(0.0, self.lidar_range_m**2 - agl_m**2))
        return min(cam, lidar)

    # ------------------------------------------------------------------ legs
    def next_leg(
        self, pos_ned_m: tuple[float, float, float], ledger: SiteLedger, rangefinder_m: float = math.nan
    ) -> Leg:
        """The next search leg from ``pos_ned_m`` (module docstring), given what the ledger holds."""
        n, e, d = pos_ned_m
        bad = [(s.ned_m[0], s.ned_m[1]) for s in ledger.sites if s.hazard >= Hazard.OBSTRUCTED]
        leg = self._roof_leg((n, e), bad) or self._new_ground_leg((n, e), bad)
        target_n, target_e, aim, reason = leg
        alt_d = self._leg_down((n, e), (target_n, target_e), d, rangefinder_m)
        dist = math.hypot(target_n - n, target_e - e)
        bearing = math.degrees(math.atan2(target_e - e, target_n - n)) % 360.0
        self._heading = math.atan2(target_e - e, target_n - n)
        out = Leg((target_n, target_e, alt_d), aim, reason, dist, bearing)
        self.legs.append(out)
        return out

    def roof_groups(self, keep: Any = None) -> list[list[tuple[int, int]]]:
        """Groups of adjacent roof cells (:meth:`roof_cells`; those whose centre ``keep`` accepts, when
        given) that look like roofs: two cells at least (one is a chimney stack or a van), and not a
        long band (an elevated deck, :meth:`_strip`)."""
        todo = {c for c in self.roof_cells() if keep is None or keep(self._centre(c))}
        groups: list[list[tuple[int, int]]] = []
        while todo:
            seed = todo.pop()
            group, stack = [seed], [seed]
            while stack:
                ci, cj = stack.pop()
                for nb in ((ci + 1, cj), (ci - 1, cj), (ci, cj + 1), (ci, cj - 1)):
                    if nb in todo:
                        todo.remove(nb)
                        group.append(nb)
                        stack.append(nb)
            groups.append(group)
        return [g for g in groups if len(g) >= 2 and not self._strip(g)]

    def _roof_leg(
        self, here: tuple[float, float], bad: list[tuple[float, float]]
    ) -> tuple[float, float, str, str] | None:
        groups = self.roof_groups(
            lambda c: (
                not self._judged(c)
                and not any(math.dist(c, b) < 15.0 for b in bad)
                and self._within(c)
                and not any(math.dist(c, b) < 2.0 * self.cell_m for b in self.blocked)
            )
        )

        def aim(g: list[tuple[int, int]]) -> tuple[float, float]:
            """The group's cell nearest its middle: a roof cell itself (what is left of a roof around a
            site struck off is a ring, whose middle is that site)."""
            centres = [self._centre(c) for c in g]
            middle = np.mean(centres, axis=0)
            return min(centres, key=lambda c: math.dist(c, middle))

        # a leg that does not move shows nothing new: a roof under the vehicle that its look from here
        # did not judge (a look from above the LiDAR's reach judges nothing) is no leg's aim
        groups = [g for g in groups if math.dist(aim(g), here) >= self.cell_m]
        if not groups:
            return None

        def score(g: list[tuple[int, int]]) -> float:
            return len(g) / (1.0 + math.dist(aim(g), here) / 100.0)

        best = max(groups, key=score)
        cn, ce = aim(best)
        area = len(best) * self.cell_m**2
        dist = math.hypot(cn - here[0], ce - here[1])
        towards = compass_point(math.degrees(math.atan2(ce - here[1], cn - here[0])))
        reason = (
            f"roofs seen by the LiDAR {dist:.0f} m {towards} "
            f"(about {area:.0f} m2 level and raised), not yet judged"
        )
        return cn, ce, "roofs", reason

    def _strip(self, group: list[tuple[int, int]]) -> bool:
        """A group of cells shaped like an elevated deck: 45 m or longer, 2.5 times as long as wide
        (Surface ID's strip rule, here on the map's cells)."""
        pts = np.array([self._centre(c) for c in group])
        if len(pts) < 3:
            return False
        evals = np.linalg.eigvalsh(np.cov(pts.T))
        length = math.sqrt(12.0 * max(evals[1], 0.0)) + self.cell_m
        width = math.sqrt(12.0 * max(evals[0], 0.0)) + self.cell_m
        return length >= 45.0 and length >= 2.5 * width

    def _new_ground_leg(
        self, here: tuple[float, float], bad: list[tuple[float, float]]
    ) -> tuple[float, float, str, str]:
        reach = self.footprint_m(self.search_agl_m)
        step = max(2.0 * reach, 60.0)  # a view's width: the next look shares no ground with this one
        roofs = [self._centre(c) for c in self.roof_cells()]
        best: tuple[float, float, float, str] | None = None
        for k in range(HEADINGS * 2):  # the second pass: headings that made no headway too
            if k == HEADINGS and (best is not None or not self.blocked):
                break
            a = 2 * math.pi * (k % HEADINGS) / HEADINGS
            u = (math.cos(a), math.sin(a))
            go = self._reach_within(here, u, step)
            if go < 0.5 * step:  # the fence leaves too little that way to show new ground
                continue
            t = (here[0] + go * u[0], here[1] + go * u[1])
            if k < HEADINGS and any(math.dist(t, b) < 0.5 * step for b in self.blocked):
                continue
            covered = self._covered(t, reach)
            if any(look.reach_m > 0 and math.dist(t, look.ne_m) < 0.5 * step for look in self.looks):
                covered = max(covered, 0.75)  # an earlier look stood about here
            toward_roofs = _pull(here, u, roofs, step * 1.5)
            toward_bad = _pull(here, u, bad, step * 1.5)
            # what the camera showed toward the target (halfway: the part of the way it can see)
            shown_bad = self._bad_ground((here[0] + 0.5 * step * u[0], here[1] + 0.5 * step * u[1]), reach)
            keep = 0.0 if self._heading is None else math.cos(a - self._heading)
            score = -2.0 * covered + toward_roofs - toward_bad - 1.5 * shown_bad + 0.3 * keep
            why = _why(covered, toward_roofs, toward_bad if bad else None, shown_bad)
            if best is None or score > best[0]:
                best = (score, t[0], t[1], why)
        if best is None:  # hemmed in by the fence every way: back toward home, where it is widest
            assert self.bounds is not None
            (hn, he), _r = self.bounds
            dist = math.dist(here, (hn, he))
            frac = min(1.0, step / dist) if dist > 0 else 0.0
            tn, te = here[0] + frac * (hn - here[0]), here[1] + frac * (he - here[1])
            bearing = compass_point(math.degrees(math.atan2(te - here[1], tn - here[0])))
            return tn, te, "new ground", f"{frac * dist:.0f} m {bearing}, back inside the autopilot's fence"
        _score, tn, te, why = best
        go_m = math.hypot(tn - here[0], te - here[1])
        bearing = compass_point(math.degrees(math.atan2(te - here[1], tn - here[0])))
        fenced = ", as far as the autopilot's fence allows" if go_m < step - 0.5 else ""
        return tn, te, "new ground", f"{go_m:.0f} m {bearing} to ground not yet seen ({why}{fenced})"

    def highest_near_path(
        self, here: tuple[float, float], to: tuple[float, float], corridor_m: float
    ) -> float | None:
        """The highest LiDAR return measured (metres up) in the map's cells whose centres lie within
        ``corridor_m`` of the straight path from ``here`` to ``to`` (north, east); None where no cell
        near it was measured. A cell is ``cell_m`` wide: a return up to half its diagonal farther from
        the path than ``corridor_m`` may count, none nearer is missed."""
        if not self._cells:
            return None
        cells = np.array(list(self._cells.keys()), dtype=float)
        tops = np.array([acc[4] for acc in self._cells.values()])
        centres = (cells + 0.5) * self.cell_m - np.asarray(here)
        seg = np.subtract(to, here)
        length = float(np.hypot(*seg))
        along = np.clip(centres @ seg / length, 0.0, length) if length > 0 else np.zeros(len(centres))
        unit = seg / length if length > 0 else np.zeros(2)
        near = np.hypot(*(centres - along[:, None] * unit).T) < corridor_m
        return float(tops[near].max()) if near.any() else None

    def _leg_down(
        self, here: tuple[float, float], to: tuple[float, float], d: float, rangefinder_m: float
    ) -> float:
        """The leg's altitude (NED down, metres): ``search_agl_m`` above the ground, and
        ``clearance_m`` above the highest return measured within ``LEG_CORRIDOR_M`` of the path."""
        if self.ground_up_m is not None:
            ground_up = self.ground_up_m
        elif math.isfinite(rangefinder_m):
            ground_up = -(d + rangefinder_m)
        else:
            return d  # nothing known of the ground: keep the altitude
        highest = self.highest_near_path(here, to, LEG_CORRIDOR_M)
        top = ground_up if highest is None else max(ground_up, highest)
        up = max(ground_up + self.search_agl_m, top + self.clearance_m)
        return -up


def _pull(here: tuple[float, float], u: tuple[float, float], points: list[Any], reach_m: float) -> float:
    """How much of ``points`` (within ``reach_m``) lies ahead along heading ``u``: 0 to 1."""
    if not points:
        return 0.0
    total = ahead = 0.0
    for p in points:
        dn, de = p[0] - here[0], p[1] - here[1]
        r = math.hypot(dn, de)
        if r < 1.0 or r > reach_m:
            continue
        total += 1.0
        ahead += max(0.0, (dn * u[0] + de * u[1]) / r)
    return ahead / total if total else 0.0


def _why(covered: float, roofs: float, bad: float | None, shown_bad: float) -> str:
    parts = [
        f"{100 * covered:.0f} % seen before",
        f"{100 * shown_bad:.0f} % of the camera's view that way water or traffic",
    ]
    if roofs > 0.3:
        parts.append("toward raised level surfaces")
    if bad is not None and bad > 0.3:
        parts.append("though toward water, traffic or clutter")
    elif bad is not None and bad == 0.0:
        parts.append("away from the water, traffic and clutter seen")
    return ", ".join(parts)
