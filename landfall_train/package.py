"""A trained LandNet model into the companion's package, its weights stored at half precision.

``python -m landfall_train.package runs/landnet-e/landnet-e`` writes ``landnet-e.onnx``, its whole read
(``landnet-e-whole.onnx``, when the sidecar names one) and ``landnet-e.json`` into
``companion/reasoning/models/`` (``--into`` elsewhere), ready for ``onboard_model = "landnet-e"``.

**Half the bytes, the same arithmetic.** Every float32 weight of more than ``MIN_ELEMENTS`` values is
stored as float16 and turned back into float32 by a ``Cast`` node in front of the graph: the files are
half the size (LandNet-E and its whole read: 13.5 MB each to 6.8 MB), and both ONNX Runtime (which
folds the casts into constants when it loads the model) and OpenCV's DNN module compute in float32 as
before, at the same speed. Rounding the weights moves the outputs a little: the largest difference of
a logit over random inputs goes into the sidecar (``storage.parity_max_abs_diff``; LandNet-E: 0.056);
on the photographs of realimages and realimages-train no decision changed and no stated probability
moved by more than 0.01 (docs/reasoning.md).
``--full`` copies the float32 files unchanged.

The sidecar keeps everything training wrote, with each file's new sha256 (which
:meth:`companion.reasoning.landnet.LandNet.load` checks) and a ``storage`` entry saying how the weights
are kept.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import shutil
import sys
from pathlib import Path
from typing import Any

import numpy as np

MODELS = Path(__file__).resolve().parent.parent / "companion" / "reasoning" / "models"
MIN_ELEMENTS = 64  # smaller tensors (biases of a few channels, scalars) stay float32
PARITY_INPUTS = 4  # random inputs each model's float16 copy is checked on


def halve(src: Path, dst: Path) -> int:
    """Write the ONNX model at ``src`` to ``dst`` with its float32 initializers of at least
    ``MIN_ELEMENTS`` values stored as float16 behind a ``Cast`` to float32; the number of tensors
    halved."""
    import onnx
    from onnx import TensorProto, helper, numpy_helper

    model = onnx.load(str(src))
    graph = model.graph
    kept, casts = [], []
    for init in graph.initializer:
        values = numpy_helper.to_array(init)
        if values.dtype != np.float32 or values.size < MIN_ELEMENTS:
            kept.append(init)
            continue
        half = numpy_helper.from_array(values.astype(np.float16), f"{init.name}__f16")
        kept.append(half)
        casts.append(helper.make_node("Cast", [half.name], [init.name], to=TensorProto.FLOAT))
    nodes = list(graph.node)
    del graph.initializer[:]
    graph.initializer.extend(kept)
    del graph.node[:]
    graph.node.extend(casts + nodes)  # the casts first: the graph stays in topological order
    onnx.checker.check_model(model)
    onnx.save(model, str(dst))
    return len(casts)


def halved(src: Path) -> bool:
    """Whether the ONNX model at ``src`` already keeps its weights as :func:`halve` writes them (a
    packaged model whose whole read is fitted again is packaged again: its net is copied as it is, and
    the float16 parity measured when it was first packaged stays in the sidecar)."""
    import onnx

    model = onnx.load(str(src), load_external_data=False)
    return any(init.name.endswith("__f16") for init in model.graph.initializer)


def parity(a: Path, b: Path, shape: tuple[int, ...], seed: int = 0) -> float:
    """The largest absolute difference between the outputs of the ONNX models ``a`` and ``b`` (ONNX
    Runtime, one thread) over ``PARITY_INPUTS`` random inputs of ``shape``, values as normalised
    images have them."""
    import onnxruntime as ort

    opts = ort.SessionOptions()
    opts.intra_op_num_threads = 1
    sessions = [ort.InferenceSession(str(p), opts, providers=["CPUExecutionProvider"]) for p in (a, b)]
    name = sessions[0].get_inputs()[0].name
    rng = np.random.default_rng(seed)
    worst = 0.0
    for _ in range(PARITY_INPUTS):
        x = rng.normal(0.0, 1.0, shape).astype(np.float32)
        out_a, out_b = (s.run(None, {name: x}) for s in sessions)
        worst = max(worst, *(float(np.abs(p - q).max()) for p, q in zip(out_a, out_b, strict=True)))
    return worst


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def package(model: Path, into: Path, *, full: bool = False) -> dict[str, Any]:
    """``model`` (``MODEL.onnx`` beside ``MODEL.json``, with its whole read if the sidecar names one)
    into the folder ``into``; returns the sidecar written there.

    Raises:
        FileNotFoundError: a file the sidecar needs is missing.
    """
    onnx_path, meta_path = model.with_suffix(".onnx"), model.with_suffix(".json")
    for p in (onnx_path, meta_path):
        if not p.is_file():
            raise FileNotFoundError(f"{p}: not found (train it first: make model-e)")
    meta: dict[str, Any] = json.loads(meta_path.read_text())
    into.mkdir(parents=True, exist_ok=True)
    side = int(meta["input"]["short_side_px"])
    files = [(onnx_path, (1, 3, side, side), meta)]
    whole = meta.get("whole_read")
    if whole:
        whole_path = model.parent / whole["file"]
        if not whole_path.is_file():
            raise FileNotFoundError(f"{whole_path}: the whole read the sidecar names is not there")
        files.append((whole_path, (1, 3, int(whole["side_px"]), int(whole["side_px"])), whole))
    earlier = meta.get("storage", {})
    diffs = []
    for src, shape, entry in files:
        dst = into / src.name
        if full:
            shutil.copyfile(src, dst)
        elif halved(src):  # a packaged file packaged again: as it is, with the parity it was packaged at
            shutil.copyfile(src, dst)
            diffs.append(float(earlier.get("parity_max_abs_diff", 0.0)))
        else:
            halve(src, dst)
            diffs.append(parity(src, dst, shape))
        entry["sha256"] = _sha256(dst)
    meta["onnx_bytes"] = (into / onnx_path.name).stat().st_size
    meta["storage"] = (
        {"weights": "float32"}
        if full
        else {
            "weights": "float16, cast to float32 when the model loads",
            "min_elements": MIN_ELEMENTS,
            "parity_max_abs_diff": round(max(diffs), 6),
            "command": "python -m landfall_train.package " + " ".join(sys.argv[1:]),
        }
    )
    (into / meta_path.name).write_text(json.dumps(meta, indent=2) + "\n")
    return meta


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("model", type=Path, help="the trained model, no suffix: e.g. runs/landnet-e/landnet-e")
    ap.add_argument("--into", type=Path, default=MODELS, help=f"where to write it (default {MODELS})")
    ap.add_argument("--full", action="store_true", help="copy the float32 weights unchanged")
    args = ap.parse_args(argv)
    try:
        meta = package(args.model, args.into, full=args.full)
    except FileNotFoundError as exc:
        print(f"landfall_train.package: {exc}", file=sys.stderr)
        return 2
    sizes = ", ".join(
        f"{p.name} {p.stat().st_size / 1e6:.1f} MB" for p in sorted(args.into.glob(f"{args.model.name}*"))
    )
    print(f"packaged into {args.into}: {sizes}; storage {meta['storage']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
