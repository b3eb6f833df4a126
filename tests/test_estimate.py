"""The emulated autopilot's estimator errors (``simbridge --ekf-error``)."""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable

import numpy as np
import pytest

from simbridge.autopilot.core import Autopilot
from simbridge.autopilot.flavours import flavour_named
from simbridge.control import Setpoint
from simbridge.estimate import (
    TRUTH,
    EstimateError,
    EstimateErrorConfig,
    GpsFault,
    GpsFaultConfig,
    estimate_preset,
)
from simbridge.geo import GeoOrigin
from simbridge.terrain import FlatTerrain
from simbridge.vehicle import Vehicle
from tests.conftest import Rig, SimProcess
from tests.mavclient import MavClient


def test_presets_and_a_clear_error_for_an_unknown_one() -> None:
    assert estimate_preset("off") is None
    assert isinstance(estimate_preset("nominal"), EstimateErrorConfig)
    with pytest.raises(ValueError, match="--ekf-error"):
        estimate_preset("perfect")


def _descend(v: Vehicle, fault: GpsFault, to_d: float, speed: float = 5.0) -> list[tuple[float, float]]:
    """Down at ``speed`` m/s to ``to_d``, the fault fed each step; its offsets."""
    out = []
    while v.state.pos_ned_m[2] < to_d:
        v.step(Setpoint(pos_ne_m=(0.0, 0.0), pos_d_m=None, vel_ned_m_s=(0.0, 0.0, speed)))
        out.append(fault.update(v.state))
    return out


