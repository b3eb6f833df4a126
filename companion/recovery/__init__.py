"""The recovery loop (DESIGN.md section 2), one idea a module:

- :mod:`~companion.recovery.machine`: :class:`Recovery`, the state machine from the alarm to the ground
  (rounds, descent steps, the autopilot's failsafes, a lost link, a defect of its own);
- :mod:`~companion.recovery.looking`: a frame, Surface ID, the reasoner's rank and confirmation, the
  LiDAR check of a site, IPM;
- :mod:`~companion.recovery.site_choice`: where to land when nothing was accepted, and the landing;
- :mod:`~companion.recovery.searching`: whether the search goes on and its legs;
- :mod:`~companion.recovery.core`: states, parameters, outcome, the record protocol and the state every
  part shares.
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
