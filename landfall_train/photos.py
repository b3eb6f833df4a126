"""Teach a trained LandNet-S what real roofs look like: fine-tune it on labelled photographs and renders.

``python -m landfall_train.photos --member runs/landnet/seed0/landnet-s.onnx --seed 0 --out OUT``
(``make model`` runs it on each member before merging them) writes ``OUT.onnx`` and its sidecar.

**Why.** A net trained on simbridge's renders alone reads real roofs poorly: corrugated metal, tiles with
snow hooks and weathered concrete are textures the renders do not have, and it calls many clear real
roofs cluttered (on ../shared/realimages-train it confirmed 81 %). The labelled photographs are few (a
hundred and some), far too few to train a net from nothing, and enough to move one that already knows
what roofs, objects and roads are.

**What it learns from.** Both at once, in every step: ``--render-batch`` randomised render views with
their full targets (the cells and the clear site, as :mod:`landfall_train.train` trains them), so the
net keeps what it knows of the simulator's world, and ``--photo-batch`` randomised views of photographs
with one target, the clear-site output: ``land`` true is 1, false is 0, null (either answer) is not
read. Photographs come from the folders given (the layout of ../shared/realimages: ``labels.json`` with
``label``, ``land``, ``source_repo``, ``license``, and ``provenance.json``). Never learnt from:

- photographs whose licence does not allow shipping weights trained on them
  (:func:`landfall_train.photo_set.trainable`: a licence naming non-commercial or research-only use:
  the Semantic Drone Dataset, AeroScapes and UDD crops of ../shared/realimages);
- the sources named by ``--hold-out`` (default ``Philippines``): they and the licence-barred ones are
  the source-split validation the sidecar reports (``photos.held_out``), sources the net never saw.

A photograph's source is its repository, and for the OpenAerialMap tiles of hotosm/fAIr-utilities the
place its provenance names (Kampala, Kathmandu, Zanzibar, Philippines): the same city's roofs look alike.

**How.** The member's ONNX weights are read into :class:`landfall_train.net.LandNetS` (batch norm folded
into the convolutions, so the norms become fixed affine maps: their statistics do not move, which suits
batches this small), every weight is trained with AdamW at ``--lr`` for ``--steps`` steps, cosine decay.
While fine-tuning, a render view is a clear site with ``--clear-share`` of roof surface (0.6; training
from renders asks 0.85, :data:`landfall_train.labels.CLEAR_ROOF_SHARE`): a labelled clear roof's
photograph often shows ground or a tree at its margins, and the two sources should not teach the
clear-site output two definitions. That share and the 600 steps were chosen by the source folds and the
held-out photographs (docs/reasoning.md, "Fine-tuning longer").
Photograph views: a random crop of 45-100 % of the area, a quarter turn and a mirror image, colour,
contrast and brightness jitter, sometimes blur or sensor noise, scaled to 128 x 128.
Then the weights are moved back toward the member's: ``--alpha`` of the way from the member's to the
fine-tuned ones (weight-space ensembling, Wortsman et al. 2022, "Robust fine-tuning of zero-shot
models"): both start from the same weights, so the line between them stays a working net, and a point
on it keeps more of what the renders taught on imagery unlike both. ``python -m landfall_train.folds``
chooses ``--alpha`` and the steps by source-split cross-validation (docs/evaluation.md).
Procedural close-ups of gravel, ballast and membrane roofs with and without objects
(:mod:`landfall_train.closeups`, ``--closeups``; ``--closeup-share`` of each render batch) join the
renders: the labelled photographs hold no
such roof seen from 10-20 m up.
Thresholds stay as ``--recalibrate`` sets them on held-out renders (``make model``).
Tried and left at 0 by default (docs/reasoning.md: the source folds did not move): hazard-free cell
targets in clear photographs' middles (``--photo-cells``, ``--photo-roof``), photographed clear roofs'
surfaces on the renders' roofs (``--real-roofs``) and renders' roofs shaded as pitched planes
(``--pitched``); at 0 none of them draws a random number, so the shipped weights are reproduced.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from landfall_train import patches
from landfall_train.augment import augment, targets
from landfall_train.closeups import closeups
from landfall_train.labels import CLASSES, HAZARD_CLASSES
from landfall_train.photo_set import (
    HOLD_OUT,
    PHOTO_DIRS,
    Photo,
    photo_view_middle,
    photos_or_exit,
    read_rgb,
    roof_surfaces,
    split,
)
from landfall_train.train import (
    CLEAR_POS_WEIGHT,
    INPUT_PX,
    POS_WEIGHT,
    _commit,
    _torch_version,
    add_training_args,
    add_validation_args,
    export,
    normalised,
    training_paths,
)

_log = logging.getLogger("landfall_train.photos")

ALPHA = 0.75
CLOSEUPS = 400
CLOSEUP_SHARE = 0.25
STREAM = 4242  # the photograph views' random stream
PHOTO_CELLS = 0.0  # weight of the clear photographs' hazard-free middle cells (--photo-cells)
PHOTO_ROOF = 0.0  # weight of the roof cells in the middle of clear roofs and of photographs of no roof
REAL_ROOFS = 0.0  # share of the render views whose roof surface is a clear photographed roof's (--real-roofs)
REAL_ROOF_MIN = 0.15  # a render with less roof than this share keeps its own
PITCHED = 0.0  # share of the render views whose roof is shaded as a pitched roof's planes (--pitched)
CLEAR_SHARE = 0.6  # a render view is a clear site with this share of roof (--clear-share; training: 0.85)
STEPS = 600  # fine-tuning steps (--steps; 300 until 2026-11-29)
ROOF = CLASSES.index("roof")


def from_onnx(spec: str) -> Any:
    """A :class:`landfall_train.net.LandNetS` in eval mode with the weights of an exported member:
    ``PATH`` or ``PATH#PREFIX`` (one member of a merged model, e.g. ``landnet-s.onnx#m0/``). Batch norm
    was folded into the convolutions at export; each norm becomes the identity plus the folded bias."""
    import onnx
    import torch
    from onnx import numpy_helper
    from torch import nn

    from landfall_train.net import LandNetS

    path, _, prefix = spec.partition("#")
    model = onnx.load(path)
    weights = {i.name: numpy_helper.to_array(i) for i in model.graph.initializer}
    convs = [n for n in model.graph.node if n.op_type == "Conv" and n.output[0].startswith(prefix)]
    head = next(n for n in convs if n.output[0] == f"{prefix}clear")
    fused = weights[head.input[1]].shape[1] > 2 * weights[convs[5].input[1]].shape[0]
    widths = (*(int(weights[convs[k].input[1]].shape[0]) for k in (0, 1, 3, 5)),)
    net = LandNetS(len(CLASSES), widths, fused=fused)  # type: ignore[arg-type]
    modules = dict(net.named_modules())
    mine = [(name, m) for name, m in net.named_modules() if isinstance(m, nn.Conv2d)]
    if len(mine) != len(convs):
        raise ValueError(f"{spec}: {len(convs)} convolutions, LandNet-S has {len(mine)}")
    with torch.no_grad():
        for (name, conv), node in zip(mine, convs, strict=True):
            w, b = (torch.from_numpy(weights[k].copy()) for k in node.input[1:3])
            if conv.weight.shape != w.shape:
                want = tuple(conv.weight.shape)
                raise ValueError(f"{spec}: {node.name} has shape {tuple(w.shape)}, not {want}")
            conv.weight.copy_(w)
            if conv.bias is not None:
                conv.bias.copy_(b)
                continue
            parent, idx = name.rsplit(".", 1)
            bn = modules[f"{parent}.{int(idx) + 1}"]
            bn.weight.fill_(1.0)
            bn.bias.copy_(b)
            bn.running_mean.zero_()
            bn.running_var.fill_(1.0 - bn.eps)
    return net.eval()


def member_sidecar(spec: str) -> dict[str, Any]:
    """The sidecar of the member ``spec`` names (:func:`from_onnx`): its own file's, or for one member of a
    merged model the merged sidecar with that member's entry over it (no ``members``, no ``file``)."""
    path, _, prefix = spec.partition("#")
    meta: dict[str, Any] = json.loads(Path(path).with_suffix(".json").read_text())
    if "members" in meta:
        member = meta["members"][int(prefix.strip("m/") or 0)]
        meta = {k: v for k, v in meta.items() if k not in ("members", "file")} | member
        meta.pop("file", None)
    return meta


