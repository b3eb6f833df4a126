"""PX4's precision land (AUTO.PRECLAND) as the emulated PX4 flies it on a companion's LANDING_TARGET.

PX4 1.15's navigator (precland) in "required" mode, with the target from MAVLink: a LANDING_TARGET in
``MAV_FRAME_LOCAL_NED`` with ``position_valid`` becomes the landing target pose, where the target is in
the autopilot's local frame, stamped on arrival. The phases, as the firmware runs them:

- **start** (on entering the mode, and on each restart while ``PLD_MAX_SRCH`` allows one more): hold
  where the vehicle is; a fresh target starts the horizontal approach; without one for a second, the
  **search** (climb to ``PLD_SRCH_ALT`` above the local origin, hold for ``PLD_SRCH_TOUT``; a target seen
  there starts the approach a second later) or, with no search time, the fallback;
- **horizontal approach**: fly over the target at the height the approach began at; once within
  ``PLD_HACC_RAD`` (north and east each) for two seconds, with a fresh target, descend. A target lost
  (older than ``PLD_BTOUT``) while over its last place restarts;
- **descend above target**: land mode's descent onto the target's place, following each new target; a
  target lost restarts, except within ``PLD_FAPPR_ALT`` of it (where one older than 0.5 s counts as
  lost), which is the **final approach**: land on;
- **fallback**: land where the vehicle is.

:class:`PrecLand` is stepped by the emulated autopilot (:mod:`simbridge.autopilot.core`), which flies
what it answers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from simbridge.geo import Vec3

HORIZONTAL_SETTLE_S = 2.0  # over the target this long before the descent
START_WAIT_S = 1.0  # no target this long after a start: search (or fall back)
SEARCH_SETTLE_S = 1.0  # a target seen while searching: approach this long after
FINAL_FRESH_S = 0.5  # within PLD_FAPPR_ALT of the target, a target this old is lost


@dataclass(frozen=True, slots=True)
class PrecLandTune:
    """PX4's ``PLD_*`` parameters (navigator's precland)."""

    timeout_s: float  # PLD_BTOUT
    hacc_rad_m: float  # PLD_HACC_RAD
    final_approach_alt_m: float  # PLD_FAPPR_ALT
    search_alt_m: float  # PLD_SRCH_ALT, above the local origin
    search_timeout_s: float  # PLD_SRCH_TOUT
    max_searches: int  # PLD_MAX_SRCH


@dataclass(frozen=True, slots=True)
class PrecLandCommand:
    """What the vehicle flies: hold at ``ne`` and ``d`` (estimate frame), or land over ``ne``."""

    land: bool
    ne: tuple[float, float]
    d: float | None = None


class PrecLand:
    """One AUTO.PRECLAND (module docstring): created on entering the mode."""

    def __init__(
        self, tune: PrecLandTune, t_s: float, est_pos_ned: Vec3, last: tuple[float, Vec3] | None = None
    ) -> None:
        """``last``: the newest target heard before the mode began (when, where): PX4 publishes each
        target whatever the mode, and precland reads the newest as new on its first cycle."""
        self.tune = tune
        self.phase = "start"
        self.since_s = t_s
        self.searches = 0
        self.here: Vec3 = est_pos_ned  # where a hold or a fallback stays
        self.approach_d = est_pos_ned[2]
        self.reached_s: float | None = None
        self.acquired_s: float | None = None
        self.target: Vec3 | None = None  # the last target heard, estimate frame
        self.heard_s = -math.inf
        self._read_s = -math.inf  # the newest target the state machine has seen
        if last is not None:
            self.heard_s, self.target = last
        self._restart(t_s, est_pos_ned)

    def heard(self, t_s: float, target_ned: Vec3) -> None:
        """A LANDING_TARGET in the local frame."""
        self.target = target_ned
        self.heard_s = t_s

    def step(self, t_s: float, est_pos_ned: Vec3) -> PrecLandCommand:
        updated = self.heard_s > self._read_s
        self._read_s = self.heard_s
        valid = self.target is not None and t_s - self.heard_s <= self.tune.timeout_s
        if self.phase == "start":
            self._start(t_s, est_pos_ned, updated, valid)
        elif self.phase == "search":
            self._search(t_s, est_pos_ned, updated, valid)
        elif self.phase == "approach":
            self._approach(t_s, est_pos_ned, updated, valid)
        elif self.phase == "descend":
            self._descend(t_s, est_pos_ned, valid)
        return self._command()

    # ------------------------------------------------------------------ phases
    def _start(self, t_s: float, pos: Vec3, updated: bool, valid: bool) -> None:
        if updated and valid:
            self._to("approach", t_s, pos)
        elif t_s - self.since_s > START_WAIT_S:
            if self.tune.search_timeout_s > 0:
                self._to("search", t_s, pos)
            else:
                self._to("fallback", t_s, pos)

    def _search(self, t_s: float, pos: Vec3, updated: bool, valid: bool) -> None:
        if updated and valid and self.acquired_s is None:
            self.acquired_s = t_s
        if self.acquired_s is not None and t_s - self.acquired_s > SEARCH_SETTLE_S and valid:
            self._to("approach", t_s, pos)
        elif t_s - self.since_s > self.tune.search_timeout_s:
            self._to("fallback", t_s, pos)

    def _approach(self, t_s: float, pos: Vec3, updated: bool, valid: bool) -> None:
        over = self._over(pos)
        if over and not valid:
            self._restart(t_s, pos)
            return
        if over and updated:
            if self.reached_s is None:
                self.reached_s = t_s
            if t_s - self.reached_s > HORIZONTAL_SETTLE_S:
                self._to("descend", t_s, pos)

    def _descend(self, t_s: float, pos: Vec3, valid: bool) -> None:
        final = self._within_final(pos, valid)
        usable = (t_s - self.heard_s < FINAL_FRESH_S) if final else valid
        if usable:
            return
        if final:
            self._to("final", t_s, pos)
        else:
            self._restart(t_s, pos)

    # ------------------------------------------------------------------ helpers
    def _over(self, pos: Vec3) -> bool:
        if self.target is None:
            return False
        r = self.tune.hacc_rad_m
        return abs(self.target[0] - pos[0]) < r and abs(self.target[1] - pos[1]) < r

    def _within_final(self, pos: Vec3, valid: bool) -> bool:
        return valid and self.target is not None and self.target[2] - pos[2] < self.tune.final_approach_alt_m

    def _restart(self, t_s: float, pos: Vec3) -> None:
        """PX4's switch to the start phase, allowed ``PLD_MAX_SRCH`` times after the first."""
        if self.searches <= self.tune.max_searches:
            self.searches += 1
            self._to("start", t_s, pos)
        else:
            self._to("fallback", t_s, pos)

    def _to(self, phase: str, t_s: float, pos: Vec3) -> None:
        self.phase = phase
        self.since_s = t_s
        self.here = pos
        self.reached_s = None
        self.acquired_s = None
        if phase == "approach":
            self.approach_d = pos[2]

    def _command(self) -> PrecLandCommand:
        here = (self.here[0], self.here[1])
        if self.phase in ("approach", "descend", "final") and self.target is not None:
            target = (self.target[0], self.target[1])
            if self.phase == "approach":
                return PrecLandCommand(False, target, self.approach_d)
            return PrecLandCommand(True, target)  # the final approach lands on over the last target
        if self.phase == "search":
            return PrecLandCommand(False, here, -self.tune.search_alt_m)
        if self.phase == "fallback":
            return PrecLandCommand(True, here)
        return PrecLandCommand(False, here, self.here[2])
