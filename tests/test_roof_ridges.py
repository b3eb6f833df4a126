"""Lines on a roof the net is firmly sure is clear are its ridges, not paint.

LandNet reads the ribs of corrugated metal and the courses of a tiled roof as painted markings: on the
real photographs clear corrugated roofs read 2-22 % markings at clear-site probabilities of 0.87-0.99,
and the binding markings veto refused 8 of realimages-train's 40 clear roofs. Every surface read with
markings that was not a clear roof read 0.51 or less. So above street level the markings veto stands
unless the net is firmly sure (over its threshold, not unsure); at street level any marking is paint.
The net is replaced here by its reading, the boundary this rule reads."""

from __future__ import annotations

from typing import Any, cast

import numpy as np
import pytest

from companion.reasoning.base import ConfirmRequest
from companion.reasoning.landnet import LandNet, SceneReading
from companion.reasoning.net_judge import MAX_MARKING_SHARE, UNSURE_MARGIN, UNSURE_SPREAD, confirm_reading
from companion.reasoning.onboard_params import ConfirmParams

THRESHOLD = 0.63


class _Reading:
    """Stands in for LandNet: every read is ``reading``."""

    clear_threshold = THRESHOLD
    confirm_short_side_px = 96

    def __init__(self, reading: SceneReading) -> None:
        self.reading = reading

    def read(self, window: np.ndarray, short_side: int) -> SceneReading:
        return self.reading

    def confirmation(self, reading: SceneReading, image: np.ndarray) -> SceneReading:
        return reading


def _judge(clear_p: float, marking: float, *, spread: float = 0.0, street_level: bool = False) -> Any:
    r = SceneReading(
        "landnet-e", (160, 160), (16, 16), clear_p, (("roof", 1.0 - marking), ("marking", marking)),
        (("marking", ("centre", "left")),), (), clear_spread=spread,
    )  # fmt: skip
    image = np.full((160, 160, 3), 120, np.uint8)
    return confirm_reading(
        cast(LandNet, _Reading(r)), ConfirmRequest(image), ConfirmParams(),
        lidar_vetoes=[], street_level=street_level, where="here",
    )  # fmt: skip


@pytest.mark.parametrize("marking", [0.03, 0.08, 0.22])
def test_lines_on_a_roof_firmly_clear_are_its_ridges(marking: float) -> None:
    vetoes, categorical, note, _r, _open = _judge(THRESHOLD + UNSURE_MARGIN + 0.05, marking)
    assert vetoes == []
    assert not categorical
    assert f"lines on it, {marking:.0%}, read as its ridges or seams" in note, note


@pytest.mark.parametrize(
    ("clear_p", "spread"),
    [
        (0.5, 0.0),  # not a clear roof: the markings are named, bindingly
        (THRESHOLD + UNSURE_MARGIN - 0.05, 0.0),  # over the threshold, but a guess
        (0.95, UNSURE_SPREAD + 0.05),  # its mirror views disagree
    ],
)
def test_markings_stand_where_the_net_is_not_firmly_sure_of_a_clear_roof(
    clear_p: float, spread: float
) -> None:
    vetoes, categorical, note, _r, _open = _judge(clear_p, 0.08, spread=spread)
    assert [kind for kind, _ in vetoes][:1] == ["markings"], vetoes
    assert categorical
    assert "ridges" not in note


def test_a_marking_at_street_level_is_paint_however_clear() -> None:
    for marking in (0.01, 0.08):
        vetoes, categorical, _note, _r, _open = _judge(0.97, marking, street_level=True)
        assert "markings" in [kind for kind, _ in vetoes], vetoes
        assert categorical


def test_a_stray_cell_was_never_a_marking() -> None:
    vetoes, _categorical, note, _r, _open = _judge(0.5, MAX_MARKING_SHARE / 2)
    assert "markings" not in [kind for kind, _ in vetoes]
    assert "ridges" not in note
