"""Merge trained LandNet models into one ONNX model whose outputs are the mean of theirs.

``python -m landfall_train.ensemble --out OUT MEMBER.onnx MEMBER.onnx [...]`` writes ``OUT.onnx`` (one
graph: every member reads the same image, each output's logits are averaged: ``cells`` and ``clear``,
and ``bare`` where every member has its bare head, ``landfall_train.bare``) and a sidecar
``OUT.json`` taken from the first member's, with ``members`` naming each member's file, sha256, seed and
training data. ONNX Runtime and OpenCV's DNN module must both give the members' mean on random inputs,
or nothing is written. The thresholds are the first member's until ``python -m landfall_train
--recalibrate --out OUT`` calibrates the merged model on the held-out renders (``make model`` does both).

Members trained from other seeds see other patches and other randomisations: where one member is unsure
on imagery unlike the renders, the other often is not, and their mean ranks more steadily. The merged
model costs as many forward passes as it has members; the companion's code is unchanged (one ONNX file).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import logging
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from companion.reasoning.landnet import BARE, OUTPUTS

_log = logging.getLogger("landfall_train.ensemble")


def merge(members: Sequence[Path]) -> Any:
    """One ONNX ModelProto: each member's graph under its own name prefix, fed by one ``image`` input,
    each output (``cells``, ``clear``, and ``bare`` where the members have it) the mean of the members'."""
    import onnx
    from onnx import compose, helper

    if len(members) < 2:
        raise ValueError("an ensemble needs at least two members")
    models = [onnx.load(str(p)) for p in members]
    opsets = {m.opset_import[0].version for m in models}
    if len(opsets) != 1:
        raise ValueError(f"members use different ONNX opsets: {sorted(opsets)}")
    nodes: list[Any] = []
    inits: list[Any] = []
    outputs = member_outputs(models[0])
    for k, m in enumerate(models):
        names = [i.name for i in m.graph.input]
        outs = [o.name for o in m.graph.output]
        if names[:1] != ["image"] or outs != list(outputs) or tuple(outs[:2]) != OUTPUTS:
            raise ValueError(
                f"{members[k]}: expected input 'image' and outputs {list(outputs)} (as the first member's), "
                f"got {names} {outs}"
            )
        m = compose.add_prefix(m, f"m{k}/")
        nodes.append(helper.make_node("Identity", ["image"], [f"m{k}/image"], name=f"m{k}/feed"))
        nodes.extend(m.graph.node)
        inits.extend(m.graph.initializer)
    scale = helper.make_tensor("ensemble/scale", onnx.TensorProto.FLOAT, [], [1.0 / len(models)])
    inits.append(scale)
    for out in outputs:
        total = f"m0/{out}"
        for k in range(1, len(models)):
            nxt = f"ensemble/{out}_sum{k}"
            nodes.append(helper.make_node("Add", [total, f"m{k}/{out}"], [nxt], name=nxt))
            total = nxt
        nodes.append(helper.make_node("Mul", [total, "ensemble/scale"], [out], name=f"ensemble/{out}"))
    first = models[0].graph
    graph = helper.make_graph(
        nodes, "landnet-ensemble", list(first.input), list(first.output), initializer=inits
    )
    model = helper.make_model(graph, opset_imports=list(models[0].opset_import))
    model.ir_version = models[0].ir_version
    onnx.checker.check_model(model)
    return model


def member_outputs(model: Any) -> tuple[str, ...]:
    """A member's outputs: ``OUTPUTS``, with ``bare`` after them where it has the bare head."""
    outs = tuple(o.name for o in model.graph.output)
    return (*OUTPUTS, BARE) if outs == (*OUTPUTS, BARE) else OUTPUTS


def parity(members: Sequence[Path], merged: Path) -> float:
    """Largest absolute difference between the merged model and the mean of its members, through each
    runtime the companion may use (ONNX Runtime and OpenCV's DNN module)."""
    import onnx

    from companion.reasoning.landnet import onnx_runner

    outputs = member_outputs(onnx.load(str(merged)))
    rng = np.random.default_rng(0)
    worst = 0.0
    for backend in ("onnxruntime", "opencv"):
        nets = [onnx_runner(p, backend, outputs)[0] for p in members]
        whole = onnx_runner(merged, backend, outputs)[0]
        for shape in ((1, 3, 128, 128), (4, 3, 96, 160), (2, 3, 256, 128)):
            x = rng.normal(0.0, 1.0, shape).astype(np.float32)
            outs = [net(x) for net in nets]
            got = whole(x)
            for i in range(len(outputs)):
                ref = np.mean([o[i].reshape(got[i].shape) for o in outs], axis=0)
                worst = max(worst, float(np.abs(got[i] - ref).max()))
    return worst


def main(argv: Sequence[str] | None = None) -> int:
    import onnx

    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s", stream=sys.stderr)
    p = argparse.ArgumentParser(prog="python -m landfall_train.ensemble", description=__doc__.split("\n")[0])
    p.add_argument("members", nargs="+", type=Path, help="member ONNX files, each with its .json sidecar")
    p.add_argument("--out", type=Path, required=True, help="model path without suffix (.onnx and .json)")
    args = p.parse_args(argv)
    for m in args.members:
        for f in (m, m.with_suffix(".json")):
            if not f.is_file():
                p.error(f"{f}: not found")
    metas = [json.loads(m.with_suffix(".json").read_text()) for m in args.members]
    try:
        model = merge(args.members)
    except ValueError as exc:
        p.error(str(exc))
    onnx_path = args.out.with_suffix(".onnx")
    onnx_path.parent.mkdir(parents=True, exist_ok=True)
    tmp = onnx_path.with_suffix(".onnx.tmp")
    onnx.save(model, str(tmp))
    worst = parity(args.members, tmp)
    if worst > 1e-4:
        tmp.unlink()
        raise SystemExit(f"the merged model differs from its members' mean by {worst:.2e}: not written")
    tmp.replace(onnx_path)
    sidecar = dict(metas[0])
    sidecar["name"] = args.out.name
    sidecar["members"] = [
        {
            "file": str(m),
            **{
                k: meta.get(k)
                for k in ("sha256", "seed", "command", "data", "training", "photos", "sim_metrics", BARE)
                if k in meta
            },
        }
        for m, meta in zip(args.members, metas, strict=True)
    ]
    for key in ("seed", "command", "data", "training", "photos", "calibration", BARE):
        sidecar.pop(key, None)
    sidecar["command"] = "python -m landfall_train.ensemble " + " ".join(
        sys.argv[1:] if argv is None else list(argv)
    )
    sidecar["parity_max_abs_diff"] = float(f"{worst:.2e}")
    sidecar["onnx_bytes"] = onnx_path.stat().st_size
    sidecar["sha256"] = hashlib.sha256(onnx_path.read_bytes()).hexdigest()
    args.out.with_suffix(".json").write_text(json.dumps(sidecar, indent=2) + "\n")
    _log.info("wrote %s (%d members, %d bytes, parity %.1e)", onnx_path, len(args.members),
              sidecar["onnx_bytes"], worst)  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
