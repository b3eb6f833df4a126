"""The figures of source folds at a clear-site threshold: confirmations right, rank pairs right, false
accepts and refusals, from each photograph's reading by the fold model that never learnt from its place
(:mod:`landfall_train.pretrained`'s folds; :mod:`landfall_train.whole_read` judges a mix of the net and
the whole-image read the same way), and the threshold chosen on them."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from landfall_train.folds import scores
from landfall_train.photo_set import Photo


def judged_at(
    reading: dict[str, Any], threshold: float, fold_threshold: float, clear_p: float | None = None
) -> bool:
    """Whether a fold's reading (:func:`landfall_train.folds.readings`, confirmed at ``fold_threshold``)
    confirms at ``threshold``: the clear-site probability (``clear_p``, default the reading's) reaches it
    and no other veto (water, markings, a canopy) refused it."""
    other_veto = not reading["confirmed"] and reading["clear_p"] >= fold_threshold
    return (reading["clear_p"] if clear_p is None else clear_p) >= threshold and not other_veto


def figures(
    photos: Sequence[Photo],
    seen: dict[str, dict[str, Any]],
    threshold: float,
    fold_threshold: float,
    mix: dict[str, float] | None = None,
) -> dict[str, Any]:
    """Confirm and rank right answers, false accepts (confirmed, labelled unsafe) and false refusals
    (refused, labelled safe) of ``photos`` at ``threshold``; ``mix``: each photograph's confirmation
    probability instead of its reading's (:mod:`landfall_train.whole_read`)."""
    safe = [p for p in photos if p.land is True]
    unsafe = [p for p in photos if p.land is False]
    verdicts = {
        str(p.path): (
            judged_at(seen[str(p.path)], threshold, fold_threshold, (mix or {}).get(str(p.path))),
            seen[str(p.path)]["rank_score"],
        )
        for p in photos
    }
    fa = sum(verdicts[str(p.path)][0] for p in unsafe)
    fr = sum(not verdicts[str(p.path)][0] for p in safe)
    return scores(photos, verdicts) | {
        "false_accepts": fa, "unsafe": len(unsafe), "false_refusals": fr, "safe": len(safe),
    }  # fmt: skip


def pooled(
    groups: Sequence[Sequence[Photo]],
    seen: dict[str, dict[str, Any]],
    threshold: float,
    fold_threshold: float,
    mix: dict[str, float] | None = None,
) -> dict[str, Any]:
    """:func:`figures` of each fold's photographs summed: rank pairs within a fold only (two folds' models
    score on scales of their own), every confirmation once."""
    each = [figures(g, seen, threshold, fold_threshold, mix) for g in groups]
    return {k: sum(f[k] for f in each) for k in each[0]}


def choose_threshold(
    photos: Sequence[Photo],
    seen: dict[str, dict[str, Any]],
    fold_threshold: float,
    max_false_accept: float,
    mix: dict[str, float] | None = None,
) -> float:
    """The clear-site threshold with the most confirmations right pooled over the folds among those whose
    false-accept rate is at most ``max_false_accept`` (ties: the higher, refusing more)."""
    best = (-1, 0.0)
    for t in np.round(np.arange(0.05, 0.96, 0.01), 2):
        f = figures(photos, seen, float(t), fold_threshold, mix)
        if f["false_accepts"] <= max_false_accept * f["unsafe"] and f["confirm_right"] >= best[0]:
            best = (f["confirm_right"], float(t))
    return best[1]
