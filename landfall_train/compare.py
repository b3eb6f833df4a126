"""Compare LandNet models on the held-out renders, the way a model is chosen.

``python -m landfall_train.compare MODEL.onnx [MODEL.onnx ...] [--seeds 0,1] [--views 1,2,4]`` reads
the validation renders of each ``--seeds`` training seed (cities ``VAL_SEEDS`` and the held-out
vignettes, rendered into ``--cache`` as training renders them; never a training patch of any seed,
never a photograph) with every model in every view count, through OpenCV's DNN module as the
companion reads images, and prints per row: clear-site AUC, Youden's J with its threshold and the
true / false accept rates there. ``--rank`` adds, per model and seed, the rank's score as the companion
computes it (two views): AUC over views at least half roof, nothing on them against something, and over
all views, clear site against not (:func:`landfall_train.bare.held_out`); ``--rank-weights 0.2,0.3``
the same with other weights of the clear-site probability. Nothing is written; the choice is the
reader's, made here and not on ``companion-bench images``.
"""

from __future__ import annotations

import argparse
import logging
import sys
from collections.abc import Sequence
from pathlib import Path

from companion.reasoning.landnet import VIEWS
from landfall_train import patches
from landfall_train.bare import held_out
from landfall_train.train import (
    _onnx_predict,
    add_validation_args,
    calibrate,
    validation_paths,
    validation_views,
)


def _ints(text: str) -> list[int]:
    return [int(t) for t in text.split(",") if t.strip()]


def _floats(text: str) -> list[float]:
    return [float(t) for t in text.split(",") if t.strip()]


def main(argv: Sequence[str] | None = None) -> int:
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s", stream=sys.stderr)
    p = argparse.ArgumentParser(prog="python -m landfall_train.compare", description=__doc__.split("\n")[0])
    p.add_argument("models", nargs="+", type=Path, help="ONNX files")
    p.add_argument("--seeds", type=_ints, default=[0], help="whose validation renders, e.g. 0,1")
    p.add_argument("--views", type=_ints, default=[4], help="readings averaged per image, e.g. 1,2,4")
    p.add_argument("--rank", action="store_true", help="also the rank's score (landfall_train.bare)")
    p.add_argument("--rank-weights", type=_floats, default=[], help="with --rank: other clear weights")
    add_validation_args(p)
    args = p.parse_args(argv)
    for v in args.views:
        if v not in VIEWS:
            p.error(f"--views: each of {VIEWS}, got {v}")
    for m in args.models:
        if not m.is_file():
            p.error(f"{m}: not found")
    print(f"{'model':<34} {'val':>4} {'views':>5} {'auc':>7} {'J':>7} {'thr':>7} {'TA':>7} {'FA':>7}")
    for seed in args.seeds:
        x, y, _digest = patches.load_shards(validation_paths(args, seed))
        val = validation_views(x, y, seed)
        for model in args.models:
            for views in args.views:
                calib = calibrate(_onnx_predict(model), val, views)
                m, thr = calib["metrics"], calib["thresholds"]["clear"]
                print(
                    f"{str(model)[-34:]:<34} {seed:>4} {views:>5} {m['clear_auc']:>7.4f} "
                    f"{m['clear_youden_j']:>7.4f} {thr:>7.4f} {m['clear_true_accept']:>7.4f} "
                    f"{m['clear_false_accept']:>7.4f}",
                    flush=True,
                )
            if args.rank:
                got = held_out(model, val, 2, args.rank_weights)
                print(f"{str(model)[-34:]:<34} {seed:>4} rank: roof-dominated AUC {got['auc_rank']:.4f} "
                      f"(without the bare head {got['auc_rank_without_bare']:.4f}), all views "
                      f"{got['auc_rank_all']:.4f}", flush=True)  # fmt: skip
                for w, (roof_auc, all_auc) in got.get("by_weight", {}).items():
                    print(
                        f"{'':<34} {seed:>4} rank, clear weight {w}: {roof_auc:.4f}, all views {all_auc:.4f}"
                    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
