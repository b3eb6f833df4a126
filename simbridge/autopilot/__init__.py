"""Autopilot emulation: PX4 and ArduPilot behaviour over one flight core."""

from simbridge.autopilot.core import Autopilot, CommandOutcome
from simbridge.autopilot.flavours import (
    ArduPilotFlavour,
    Flavour,
    ModeSpec,
    Px4Flavour,
    flavour_named,
)

__all__ = [
    "ArduPilotFlavour",
    "Autopilot",
    "CommandOutcome",
    "Flavour",
    "ModeSpec",
    "Nav",
    "Px4Flavour",
    "flavour_named",
]
