"""A simple LiPo energy model: rotor power from momentum theory drains a 4S pack."""

from __future__ import annotations

import math
from dataclasses import dataclass

_RHO_KG_M3 = 1.225
_DISK_AREA_M2 = math.pi * (9.4 * 0.0254 / 2) ** 2  # DJI 9450 propeller


@dataclass(frozen=True, slots=True)
class BatteryConfig:
    cells: int = 4
    capacity_mah: float = 5000.0
    initial_fraction: float = 1.0
    internal_resistance_ohm: float = 0.02
    efficiency: float = 0.45  # electrical -> ideal induced power (motor, ESC, figure of merit)
    avionics_w: float = 6.0

    def __post_init__(self) -> None:
        if not 0.0 <= self.initial_fraction <= 1.0:
            raise ValueError(f"battery initial_fraction must be in [0, 1], got {self.initial_fraction}")
        if self.capacity_mah <= 0 or self.cells <= 0:
            raise ValueError("battery capacity_mah and cells must be positive")


class Battery:
    """State of charge, voltage under load and current for BATTERY_STATUS / SYS_STATUS."""

    def __init__(self, config: BatteryConfig | None = None) -> None:
        self.config = config or BatteryConfig()
        self.consumed_mah = self.config.capacity_mah * (1.0 - self.config.initial_fraction)
        self.current_a = 0.0
        self.voltage_v = self._open_circuit_v()

    @property
    def remaining_fraction(self) -> float:
        return max(0.0, 1.0 - self.consumed_mah / self.config.capacity_mah)

    def _open_circuit_v(self) -> float:
        # 3.3 V/cell empty to 4.2 V/cell full, steeper near empty
        f = self.remaining_fraction
        per_cell = 3.3 + 0.75 * f + 0.15 * (1 - math.exp(-12 * f))
        return self.config.cells * per_cell

    def step(self, thrust_per_motor_n: float, motors: int, dt_s: float) -> None:
        induced_w = motors * max(thrust_per_motor_n, 0.0) ** 1.5 / math.sqrt(2 * _RHO_KG_M3 * _DISK_AREA_M2)
        power_w = induced_w / self.config.efficiency + self.config.avionics_w
        ocv = self._open_circuit_v()
        self.current_a = power_w / max(ocv, 1.0)
        self.voltage_v = ocv - self.current_a * self.config.internal_resistance_ohm
        self.consumed_mah += self.current_a * dt_s / 3.6
