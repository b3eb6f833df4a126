"""Compare LandNet models on the held-out renders, the way a model is chosen.

``python -m landfall_train.compare MODEL.onnx [MODEL.onnx ...] [--seeds 0,1] [--views 1,2,4]`` reads
the validation renders of each ``--seeds`` training seed (cities ``VAL_SEEDS`` and the held-out
vignettes, rendered into ``--cache`` as training renders them; never a training patch of any seed,
never a photograph) with every model in every view count, through OpenCV's DNN module as the
companion reads images, and prints per row: clear-site AUC, Youden's J with its threshold and the
true / false accept rates there. Nothing is written; the choice is the reader's, made here and not on
``companion-bench images``.
"""

from __future__ import annotations

import argparse
import logging
import sys
from collections.abc import Sequence
from pathlib import Path

from companion.reasoning.landnet import VIEWS
from landfall_train import patches
from landfall_train.train import (
    _onnx_predict,
    add_validation_args,
    calibrate,
    validation_paths,
    validation_views,
)


def _ints(text: str) -> list[int]:
    return [int(t) for t in text.split(",") if t.strip()]


def main(argv: Sequence[str] | None = None) -> int:
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s", stream=sys.stderr)
    p = argparse.ArgumentParser(prog="python -m landfall_train.compare", description=__doc__.split("\n")[0])
    p.add_argument("models", nargs="+", type=Path, help="ONNX files")
    p.add_argument("--seeds", type=_ints, default=[0], help="whose validation renders, e.g. 0,1")
    p.add_argument("--views", type=_ints, default=[4], help="readings averaged per image, e.g. 1,2,4")
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
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
