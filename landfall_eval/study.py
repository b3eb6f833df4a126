"""The reference study's figures (DESIGN.md section 6), which every report and script compares with."""

from __future__ import annotations

__all__ = [
    "STUDY_JACCARD",
    "STUDY_LANDING_DISTANCE_M",
    "STUDY_PEAK_RSS_MB",
    "STUDY_ROUNDS_PER_SAFE",
    "STUDY_SAFE_RATE",
]

STUDY_SAFE_RATE = 0.75  # city-wide, 20 quasi-random launches, its best model
STUDY_ROUNDS_PER_SAFE = 2.2  # reasoning rounds per safe landing, on average
STUDY_JACCARD = {"scenario1": 0.871, "scenario2": 0.596}  # Surface ID against the safe zone
STUDY_LANDING_DISTANCE_M = {"scenario1": 0.80, "scenario2": 1.15}  # touchdown to intended target
STUDY_PEAK_RSS_MB = 716.0  # its pipeline's memory