def test_a_gps_fault_starts_at_the_first_crossing_downward_and_jumps_or_drifts() -> None:
    starts: list[tuple[float, float]] = []
    v = Vehicle(GeoOrigin(), FlatTerrain())
    v.reset((0.0, 0.0, -10.0), 0.0)  # below the threshold from the start: not a crossing
    jump = GpsFault(GpsFaultConfig((15.0, 10.0), below_m=40.0), lambda t, h: starts.append((t, h)))
    assert set(_descend(v, jump, -5.0)) == {(0.0, 0.0)}
    v.reset((0.0, 0.0, -60.0), 0.0)
    offsets = _descend(v, jump, -20.0)
    assert offsets[0] == (0.0, 0.0)
    assert offsets[-1] == (15.0, 10.0)
    ((_t0, h0),) = starts
    assert h0 == pytest.approx(40.0, abs=0.2)
    assert len(set(offsets)) == 2  # nothing between: a jump
    drift = GpsFault(GpsFaultConfig((-20.0, 0.0), below_m=40.0, ramp_s=10.0))
    v.reset((0.0, 0.0, -60.0), 0.0)
    offsets = _descend(v, drift, -15.0, speed=1.0)  # 25 s below the threshold
    grown = [n for n, _e in offsets if n != 0.0]
    assert len(grown) > 100
    assert grown[-1] == -20.0
    assert np.all(np.diff(grown) <= 0)  # growing evenly to the full offset, then holding it
    assert -20.0 < grown[len(grown) // 4] < -1.0
    for bad in ({"offset_ne_m": (math.nan, 0.0)}, {"offset_ne_m": (1.0, 0.0), "below_m": 0.0},
                {"offset_ne_m": (1.0, 0.0), "ramp_s": -1.0}):  # fmt: skip
        with pytest.raises(ValueError, match="--gps-fault"):
            GpsFaultConfig(**bad)  # type: ignore[arg-type]


def test_the_emulated_estimate_follows_the_gps_fault_and_the_autopilot_flies_in_it() -> None:
    """With no estimator error of its own (``TRUTH``) the estimate is the truth until the fault,
    then the truth plus its offset; a held target is then flown that far off in the world."""
    v = Vehicle(GeoOrigin(), FlatTerrain())
    v.reset((0.0, 0.0, -45.0), 0.0)
    est = EstimateError(TRUTH, np.random.default_rng(1), GpsFault(GpsFaultConfig((15.0, 10.0))))
    ap = Autopilot(
        flavour_named("ardupilot"), v, (0.0, 0.0, 0.0), lambda *_: None, lambda *_: None, estimate=est
    )
    ap.spawn_in_air(v.state)
    assert ap.set_mode(ap.flavour.mode("GUIDED")).result == 0
    for k in range(120 * 25):  # down to 35 m, holding north/east 0
        if k % 6 == 0:
            ap.external_setpoint(Setpoint.hold((0.0, 0.0, -35.0)), False)
        v.step(ap.tick(v.state), ap.armed)
    assert est.bias_ned_m[:2] == (15.0, 10.0)
    assert ap.estimated_state.pos_ned_m[:2] == pytest.approx((0.0, 0.0), abs=0.3)
    assert v.state.pos_ned_m[:2] == pytest.approx((-15.0, -10.0), abs=0.3)  # where the lie put it


def test_the_bias_wanders_with_its_sigma_and_the_estimate_lags() -> None:
    cfg = EstimateErrorConfig(pos_bias_sigma_m=0.5, pos_bias_tau_s=5.0, lag_s=0.1, pos_noise_m=0.0)
    v = Vehicle(GeoOrigin(), FlatTerrain())
    v.reset((0.0, 0.0, -50.0), 0.0)
    est = EstimateError(cfg, np.random.default_rng(3))
    biases = []
    for _ in range(120 * 200):  # 200 s at 120 Hz, hovering
        v.step(Setpoint.hold((0.0, 0.0, -50.0)))
        est.step(v.state)
        biases.append(est.bias_ned_m[0])
    assert 0.3 < float(np.std(biases)) < 0.7
    assert len({round(b, 3) for b in biases[::1200]}) > 10  # it moves
    # lag: climbing at about 1 m/s, the estimate's height trails by about lag x speed
    for _ in range(240):
        v.step(Setpoint(pos_ne_m=(0.0, 0.0), pos_d_m=None, vel_ned_m_s=(0.0, 0.0, -1.0)))
        e = est.step(v.state)
    lag_m = (e.pos_ned_m[2] - est.bias_ned_m[2]) - v.state.pos_ned_m[2]
    assert lag_m == pytest.approx(-v.state.vel_ned_m_s[2] * 0.1, abs=0.03)


def test_the_autopilot_flies_targets_in_its_estimated_frame() -> None:
    """A target p is reached when the estimate says so: the airframe holds at p - bias."""
    cfg = EstimateErrorConfig(
        pos_bias_sigma_m=1.0, vert_bias_sigma_m=0.5, pos_bias_tau_s=1e6, pos_noise_m=0.0
    )
    v = Vehicle(GeoOrigin(), FlatTerrain())
    v.reset((0.0, 0.0, -30.0), 0.0)
    est = EstimateError(cfg, np.random.default_rng(5))
    ap = Autopilot(
        flavour_named("ardupilot"), v, (0.0, 0.0, 0.0), lambda *_: None, lambda *_: None, estimate=est
    )
    ap.spawn_in_air(v.state)
    assert ap.set_mode(ap.flavour.mode("GUIDED")).result == 0
    for k in range(120 * 30):
        if k % 6 == 0:
            ap.external_setpoint(Setpoint.hold((10.0, 5.0, -30.0)), False)
        v.step(ap.tick(v.state), ap.armed)
    bn, be, bd = est.bias_ned_m
    assert math.hypot(bn, be) > 0.3  # the test means something
    n, e, d = v.state.pos_ned_m
    assert (n, e, d) == pytest.approx((10.0 - bn, 5.0 - be, -30.0 - bd), abs=0.25)
    told = ap.estimated_state.pos_ned_m
    assert told == pytest.approx((10.0, 5.0, -30.0), abs=0.3)  # what its telemetry says


@pytest.mark.slow
def test_telemetry_carries_the_estimate_and_the_episode_log_both(
    start_sim: Callable[..., SimProcess], client_for: Callable[..., MavClient]
) -> None:
    sim = start_sim("--autopilot", "ardupilot", "--ekf-error", "nominal", "--seed", "4", "--speed", "4")
    c = client_for(sim.port)
    c.wait_heartbeat()
    lpos = c.position()
    states = []
    while len(states) < 5:
        states = [e for e in sim.events("state") if "est_pos_ned_m" in e]
    truth, told = states[-1]["pos_ned_m"], states[-1]["est_pos_ned_m"]
    assert isinstance(truth, list)
    assert isinstance(told, list)
    off = math.dist(truth, told)
    assert 0.02 < off < 3.0  # an estimate, not the truth
    assert math.dist((lpos.x, lpos.y, lpos.z), told) < 2.0
    assert json.loads(sim.episode_log.read_text().splitlines()[0])["ekf_error"] == "nominal"


@pytest.mark.slow
def test_the_companion_lands_on_the_clear_roof_on_an_estimate_with_errors(
    start_rig: Callable[..., Rig],
) -> None:
    """The companion places its frames with the autopilot's estimate (bias, noise, lag, attitude
    error) and flies in that frame: it still lands on scenario1's clear roof."""
    rig = start_rig(["--scenario", "scenario1", "--ekf-error", "nominal", "--seed", "2", "--speed", "8"])
    rig.wait_log("sensor stream connected", timeout_s=60)
    out = rig.alarm_accepted("--reason", "GPS spoofing detected", "--criticality", "high")
    assert out.returncode == 0, out.stdout + out.stderr
    deadline = time.monotonic() + 200
    while not rig.sim.events("touchdown"):
        assert time.monotonic() < deadline, rig.log_text()[-3000:]
        assert rig.companion.poll() is None, rig.log_text()[-3000:]
        time.sleep(0.5)
    td = rig.sim.events("touchdown")[0]
    assert td["surface"] == "rooftop_clear", (td, rig.log_text()[-2000:])
    assert td["safe"] is True
    rig.wait_log("recovery ended: landed", timeout_s=60)


def test_a_vehicle_flying_on_the_nominal_estimate_hovers_without_rocking() -> None:
    """The position bias under the nominal preset moves smoothly, as an EKF's does: the airframe
    holding a target on it turns 3 degrees a second at most (77 deg/s when the bias stepped
    afresh each physics step and the controller fed its setpoint's acceleration forward)."""
    v = Vehicle(GeoOrigin(), FlatTerrain())
    v.reset((0.0, 0.0, -30.0), 0.0)
    est = EstimateError(estimate_preset("nominal") or TRUTH, np.random.default_rng(11))
    ap = Autopilot(
        flavour_named("ardupilot"), v, (0.0, 0.0, 0.0), lambda *_: None, lambda *_: None, estimate=est
    )
    ap.spawn_in_air(v.state)
    assert ap.set_mode(ap.flavour.mode("GUIDED")).result == 0
    rates = []
    for k in range(120 * 40):
        if k % 6 == 0:
            ap.external_setpoint(Setpoint.hold((0.0, 0.0, -30.0)), False)
        v.step(ap.tick(v.state), ap.armed)
        if k > 120 * 10:  # settled
            rates.append(math.degrees(math.hypot(*v.state.rates_frd_rad_s[:2])))
    assert max(rates) < 5.0, max(rates)
    bn, be, _bd = est.bias_ned_m
    assert math.hypot(bn, be) > 0.1  # there is a bias to fly on


def _peak_turn_after_a_step(flavour: str, step_m: float) -> float:
    """An emulated vehicle hovering 3 m up on the nominal estimate, its target moved ``step_m`` across:
    the fastest it turns (deg/s, roll and pitch) in the 8 s after."""
    v = Vehicle(GeoOrigin(), FlatTerrain())
    v.reset((0.0, 0.0, -3.0), 0.0)
    est = EstimateError(estimate_preset("nominal") or TRUTH, np.random.default_rng(1))
    ap = Autopilot(flavour_named(flavour), v, (0.0, 0.0, 0.0), lambda *_: None, lambda *_: None, estimate=est)
    ap.spawn_in_air(v.state)
    target = (0.0, 0.0, -3.0)
    ap.external_setpoint(Setpoint.hold(target), False)
    assert ap.set_mode(ap.flavour.mode("GUIDED" if flavour == "ardupilot" else "OFFBOARD")).result == 0
    rates = []
    for k in range(120 * 16):
        if k == 120 * 8:
            target = (0.0, step_m, -3.0)
        if k % 6 == 0:
            ap.external_setpoint(Setpoint.hold(target), False)
        v.step(ap.tick(v.state), ap.armed)
        if k > 120 * 8:
            rates.append(math.degrees(math.hypot(*v.state.rates_frd_rad_s[:2])))
    return max(rates)


def test_arducopter_shapes_a_step_in_its_target_within_its_jerk_limit() -> None:
    """ArduCopter's position controller shapes the path to a new target (PSC_JERK_XY, 5 m/s3): a
    landing target that moves 0.33 m near the ground tilts the airframe gently (37 deg/s at most,
    2026-12-05; 121 deg/s when the setpoint's acceleration was fed forward at once, which set the
    emulated land mode rocking at 120-230 deg/s under a companion's precision landing). PX4's
    offboard control flies its setpoints without a planned path, and stays so."""
    ardupilot = flavour_named("ardupilot")
    defaults = {p.name: float(p.default) for p in ardupilot.params}
    assert ardupilot.tunables(defaults).limits.max_jerk_xy_m_s3 == 5.0
    assert _peak_turn_after_a_step("ardupilot", 0.33) < 60.0
    assert _peak_turn_after_a_step("px4", 0.33) > 90.0
