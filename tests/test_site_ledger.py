"""The least-bad-site policy (companion/site_ledger.py) and the test-only fault hook (companion/faults.py)."""

from __future__ import annotations

import math

import pytest

from companion.faults import FaultHook, InjectedFault
from companion.site_ledger import Hazard, LedgerSite, SiteLedger, hazard_of


def _site(n: float, hazard: Hazard, *, closeup: bool = True, edge: float = math.nan) -> LedgerSite:
    return LedgerSite((n, 0.0, -20.0), hazard, hazard.name, 1, closeup, edge, f"site at {n:.0f}")


@pytest.mark.parametrize(
    ("kinds", "accepted", "street", "strip", "expected"),
    [
        (("water", "markings"), False, True, False, Hazard.WATER),
        (("water",), True, False, False, Hazard.WATER),  # a yes never makes water landable
        (("markings",), False, True, False, Hazard.TRAFFIC),
        (("street_asphalt",), False, True, False, Hazard.TRAFFIC),
        ((), False, False, True, Hazard.TRAFFIC),  # an elevated strip: a deck
        ((), True, False, False, Hazard.ACCEPTED),
        (("lidar_obstacle",), False, False, False, Hazard.OBSTRUCTED),
        (("raised",), False, True, False, Hazard.OBSTRUCTED),
        (("vegetation",), False, False, False, Hazard.OBSTRUCTED),  # tree crowns up on a roof
        (("canopy",), False, False, False, Hazard.OBSTRUCTED),  # the same, measured on the pixels
        (("vegetation",), False, True, False, Hazard.OFF_ROOF),  # a lawn
        ((), False, True, False, Hazard.OFF_ROOF),  # nothing seen on it: a lawn, a yard
        (("street_level",), False, True, False, Hazard.STREET),  # refused among buildings: last resort
        (("cramped",), False, True, False, Hazard.OFF_ROOF),  # open ground near its edge: before a sidewalk
        (("cramped",), False, False, False, Hazard.OFF_ROOF),  # a small terrace: not a doubted roof
        (("hazard",), False, False, False, Hazard.DOUBTED),  # a roof with soft doubts only
        (("not_clear",), False, False, False, Hazard.OBSTRUCTED),  # the image sure it is no clear roof
        ((), False, False, False, Hazard.DOUBTED),
    ],
)
def test_hazard_of_orders_what_was_seen(
    kinds: tuple[str, ...], accepted: bool, street: bool, strip: bool, expected: Hazard
) -> None:
    assert hazard_of(kinds, accepted=accepted, street_level=street, strip=strip) is expected


def test_hazard_of_nothing_measured_is_unknown() -> None:
    assert hazard_of((), accepted=False, street_level=True, strip=False, judged=False) is Hazard.UNKNOWN


def test_least_bad_never_water_or_traffic_when_anything_else_was_seen() -> None:
    ledger = SiteLedger()
    for k, h in enumerate((Hazard.WATER, Hazard.TRAFFIC, Hazard.OBSTRUCTED, Hazard.TRAFFIC)):
        ledger.add(_site(10.0 * k, h))
    chosen = ledger.least_bad((0.0, 0.0))
    assert chosen is not None
    assert chosen.hazard is Hazard.OBSTRUCTED


def test_least_bad_takes_a_sidewalk_before_a_road_and_a_roof_before_both() -> None:
    ledger = SiteLedger()
    ledger.add(_site(0.0, Hazard.TRAFFIC))
    ledger.add(_site(50.0, Hazard.OFF_ROOF))
    assert ledger.least_bad((0.0, 0.0)).hazard is Hazard.OFF_ROOF  # type: ignore[union-attr]
    ledger.add(_site(90.0, Hazard.DOUBTED, closeup=False))
    assert ledger.least_bad((0.0, 0.0)).hazard is Hazard.DOUBTED  # type: ignore[union-attr]
    assert ledger.best_hazard() is Hazard.DOUBTED
    assert Hazard.DOUBTED.acceptable
    assert not Hazard.OFF_ROOF.acceptable


def test_least_bad_within_a_kind_prefers_a_closeup_then_room_then_nearness() -> None:
    ledger = SiteLedger()
    ledger.add(_site(10.0, Hazard.OFF_ROOF, closeup=False, edge=8.0))
    ledger.add(_site(40.0, Hazard.OFF_ROOF, closeup=True, edge=2.0))
    ledger.add(_site(80.0, Hazard.OFF_ROOF, closeup=True, edge=6.0))
    ledger.add(_site(120.0, Hazard.OFF_ROOF, closeup=True, edge=6.0))
    chosen = ledger.least_bad((105.0, 0.0))
    assert chosen is not None
    assert chosen.ned_m[0] == 120.0


