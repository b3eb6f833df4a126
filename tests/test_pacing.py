"""simbridge's clock against the wall clock (simbridge.pacing): at its speed, and a loop that fell
behind goes on from where it is instead of racing through the simulated time it missed, during which
the link is read only between steps (an emulated PX4 then met its offboard-loss failsafe with no
setpoint late on the wire)."""

from __future__ import annotations

import pytest

from simbridge.pacing import Pacer


def test_on_time_the_target_is_the_wall_clock_times_the_speed() -> None:
    p = Pacer(8.0, max_lag_s=0.25)
    p.start(100.0, 5.0)
    assert p.target(100.01, 5.0) == pytest.approx(5.08)
    assert p.target(100.02, 5.08) == pytest.approx(5.16)
    assert p.slipped_s == 0.0


def test_a_loop_far_behind_slips_its_clock_and_goes_on_at_its_speed() -> None:
    p = Pacer(8.0, max_lag_s=0.25)
    p.start(100.0, 5.0)
    # starved for half a wall second: the wall clock says 9.0 s, the simulation is at 5.0
    assert p.target(100.5, 5.0) == pytest.approx(5.25)  # no further than the lag allowed
    assert p.slipped_s == pytest.approx(3.75)
    # stepped up to it, the loop goes on at its speed from there: 20 ms later, 0.16 s further
    assert p.target(100.52, 5.25) == pytest.approx(5.41)
    assert p.slipped_s == pytest.approx(3.75)


def test_the_target_never_runs_more_than_the_lag_ahead_of_the_simulation() -> None:
    p = Pacer(12.0, max_lag_s=0.25)
    p.start(0.0, 0.0)
    sim, wall = 0.0, 0.0
    for k in range(200):  # the loop advances in uneven steps, sometimes not at all
        wall += 0.003 * (k % 7)
        target = p.target(wall, sim)
        assert target - sim <= 0.25 + 1e-9
        sim = max(sim, target - (0.2 if k % 5 == 0 else 0.0))
    assert p.slipped_s > 0.0


@pytest.mark.parametrize(("speed", "lag"), [(0.0, 0.25), (-1.0, 0.25), (4.0, 0.0)])
def test_a_speed_or_lag_that_is_not_positive_is_refused(speed: float, lag: float) -> None:
    with pytest.raises(ValueError, match="must be positive"):
        Pacer(speed, max_lag_s=lag)
