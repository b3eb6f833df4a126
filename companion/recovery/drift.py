"""A followed site's drift in the autopilot's estimate: a GPS that drifts moves the estimate, and the
vehicle holding its target in it, while the site stays put. The places the frames found the site at,
``(t_boot_s, north, east)``, fitted with a line in time (docs/companion.md, "Under a lying GPS")."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

DRIFT_WINDOW_S = 12.0  # the site's drift in the estimate: a line fitted to its last seconds of frames
DRIFT_MIN_SPAN_S = 2.5  # ... at least three frames this far apart (autopilot seconds)
DRIFT_MIN_M_S = 0.15  # drifting faster than this: the final approach waits, following the site
DRIFT_WAIT_S = 60.0  # a round holds for at most this long (autopilot seconds): a drift that never stops
DRIFT_BLIND_S = 8.0  # a hold ends when no frame found the site for this long (autopilot seconds)
DRIFT_FIT_M = 0.5  # a drift is carried forward only while the line fits the site's places this well (RMS)


@dataclasses.dataclass(frozen=True, slots=True)
class DriftLine:
    """A site's place in the autopilot's estimate as a line in time: at ``t_s`` (autopilot seconds)
    it was at ``north``, ``east`` and moves ``vn``, ``ve`` m/s; ``rms_m``: how far the places it was
    fitted to lie from it; ``newest_s``: the newest of them."""

    t_s: float
    north: float
    east: float
    vn: float
    ve: float
    rms_m: float
    newest_s: float

    @property
    def speed_m_s(self) -> float:
        return math.hypot(self.vn, self.ve)

    def at(self, t_s: float) -> tuple[float, float]:
        """Where the line puts the site at ``t_s``."""
        dt = t_s - self.t_s
        return self.north + self.vn * dt, self.east + self.ve * dt


def site_drift_line(seen: list[tuple[float, float, float]], since_s: float = -math.inf) -> DriftLine | None:
    """The line fitted to where frames found a site (``(t_boot_s, north, east)``, oldest first) over
    the last ``DRIFT_WINDOW_S`` (and after ``since_s``); None with fewer than three spanning
    ``DRIFT_MIN_SPAN_S``. A GPS that drifts moves the estimate, and the vehicle holding its target in
    it, while the site stays put."""
    if not seen:
        return None
    newest = seen[-1][0]
    pts = np.array([p for p in seen if p[0] >= max(newest - DRIFT_WINDOW_S, since_s)])
    if len(pts) < 3 or pts[-1, 0] - pts[0, 0] < DRIFT_MIN_SPAN_S:
        return None
    mean = pts.mean(axis=0)
    t = pts[:, 0] - mean[0]
    vn = float(np.dot(t, pts[:, 1] - mean[1]) / np.dot(t, t))
    ve = float(np.dot(t, pts[:, 2] - mean[2]) / np.dot(t, t))
    resid = pts[:, 1:] - mean[1:] - np.outer(t, (vn, ve))
    rms = float(np.sqrt((resid**2).sum(axis=1).mean()))
    return DriftLine(float(mean[0]), float(mean[1]), float(mean[2]), vn, ve, rms, float(newest))


def site_drift_m_s(seen: list[tuple[float, float, float]], since_s: float = -math.inf) -> float:
    """How fast a site moves in the autopilot's estimate (m/s): :func:`site_drift_line`'s speed, NaN
    without one."""
    line = site_drift_line(seen, since_s)
    return line.speed_m_s if line is not None else math.nan


def drift_prediction(line: DriftLine | None, t_s: float) -> tuple[float, float] | None:
    """Where a steadily drifting site is at ``t_s`` in the estimate: ``line`` carried forward, at most
    ``DRIFT_BLIND_S`` past the newest place it was fitted to. None where there is nothing to carry:
    no line, slower than ``DRIFT_MIN_M_S`` (the site is where it was last found), or a line that fits
    badly (a jump of the estimate is not a drift)."""
    if line is None or not math.isfinite(t_s) or line.speed_m_s < DRIFT_MIN_M_S or line.rms_m > DRIFT_FIT_M:
        return None
    return line.at(min(t_s, line.newest_s + DRIFT_BLIND_S))
