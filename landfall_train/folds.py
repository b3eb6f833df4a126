"""Source-split cross-validation of the photograph fine-tuning (:mod:`landfall_train.photos`).

``python -m landfall_train.folds --member MEMBER.onnx --seed 0 --out runs/folds/seed0.json`` fine-tunes
the member once per fold and judges the fold's photographs, which it never learnt from, at each
``--alphas`` (how far toward the fine-tuned weights, :func:`landfall_train.photos.interpolate`):

- one fold per source that may be learnt from (Kampala, Kathmandu, Zanzibar, Boruszyn, ...): learn from
  every other one, judge that source's photographs;
- the ``held-out`` fold: learn from every learnable source, judge the held-out ones (``--hold-out`` and
  the photographs whose licence bars training): what the shipped weights are judged on.

The judgement is the net's part of the companion's (``companion.reasoning.net_judge.confirm_reading``):
confirm reads the middle two thirds in four views and accepts when the clear-site probability reaches
the member's threshold with no water (over 10 % of the cells) or markings (over 2 %); rank orders by the
reading's hazard (two views), every (clear roof, cluttered roof) pair of the fold. Pooled over the source
folds, these are the figures that choose ``--alpha`` and ``--steps``; alpha 0 is the member as trained.
``--sides 0,96`` reads the judged photographs at each listed shorter side as well (0: the sidecar's;
figures keyed ``ALPHA@SIDE``; confirmations and ranks both at it), which chose the confirmation's
96 px and the rank's 144.
Each fold's model is exported to ONNX and read by :class:`companion.reasoning.landnet.LandNet`, as the
companion reads it. Folds run in ``--jobs`` processes, one core each.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import tempfile
import time
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

from landfall_train import patches
from landfall_train.photo_set import Photo, load_photos, read_rgb, split
from landfall_train.photos import (
    build_parser,
    fine_tune,
    from_onnx,
    interpolate,
    member_sidecar,
    render_set,
)
from landfall_train.train import export, training_paths

_log = logging.getLogger("landfall_train.folds")

ALPHAS = (0.0, 0.25, 0.5, 0.75, 1.0)
HELD_OUT = "held-out"


def readings(model: Path, images: dict[str, np.ndarray], short_side: int = 0) -> dict[str, dict[str, Any]]:
    """Per photograph (its path, in ``images`` with its pixels): whether the companion's net judgement
    confirms it (:func:`companion.reasoning.net_judge.confirm_reading` on a roof, no LiDAR, the
    middle two thirds), its rank score (higher first) and what they came from (the
    clear-site probability and the spread of its views, the shares of water, markings and objects, the
    hazard peak), for choosing thresholds afterwards. ``short_side`` (pixels, 0: the sidecar's) reads
    the photographs at another scale, the longer side at most twice it."""
    from companion.reasoning.base import ConfirmRequest
    from companion.reasoning.image_cues import CueParams
    from companion.reasoning.landnet import LandNet
    from companion.reasoning.net_judge import confirm_reading
    from companion.reasoning.onboard_params import ConfirmParams

    net = LandNet.load(model, backend="onnxruntime")
    if short_side:  # both readings below pass their own side; the longer side's cap scales with it
        net.confirm_short_side_px = net.rank_short_side_px = short_side
    params = ConfirmParams(site_window=CueParams().site_window_crop)  # a crop's window, whatever its shape
    out = {}
    for key, rgb in images.items():
        vetoes, _categorical, _note, r, _open = confirm_reading(
            net, ConfirmRequest(rgb), params, lidar_vetoes=[], street_level=False, where=""
        )
        whole = net.read_rank(rgb)
        out[key] = {
            "confirmed": not vetoes, "rank_score": -whole.hazard,
            "clear_p": round(r.clear_p, 4), "spread": round(r.clear_spread, 4),
            "water": r.share("water"), "marking": r.share("marking"), "object": r.share("object"),
            "objects": r.count("object"), "hazard_peak": round(r.hazard_peak, 4),
            "rank_clear_p": round(whole.clear_p, 4),
        }  # fmt: skip
    return out


def scores(photos: Sequence[Photo], verdicts: dict[str, tuple[bool, float]]) -> dict[str, Any]:
    """Confirm and rank right answers of ``verdicts`` on ``photos``: the confirm cases of ``companion-bench
    images`` (land true or false), and each (clear roof, cluttered roof) pair once (the bench asks both
    orders of an order-blind judgement)."""
    confirm = [verdicts[str(p.path)][0] == p.land for p in photos if p.land is not None]
    clear = [verdicts[str(p.path)][1] for p in photos if p.label == "clear_roof"]
    cluttered = [verdicts[str(p.path)][1] for p in photos if p.label == "cluttered_roof"]
    rank = [a > b for a in clear for b in cluttered]
    return {
        "confirm_right": int(sum(confirm)), "confirm_cases": len(confirm),
        "rank_right": int(sum(rank)), "rank_cases": len(rank),
    }  # fmt: skip


def _fold(job: tuple[str, list[Photo], list[Photo], argparse.Namespace, Sequence[float]]) -> dict[str, Any]:
    name, learn, judged, args, alphas = job
    t0 = time.monotonic()
    x, y, _digest, first_closeup = render_set(args)
    net = from_onnx(args.member)
    start = {k: v.clone() for k, v in net.state_dict().items()}
    tuned = {
        k: v.clone() for k, v in fine_tune(net, learn, x, y, args, first_closeup)[0].state_dict().items()
    }
    meta = member_sidecar(args.member)
    images = {str(p.path): read_rgb(p.path) for p in judged}
    out: dict[str, Any] = {"fold": name, "learnt": len(learn), "by_alpha": {}}
    with tempfile.TemporaryDirectory() as tmp:
        for a in alphas:
            net.load_state_dict(tuned)
            interpolate(net, start, a)
            path = Path(tmp) / f"a{a:g}"
            export(net, path, meta)
            for side in args.sides:
                key = f"{a:g}@{side}" if side else f"{a:g}"
                seen = readings(path.with_suffix(".onnx"), images, side)
                verdicts = {k: (v["confirmed"], v["rank_score"]) for k, v in seen.items()}
                out["by_alpha"][key] = scores(judged, verdicts) | {"threshold": meta["thresholds"]["clear"]}
                out.setdefault("photos", {})[key] = seen
    _log.info("fold %s: %.0f s", name, time.monotonic() - t0)
    return out


def pooled(folds: Sequence[dict[str, Any]], alpha: str) -> dict[str, Any]:
    """The source folds' counts summed at ``alpha``, with the accuracies."""
    keys = ("confirm_right", "confirm_cases", "rank_right", "rank_cases")
    tot = {k: sum(f["by_alpha"][alpha][k] for f in folds) for k in keys}
    tot["confirm_accuracy"] = round(tot["confirm_right"] / max(tot["confirm_cases"], 1), 4)
    tot["rank_accuracy"] = round(tot["rank_right"] / max(tot["rank_cases"], 1), 4)
    return tot


def main(argv: Sequence[str] | None = None) -> int:
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s", stream=sys.stderr)
    p = build_parser()
    p.prog = "python -m landfall_train.folds"
    p.description = __doc__.split("\n")[0]
    p.add_argument("--alphas", type=lambda s: [float(v) for v in s.split(",")], default=list(ALPHAS))
    p.add_argument("--jobs", type=int, default=2, help="folds fine-tuned side by side")
    p.add_argument(
        "--sides", type=lambda s: [int(v) for v in s.split(",")], default=[0],
        help="short sides (px) to read the judged photographs at, 0 the sidecar's: e.g. 0,96",
    )  # fmt: skip
    args = p.parse_args(argv)
    photos = load_photos(args.photos)
    learn, held = split(photos, args.hold_out)
    sources = sorted({ph.source for ph in learn})
    jobs = [
        (s, [ph for ph in learn if ph.source != s], [ph for ph in learn if ph.source == s], args, args.alphas)
        for s in sources
    ]
    jobs.append((HELD_OUT, learn, held, args, args.alphas))
    patches.load_shards(training_paths(args, args.seed))  # rendered once, before the folds read the cache
    t0 = time.monotonic()
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        folds = list(pool.map(_fold, jobs))
    source_folds = [f for f in folds if f["fold"] != HELD_OUT]
    held_fold = next(f for f in folds if f["fold"] == HELD_OUT)
    report = {
        "member": args.member, "seed": args.seed, "steps": args.steps, "lr": args.lr,
        "photo_weight": args.photo_weight, "photo_cells": args.photo_cells,
        "photo_roof": args.photo_roof, "hold_out": args.hold_out,
        "folds": folds,
        "sides": args.sides,
        "source_folds": {k: pooled(source_folds, k) for k in held_fold["by_alpha"]},
        "held_out": {k: pooled([held_fold], k) for k in held_fold["by_alpha"]},
        "seconds": round(time.monotonic() - t0, 1),
    }  # fmt: skip
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.with_suffix(".json").write_text(json.dumps(report, indent=2) + "\n")
    print(f"{'alpha':>8} {'source folds: confirm':>22} {'rank':>7}   {'held-out: confirm':>18} {'rank':>7}")
    for k in held_fold["by_alpha"]:
        s, h = report["source_folds"][k], report["held_out"][k]
        print(f"{k:>8} {s['confirm_accuracy']:>22.3f} {s['rank_accuracy']:>7.3f}   "
              f"{h['confirm_accuracy']:>18.3f} {h['rank_accuracy']:>7.3f}")  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
