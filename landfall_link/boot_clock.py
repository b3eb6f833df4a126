"""The autopilot's boot clock seen from another computer: a camera, a LiDAR driver or the companion
dates what it captures on the clock the autopilot stamps its messages with (``time_boot_ms``), so the
autopilot's own pose history can place it (docs/camera.md, docs/sensor-stream.md)."""

from __future__ import annotations

import collections

__all__ = ["BootClock"]


class BootClock:
    """The autopilot's boot clock as a function of this computer's monotonic clock, fitted from the
    messages it stamps (``time_boot_ms``) and the moments they arrived.

    ``boot = rate * monotonic + offset`` over the last ``WINDOW_S`` seconds of arrivals: the rate by least
    squares (1 on a vehicle, up to crystal drift; the simulator's speed-up in simulation), the offset from
    the message that arrived soonest after it was stamped (the lower envelope of the transport delay, as
    MAVLink's TIMESYNC estimators take the shortest round trip). A camera frame decoded at monotonic ``t``
    was captured at ``boot_at(t) - latency`` on the autopilot's clock (``camera.latency_ms``).
    """

    WINDOW_S = 10.0
    MIN_SAMPLES = 5

    def __init__(self) -> None:
        self._samples: collections.deque[tuple[float, float]] = collections.deque()
        self._fit: tuple[float, float] | None = None

    def add(self, monotonic_s: float, boot_s: float) -> None:
        if self._samples and boot_s < self._samples[-1][1] - 1.0:
            self._samples.clear()  # the autopilot rebooted: its clock started again
        self._samples.append((monotonic_s, boot_s))
        while self._samples and self._samples[0][0] < monotonic_s - self.WINDOW_S:
            self._samples.popleft()
        self._fit = None

    def _fitted(self) -> tuple[float, float] | None:
        if self._fit is None and len(self._samples) >= self.MIN_SAMPLES:
            n = len(self._samples)
            mean_m = sum(m for m, _ in self._samples) / n
            mean_b = sum(b for _, b in self._samples) / n
            var = sum((m - mean_m) ** 2 for m, _ in self._samples)
            if var <= 1e-9:
                return None
            rate = sum((m - mean_m) * (b - mean_b) for m, b in self._samples) / var
            if not rate > 0:
                return None
            self._fit = (rate, max(b - rate * m for m, b in self._samples))
        return self._fit

    def boot_at(self, monotonic_s: float) -> float | None:
        """The autopilot's boot clock (s) at ``monotonic_s``; None until enough messages came."""
        fit = self._fitted()
        return None if fit is None else fit[0] * monotonic_s + fit[1]

    @property
    def rate(self) -> float | None:
        fit = self._fitted()
        return None if fit is None else fit[0]
