"""A tree's crown is no landing site: the colour-and-texture veto of the LandNet-S judgement
(companion.reasoning.net_judge.canopy_share), which the net's own tree cells miss on real canopy."""

from __future__ import annotations

import cv2
import numpy as np

from companion.reasoning.base import ConfirmRequest
from companion.reasoning.landnet import LandNet
from companion.reasoning.net_judge import MAX_CANOPY_SHARE, canopy_share, confirm_reading
from companion.reasoning.onboard import OnboardReasoner
from companion.reasoning.onboard_params import ConfirmParams


def _canopy(seed: int) -> np.ndarray:
    """Leaves from above: overlapping crowns of greens, lit and shaded."""
    rng = np.random.default_rng(seed)
    img = np.zeros((192, 192, 3))
    img[:] = (40, 70, 30)
    for _ in range(900):
        x, y = (int(v) for v in rng.integers(0, 192, 2))
        green = rng.uniform(60, 170)
        colour = (green * rng.uniform(0.35, 0.6), green, green * rng.uniform(0.2, 0.45))
        cv2.circle(img, (x, y), int(rng.integers(2, 7)), colour, -1)
    return np.asarray(np.clip(img, 0, 255), np.uint8)


def _green_metal_roof() -> np.ndarray:
    """A dark-green corrugated roof: green, but smooth between its ribs."""
    img = np.zeros((192, 192, 3))
    img[:] = (40, 95, 70)
    img[:, ::12] *= 0.8
    return np.asarray(img, np.uint8)


def _gravel(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    img = rng.normal(130, 25, (192, 192, 1)) * np.array([1.0, 0.97, 0.9])
    return np.asarray(np.clip(cv2.GaussianBlur(img, (0, 0), 0.8), 0, 255), np.uint8)


def test_leaves_are_canopy_and_roofs_green_or_grey_are_not() -> None:
    for seed in range(3):
        assert canopy_share(_canopy(seed)) > MAX_CANOPY_SHARE
        assert canopy_share(_gravel(seed)) < 0.05
    assert canopy_share(_green_metal_roof()) < 0.1


def test_a_crown_is_refused_by_name_above_street_level_and_left_to_the_parks_rules_below() -> None:
    net = LandNet.load()
    d = OnboardReasoner(judge="landnet", landnet=net).confirm_sync(ConfirmRequest(_canopy(0)))
    assert not d.accept
    assert "tree canopy" in d.rationale, d.rationale
    vetoes, _, _, _, _ = confirm_reading(
        net, ConfirmRequest(_canopy(0)), ConfirmParams(), lidar_vetoes=[], street_level=True, where="here"
    )
    assert "canopy" not in [kind for kind, _ in vetoes]
