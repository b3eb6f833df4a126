"""The airframe as the autopilot sees it: JSBSim physics, the multicopter controller, the battery.

The autopilot decides *what* to fly (a :class:`~simbridge.control.Setpoint`, or motors off);
the vehicle flies it for one physics step.
"""

from __future__ import annotations

from simbridge.battery import Battery, BatteryConfig
from simbridge.control import ControlLimits, MulticopterController, Setpoint
from simbridge.geo import GeoOrigin, Vec3
from simbridge.physics import MOTOR_COUNT, F450Physics, VehicleState
from simbridge.terrain import Terrain
from simbridge.wind import WindModel

IDLE_THROTTLE = 0.12  # armed spin-up on the ground: well below hover (about 0.42)


class Vehicle:
    """One F450 with its controller; ``step`` advances ``DT_S`` of simulated time."""

    DT_S = F450Physics.DT_S

    def __init__(
        self,
        origin: GeoOrigin,
        terrain: Terrain,
        *,
        limits: ControlLimits | None = None,
        wind: WindModel | None = None,
        battery: BatteryConfig | None = None,
    ) -> None:
        self.physics = F450Physics(origin, terrain, wind)
        self.controller = MulticopterController(limits)
        self.battery = Battery(battery)
        self.state: VehicleState = self.physics.state()
        self.motors_on = False

    def reset(self, pos_ned_m: Vec3, yaw_rad: float) -> None:
        self.physics.reset(pos_ned_m, yaw_rad)
        self.controller.reset()
        self.state = self.physics.state()

    def step(self, setpoint: Setpoint | None, armed: bool = True) -> VehicleState:
        """Fly ``setpoint`` for one step; ``None`` runs the motors at idle (armed) or stops them."""
        if setpoint is None:
            if self.motors_on:
                self.controller.reset()
            self.motors_on = False
            idle = IDLE_THROTTLE if armed else 0.0
            self.physics.step((idle, idle, idle, idle))
        else:
            self.motors_on = True
            self.physics.step(self.controller.update(self.state, setpoint, self.DT_S))
        self.state = self.physics.state()
        self.battery.step(self.state.thrust_n / MOTOR_COUNT, MOTOR_COUNT, self.DT_S)
        return self.state

    def step_esc(self, throttles: tuple[float, float, float, float]) -> VehicleState:
        """One physics step with ESC commands from an outside autopilot (JSBSim motor order), the
        controller bypassed; the battery drains as with ``step``."""
        self.motors_on = any(th > 0.0 for th in throttles)
        self.physics.step(throttles)
        self.state = self.physics.state()
        self.battery.step(self.state.thrust_n / MOTOR_COUNT, MOTOR_COUNT, self.physics.dt_s)
        return self.state

    def set_limits(self, limits: ControlLimits) -> None:
        self.controller.limits = limits
