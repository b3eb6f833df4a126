"""The companion's table of the modes in which an autopilot lands or flies home by itself (a failsafe
that picks one keeps the vehicle), against the mode tables simbridge's emulation flies by."""

from __future__ import annotations

import pytest

from companion.flavour import ARDUPILOT, PX4, Flavour
from simbridge.autopilot.flavours import flavour_named


@pytest.mark.parametrize(
    ("ours", "name", "expect"),
    [
        (PX4, "px4", {"AUTO.LAND", "AUTO.RTL", "AUTO.PRECLAND"}),
        (ARDUPILOT, "ardupilot", {"LAND", "RTL", "SMART_RTL", "AUTO_RTL"}),
    ],
)
def test_the_modes_an_autopilot_comes_down_in_by_itself(ours: Flavour, name: str, expect: set[str]) -> None:
    emulated = flavour_named(name)
    found = {m.name for m in emulated.modes if ours.lands_or_returns(m.custom_mode) is not None}
    assert found == expect & {m.name for m in emulated.modes}  # the emulation flies a subset
    for m in emulated.modes:
        got = ours.lands_or_returns(m.custom_mode)
        assert got is None or got == m.name  # the same name for the same number
    # holding, the companion's own mode and a manual one are none of them: a failsafe that holds is
    # taken back (PX4's offboard-loss hold), an operator's mode is a takeover
    for held in ("POSCTL", "AUTO.LOITER", "OFFBOARD", "LOITER", "BRAKE", "GUIDED", "ALT_HOLD", "POSHOLD"):
        spec = next((m for m in emulated.modes if m.name == held), None)
        if spec is not None:
            assert ours.lands_or_returns(spec.custom_mode) is None
