"""Train LandNet-S on rendered patches, calibrate it on held-out renders, export ONNX and its sidecar.

``python -m landfall_train [--steps N] [--max-minutes M] ...`` (``make model``):

1. render the patches (:mod:`landfall_train.patches`): training cities ``TRAIN_SEEDS`` and vignettes
   ``0 .. --vignettes - 1`` (fine-grained houses, barns, roofs, gardens, streets under the renderer's
   domain randomisation), validation cities ``VAL_SEEDS`` and vignettes from ``VAL_FIRST_VIGNETTE``
   (other seeds, same generators), cached under ``--cache`` by generator settings;
2. train on CPU, seeded: each step's batch and each sample's randomisation (:mod:`landfall_train.augment`)
   come from ``np.random.default_rng([seed, step, slot])``, so the run does not depend on worker timing;
   AdamW with a warm-up and a cosine decay over ``--steps``; ``--max-minutes`` stops it early (the
   sidecar says where it stopped);
3. calibrate on the validation renders only (one seeded randomised view of each), read as the
   companion reads images (``--views``: 4, the patch and its three mirror images averaged, as
   :meth:`companion.reasoning.landnet.LandNet.read` does with the sidecar's ``input.views``; ranks read
   their crops with ``--rank-views``, 2 by default, which order them nearly as well at half the cost): the
   ``clear`` threshold maximises Youden's J (true-accept rate less false-accept rate), each class's cell
   threshold maximises F1; then report the sim metrics at those thresholds;
4. export ONNX (opset 13, dynamic batch and size, batch norm folded), check that OpenCV's DNN module
   gives the same outputs as torch, and write ``MODEL.onnx`` and ``MODEL.json`` (the sidecar: classes,
   normalisation, thresholds, seed, command, data digest, sim metrics, the ONNX file's sha256).

``python -m landfall_train --recalibrate [--views V]`` redoes step 3 alone for the model at ``--out``
(its ONNX file through OpenCV's DNN module, no training, the weights untouched) and rewrites the
sidecar's thresholds, sim metrics and ``input.views``; the sidecar's ``calibration`` says how.
``--clear-floor P`` keeps the clear threshold at P at least (``make model``: the threshold the source-split
cross-validation on photographs chose for nets fine-tuned on them, :mod:`landfall_train.folds`): a site
then passes only where both the renders' calibration and the photographs' would pass it.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import logging
import math
import os
import platform
import subprocess
import sys
import time
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from companion.reasoning.landnet import VIEWS, average_views, onnx_runner, view_batch
from landfall_train import patches
from landfall_train.augment import augment, targets
from landfall_train.labels import CLASSES, HAZARD_CLASSES

_log = logging.getLogger("landfall_train")

TRAIN_SEEDS = tuple(range(100, 148))  # 48 cities
VAL_SEEDS = (900, 901, 902, 903)
PER_CITY = 200
VAL_PER_CITY = 150
VIGNETTES = 1500  # training vignettes 0 .. VIGNETTES - 1
PER_VIGNETTE = 20
VAL_FIRST_VIGNETTE = 1_000_000  # validation vignettes: their own numbers
VAL_VIGNETTES = 100
INPUT_PX = 128
POS_WEIGHT = {"object": 3.0, "person": 4.0, "vehicle": 3.0, "marking": 2.0}
CLEAR_POS_WEIGHT = 2.0
MODEL = Path("companion/reasoning/models/landnet-s")
WIDTHS = (16, 32, 64, 96)


def _widths(text: str) -> tuple[int, int, int, int]:
    parts = tuple(int(v) for v in text.split(","))
    if len(parts) != 4 or min(parts) < 1:
        raise argparse.ArgumentTypeError(f"four positive channel counts expected, got {text!r}")
    return parts


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m landfall_train", description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=Path, default=MODEL, help="model path without suffix (.onnx and .json)")
    add_validation_args(p)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--steps", type=int, default=6000)
    p.add_argument("--batch", type=int, default=64)
    p.add_argument("--lr", type=float, default=2e-3)
    p.add_argument("--max-minutes", type=float, default=60.0, help="stop training after this long")
    add_training_args(p)
    p.add_argument("--threads", type=int, default=1, help="torch threads")
    p.add_argument(
        "--views", type=int, choices=VIEWS, default=4,
        help="readings averaged per image at calibration and in the companion (4: with mirror images)",
    )  # fmt: skip
    p.add_argument(
        "--rank-views", type=int, choices=VIEWS, default=2,
        help="readings averaged per crop when the companion ranks (sidecar input.rank_views)",
    )  # fmt: skip
    p.add_argument(
        "--confirm-side", type=int, default=INPUT_PX, metavar="PX",
        help="shorter side a confirmation's window is read at in the companion (sidecar "
        "input.confirm_short_side_px; the Makefile's model uses 96, chosen on photographs)",
    )  # fmt: skip
    p.add_argument(
        "--rank-side", type=int, default=INPUT_PX, metavar="PX",
        help="shorter side a rank's crops are read at in the companion (sidecar input.rank_short_side_px; "
        "the Makefile's model uses 144, chosen on photographs)",
    )  # fmt: skip
    p.add_argument(
        "--recalibrate", action="store_true",
        help="only calibrate the model at --out again (its ONNX file; no training) and rewrite its sidecar",
    )  # fmt: skip
    p.add_argument(
        "--clear-floor", type=float, default=0.0,
        help="--recalibrate: the clear threshold is at least this (chosen on photographs)",
    )  # fmt: skip
    p.add_argument(
        "--head", choices=("fused", "features"), default="fused",
        help="clear-site head: pooled features and cell logits (fused) or pooled features only",
    )  # fmt: skip
    p.add_argument(
        "--widths", type=_widths, default=WIDTHS, help="channels of the net's four stages, e.g. 16,32,64,96"
    )
    return p


def cache_dir(root: Path, seed: int) -> Path:
    """Where the patches of training seed ``seed`` are cached under ``root`` (by generator settings)."""
    gen = f"{patches.GENERATOR}-{patches.PATCH_PX}-{patches.CITY_SIZE_M}-{patches.CITY_RES_M}-{seed}"
    return root / hashlib.sha256(gen.encode()).hexdigest()[:12]


def validation_paths(args: argparse.Namespace, seed: int) -> list[Path]:
    """The validation renders' shards of training seed ``seed`` (rendered when not cached): the first
    ``args.val_cities`` of ``VAL_SEEDS`` and ``args.val_vignettes`` vignettes from ``VAL_FIRST_VIGNETTE``."""
    cache = cache_dir(args.cache, seed)
    cities = VAL_SEEDS[: args.val_cities]
    return patches.generate(
        cache / f"val-{args.val_per_city}", cities, args.val_per_city, seed, args.workers
    ) + patches.generate_vignettes(
        cache / f"val-vignettes-{args.per_vignette}", VAL_FIRST_VIGNETTE, args.val_vignettes,
        args.per_vignette, seed, args.workers,
    )  # fmt: skip


def training_paths(args: argparse.Namespace, seed: int) -> list[Path]:
    """The training renders' shards of seed ``seed`` (rendered when not cached): the first
    ``args.train_cities`` of ``TRAIN_SEEDS`` and vignettes ``0 .. args.vignettes - 1``."""
    cache = cache_dir(args.cache, seed)
    paths = patches.generate(
        cache / f"train-{args.per_city}", TRAIN_SEEDS[: args.train_cities], args.per_city, seed, args.workers
    )
    _log.info("rendering %d vignettes", args.vignettes)
    return paths + patches.generate_vignettes(
        cache / f"vignettes-{args.per_vignette}", 0, args.vignettes, args.per_vignette, seed, args.workers
    )


def add_training_args(p: argparse.ArgumentParser) -> None:
    """The options :func:`training_paths` reads (shared with ``landfall_train.bare``)."""
    p.add_argument("--train-cities", type=int, default=len(TRAIN_SEEDS), help="how many of TRAIN_SEEDS")
    p.add_argument("--per-city", type=int, default=PER_CITY)
    p.add_argument(
        "--vignettes", type=int, default=VIGNETTES, help="training vignettes (fine-grained scenes)"
    )


def add_validation_args(p: argparse.ArgumentParser) -> None:
    """The options :func:`validation_paths` reads (shared with ``landfall_train.compare``)."""
    p.add_argument("--cache", type=Path, default=Path("runs/train-cache"), help="rendered patches")
    p.add_argument("--val-cities", type=int, default=len(VAL_SEEDS))
    p.add_argument("--val-per-city", type=int, default=VAL_PER_CITY)
    p.add_argument("--per-vignette", type=int, default=PER_VIGNETTE)
    p.add_argument("--val-vignettes", type=int, default=VAL_VIGNETTES)
    p.add_argument("--workers", type=int, default=2, help="processes rendering patches")


def main(argv: Sequence[str] | None = None) -> int:
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s", stream=sys.stderr)
    parser = build_parser()
    args = parser.parse_args(argv)
    for flag, side in (("--confirm-side", args.confirm_side), ("--rank-side", args.rank_side)):
        if side < 32:  # LandNet.load refuses a sidecar with less than twice input.multiple
            parser.error(f"{flag} must be at least 32 px, got {side}")
    command = "python -m landfall_train " + " ".join(sys.argv[1:] if argv is None else argv)
    t0 = time.monotonic()
    cache = cache_dir(args.cache, args.seed)
    train_seeds = TRAIN_SEEDS[: args.train_cities]
    val_seeds = VAL_SEEDS[: args.val_cities]
    _log.info("rendering %d + %d cities into %s", len(train_seeds), len(val_seeds), cache)
    x_val, y_val, val_digest = patches.load_shards(validation_paths(args, args.seed))
    if args.recalibrate:  # the validation renders only
        val = validation_views(x_val, y_val, args.seed)
        return recalibrate(args.out, val, reading_input(args), command, val_digest, args.clear_floor)
    x_train, y_train, train_digest = patches.load_shards(training_paths(args, args.seed))
    t_render = time.monotonic() - t0
    _log.info("%d training and %d validation patches in %.0f s", len(x_train), len(x_val), t_render)
    net, steps_done, t_train = fit(x_train, y_train, args)
    val = validation_views(x_val, y_val, args.seed)
    calib = calibrate(lambda x: _torch_predict(net, x), val, args.views)
    sidecar = {
        "name": args.out.name,
        "format": "landfall-landnet/1",
        "classes": list(CLASSES),
        "hazard_classes": [CLASSES[k] for k in HAZARD_CLASSES],
        "input": {"mean": [0.5] * 3, "std": [0.25] * 3, "multiple": 16, "short_side_px": INPUT_PX,
                  "max_long_side_px": 2 * INPUT_PX, "order": "RGB", "scale": 1 / 255, **reading_input(args)},
        "outputs": {"cells": "(N, K, H/8, W/8) presence logits", "clear": "(N, 1, 1, 1) clear-site logit"},
        "thresholds": calib["thresholds"],
        "sim_metrics": calib["metrics"],
        "seed": args.seed,
        "command": command,
        "data": {
            "train_city_seeds": list(train_seeds), "val_city_seeds": list(val_seeds),
            "train_vignettes": [0, args.vignettes], "per_vignette": args.per_vignette,
            "val_vignettes": [VAL_FIRST_VIGNETTE, VAL_FIRST_VIGNETTE + args.val_vignettes],
            "train_patches": len(x_train), "val_patches": len(x_val), "patch_px": patches.PATCH_PX,
            "train_digest": train_digest, "val_digest": val_digest,
            "excluded": "city seeds < 100 (companion-bench city flies 0), scenario1, scenario2, "
                        "tests/onboard_scene.toml: never rendered for training",
        },
        "training": {
            "widths": list(args.widths), "head": args.head, "steps_planned": args.steps,
            "steps_done": steps_done,
            "batch": args.batch, "lr": args.lr,
            "render_s": round(t_render, 1), "train_s": round(t_train, 1), "threads": args.threads,
            "torch": _torch_version(), "python": platform.python_version(), "commit": _commit(),
        },
    }  # fmt: skip
    export(net, args.out, sidecar)
    _log.info("wrote %s.onnx and .json in %.0f s in all", args.out, time.monotonic() - t0)
    return 0


def fit(x: np.ndarray, y: np.ndarray, args: argparse.Namespace) -> tuple[Any, int, float]:
    """Train a fresh LandNet-S; returns (net in eval mode, steps done, seconds)."""
    import torch

    from landfall_train.net import LandNetS

    torch.manual_seed(args.seed)
    torch.set_num_threads(args.threads)
    torch.use_deterministic_algorithms(True)
    net = LandNetS(len(CLASSES), args.widths, fused=args.head == "fused")
    opt = torch.optim.AdamW(net.parameters(), lr=args.lr, weight_decay=1e-4)
    warm: int = max(1, min(200, int(args.steps) // 20))

    def lr_at(step: int) -> float:
        if step < warm:
            return (step + 1) / warm
        total = max(1, int(args.steps) - warm)
        return 0.5 + 0.5 * math.cos(math.pi * float(step - warm) / total)

    sched = torch.optim.lr_scheduler.LambdaLR(opt, lr_at)
    pos_weight = torch.tensor([POS_WEIGHT.get(c, 1.0) for c in CLASSES]).view(1, -1, 1, 1)
    loader = torch.utils.data.DataLoader(
        _Batches(x, y, args.seed, args.batch, args.steps), batch_size=None, num_workers=1, prefetch_factor=4,
        worker_init_fn=lambda _w: torch.set_num_threads(1),
    )  # fmt: skip
    t0 = time.monotonic()
    step = 0
    net.train()
    running = 0.0
    for step, (img, cells, valid, clear) in enumerate(loader):
        logits, clear_logit = net(_normalise(img))
        bce = torch.nn.functional.binary_cross_entropy_with_logits(
            logits, cells, pos_weight=pos_weight, reduction="none"
        )
        cell_loss = (bce * valid[:, None]).sum() / (valid.sum() * len(CLASSES)).clamp(min=1.0)
        clear_loss = torch.nn.functional.binary_cross_entropy_with_logits(
            clear_logit.view(-1), clear, pos_weight=torch.tensor(CLEAR_POS_WEIGHT)
        )
        loss = cell_loss + clear_loss
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        sched.step()
        running = 0.98 * running + 0.02 * float(loss.detach()) if step else float(loss.detach())
        elapsed = time.monotonic() - t0
        if step % 100 == 0:
            _log.info("step %d loss %.4f (%.0f s, %.2f s/step)", step, running, elapsed, elapsed / (step + 1))
        if elapsed > 60.0 * args.max_minutes:
            _log.warning("stopping at step %d: --max-minutes %.1f reached", step + 1, args.max_minutes)
            break
    net.eval()
    return net, step + 1, time.monotonic() - t0


class _Batches:
    """Step ``k``'s batch (images NCHW uint8, cell targets, cell validity, clear targets), a map-style
    dataset of steps: what a step sees depends on (seed, step) only."""

    def __init__(self, x: np.ndarray, y: np.ndarray, seed: int, batch: int, steps: int) -> None:
        self.x, self.y, self.seed, self.batch, self.steps = x, y, seed, batch, steps

    def __len__(self) -> int:
        return self.steps

    def __getitem__(self, step: int) -> tuple[Any, ...]:
        import torch

        pick = np.random.default_rng([self.seed, step]).integers(0, len(self.x), self.batch)
        imgs, cells, valid, clear = [], [], [], []
        for slot, i in enumerate(pick.tolist()):
            img, lab = augment(self.x[i], self.y[i], np.random.default_rng([self.seed, step, slot]), INPUT_PX)
            c, v, s = targets(lab)
            imgs.append(img)
            cells.append(c)
            valid.append(v)
            clear.append(s)
        return (
            torch.from_numpy(np.stack(imgs).transpose(0, 3, 1, 2).copy()),
            torch.from_numpy(np.stack(cells)),
            torch.from_numpy(np.stack(valid)),
            torch.tensor(clear, dtype=torch.float32),
        )


def _normalise(img: Any) -> Any:
    return (img.float() / 255.0 - 0.5) / 0.25


def validation_views(x: np.ndarray, y: np.ndarray, seed: int) -> dict[str, np.ndarray]:
    """One seeded randomised view of each validation patch: images, cell targets, validity, clear."""
    out: dict[str, list[Any]] = {"img": [], "cells": [], "valid": [], "clear": []}
    for i in range(len(x)):
        img, lab = augment(x[i], y[i], np.random.default_rng([seed, 10**9, i]), INPUT_PX)
        c, v, s = targets(lab)
        for key, val in zip(("img", "cells", "valid", "clear"), (img, c, v, s), strict=True):
            out[key].append(val)
    return {k: np.stack(v) if k != "clear" else np.array(v, np.float32) for k, v in out.items()}


Predict = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]  # normalised NCHW -> (cell, clear) logits


def _torch_predict(net: Any, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    import torch

    with torch.no_grad():
        c, s = net(torch.from_numpy(x))
    return c.numpy(), s.numpy().reshape(-1)


def _onnx_predict(path: Path) -> Predict:
    """The exported model run as the companion runs it (:func:`companion.reasoning.landnet.onnx_runner`)."""
    run, _backend = onnx_runner(path)

    def predict(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        c, s = run(x)
        return c, s.reshape(-1)

    return predict


Norm = tuple[Sequence[float], Sequence[float]]  # per channel (mean, std) of RGB / 255
LANDNET_S_NORM: Norm = ((0.5, 0.5, 0.5), (0.25, 0.25, 0.25))


def normalised(img: np.ndarray, norm: Norm = LANDNET_S_NORM) -> np.ndarray:
    """NHWC uint8 images as the net reads them: NCHW float32, RGB / 255 normalised by ``norm``'s mean and
    standard deviation (LandNet-S's 0.5 and 0.25 by default; a sidecar's ``input.mean`` and ``input.std``)."""
    mean, std = (np.asarray(v, np.float32) for v in norm)
    x = (img.astype(np.float32) / np.float32(255.0) - mean) / std
    return np.ascontiguousarray(x.transpose(0, 3, 1, 2))


def read_views(
    predict: Callable[[np.ndarray], tuple[np.ndarray, ...]],
    img: np.ndarray,
    views: int,
    norm: Norm = LANDNET_S_NORM,
) -> list[np.ndarray]:
    """Probabilities of NHWC uint8 images, each read in ``views`` views and averaged as the companion
    does (:func:`companion.reasoning.landnet.average_views`): the cells (N, K, h, w), then per image each
    further output ``predict`` gives (the clear site; the bare head where a model has it)."""
    parts: list[list[np.ndarray]] = []
    for k in range(0, len(img), 64):
        batch = np.concatenate([view_batch(chw, views) for chw in normalised(img[k : k + 64], norm)])
        c, *rest = predict(batch)
        probs = [1.0 / (1.0 + np.exp(-np.asarray(r).reshape(-1))) for r in rest]
        c_p, first = average_views(1.0 / (1.0 + np.exp(-c.astype(np.float64))), probs[0], views)
        got = [c_p, first, *(q.reshape(-1, views).mean(axis=1) for q in probs[1:])]
        parts = parts or [[] for _ in got]
        for acc, a in zip(parts, got, strict=True):
            acc.append(a)
    return [np.concatenate(a) for a in parts]


def _predict(
    predict: Predict, img: np.ndarray, views: int, norm: Norm = LANDNET_S_NORM
) -> tuple[np.ndarray, np.ndarray]:
    """Cell and clear probabilities of NHWC uint8 images (:func:`read_views`)."""
    cells, clear = read_views(predict, img, views, norm)
    return cells, clear


def reading_input(args: argparse.Namespace) -> dict[str, int]:
    """How the companion reads images with the model, as sidecar ``input`` keys: the views averaged to
    confirm and to rank, and the shorter sides a confirmation's window and a rank's crops are scaled to."""
    return {
        "views": args.views, "rank_views": args.rank_views,
        "confirm_short_side_px": args.confirm_side, "rank_short_side_px": args.rank_side,
    }  # fmt: skip


def recalibrate(
    out: Path,
    val: dict[str, np.ndarray],
    reading: dict[str, int],
    command: str,
    val_digest: str,
    clear_floor: float = 0.0,
) -> int:
    """Calibrate the exported model at ``out`` again (``--recalibrate``) as the companion reads it
    (``reading``: :func:`reading_input`) and rewrite its sidecar."""
    meta_path = out.with_suffix(".json")
    meta = json.loads(meta_path.read_text())
    norm = (meta["input"]["mean"], meta["input"]["std"])
    calib = calibrate(_onnx_predict(out.with_suffix(".onnx")), val, reading["views"], clear_floor, norm)
    meta["thresholds"] = calib["thresholds"]
    meta["sim_metrics"] = calib["metrics"]
    meta["input"].update(reading)
    meta["calibration"] = {
        "command": command, **reading, "val_digest": val_digest,
        "clear_youden": calib["clear_youden"], "clear_floor": clear_floor, "commit": _commit(),
    }  # fmt: skip
    meta_path.write_text(json.dumps(meta, indent=2) + "\n")
    _log.info("recalibrated %s: clear threshold %.4f, sim AUC %.4f", meta_path, calib["thresholds"]["clear"],
              calib["metrics"]["clear_auc"])  # fmt: skip
    return 0


def calibrate(
    predict: Predict,
    val: dict[str, np.ndarray],
    views: int = 1,
    clear_floor: float = 0.0,
    norm: Norm = LANDNET_S_NORM,
) -> dict[str, Any]:
    """Thresholds and sim metrics on the validation views (module docstring, 3) read as ``norm``
    normalises them; the clear threshold is ``clear_floor`` where Youden's is lower (the metrics are
    those at the threshold kept)."""
    cells, clear = _predict(predict, val["img"], views, norm)
    truth = val["clear"] > 0.5
    youden, _j = _youden(clear, truth)
    t_clear = max(youden, clear_floor)
    j = float((clear[truth] >= t_clear).mean() - (clear[~truth] >= t_clear).mean())
    metrics: dict[str, Any] = {
        "clear_auc": round(_auc(clear, truth), 4),
        "clear_positives": int(truth.sum()),
        "clear_negatives": int((~truth).sum()),
        "clear_true_accept": round(float((clear[truth] >= t_clear).mean()), 4),
        "clear_false_accept": round(float((clear[~truth] >= t_clear).mean()), 4),
        "clear_youden_j": round(j, 4),
        "cells": {},
    }
    cell_t: dict[str, float] = {}
    valid = val["valid"][:, None].repeat(len(CLASSES), 1) > 0.5
    for k, name in enumerate(CLASSES):
        p = cells[:, k][valid[:, k]]
        t = val["cells"][:, k][valid[:, k]] > 0.5
        thr, f1 = _best_f1(p, t)
        cell_t[name] = round(thr, 4)
        metrics["cells"][name] = {
            "ap": round(_ap(p, t), 4),
            "f1": round(f1, 4),
            "prevalence": round(float(t.mean()), 4),
        }
    return {
        "thresholds": {"clear": round(t_clear, 4), "cells": cell_t}, "metrics": metrics,
        "clear_youden": round(youden, 4),
    }  # fmt: skip


def _youden(p: np.ndarray, t: np.ndarray) -> tuple[float, float]:
    best, thr = -1.0, 0.5
    for c in np.unique(np.round(p, 4)):
        j = float((p[t] >= c).mean() - (p[~t] >= c).mean()) if t.any() and (~t).any() else 0.0
        if j > best:
            best, thr = j, float(c)
    return thr, best


def _best_f1(p: np.ndarray, t: np.ndarray) -> tuple[float, float]:
    order = np.argsort(-p, kind="stable")
    tp = np.cumsum(t[order])
    fp = np.cumsum(~t[order])
    f1 = 2 * tp / np.maximum(tp + fp + t.sum(), 1)
    k = int(np.argmax(f1))
    return float(p[order][k]), float(f1[k])


def _ap(p: np.ndarray, t: np.ndarray) -> float:
    if not t.any():
        return float("nan")
    order = np.argsort(-p, kind="stable")
    tp = np.cumsum(t[order])
    precision = tp / np.arange(1, len(p) + 1)
    return float((precision * t[order]).sum() / t.sum())


def _auc(p: np.ndarray, t: np.ndarray) -> float:
    pos, neg = p[t], p[~t]
    if not len(pos) or not len(neg):
        return float("nan")
    ranks = np.argsort(np.argsort(np.concatenate([pos, neg]), kind="stable"), kind="stable") + 1.0
    return float((ranks[: len(pos)].sum() - len(pos) * (len(pos) + 1) / 2) / (len(pos) * len(neg)))


def export(net: Any, out: Path, sidecar: dict[str, Any]) -> None:
    """ONNX + sidecar; raises RuntimeError when ONNX Runtime or OpenCV's DNN module (the companion's
    runtimes) disagrees with torch."""
    import torch

    out.parent.mkdir(parents=True, exist_ok=True)
    onnx_path = out.with_suffix(".onnx")
    dummy = torch.zeros(1, 3, INPUT_PX, INPUT_PX)
    with warnings.catch_warnings():  # the TorchScript exporter (dynamo=False) is deprecated, and works
        warnings.simplefilter("ignore", DeprecationWarning)
        torch.onnx.export(
            net, (dummy,), str(onnx_path), input_names=["image"], output_names=["cells", "clear"],
            dynamic_axes={
                "image": {0: "n", 2: "h", 3: "w"}, "cells": {0: "n", 2: "gh", 3: "gw"}, "clear": {0: "n"}
            },
            opset_version=13, dynamo=False, do_constant_folding=True,
        )  # fmt: skip
    rng = np.random.default_rng(0)
    worst = 0.0
    runs = [onnx_runner(onnx_path, backend)[0] for backend in ("onnxruntime", "opencv")]
    for shape in ((1, 3, 128, 128), (5, 3, 96, 96), (1, 3, 128, 208), (2, 3, 256, 160)):
        x = rng.normal(0.0, 1.0, shape).astype(np.float32)
        with torch.no_grad():
            ref_c, ref_s = (t.numpy() for t in net(torch.from_numpy(x)))
        for run in runs:
            got_c, got_s = run(x)
            worst = max(
                worst,
                float(np.abs(got_c - ref_c).max()),
                float(np.abs(got_s.reshape(ref_s.shape) - ref_s).max()),
            )
    if worst > 1e-3:
        raise RuntimeError(f"the ONNX runtimes and torch disagree by {worst:.2e} on {onnx_path}")
    sidecar = dict(sidecar)
    sidecar["parity_max_abs_diff"] = float(f"{worst:.2e}")
    sidecar["onnx_bytes"] = onnx_path.stat().st_size
    sidecar["sha256"] = hashlib.sha256(onnx_path.read_bytes()).hexdigest()
    out.with_suffix(".json").write_text(json.dumps(sidecar, indent=2) + "\n")


def _torch_version() -> str:
    import torch

    return str(torch.__version__)


def _commit() -> str:
    try:
        return subprocess.run(
            ["git", "rev-parse", "HEAD"],
            capture_output=True,
            text=True,
            check=True,
            timeout=5,
            cwd=os.getcwd(),
        ).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return "unknown"
