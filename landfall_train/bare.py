"""The bare head: a third output of a trained LandNet, the logit that nothing stands on the surface.

``python -m landfall_train.bare --seed S --out runs/landnet/seedS/landnet-s`` (``make model`` runs it on
each member before merging them) rewrites the model at ``--out`` with the head and its sidecar as format
``landfall-landnet/2``.

**Why.** A rank asks which of several roofs has nothing on it. The clear head answers another question
(a clear site: at least 85 % roof and no hazard), so its probability also falls when a roof does not fill
the view: a clear roof seen with its garden can order below a cluttered roof that fills the frame. The
bare head learns the rank's own question: among views that are at least half roof, is any cell an
object, a person, a vehicle, water or a marking (cell presence as training defines it,
:func:`landfall_train.augment.targets`)?

**How.** The net stays as trained (its cells and clear outputs do not change). The clear head's input,
the stride-16 features and the cell logits pooled over the image (average and max), is read for
``--samples`` seeded randomised views (:func:`landfall_train.augment.augment`) of seed S's training
renders, the renders the net learnt from: never a validation render, never a photograph. A logistic
regression (scikit-learn, L2, ``--C``) fits the views whose cells are at least ``ROOF_MIN_SHARE`` roof;
its weights, unscaled, become a 1 x 1 convolution of the same pooled vector, output ``bare``
(N, 1, 1, 1). ONNX Runtime and OpenCV's DNN module must both give the regression's logit, or nothing is
written. The sidecar records the fit and, on seed S's validation renders (two views, as ranks read),
the held-out AUC of the bare probability and of the rank's score over roof-dominated views.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import logging
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from companion.reasoning.landnet import BARE, OUTPUTS, onnx_runner, rank_hazard
from landfall_train import patches
from landfall_train.augment import augment, targets
from landfall_train.labels import CLASSES, HAZARD_CLASSES
from landfall_train.train import (
    INPUT_PX,
    _auc,
    _commit,
    add_training_args,
    add_validation_args,
    normalised,
    read_views,
    training_paths,
    validation_paths,
    validation_views,
)

_log = logging.getLogger("landfall_train.bare")

ROOF_MIN_SHARE = 0.5  # the head learns from views whose valid cells are at least this share roof
SAMPLES = 24_000
STREAM = 777  # the views' random stream: np.random.default_rng([seed, STREAM, patch])
DESCRIPTION = (
    "(N, 1, 1, 1) logit that nothing (object, person, vehicle, water, marking) stands on the surface, "
    "learnt from views at least half roof"
)


def pooled_input(model: Any) -> str:
    """Name of the pooled vector the clear head reads (the input of the convolution giving ``clear``)."""
    heads = [n for n in model.graph.node if "clear" in n.output]
    if len(heads) != 1 or heads[0].op_type != "Conv":
        raise ValueError("no single convolution gives 'clear': not a LandNet graph")
    return str(heads[0].input[0])


def pooled_features(model: Any, imgs: np.ndarray) -> np.ndarray:
    """(N, F) pooled vectors of NHWC uint8 images (one view each), through ONNX Runtime on one thread."""
    import onnx
    import onnxruntime as ort

    name = pooled_input(model)
    probe = onnx.ModelProto()
    probe.CopyFrom(model)
    probe.graph.output.append(onnx.helper.make_tensor_value_info(name, onnx.TensorProto.FLOAT, None))
    opts = ort.SessionOptions()
    opts.intra_op_num_threads = opts.inter_op_num_threads = 1
    session = ort.InferenceSession(probe.SerializeToString(), opts, providers=["CPUExecutionProvider"])
    out = []
    for k in range(0, len(imgs), 64):
        blob = normalised(imgs[k : k + 64])
        out.append(session.run([name], {"image": blob})[0].reshape(len(blob), -1))
    return np.concatenate(out)


def roof_and_hazard(cells: np.ndarray, valid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per view: the share of its valid cells that are roof, and whether any valid cell holds a hazard."""
    n_valid = np.maximum(valid.sum(axis=(1, 2)), 1.0)
    roof = (cells[:, CLASSES.index("roof")] * valid).sum(axis=(1, 2)) / n_valid
    hazard = (cells[:, list(HAZARD_CLASSES)] * valid[:, None]).max(axis=(1, 2, 3)) > 0.5
    return roof, hazard


def training_views(x: np.ndarray, y: np.ndarray, seed: int, n: int) -> tuple[np.ndarray, ...]:
    """``n`` seeded randomised views of the training patches (each patch once before any twice): images,
    roof shares, hazard flags."""
    order = np.random.default_rng([seed, STREAM]).permutation(len(x))
    imgs, cells, valid = [], [], []
    for j in range(n):
        i, again = int(order[j % len(x)]), j // len(x)
        key = [seed, STREAM, i] if not again else [seed, STREAM, i, again]
        img, lab = augment(x[i], y[i], np.random.default_rng(key), INPUT_PX)
        c, v, _clear = targets(lab)
        imgs.append(img)
        cells.append(c)
        valid.append(v)
    roof, hazard = roof_and_hazard(np.stack(cells), np.stack(valid))
    return np.stack(imgs), roof, hazard