def _views(
    photos: Sequence[Photo], images: dict[Path, np.ndarray], rng: np.random.Generator, n: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``n`` photograph views, their clear-site targets and their cell targets: per view and stride-8
    cell lying wholly in the photograph's middle, 0 (no hazard) where the photograph is a clear site,
    and the roof cell's target, 1 on a clear roof, 0 where the photograph shows no roof (``label``
    ``not_roof``); -1 where the label says nothing of the cell."""
    pick = rng.integers(0, len(photos), n).tolist()
    views = [photo_view_middle(images[photos[i].path], rng) for i in pick]
    clear = np.array([1.0 if photos[i].land else 0.0 for i in pick], np.float32)
    side = INPUT_PX // 8
    middle = np.stack([m for _v, m in views]).reshape(n, side, 8, side, 8).all(axis=(2, 4))
    free = middle & (clear > 0)[:, None, None]
    roof_value = np.array(
        [1.0 if photos[i].land and photos[i].label == "clear_roof" else 0.0 if photos[i].label == "not_roof"
         else -1.0 for i in pick], np.float32,
    )  # fmt: skip
    roof = np.where(middle, roof_value[:, None, None], -1.0).astype(np.float32)
    return np.stack([v for v, _m in views]), clear, free, roof


def with_real_roof(
    rgb: np.ndarray, labels: np.ndarray, surfaces: Sequence[np.ndarray], rng: np.random.Generator
) -> np.ndarray:
    """A render (uint8 RGB) whose roof pixels show a photographed clear roof's surface instead of the
    renderer's, lit as the render's roof was (its brightness relative to the roof's mean, smoothed, so
    shadows and the light's fall-off stay), turned, mirrored and scaled to cover the render (up to 1.5
    times more); everything else, and the labels, unchanged. The renders teach where objects, edges and
    roads are; the photographs what a real roof's tiles, sheets and stains look like between them."""
    roof = labels == ROOF
    h, w = labels.shape
    if not surfaces or roof.mean() < REAL_ROOF_MIN:
        return rgb
    tex = np.rot90(surfaces[int(rng.integers(len(surfaces)))], int(rng.integers(4)))
    if rng.random() < 0.5:
        tex = tex[:, ::-1]
    scale = max(h / tex.shape[0], w / tex.shape[1]) * rng.uniform(1.0, 1.5)
    th, tw = max(h, math.ceil(tex.shape[0] * scale)), max(w, math.ceil(tex.shape[1] * scale))
    interp = cv2.INTER_AREA if scale < 1 else cv2.INTER_LINEAR
    tex = np.asarray(cv2.resize(np.ascontiguousarray(tex), (tw, th), interpolation=interp), np.float32)
    oy, ox = int(rng.integers(th - h + 1)), int(rng.integers(tw - w + 1))
    x = rgb.astype(np.float32) / np.float32(255.0)
    lum = x.mean(axis=2)
    light = np.asarray(cv2.GaussianBlur(lum, (0, 0), 4.0), np.float32) / max(float(lum[roof].mean()), 1e-3)
    surface = tex[oy : oy + h, ox : ox + w] * np.clip(light, 0.3, 1.5)[..., None]
    out = np.where(roof[..., None], surface, x)
    return np.asarray(np.clip(out * 255.0 + 0.5, 0, 255), np.uint8)


