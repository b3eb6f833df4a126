"""The simulation's clock against the wall clock: ``speed`` simulated seconds a wall second, no bursts.

The emulated autopilot's loop steps the physics up to where the wall clock says the simulation should
be. A loop that falls behind (its process starved of the CPU, a frame rendered beside it holding the
interpreter) used to catch up at once: steps back to back, simulated time racing ahead while the
link was read only between them. A companion streaming setpoints at 20 Hz of wall time then went more
than a simulated second without one being read, and the emulated PX4's offboard-loss failsafe fired
although no setpoint was late on the wire (town city 21 at 8x, 2026-12-05: 11 flights of 100, all in
rain, each with the companion's longest gap between two setpoints under 70 ms of wall time, 0.56 s
simulated). Behind by more than ``max_lag_s`` simulated seconds, the clock slips instead: the
simulation goes on from where it is at its speed, as a real-time simulator gives up time rather than
fast-forwarding, and ``slipped_s`` counts what was given up (the episode log's ``stop`` event).
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["MAX_LAG_S", "Pacer"]

MAX_LAG_S = 0.25  # simulated seconds the loop may fall behind the wall clock before the clock slips


@dataclass
class Pacer:
    """Where the simulation should be (:meth:`target`) at a wall time, from the wall and simulated
    times it started at (:meth:`start`), at ``speed``, never more than ``max_lag_s`` ahead of where it
    is. Wall and simulated times in seconds."""

    speed: float
    max_lag_s: float = MAX_LAG_S
    wall0_s: float = 0.0
    sim0_s: float = 0.0
    slipped_s: float = 0.0  # simulated seconds given up to the slips, in all

    def __post_init__(self) -> None:
        if not self.speed > 0 or not self.max_lag_s > 0:
            raise ValueError(f"speed and max_lag_s must be positive, got {self.speed} and {self.max_lag_s}")

    def start(self, wall_s: float, sim_s: float) -> None:
        self.wall0_s, self.sim0_s = wall_s, sim_s

    def target(self, wall_s: float, sim_s: float) -> float:
        """The simulated time to step up to at ``wall_s``, the simulation being at ``sim_s``: the wall
        clock's, or ``sim_s + max_lag_s`` when that is further behind (the clock slips by the rest)."""
        target = self.sim0_s + (wall_s - self.wall0_s) * self.speed
        behind = target - sim_s
        if behind > self.max_lag_s:
            slip = behind - self.max_lag_s
            self.wall0_s += slip / self.speed
            self.slipped_s += slip
            target -= slip
        return target