def used_columns(n_features: int, inputs: str) -> np.ndarray:
    """Which of the pooled vector's ``n_features`` entries the head reads: all of them, or (``parts``)
    the last 2 K, the cell logits' average and maximum over the image (the vector is the stride-16
    features' average and maximum, then the cell logits' average and maximum: ``landfall_train.net``)."""
    if inputs == "all":
        return np.arange(n_features)
    if inputs == "parts":
        return np.arange(n_features - 2 * len(CLASSES), n_features)
    raise ValueError(f"inputs must be 'parts' or 'all', got {inputs!r}")


def fit(features: np.ndarray, bare: np.ndarray, c: float, inputs: str = "parts") -> tuple[np.ndarray, float]:
    """Logistic regression of ``bare`` on the standardised ``inputs`` columns (:func:`used_columns`);
    returns weights over the whole pooled vector (zero where unread) and the bias, on the features as
    they are (the standardisation folded in)."""
    from sklearn.linear_model import LogisticRegression
    from sklearn.preprocessing import StandardScaler

    if bare.all() or not bare.any():
        raise ValueError("the views are all bare or none is: nothing to learn (render more patches)")
    cols = used_columns(features.shape[1], inputs)
    scaler = StandardScaler().fit(features[:, cols])
    reg = LogisticRegression(C=c, max_iter=5000).fit(scaler.transform(features[:, cols]), bare)
    weight = np.zeros(features.shape[1], np.float32)
    weight[cols] = reg.coef_[0] / scaler.scale_
    return weight, float(reg.intercept_[0] - (reg.coef_[0] * scaler.mean_ / scaler.scale_).sum())


def attach(model: Any, weight: np.ndarray, bias: float) -> Any:
    """A copy of ``model`` with output ``bare``: a 1 x 1 convolution of the clear head's pooled input."""
    import onnx
    from onnx import helper, numpy_helper

    out = onnx.ModelProto()
    out.CopyFrom(model)
    if BARE in {o.name for o in out.graph.output}:
        raise ValueError("the model has a bare head already")
    w = numpy_helper.from_array(weight.reshape(1, -1, 1, 1).astype(np.float32), "bare.weight")
    b = numpy_helper.from_array(np.array([bias], np.float32), "bare.bias")
    out.graph.initializer.extend([w, b])
    out.graph.node.append(
        helper.make_node("Conv", [pooled_input(model), "bare.weight", "bare.bias"], [BARE], name="bare")
    )
    out.graph.output.append(helper.make_tensor_value_info(BARE, onnx.TensorProto.FLOAT, ["n", 1, 1, 1]))
    onnx.checker.check_model(out)
    return out


def parity(model: Any, path: Path, weight: np.ndarray, bias: float) -> float:
    """Largest difference between the written model's ``bare`` (each runtime) and the regression's logit
    of the original model's pooled vector, on random images."""
    rng = np.random.default_rng(0)
    imgs = rng.integers(0, 256, (4, 96, 128, 3), dtype=np.uint8)
    want = pooled_features(model, imgs) @ weight.astype(np.float64) + bias
    worst = 0.0
    for backend in ("onnxruntime", "opencv"):
        run, _used = onnx_runner(path, backend, (*OUTPUTS, BARE))
        got = run(normalised(imgs))[2].reshape(-1)
        worst = max(worst, float(np.abs(got - want).max()))
    return worst


def rank_readings(path: Path, val: dict[str, np.ndarray], views: int) -> dict[str, np.ndarray]:
    """Per validation view, read in ``views`` views as the companion reads (probabilities averaged):
    ``clear``, ``peak`` (the likeliest hazard cell) and ``bare`` (absent for a model without the head)."""
    import onnx

    from landfall_train.ensemble import member_outputs

    run, _used = onnx_runner(path, "onnxruntime", member_outputs(onnx.load(str(path))))
    cells, clear, *bare = read_views(run, val["img"], views)
    out = {"clear": clear, "peak": cells[:, list(HAZARD_CLASSES)].max(axis=(1, 2, 3))}
    return out | ({"bare": bare[0]} if bare else {})


