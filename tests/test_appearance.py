"""Surfaces by their look, for a camera alone (companion.perception.appearance): a clear-cell mask to
candidates, and each packaged net's cells over a scenario1 frame from the launch pose."""

from __future__ import annotations

import numpy as np
import pytest

from companion.perception.appearance import appearance_candidates, clear_cells


def test_clear_parts_become_candidates_largest_first_centred_inside() -> None:
    clear = np.zeros((20, 40), bool)
    clear[2:8, 2:10] = True  # 48 cells
    clear[10:19, 20:38] = True  # 162 cells: the larger part
    clear[15, 5] = True  # a single cell: gone with the erosion
    cands = appearance_candidates(clear, 400, 200)
    assert [c.index for c in cands] == [0, 1]
    big, small = cands
    assert big.box_px == (200, 100, 380, 190)  # the part grown back by the eroded cell, in pixels
    u, v = big.centre_px
    assert (u, v) == (285.0, 145.0)  # its most interior cell, the middle of the ridge of them
    assert small.box_px == (20, 20, 100, 80)
    assert all(c.measured_share == 0.0 and not c.fallback for c in cands)
    assert np.isnan(big.area_m2)  # no geometry: nothing measured
    assert appearance_candidates(np.zeros((20, 40), bool), 400, 200) == []


def test_a_judge_without_a_roof_class_is_refused() -> None:
    with pytest.raises(ValueError, match="no 'roof' class"):
        clear_cells(np.zeros((40, 60, 3), np.uint8), lambda img: np.zeros((2, 4, 4), bool), ("water", "road"))


@pytest.mark.parametrize("model", ["landnet-s", "landnet-e"])
def test_scenario1s_clear_roof_is_the_largest_surface_by_its_look(model: str) -> None:
    """From the launch pose 110 m up, the largest candidate by the net's cells is centred on the clear
    gravel roof and none on the cluttered one. With LandNet-S its box holds the roof's middle; LandNet-E's
    rank cells read much of that gravel from so high as grass too (docs/reasoning.md, "Rank cells"), so
    its clear cells break the roof into parts: the two largest are both on it."""
    from companion.reasoning.landnet import PACKAGED, LandNet
    from tests.views import LAUNCH, render, world

    frame = render(world("scenario1"), LAUNCH)
    net = LandNet.load(PACKAGED[model])
    clear = clear_cells(frame.rgb, net.presence, tuple(net.classes))
    cands = appearance_candidates(clear, frame.rgb.shape[1], frame.rgb.shape[0])
    assert cands
    # the clear gravel roof west of the street (pixels 250-415 x 160-375 from the launch pose)
    on_roof = [250 <= c.centre_px[0] <= 415 and 160 <= c.centre_px[1] <= 375 for c in cands]
    assert on_roof[0], cands[0]
    if model == "landnet-s":
        x0, y0, x1, y1 = cands[0].box_px
        assert max(x0 - 300, y0 - 200, 380 - x1, 340 - y1) <= 0, cands[0]  # the box holds the roof's middle
    else:
        assert on_roof[1], cands[1]
    # the cluttered roof with "LAND HERE" painted on it (pixels 545-720 x 165-375) is no candidate centre
    assert not any(545 <= c.centre_px[0] <= 720 and 165 <= c.centre_px[1] <= 375 for c in cands)
