"""LandNet-E's cells learnt again from every kind of place and from high up: a second cell head for ranks.

LandNet-E's cells learnt from downtown cities and vignettes seen at 3-25 cm per pixel. A rank from 110 m
and the search's reading of its frames see the ground at 0.2-0.6 m per pixel, where those cells took
rendered water for roof: with a camera and no LiDAR the search proposed the harbour and the rank put it
first. Its confirmations were chosen on the photographs' source folds, and they read the first head's
cells (the water and marking vetoes) and the clear site, which reads the cells' pooled logits. So the
cells are learnt again **beside** them:

- a second head, the same layers as the first (1 x 1 projections of blocks 4 and 10, a depthwise-
  separable 3 x 3 fusion, one logit per class and cell), reads the same frozen backbone and is a new
  output, ``cells_rank`` (:data:`companion.reasoning.landnet.RANK_CELLS`), which ranks and the search's
  camera read (the sidecar's ``rank_cells`` names it and its thresholds); it starts from the first
  head's weights;
- the first head's ``cells`` and the ``clear`` output stay exactly as they were
  (:func:`check_unchanged`): every confirmation reads what the folds measured;
- it learns from downtown cities and vignettes as before and from every kind of place
  (:func:`landfall_train.patches.render_place`: suburb, industrial estate, farmland, waterfront,
  hillside, town, downtown) seen at 5-60 cm per pixel, water more often.

A second head in the confirmations' place was tried first: its water and marking cells refused 15 more
clear roofs among realimages-train2's photographs (26 of 76 against 11), so confirmations keep the first.

The backbone's features of each randomised view are read once by ONNX Runtime from the model as the
companion loads it; the head then learns over them for ``--epochs`` passes (a few minutes on a CPU).
Thresholds per class are calibrated on held-out renders (other seeds of every kind, downtown cities and
vignettes), as the first head's were, and the figures before and after are written into the sidecar.

``python -m landfall_train.cells_head --model runs/landnet-e/landnet-e --out runs/landnet-e/cells/landnet-e``
(``make model-e``'s last step; ``--model`` may name a packaged first-head model too: its float16 weights
are made float32 again, exactly) then ``python -m landfall_train.package runs/landnet-e/cells/landnet-e``
(``make model-e-package``) puts it on the vehicle.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import logging
import shutil
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from companion.reasoning.landnet import RANK_CELLS, onnx_runner
from landfall_train import patches
from landfall_train.augment import augment, targets
from landfall_train.labels import CLASSES, CROP
from landfall_train.train import (
    INPUT_PX,
    POS_WEIGHT,
    TRAIN_SEEDS,
    VAL_FIRST_VIGNETTE,
    VAL_SEEDS,
    _ap,
    _best_f1,
    _commit,
    cache_dir,
)

_log = logging.getLogger("landfall_train.cells_head")

MODEL = Path("runs/landnet-e/landnet-e")  # make model-e's; the packaged file of 2026-12-02 served too
S8, S16 = "/_blocks.4/Add_output_0", "/_blocks.10/Add_output_0"  # the first head's inputs in the graph
FIRST_CELLS = "/cells/Conv"  # the first head's last node
PREFIX = "cells2."  # the second head's nodes and weights
PLACES = ("downtown", "suburb", "industrial", "farmland", "waterfront", "hillside", "town")
PLACE_SEEDS = (100, 101, 102, 103)
VAL_PLACE_SEEDS = (900, 901)
CITIES = 16  # of TRAIN_SEEDS
VIGNETTES = 300
VEGETATION = CLASSES.index("low_vegetation")
HIGH_GSD_M = 0.25  # views at least this coarse are "high up" in the figures


def unhalved(path: Path) -> Any:
    """The ONNX model at ``path`` with float16 initializers behind casts (landfall_train.package) made
    float32 initializers again (float16 to float32 is exact: halving them again gives the same bytes)."""
    import onnx
    from onnx import numpy_helper

    model = onnx.load(str(path))
    graph = model.graph
    halves = {i.name: i for i in graph.initializer if i.name.endswith("__f16")}
    casts = [n for n in graph.node if n.op_type == "Cast" and len(n.input) == 1 and n.input[0] in halves]
    kept = [i for i in graph.initializer if i.name not in halves]
    for n in casts:
        kept.append(
            numpy_helper.from_array(numpy_helper.to_array(halves[n.input[0]]).astype(np.float32), n.output[0])
        )
    nodes = [n for n in graph.node if n not in casts]
    del graph.initializer[:]
    graph.initializer.extend(kept)
    del graph.node[:]
    graph.node.extend(nodes)
    onnx.checker.check_model(model)
    return model


def without_rank_cells(model: Any) -> Any:
    """``model`` with a second cell head grafted earlier (:func:`graft`) taken out: its nodes, weights
    and output; a model without one comes back as it was."""
    graph = model.graph
    nodes = [n for n in graph.node if not n.name.startswith(PREFIX)]
    inits = [i for i in graph.initializer if not i.name.startswith(PREFIX)]
    outputs = [o for o in graph.output if o.name != RANK_CELLS]
    for field, kept in ((graph.node, nodes), (graph.initializer, inits), (graph.output, outputs)):
        del field[:]
        field.extend(kept)
    return model


def first_head(model: Any) -> dict[str, np.ndarray]:
    """The first cell head's weights, by the layer names :class:`CellHead` uses."""
    from onnx import numpy_helper

    by_name = {i.name: numpy_helper.to_array(i) for i in model.graph.initializer}
    return {
        f"{layer}.{kind}": by_name[f"{layer}.{kind}"]
        for layer in ("proj8", "proj16", "fuse_dw", "fuse_pw", "cells")
        for kind in ("weight", "bias")
    }


