"""The recovery loop (DESIGN.md section 2): one :class:`Recovery` per alarm, the state machine from the
alarm to the ground (rounds, descent steps, the autopilot's failsafes, a lost link, a defect of its
own), in :mod:`~companion.recovery.machine`. It owns six parts, each built on the one context they
share (:class:`~companion.recovery.core.RecoveryContext`: the alarm's criticality, the state, the
round, the accepted and rejected sites, the site ledger, the record and the announcement) and given,
at its construction, the parts it calls (the looker and the searcher, the search's map); none is
another's ``self``.

Its parts, as ``Recovery.<attribute>``:

- ``looker``: :class:`~companion.recovery.looking.Looker`, a frame, Surface ID, the reasoner's rank
  and confirmation, the LiDAR check and the onboard tier's judgement of a site, IPM, the close-up,
  and the candidates noted into the ledger;
- ``follower``: :class:`~companion.recovery.following.SiteFollower`, the chosen site found again in
  each newer frame, the estimate's resets and drift, and the precision landing's targets;
- ``lander``: :class:`~companion.recovery.landing.Lander`, the landing at the accepted site, else at
  the least bad one measured, the fly-over and the final approach;
- ``searcher``: :class:`~companion.recovery.searching.Searcher`, whether the search goes on, its legs
  and the exploring step, and the round's work deferred until the vehicle moves.
- ``watch``: :class:`~companion.recovery.watching.PeopleWatch`, the look for people near a site off
  the roofs through each descent step and the final approach, and what follows someone seen (hold,
  step aside, or another site);
- ``handover``: :class:`~companion.recovery.handover.Handover`, the policies for the autopilot's own
  failsafes (ridden out, re-engaged, or left to the autopilot) and a lost link.

Beside them: :mod:`~companion.recovery.core` (states, parameters, outcome, the record protocol and
the context), :mod:`~companion.recovery.search_plan` (the search's map and planner) and
:mod:`~companion.recovery.drift` (a followed site's drift in the estimate).
"""

from companion.recovery.core import (
    FrameSource,
    FrameUnavailable,
    NoRecord,
    Outcome,
    Record,
    RecoveryParams,
    SensorsLost,
    Site,
    State,
)
from companion.recovery.looking import site_closeup
from companion.recovery.machine import Recovery

__all__ = [
    "FrameSource",
    "FrameUnavailable",
    "NoRecord",
    "Outcome",
    "Record",
    "Recovery",
    "RecoveryParams",
    "SensorsLost",
    "Site",
    "State",
    "site_closeup",
]
