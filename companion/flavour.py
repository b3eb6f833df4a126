"""PX4 and ArduPilot as the companion commands them: which mode is which, told apart by the
heartbeat's ``autopilot`` field."""

from __future__ import annotations

import enum
from dataclasses import dataclass

from companion.telemetry import MAV_AUTOPILOT_ARDUPILOTMEGA, MAV_AUTOPILOT_PX4


class Mode(enum.Enum):
    GUIDED = "guided"  # PX4 OFFBOARD, ArduPilot GUIDED: the companion flies
    HOLD = "hold"  # PX4 AUTO.LOITER, ArduPilot LOITER
    LAND = "land"  # PX4 AUTO.LAND, ArduPilot LAND
    PRECLAND = "precland"  # PX4 AUTO.PRECLAND; ArduPilot lands on a target in LAND
    RTL = "rtl"  # PX4 AUTO.RTL, ArduPilot RTL: home by itself (a cancelled recovery's choice)


@dataclass(frozen=True, slots=True)
class Flavour:
    name: str
    modes: dict[Mode, int]  # custom_mode values in the heartbeat
    set_mode: dict[Mode, tuple[float, float, float]]  # DO_SET_MODE params 1-3
    needs_stream: bool  # PX4: setpoints must stream before and during OFFBOARD
    # modes in which the autopilot lands or flies home by itself (custom_mode -> its name): a failsafe
    # that picks one of them has decided how the flight ends, and the companion does not take it back
    comes_down: dict[int, str]
    names: dict[int, str]  # custom_mode -> the autopilot's own name for it (for what the companion says)

    def mode_of(self, custom_mode: int) -> Mode | None:
        for mode, value in self.modes.items():
            if value == custom_mode:
                return mode
        return None

    def mode_name(self, custom_mode: int) -> str:
        return self.names.get(custom_mode, f"custom_mode {custom_mode}")

    def lands_or_returns(self, custom_mode: int) -> str | None:
        """The name of ``custom_mode`` when the autopilot lands or returns home in it by itself."""
        return self.comes_down.get(custom_mode)


PX4 = Flavour(
    name="px4",
    modes={
        Mode.GUIDED: 6 << 16,
        Mode.HOLD: (4 << 16) | (3 << 24),
        Mode.LAND: (4 << 16) | (6 << 24),
        Mode.PRECLAND: (4 << 16) | (9 << 24),
        Mode.RTL: (4 << 16) | (5 << 24),
    },
    set_mode={
        Mode.GUIDED: (1, 6, 0),
        Mode.HOLD: (1, 4, 3),
        Mode.LAND: (1, 4, 6),
        Mode.PRECLAND: (1, 4, 9),
        Mode.RTL: (1, 4, 5),
    },
    needs_stream=True,
    comes_down={
        (4 << 16) | (5 << 24): "AUTO.RTL",
        (4 << 16) | (6 << 24): "AUTO.LAND",
        (4 << 16) | (9 << 24): "AUTO.PRECLAND",
    },
    names={
        **{
            main << 16: name
            for main, name in (
                (1, "MANUAL"),
                (2, "ALTCTL"),
                (3, "POSCTL"),
                (5, "ACRO"),
                (6, "OFFBOARD"),
                (7, "STABILIZED"),
            )
        },
        **{
            (4 << 16) | (sub << 24): f"AUTO.{name}"
            for sub, name in (
                (2, "TAKEOFF"),
                (3, "LOITER"),
                (4, "MISSION"),
                (5, "RTL"),
                (6, "LAND"),
                (8, "FOLLOW_TARGET"),
                (9, "PRECLAND"),
            )
        },
    },
)
ARDUPILOT = Flavour(
    name="ardupilot",
    modes={Mode.GUIDED: 4, Mode.HOLD: 5, Mode.LAND: 9, Mode.PRECLAND: 9, Mode.RTL: 6},
    set_mode={
        Mode.GUIDED: (1, 4, 0),
        Mode.HOLD: (1, 5, 0),
        Mode.LAND: (1, 9, 0),
        Mode.PRECLAND: (1, 9, 0),
        Mode.RTL: (1, 6, 0),
    },
    needs_stream=False,
    comes_down={6: "RTL", 9: "LAND", 21: "SMART_RTL", 27: "AUTO_RTL"},
    names={
        0: "STABILIZE",
        1: "ACRO",
        2: "ALT_HOLD",
        3: "AUTO",
        4: "GUIDED",
        5: "LOITER",
        6: "RTL",
        9: "LAND",
        16: "POSHOLD",
        17: "BRAKE",
        21: "SMART_RTL",
        27: "AUTO_RTL",
    },
)


def flavour_for(autopilot: int) -> Flavour:
    if autopilot == MAV_AUTOPILOT_PX4:
        return PX4
    if autopilot == MAV_AUTOPILOT_ARDUPILOTMEGA:
        return ARDUPILOT
    raise ValueError(f"unsupported autopilot type {autopilot} (expected 12 PX4 or 3 ArduPilot)")