def pitched(rgb: np.ndarray, labels: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A render (uint8 RGB) whose roof is shaded as a pitched roof's: a ridge at a random place and angle,
    the two long planes either side lit differently, and for a hipped roof (half of them) the two end
    planes beyond the ridge's ends lit differently again; sometimes a ridge cap along it. Labels
    unchanged: on real photographs a clear gable or hipped roof is still a clear roof (its slope is
    geometry's business), and renders' roofs are flat."""
    roof = labels == ROOF
    if roof.mean() < REAL_ROOF_MIN:
        return rgb
    h, w = labels.shape
    ys, xs = np.nonzero(roof)
    k = int(rng.integers(len(ys)))
    cy, cx = float(ys[k]), float(xs[k])
    theta = float(rng.uniform(0.0, math.pi))
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    along = (xx - cx) * math.cos(theta) + (yy - cy) * math.sin(theta)
    across = -(xx - cx) * math.sin(theta) + (yy - cy) * math.cos(theta)
    d = float(rng.uniform(0.1, 0.4))
    gain = np.where(across > 0, 1.0 + d, 1.0 - d).astype(np.float32)
    if rng.random() < 0.5:  # hipped: end planes beyond the ridge's ends, at 45 degrees
        half = float(rng.uniform(0.0, 0.3)) * max(h, w)
        end = (np.abs(along) - half) > np.abs(across)
        d_end = float(rng.uniform(-0.3, 0.3))
        gain = np.where(end, np.where(along > 0, 1.0 + d_end, 1.0 - d_end), gain).astype(np.float32)
    if rng.random() < 0.5:  # a ridge cap: a line one or two pixels wide, lighter or darker
        cap = np.abs(across) < float(rng.uniform(0.5, 1.5))
        gain = np.where(cap, float(rng.uniform(0.6, 1.4)), gain).astype(np.float32)
    x = rgb.astype(np.float32) * np.where(roof, gain, 1.0)[..., None]
    return np.asarray(np.clip(x + 0.5, 0, 255), np.uint8)


def fine_tune(
    net: Any,
    photos: Sequence[Photo],
    x: np.ndarray,
    y: np.ndarray,
    args: argparse.Namespace,
    first_closeup: int | None = None,
) -> tuple[Any, float]:
    """Fine-tune ``net`` on ``photos`` (land true or false only) and the renders ``x``, ``y``, whose
    entries from ``first_closeup`` on are close-ups (``args.closeup_share`` of each render batch)."""
    first_closeup = len(x) if first_closeup is None else first_closeup
    import torch

    torch.manual_seed(args.seed)
    torch.set_num_threads(args.threads)
    used = [p for p in photos if p.land is not None]
    images = {p.path: read_rgb(p.path) for p in used}
    surfaces = roof_surfaces(used, images) if args.real_roofs > 0 else []
    pos = sum(1 for p in used if p.land)
    photo_pos_weight = torch.tensor((len(used) - pos) / max(pos, 1))
    pos_weight = torch.tensor([POS_WEIGHT.get(c, 1.0) for c in CLASSES]).view(1, -1, 1, 1)
    opt = torch.optim.AdamW(net.parameters(), lr=args.lr, weight_decay=1e-4)
    sched = torch.optim.lr_scheduler.LambdaLR(
        opt, lambda s: 0.5 + 0.5 * math.cos(math.pi * min(s, args.steps) / max(args.steps, 1))
    )
    t0 = time.monotonic()
    running = 0.0
    closeups_here = round(args.closeup_share * args.render_batch) if len(x) > first_closeup else 0
    net.eval()  # the folded norms stay fixed maps (module docstring)
    for step in range(args.steps):
        rng = np.random.default_rng([args.seed, STREAM, step])
        p_img, p_clear, p_free, p_roof = _views(used, images, rng, args.photo_batch)
        r_img, cells, valid, clear = [], [], [], []
        picks = np.concatenate([
            rng.integers(0, first_closeup, args.render_batch - closeups_here),
            rng.integers(first_closeup, len(x), closeups_here),
        ])  # fmt: skip
        for i in picks.tolist():
            real = surfaces and i < first_closeup and rng.random() < args.real_roofs  # no draw at 0
            src = with_real_roof(x[i], y[i], surfaces, rng) if real else x[i]
            if args.pitched > 0 and i < first_closeup and rng.random() < args.pitched:  # no draw at 0
                src = pitched(src, y[i], rng)
            img, lab = augment(src, y[i], rng, INPUT_PX)
            c, v, s = targets(lab, args.clear_share)
            r_img.append(img)
            cells.append(c)
            valid.append(v)
            clear.append(s)
        batch = np.concatenate([np.stack(r_img), p_img])
        blob = torch.from_numpy(normalised(batch))
        logits, clear_logit = net(blob)
        n = args.render_batch
        weights = (pos_weight, photo_pos_weight)
        loss, photo_clear = mixed_loss(
            logits, clear_logit, (cells, valid, clear), p_clear, weights, args.photo_weight
        )
        if args.photo_cells > 0 and p_free.any():
            # a clear photograph's middle holds no object, person, vehicle, water or marking
            free = torch.from_numpy(p_free)
            hazard_logits = logits[n:, list(HAZARD_CLASSES)]
            bce = torch.nn.functional.binary_cross_entropy_with_logits(
                hazard_logits, torch.zeros_like(hazard_logits), reduction="none"
            )
            loss = loss + args.photo_cells * (bce * free[:, None]).sum() / (free.sum() * len(HAZARD_CLASSES))
        if args.photo_roof > 0 and (p_roof >= 0).any():
            # a clear roof's middle is roof surface; a photograph of no roof has none there
            target = torch.from_numpy(p_roof)
            known = (target >= 0).float()
            bce = torch.nn.functional.binary_cross_entropy_with_logits(
                logits[n:, ROOF], target.clamp(min=0.0), reduction="none"
            )
            loss = loss + args.photo_roof * (bce * known).sum() / known.sum()
        running = take_step(opt, sched, loss, photo_clear, running, (step, args.steps, t0))
    return net.eval(), time.monotonic() - t0


def take_step(
    opt: Any, sched: Any, loss: Any, photo_loss: Any, running: float, when: tuple[int, int, float]
) -> float:
    """One optimiser and schedule step on ``loss``; returns the photographs' running loss, which is
    logged every 50 steps with the time per step (``when``: this step, the steps planned, the start)."""
    step, steps, t0 = when
    opt.zero_grad(set_to_none=True)
    loss.backward()
    opt.step()
    sched.step()
    running = 0.95 * running + 0.05 * float(photo_loss.detach()) if step else float(photo_loss.detach())
    if step % 50 == 0 or step == steps - 1:
        el = time.monotonic() - t0
        _log.info("step %d/%d photo loss %.3f (%.0f s, %.2f s/step)", step + 1, steps, running, el,
                  el / (step + 1))  # fmt: skip
    return running


def render_loss(
    logits: Any,
    clear_logit: Any,
    render: tuple[list[np.ndarray], list[np.ndarray], list[float]],
    cell_pos: Any,
) -> Any:
    """The loss of the first ``len(render[0])`` views of a batch, renders (``render``: their cell targets,
    cell validity and clear-site targets): the cells' (weighted per class by ``cell_pos``) and the
    clear site's."""
    import torch

    cells, valid, clear = render
    n = len(cells)
    bce = torch.nn.functional.binary_cross_entropy_with_logits(
        logits[:n], torch.from_numpy(np.stack(cells)), pos_weight=cell_pos, reduction="none"
    )
    v = torch.from_numpy(np.stack(valid))
    cell_loss = (bce * v[:, None]).sum() / (v.sum() * len(CLASSES)).clamp(min=1.0)
    render_clear = torch.nn.functional.binary_cross_entropy_with_logits(
        clear_logit[:n].view(-1), torch.tensor(clear, dtype=torch.float32),
        pos_weight=torch.tensor(CLEAR_POS_WEIGHT),
    )  # fmt: skip
    return cell_loss + render_clear


def mixed_loss(
    logits: Any,
    clear_logit: Any,
    render: tuple[list[np.ndarray], list[np.ndarray], list[float]],
    photo_clear: np.ndarray,
    pos_weights: tuple[Any, Any],
    photo_weight: float,
) -> tuple[Any, Any]:
    """The loss of a batch of render views (first: :func:`render_loss`) followed by photograph views
    (``photo_clear``: their clear-site targets): the renders' loss and ``photo_weight`` times the
    photographs' clear site, weighted by ``pos_weights`` (the cells' per class, the photographs' clear
    sites). Returns (loss, photograph loss)."""
    import torch

    cell_pos, photo_pos = pos_weights
    n = len(render[0])
    photo = torch.nn.functional.binary_cross_entropy_with_logits(
        clear_logit[n:].view(-1), torch.from_numpy(photo_clear), pos_weight=photo_pos
    )
    return render_loss(logits, clear_logit, render, cell_pos) + photo_weight * photo, photo


def interpolate(net: Any, start: dict[str, Any], alpha: float) -> Any:
    """``net`` with its weights moved to ``start + alpha * (weights - start)`` (module docstring)."""
    import torch

    with torch.no_grad():
        for name, tensor in net.state_dict().items():
            if tensor.dtype.is_floating_point:
                tensor.copy_(start[name] + alpha * (tensor - start[name]))
    return net


def render_set(args: argparse.Namespace) -> tuple[np.ndarray, np.ndarray, str, int]:
    """The renders (:func:`landfall_train.train.training_paths`), then ``args.closeups`` procedural roof
    close-ups of seed ``args.seed``: images, class maps, the renders' digest and the first close-up's
    index."""
    x, y, digest = patches.load_shards(training_paths(args, args.seed))
    first = len(x)
    if args.closeups:
        cx, cy = closeups(args.seed, args.closeups, x.shape[1])
        x, y = np.concatenate([x, cx]), np.concatenate([y, cy])
    return x, y, digest, first


def _share(text: str) -> float:
    value = float(text)
    if not 0.0 < value <= 1.0:
        raise argparse.ArgumentTypeError(f"{text}: a share of the view, over 0 and at most 1")
    return value


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m landfall_train.photos", description=__doc__.split("\n")[0])
    p.add_argument("--member", required=True, help="the trained member: X.onnx, or MERGED.onnx#m0/")
    p.add_argument("--seed", type=int, required=True)
    p.add_argument("--out", type=Path, required=True, help="where to write OUT.onnx and OUT.json")
    p.add_argument("--photos", type=Path, nargs="+", default=list(PHOTO_DIRS), help="labelled photo folders")
    p.add_argument("--hold-out", nargs="*", default=list(HOLD_OUT), help="sources never learnt from")
    p.add_argument("--steps", type=int, default=STEPS)
    p.add_argument("--lr", type=float, default=3e-4)
    p.add_argument("--photo-batch", type=int, default=16)
    p.add_argument("--render-batch", type=int, default=16)
    p.add_argument("--photo-weight", type=float, default=1.0, help="weight of the photographs' loss")
    p.add_argument(
        "--photo-cells", type=float, default=PHOTO_CELLS,
        help="weight of the hazard cells held at 0 in the middle of the clear photographs' views",
    )  # fmt: skip
    p.add_argument(
        "--photo-roof", type=float, default=PHOTO_ROOF,
        help="weight of the roof cells held at 1 in a clear roof's middle, at 0 in a photograph of no roof",
    )  # fmt: skip
    p.add_argument(
        "--real-roofs", type=float, default=REAL_ROOFS,
        help="share of the render views whose roof shows a photographed clear roof's surface",
    )  # fmt: skip
    p.add_argument(
        "--pitched", type=float, default=PITCHED,
        help="share of the render views whose roof is shaded as a gable or hipped roof's planes",
    )  # fmt: skip
    p.add_argument(
        "--closeups", type=int, default=CLOSEUPS,
        help="procedural roof close-ups beside the renders (landfall_train.closeups)",
    )  # fmt: skip
    p.add_argument("--closeup-share", type=float, default=CLOSEUP_SHARE, help="of each render batch")
    p.add_argument(
        "--clear-share", type=_share, default=CLEAR_SHARE,
        help="share of roof surface that makes a render view a clear site (hazard-free) while fine-tuning",
    )  # fmt: skip
    p.add_argument("--alpha", type=float, default=ALPHA, help="share of the way to the fine-tuned weights")
    p.add_argument("--threads", type=int, default=1)
    add_render_set_args(p)
    return p


def add_render_set_args(p: argparse.ArgumentParser) -> None:
    """The renders options of :func:`render_set` (and the validation renders'), with the smaller render
    set that learning from photographs beside renders uses: 8 cities and 300 vignettes."""
    add_training_args(p)
    add_validation_args(p)
    p.set_defaults(train_cities=8, vignettes=300)


def main(argv: Sequence[str] | None = None) -> int:
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s", stream=sys.stderr)
    args = build_parser().parse_args(argv)
    command = "python -m landfall_train.photos " + " ".join(sys.argv[1:] if argv is None else argv)
    path = Path(args.member.partition("#")[0])
    meta_path = path.with_suffix(".json")
    for f in (path, meta_path):
        if not f.is_file():
            raise SystemExit(f"{f}: not found (train the member first: python -m landfall_train --seed S)")
    photos = photos_or_exit(args.photos)
    learn, held = split(photos, args.hold_out)
    if not any(p.land for p in learn) or not any(p.land is False for p in learn):
        raise SystemExit("the photographs to learn from need both clear and unclear sites")
    _log.info("learning from %d photographs (%s); holding out %d", len(learn),
              ", ".join(sorted({p.source for p in learn})), len(held))  # fmt: skip
    t0 = time.monotonic()
    x, y, digest, first_closeup = render_set(args)
    net = from_onnx(args.member)
    start = {k: v.clone() for k, v in net.state_dict().items()}
    net, seconds = fine_tune(net, learn, x, y, args, first_closeup)
    interpolate(net, start, args.alpha)
    meta = member_sidecar(args.member)
    meta["name"] = args.out.name
    meta["photos"] = {
        "command": command, "from": args.member, "learnt": len(learn),
        "learnt_sources": sorted({p.source for p in learn}),
        "held_out_sources": sorted({p.source for p in held}),
        "steps": args.steps, "lr": args.lr, "photo_batch": args.photo_batch,
        "render_batch": args.render_batch, "photo_weight": args.photo_weight,
        "photo_cells": args.photo_cells, "photo_roof": args.photo_roof, "alpha": args.alpha,
        "real_roofs": args.real_roofs, "pitched": args.pitched,
        "closeups": args.closeups, "closeup_share": args.closeup_share,
        "clear_share": args.clear_share, "render_digest": digest,
        "seconds": round(seconds, 1), "torch": _torch_version(), "commit": _commit(),
        "render_s": round(time.monotonic() - t0 - seconds, 1),
    }  # fmt: skip
    export(net, args.out, meta)
    _log.info("wrote %s.onnx and .json in %.0f s", args.out, time.monotonic() - t0)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