def held_out(
    path: Path, val: dict[str, np.ndarray], views: int, weights: Sequence[float] = ()
) -> dict[str, Any]:
    """The rank's score (lower hazard first) on validation views, read in ``views`` views: AUC over the
    views at least ``ROOF_MIN_SHARE`` roof, nothing on them against something (``auc_rank``; also the bare
    and clear probabilities alone, and the score a model without the head gives), and over all views,
    clear site or not (``auc_rank_all``: what ranking non-roofs asks). ``weights``: the same two AUCs with
    other weights of the clear-site probability (``rank_hazard``'s ``weight``)."""
    r = rank_readings(path, val, views)
    roof, hazard = roof_and_hazard(val["cells"], val["valid"])
    sel = roof >= ROOF_MIN_SHARE
    bare_ok, site_ok = ~hazard[sel], val["clear"] > 0.5
    bare = r.get("bare")

    def both(w: float | None) -> tuple[float, float]:
        score = -rank_hazard(r["clear"], r["peak"], bare, w)
        return round(_auc(score[sel], bare_ok), 4), round(_auc(score, site_ok), 4)

    out: dict[str, Any] = {"views": views, "roof_views": int(sel.sum()), "bare_views": int(bare_ok.sum())}
    out["auc_rank"], out["auc_rank_all"] = both(None)
    out["auc_rank_without_bare"] = round(_auc(-rank_hazard(r["clear"], r["peak"], None)[sel], bare_ok), 4)
    out["auc_clear"] = round(_auc(r["clear"][sel], bare_ok), 4)
    if bare is not None:
        out["auc_bare"] = round(_auc(bare[sel], bare_ok), 4)
    if weights:
        out["by_weight"] = {f"{w:g}": both(w) for w in weights}
    return out


def main(argv: Sequence[str] | None = None) -> int:
    import onnx

    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s", stream=sys.stderr)
    p = argparse.ArgumentParser(prog="python -m landfall_train.bare", description=__doc__.split("\n")[0])
    p.add_argument("--out", type=Path, required=True, help="the trained model, without suffix (rewritten)")
    p.add_argument("--seed", type=int, required=True, help="the seed the model was trained from")
    p.add_argument("--samples", type=int, default=SAMPLES, help="randomised training views read")
    p.add_argument("--C", type=float, default=1.0, help="inverse L2 strength of the regression")
    p.add_argument(
        "--inputs", choices=("parts", "all"), default="parts",
        help="what the head reads: the cell logits pooled (parts) or the stride-16 features too (all)",
    )  # fmt: skip
    p.add_argument("--rank-views", type=int, default=2, help="views per validation image (ranks read 2)")
    add_training_args(p)
    add_validation_args(p)
    args = p.parse_args(argv)
    command = "python -m landfall_train.bare " + " ".join(sys.argv[1:] if argv is None else argv)
    onnx_path, meta_path = args.out.with_suffix(".onnx"), args.out.with_suffix(".json")
    for f in (onnx_path, meta_path):
        if not f.is_file():
            p.error(f"{f}: not found (train it first: python -m landfall_train --seed {args.seed})")
    meta = json.loads(meta_path.read_text())
    if BARE in meta.get("outputs", {}):
        p.error(f"{meta_path}: the model has a bare head already")
    if meta.get("seed") != args.seed:
        p.error(f"{meta_path} was trained from seed {meta.get('seed')}, not --seed {args.seed}")
    t0 = time.monotonic()
    model = onnx.load(str(onnx_path))
    x, y, digest = patches.load_shards(training_paths(args, args.seed))
    imgs, roof, hazard = training_views(x, y, args.seed, args.samples)
    del x, y
    sel = roof >= ROOF_MIN_SHARE
    features = pooled_features(model, imgs[sel])
    try:
        weight, bias = fit(features, ~hazard[sel], args.C, args.inputs)
    except ValueError as exc:
        p.error(str(exc))
    train_auc = _auc(features @ weight.astype(np.float64) + bias, ~hazard[sel])
    with_head = attach(model, weight, bias)
    tmp = onnx_path.with_suffix(".onnx.tmp")
    onnx.save(with_head, str(tmp))
    worst = parity(model, tmp, weight, bias)
    if worst > 1e-3:
        tmp.unlink()
        raise SystemExit(
            f"the runtimes' bare logit differs from the regression's by {worst:.2e}: not written"
        )
    xv, yv, val_digest = patches.load_shards(validation_paths(args, args.seed))
    scores = held_out(tmp, validation_views(xv, yv, args.seed), args.rank_views)
    tmp.replace(onnx_path)
    meta["format"] = "landfall-landnet/2"
    meta.setdefault("outputs", {})[BARE] = DESCRIPTION
    meta[BARE] = {
        "command": command, "samples": len(imgs), "fitted_views": int(sel.sum()),
        "bare_views": int((~hazard[sel]).sum()), "roof_min_share": ROOF_MIN_SHARE, "C": args.C,
        "inputs": args.inputs,
        "train_auc": round(train_auc, 4), "held_out": scores, "train_digest": digest,
        "val_digest": val_digest, "seconds": round(time.monotonic() - t0, 1), "commit": _commit(),
    }  # fmt: skip
    meta["parity_max_abs_diff"] = max(float(meta.get("parity_max_abs_diff", 0.0)), float(f"{worst:.2e}"))
    meta["onnx_bytes"] = onnx_path.stat().st_size
    meta["sha256"] = hashlib.sha256(onnx_path.read_bytes()).hexdigest()
    meta_path.write_text(json.dumps(meta, indent=2) + "\n")
    _log.info("wrote %s with its bare head: held-out AUC rank %.4f (without the head %.4f), %.0f s",
              onnx_path, scores["auc_rank"], scores["auc_rank_without_bare"],
              time.monotonic() - t0)  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