def feature_reader(model: Any, threads: int) -> Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]:
    """The backbone up to blocks 4 and 10 cut out of ``model`` and run by ONNX Runtime: normalised NCHW
    float32 to (stride-8, stride-16) features."""
    import onnx
    import onnxruntime as ort

    with tempfile.TemporaryDirectory() as tmp:
        full, cut = Path(tmp) / "model.onnx", Path(tmp) / "features.onnx"
        onnx.save(model, str(full))
        onnx.utils.extract_model(str(full), str(cut), ["image"], [S8, S16])
        options = ort.SessionOptions()
        options.intra_op_num_threads = threads
        options.inter_op_num_threads = 1
        session = ort.InferenceSession(str(cut), options, providers=["CPUExecutionProvider"])

    def read(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        s8, s16 = session.run(None, {"image": x})
        return s8, s16

    return read


def cell_head(first: dict[str, np.ndarray]) -> Any:
    """A :class:`CellHead` started from the first head's weights."""
    import torch

    head = CellHead(len(CLASSES))
    head.load_state_dict({k: torch.from_numpy(np.array(v)) for k, v in first.items()}, strict=True)
    return head


def _torch_module() -> Any:
    import torch
    from torch import nn

    from landfall_train.effnet import CELL_CHANNELS, LandNetE

    class _CellHead(nn.Module):  # type: ignore[misc]
        """LandNet-E's cell head alone (:meth:`landfall_train.effnet.LandNetE.heads`' first half)."""

        def __init__(self, classes: int) -> None:
            super().__init__()
            ref = LandNetE(1)
            c = CELL_CHANNELS
            self.proj8, self.proj16, self.up = ref.proj8, ref.proj16, ref.up
            self.fuse_dw, self.fuse_pw = ref.fuse_dw, ref.fuse_pw
            self.cells = nn.Conv2d(c, classes, 1)

        def forward(self, s8: torch.Tensor, s16: torch.Tensor) -> torch.Tensor:
            f = nn.functional.relu6(self.up(self.proj16(s16)) + self.proj8(s8))
            f = nn.functional.relu6(self.fuse_pw(nn.functional.relu6(self.fuse_dw(f))))
            return self.cells(f)

    return _CellHead


def CellHead(classes: int) -> Any:
    return _torch_module()(classes)


def graft(model: Any, head: dict[str, np.ndarray], classes: int) -> Any:
    """``model`` with a second cell head (weights ``head``, by :class:`CellHead`'s names) as a new
    output, ``cells_rank`` (:data:`companion.reasoning.landnet.RANK_CELLS`); the first head's ``cells``
    and ``clear`` outputs stay as they were. The new nodes copy the first head's attributes (padding,
    groups, resize mode), so they compute what PyTorch does."""
    import copy

    import onnx
    from onnx import helper, numpy_helper

    graph = model.graph
    by_name = {n.name: n for n in graph.node}
    p = PREFIX
    inits = [numpy_helper.from_array(np.asarray(v, np.float32), p + k) for k, v in head.items()]
    inits += [
        numpy_helper.from_array(np.array([1.0, 1.0, 2.0, 2.0], np.float32), p + "scales"),
        numpy_helper.from_array(np.array(0.0, np.float32), p + "zero"),
        numpy_helper.from_array(np.array(6.0, np.float32), p + "six"),
    ]

    def like(ref: str, inputs: list[str], out: str) -> Any:
        src = by_name[ref]
        node = helper.make_node(src.op_type, inputs, [out], name=p + ref.strip("/").replace("/", "."))
        node.attribute.extend(src.attribute)
        return node

    def clip(x: str, out: str) -> Any:
        return helper.make_node("Clip", [x, p + "zero", p + "six"], [out], name=p + out)

    nodes = [
        like("/proj16/Conv", [S16, p + "proj16.weight", p + "proj16.bias"], p + "p16"),
        like("/up/Resize", [p + "p16", "", p + "scales"], p + "up"),
        like("/proj8/Conv", [S8, p + "proj8.weight", p + "proj8.bias"], p + "p8"),
        helper.make_node("Add", [p + "up", p + "p8"], [p + "sum"], name=p + "add"),
        clip(p + "sum", p + "f0"),
        like("/fuse_dw/Conv", [p + "f0", p + "fuse_dw.weight", p + "fuse_dw.bias"], p + "dw"),
        clip(p + "dw", p + "f1"),
        like("/fuse_pw/Conv", [p + "f1", p + "fuse_pw.weight", p + "fuse_pw.bias"], p + "pw"),
        clip(p + "pw", p + "f2"),
        like(FIRST_CELLS, [p + "f2", p + "cells.weight", p + "cells.bias"], RANK_CELLS),
    ]
    graph.initializer.extend(inits)
    # topological order: the new nodes after the last one they read from (block 10's output)
    at = max(k for k, n in enumerate(graph.node) if S16 in n.output) + 1
    for k, node in enumerate(nodes):
        graph.node.insert(at + k, node)
    first = next(o for o in graph.output if o.name == "cells")
    out = copy.deepcopy(first)
    out.name = RANK_CELLS
    dims = out.type.tensor_type.shape.dim
    if len(dims) > 1:
        dims[1].ClearField("dim_param")
        dims[1].dim_value = classes
    graph.output.append(out)
    onnx.checker.check_model(model)
    return model


# --- renders and views ---------------------------------------------------------------------------


def shards(args: argparse.Namespace, validation: bool) -> list[Path]:
    """The renders' shards (rendered when not cached under ``args.cache``): downtown cities, vignettes
    and every kind of place; their validation counterparts on seeds no training view comes from."""
    cache, w = cache_dir(args.cache, 0), args.workers
    if validation:
        cities = VAL_SEEDS[: args.val_cities]
        city_dir, per_city = cache / f"val-{args.val_per_city}", args.val_per_city
        first, count, vignette_dir = (
            VAL_FIRST_VIGNETTE,
            args.val_vignettes,
            f"val-vignettes-{args.per_vignette}",
        )
        seeds, per_place = VAL_PLACE_SEEDS, args.val_per_place
    else:
        cities = TRAIN_SEEDS[: args.cities]
        city_dir, per_city = cache / f"train-{args.per_city}", args.per_city
        first, count, vignette_dir = 0, args.vignettes, f"vignettes-{args.per_vignette}"
        seeds, per_place = args.place_seeds, args.per_place
    return (
        patches.generate(city_dir, cities, per_city, 0, w)
        + patches.generate_vignettes(cache / vignette_dir, first, count, args.per_vignette, 0, w)
        + patches.generate_places(cache / "places", args.places, seeds, per_place, 0, w)
    )


def load(paths: Sequence[Path]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, str]:
    """Patches, class maps, each patch's ground resolution and whether it comes from a kind of place;
    the digest of their bytes."""
    x, y, digest = patches.load_shards(paths)
    gsd, place = [], []
    for p in paths:
        with np.load(p) as z:
            meta = json.loads(str(z["meta"]))
        gsd += [float(m["gsd_m"]) for m in meta]
        place += [p.parent.name == "places"] * len(meta)
    return x, y, np.array(gsd, np.float32), np.array(place, bool), digest


def views(
    x: np.ndarray, y: np.ndarray, n: int, seed: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``n`` randomised views (patch ``k % len(x)``, each its own stream): images, cell targets over
    ``CLASSES`` (standing crops, which the kinds of place label apart, are ``low_vegetation`` here as
    they were for the first head), cell validity, and which patch each came from."""
    k = len(CLASSES)
    imgs = np.empty((n, INPUT_PX, INPUT_PX, 3), np.uint8)
    cells = np.empty((n, k, INPUT_PX // 8, INPUT_PX // 8), np.uint8)
    valid = np.empty((n, INPUT_PX // 8, INPUT_PX // 8), np.uint8)
    src = np.arange(n) % len(x)
    for i in range(n):
        img, lab = augment(x[src[i]], y[src[i]], np.random.default_rng([seed, 77, i]), INPUT_PX)
        lab[lab == CROP] = VEGETATION
        c, v, _ = targets(lab, classes=k)
        imgs[i], cells[i], valid[i] = img, c, v
    return imgs, cells, valid, src


def features(
    read: Callable[..., tuple[np.ndarray, np.ndarray]], imgs: np.ndarray, batch: int = 64
) -> tuple[np.ndarray, np.ndarray]:
    """The backbone's features of every image (float16 to halve the memory)."""
    from landfall_train.effnet import IMAGENET_MEAN, IMAGENET_STD
    from landfall_train.train import normalised

    s8s, s16s = [], []
    t0 = time.monotonic()
    for start in range(0, len(imgs), batch):
        s8, s16 = read(normalised(imgs[start : start + batch], (IMAGENET_MEAN, IMAGENET_STD)))
        s8s.append(s8.astype(np.float16))
        s16s.append(s16.astype(np.float16))
        if (start // batch) % 50 == 0:
            _log.info("features %d/%d (%.0f s)", start + len(s8), len(imgs), time.monotonic() - t0)
    return np.concatenate(s8s), np.concatenate(s16s)


# --- training and figures ------------------------------------------------------------------------


def fit(
    head: Any, s8: np.ndarray, s16: np.ndarray, cells: np.ndarray, valid: np.ndarray, args: argparse.Namespace
) -> Any:
    """The head learnt over the features for ``args.epochs`` passes (AdamW, cosine decay), each cell's
    loss weighted per class as LandNet-E's first head was."""
    import torch

    torch.manual_seed(args.seed)
    torch.set_num_threads(args.threads)
    pos = torch.tensor([POS_WEIGHT.get(c, 1.0) for c in CLASSES]).view(1, -1, 1, 1)
    opt = torch.optim.AdamW(head.parameters(), lr=args.lr, weight_decay=1e-4)
    n = len(s8)
    steps = args.epochs * (n // args.batch)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, steps)
    rng = np.random.default_rng(args.seed)
    head.train()
    t0, step = time.monotonic(), 0
    for epoch in range(args.epochs):
        order = rng.permutation(n)
        total = 0.0
        for start in range(0, n - args.batch + 1, args.batch):
            idx = np.sort(order[start : start + args.batch])
            logits = head(
                torch.from_numpy(s8[idx].astype(np.float32)), torch.from_numpy(s16[idx].astype(np.float32))
            )
            v = torch.from_numpy(valid[idx].astype(np.float32))[:, None]
            bce = torch.nn.functional.binary_cross_entropy_with_logits(
                logits, torch.from_numpy(cells[idx].astype(np.float32)), pos_weight=pos, reduction="none"
            )
            loss = (bce * v).sum() / (v.sum() * len(CLASSES)).clamp(min=1.0)
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            sched.step()
            total += float(loss.detach())
            step += 1
        _log.info("epoch %d/%d loss %.4f (%.0f s)", epoch + 1, args.epochs, total / max(1, n // args.batch),
                  time.monotonic() - t0)  # fmt: skip
    head.eval()
    return head


def cell_probabilities(
    predict: Callable[[np.ndarray], np.ndarray], imgs: np.ndarray, batch: int = 64
) -> np.ndarray:
    """Each view's cell probabilities from ``predict`` (NHWC uint8 to cell logits)."""
    out = [predict(imgs[s : s + batch]) for s in range(0, len(imgs), batch)]
    return 1.0 / (1.0 + np.exp(-np.concatenate(out).astype(np.float64)))


def figures(
    p: np.ndarray, cells: np.ndarray, valid: np.ndarray, mask: np.ndarray, names: Sequence[str]
) -> dict[str, Any]:
    """Average precision, best F1 and its threshold per class over the views in ``mask``."""
    out: dict[str, Any] = {}
    v = valid[mask] > 0
    for k, name in enumerate(names):
        prob = p[mask][:, k][v]
        truth = cells[mask][:, k][v] > 0
        if not truth.any():
            continue
        thr, f1 = _best_f1(prob, truth)
        out[name] = {"ap": round(_ap(prob, truth), 4), "f1": round(f1, 4), "threshold": round(thr, 4),
                     "prevalence": round(float(truth.mean()), 4)}  # fmt: skip
    return out


def onnx_cells(path: Path, output: str = "cells") -> Callable[[np.ndarray], np.ndarray]:
    """NHWC uint8 views to the model's ``output`` cell logits, read as the companion reads the file
    (:func:`companion.reasoning.landnet.onnx_runner`)."""
    from landfall_train.effnet import IMAGENET_MEAN, IMAGENET_STD
    from landfall_train.train import normalised

    run, _backend = onnx_runner(path, "onnxruntime", (output,))
    return lambda imgs: run(normalised(imgs, (IMAGENET_MEAN, IMAGENET_STD)))[0]


def check_unchanged(a: Path, b: Path) -> float:
    """The largest difference between two models' ``cells`` and ``clear`` logits over random inputs at
    the sizes the companion reads (the second head must leave the first's outputs exactly as they were)."""
    rng = np.random.default_rng(0)
    runs = [onnx_runner(p, "onnxruntime", ("cells", "clear"))[0] for p in (a, b)]
    worst = 0.0
    for shape in ((1, 3, 128, 128), (4, 3, 96, 96), (1, 3, 144, 256)):
        x = rng.normal(0.0, 1.0, shape).astype(np.float32)
        ra, rb = (run(x) for run in runs)
        worst = max(worst, *(float(np.abs(u - v).max()) for u, v in zip(ra, rb, strict=True)))
    return worst


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m landfall_train.cells_head", description=(__doc__ or "").splitlines()[0]
    )
    p.add_argument(
        "--model", type=Path, default=MODEL, help=f"the LandNet-E to read again, no suffix (default {MODEL})"
    )
    p.add_argument(
        "--out", type=Path, required=True, help="the new model, no suffix: e.g. runs/landnet-e2/landnet-e"
    )
    p.add_argument("--cache", type=Path, default=Path("runs/train-cache"), help="rendered patches")
    p.add_argument(
        "--places", type=lambda s: tuple(s.split(",")), default=PLACES, help="kinds of place, comma-separated"
    )
    p.add_argument("--place-seeds", type=lambda s: tuple(int(v) for v in s.split(",")), default=PLACE_SEEDS)
    p.add_argument("--per-place", type=int, default=200)
    p.add_argument("--val-per-place", type=int, default=100)
    p.add_argument(
        "--cities", type=int, default=CITIES, help="downtown cities of TRAIN_SEEDS (400 m, as before)"
    )
    p.add_argument("--per-city", type=int, default=200)
    p.add_argument("--vignettes", type=int, default=VIGNETTES)
    p.add_argument("--per-vignette", type=int, default=20)
    p.add_argument("--val-cities", type=int, default=2)
    p.add_argument("--val-per-city", type=int, default=150)
    p.add_argument("--val-vignettes", type=int, default=40)
    p.add_argument("--views", type=int, default=3, help="randomised views of each training patch")
    p.add_argument("--epochs", type=int, default=16)
    p.add_argument("--batch", type=int, default=64)
    p.add_argument("--lr", type=float, default=1e-3)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--workers", type=int, default=2, help="processes rendering patches")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s", stream=sys.stderr)
    args = build_parser().parse_args(argv)
    command = "python -m landfall_train.cells_head " + " ".join(sys.argv[1:] if argv is None else argv)
    src_onnx, src_meta = args.model.with_suffix(".onnx"), args.model.with_suffix(".json")
    if not src_onnx.is_file() or not src_meta.is_file():
        print(f"cells_head: {src_onnx} and its sidecar are needed", file=sys.stderr)
        return 2
    meta = json.loads(src_meta.read_text())
    if meta.get("classes") != list(CLASSES):
        print(
            f"cells_head: {src_onnx} is not a first-head LandNet-E (classes {meta.get('classes')})",
            file=sys.stderr,
        )
        return 2
    t0 = time.monotonic()
    _log.info("rendering (or reading cached) training and validation patches")
    train_x, train_y, _g, _pl, digest = load(shards(args, validation=False))
    val_x, val_y, val_gsd, val_place, val_digest = load(shards(args, validation=True))
    render_s = time.monotonic() - t0
    _log.info("%d training patches, %d validation patches (%.0f s)", len(train_x), len(val_x), render_s)

    base = without_rank_cells(unhalved(src_onnx))
    read = feature_reader(base, args.threads)
    imgs, cells, valid, _src = views(train_x, train_y, args.views * len(train_x), args.seed)
    del train_x, train_y
    s8, s16 = features(read, imgs)
    del imgs
    k = len(CLASSES)
    head = fit(cell_head(first_head(base)), s8, s16, cells, valid, args)
    del s8, s16
    train_s = time.monotonic() - t0 - render_s
    state = {name: t.detach().numpy() for name, t in head.state_dict().items()}

    args.out.parent.mkdir(parents=True, exist_ok=True)
    out_onnx = args.out.with_suffix(".onnx")
    import onnx

    onnx.save(graft(without_rank_cells(unhalved(src_onnx)), state, k), str(out_onnx))
    unchanged = check_unchanged(src_onnx, out_onnx)
    if unchanged > 1e-5:
        raise RuntimeError(f"the second head moved the first head's outputs by {unchanged:.2e}")

    vimgs, vcells, vvalid, vsrc = views(val_x, val_y, len(val_x), args.seed + 1)
    high = val_gsd[vsrc] >= HIGH_GSD_M
    place = val_place[vsrc]
    before = cell_probabilities(onnx_cells(src_onnx), vimgs)
    after = cell_probabilities(onnx_cells(out_onnx, RANK_CELLS), vimgs)
    every = np.ones(len(vimgs), bool)
    report: dict[str, Any] = {
        "before": {
            "all": figures(before, vcells, vvalid, every, CLASSES),
            "high_up": figures(before, vcells, vvalid, high, CLASSES),
            "places": figures(before, vcells, vvalid, place, CLASSES),
        },
        "after": {
            "all": figures(after, vcells, vvalid, every, CLASSES),
            "high_up": figures(after, vcells, vvalid, high, CLASSES),
            "places": figures(after, vcells, vvalid, place, CLASSES),
        },
        "views": {"all": int(every.sum()), "high_up": int(high.sum()), "places": int(place.sum())},
    }
    thresholds = {name: f["threshold"] for name, f in report["after"]["all"].items()}
    missing = [c for c in CLASSES if c not in thresholds]
    if missing:
        raise RuntimeError(f"no validation view holds {missing}: render more validation patches")
    meta = {k: v for k, v in meta.items() if k != "rank_cells"}
    meta["architecture"] = meta["architecture"].split("; a second cell head")[0]
    meta["architecture"] += (
        "; a second cell head (every kind of place, from high up) for ranks and the search"
    )
    meta["rank_cells"] = {
        "output": RANK_CELLS, "thresholds": thresholds,
        "command": command, "from": str(args.model), "commit": _commit(), "render_digest": digest,
        "val_digest": val_digest, "train_patches": int(len(cells) // max(1, args.views)),
        "views": len(cells), "epochs": args.epochs, "lr": args.lr, "batch": args.batch,
        "places": list(args.places), "place_seeds": list(args.place_seeds),
        "val_place_seeds": list(VAL_PLACE_SEEDS), "high_up_gsd_m": HIGH_GSD_M,
        "first_head_max_abs_diff": unchanged, "render_s": round(render_s, 1), "train_s": round(train_s, 1),
        "figures": report,
    }  # fmt: skip
    meta.pop("sha256", None)
    meta.pop("storage", None)
    meta["sha256"] = hashlib.sha256(out_onnx.read_bytes()).hexdigest()
    meta["onnx_bytes"] = out_onnx.stat().st_size
    whole = meta.get("whole_read")
    if whole:
        shutil.copyfile(args.model.parent / whole["file"], args.out.parent / whole["file"])
    args.out.with_suffix(".json").write_text(json.dumps(meta, indent=2) + "\n")
    for part in ("all", "high_up", "places"):
        for name in ("water", "roof", "road", "marking"):
            b = report["before"][part].get(name, {}).get("ap")
            a = report["after"][part].get(name, {}).get("ap")
            _log.info("%s %s: AP %s -> %s", part, name, b, a)
    _log.info("wrote %s (%.0f s)", out_onnx, time.monotonic() - t0)
    return 0


if __name__ == "__main__":
    sys.exit(main())