def test_ledger_a_closer_look_replaces_a_farther_one_never_the_reverse() -> None:
    ledger = SiteLedger(same_site_m=4.0)
    ledger.add(_site(0.0, Hazard.DOUBTED, closeup=False))
    ledger.add(_site(1.0, Hazard.WATER, closeup=True))  # the close-up saw water there
    assert [s.hazard for s in ledger.sites] == [Hazard.WATER]
    ledger.add(_site(2.0, Hazard.DOUBTED, closeup=False))  # seen from afar again: still water
    assert [s.hazard for s in ledger.sites] == [Hazard.WATER]
    ledger.add(_site(9.0, Hazard.OFF_ROOF))  # another place
    assert len(ledger.sites) == 2
    assert ledger.near((0.5, 0.0)) is ledger.sites[0]
    assert ledger.near((5.0, 0.0)) is None


def test_least_bad_of_an_empty_ledger_is_none() -> None:
    assert SiteLedger().least_bad((0.0, 0.0)) is None
    assert SiteLedger().best_hazard() is None


def test_fault_hook_is_off_unless_the_variable_names_a_stage() -> None:
    hook = FaultHook.from_env({})
    for stage in ("acquire", "rank", "land"):
        hook.check(stage, 1)  # nothing raised
    assert FaultHook.from_env({"LANDFALL_TEST_FAULT": ""}).stage is None


def test_fault_hook_fires_once_at_its_stage_and_round() -> None:
    hook = FaultHook.from_env({"LANDFALL_TEST_FAULT": "confirm:2"})
    hook.check("confirm", 1)
    hook.check("rank", 2)
    with pytest.raises(InjectedFault, match="'confirm' \\(round 2"):
        hook.check("confirm", 2)
    hook.check("confirm", 2)  # never twice


@pytest.mark.parametrize("text", ["nowhere", "rank:0", "rank:two"])
def test_fault_hook_refuses_a_bad_setting(text: str) -> None:
    with pytest.raises(ValueError, match="LANDFALL_TEST_FAULT"):
        FaultHook.from_env({"LANDFALL_TEST_FAULT": text})


def test_every_kind_a_judge_vetoes_with_is_a_known_hazard_kind_and_none_is_a_soft_doubt_unawares() -> None:
    """Each kind the onboard tier's judges put in a veto (``vetoes.append(("kind", ...))`` in
    companion/) is one of ``HAZARD_KINDS``, and only the soft ones leave a roof "doubted": a kind the
    ledger did not know fell through to DOUBTED, which the fallback takes as acceptable (a hillside
    launch landed on crops read as tree canopy, 2026-12-03)."""
    import re
    from pathlib import Path

    from companion.reasoning.base import HAZARD_KINDS

    root = Path(__file__).resolve().parents[1] / "companion"
    pattern = re.compile(r'vetoes\.append\(\s*\(\s*"([a-z_]+)"')
    kinds = {k for f in root.rglob("*.py") for k in pattern.findall(f.read_text())}
    assert {"canopy", "water", "markings", "raised"} <= kinds  # the scan finds what it should
    assert kinds <= set(HAZARD_KINDS), kinds - set(HAZARD_KINDS)
    soft = {k for k in HAZARD_KINDS if hazard_of((k,), accepted=False, street_level=False, strip=False)
            is Hazard.DOUBTED}  # fmt: skip
    assert soft == {"hazard"}, soft


def test_a_label_two_rounds_share_is_named_with_its_round() -> None:
    """Surface ID numbers each round's candidates from 0: two "site 1"s measured in different rounds are
    told apart by their round when said (a farmland fallback said "site 1 from overhead: obstructed;
    landing at site 1 instead"); a label of its own is said as it is."""
    ledger = SiteLedger()
    first = LedgerSite((0.0, 0.0, 0.0), Hazard.OBSTRUCTED, "crops", 3, True, label="site 1")
    ledger.add(first)
    assert ledger.name(first) == "site 1"
    second = LedgerSite((80.0, 0.0, 0.0), Hazard.OFF_ROOF, "from afar", 7, False, label="site 1")
    ledger.add(second)
    here = LedgerSite((160.0, 0.0, 0.0), Hazard.OFF_ROOF, "below", 7, True, label="here")
    ledger.add(here)
    assert (ledger.name(first), ledger.name(second), ledger.name(here)) == (
        "site 1, round 3",
        "site 1, round 7",
        "here",
    )
