"""Training the onboard judgement (landfall_train): a smoke run that renders, trains, exports and merges
LandNet-S-style nets and their bare head, and the vignette shards and patches it learns from (needs
torch). The runtime it exports for: tests/test_landnet.py."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from companion.reasoning.landnet import LandNet
from tests.test_landnet import _image


# --- training (landfall_train) --------------------------------------------------------------------------
@pytest.mark.slow
def test_landfall_train_smoke_renders_trains_and_exports(tmp_path: Path) -> None:
    pytest.importorskip("torch", reason="training needs torch: pip install -e '.[train]'")
    pytest.importorskip("onnx", reason="ONNX export needs onnx: pip install -e '.[train]'")
    from landfall_train.train import main

    out = tmp_path / "tiny"
    argv = [
        "--out", str(out), "--cache", str(tmp_path / "cache"), "--steps", "2", "--batch", "4", "--workers",
        "1", "--train-cities", "1", "--per-city", "4", "--val-cities", "1", "--val-per-city", "4",
        "--vignettes", "1", "--per-vignette", "3", "--val-vignettes", "1",
    ]  # fmt: skip
    assert main(argv) == 0
    tiny = LandNet.load(out.with_suffix(".onnx"))
    meta = json.loads(out.with_suffix(".json").read_text())
    assert meta["training"]["steps_done"] == 2
    assert meta["data"]["train_city_seeds"] == [100]
    assert meta["data"]["train_patches"] == 4 + 3
    assert meta["parity_max_abs_diff"] < 1e-3
    assert tiny.read(_image(64, 64)).grid == (16, 16)
    assert meta["input"]["views"] == 4  # calibrated as the companion reads: with the mirror images
    assert meta["input"]["confirm_short_side_px"] == 128  # --confirm-side's default: the input's side
    assert meta["input"]["rank_short_side_px"] == 128  # --rank-side's too
    assert tiny.views == 4
    # --recalibrate through OpenCV's DNN module gives the thresholds training gave through torch
    thresholds = meta["thresholds"]
    meta["thresholds"] = {"clear": 0.5, "cells": dict.fromkeys(thresholds["cells"], 0.5)}
    out.with_suffix(".json").write_text(json.dumps(meta))
    assert main([*argv, "--recalibrate"]) == 0
    again = json.loads(out.with_suffix(".json").read_text())
    assert again["thresholds"]["clear"] == pytest.approx(thresholds["clear"], abs=2e-4)
    assert again["calibration"]["views"] == 4
    assert again["sha256"] == meta["sha256"]  # the weights are untouched
    from landfall_train.patches import generate

    with pytest.raises(ValueError, match="reserved for evaluation"):
        generate(tmp_path / "x", [0], 1, 0)

    # a second seed, merged with the first: one ONNX model whose logits are the members' mean
    from landfall_train import compare, ensemble

    other = tmp_path / "tiny1"
    assert main([*argv, "--out", str(other), "--seed", "1"]) == 0
    merged = tmp_path / "both"
    assert (
        ensemble.main([str(out.with_suffix(".onnx")), str(other.with_suffix(".onnx")), "--out", str(merged)])
        == 0
    )
    both = LandNet.load(merged.with_suffix(".onnx"))
    side = json.loads(merged.with_suffix(".json").read_text())
    assert [m["seed"] for m in side["members"]] == [0, 1]
    assert side["parity_max_abs_diff"] < 1e-4
    img = _image(96, 128)
    logit = [
        math.log(r.clear_p / (1 - r.clear_p))
        for r in (tiny.read(img), LandNet.load(other.with_suffix(".onnx")).read(img))
    ]
    got = both.read(img).clear_p
    assert math.log(got / (1 - got)) == pytest.approx(sum(logit) / 2, abs=1e-4)
    assert main([*argv, "--out", str(merged), "--recalibrate"]) == 0
    assert json.loads(merged.with_suffix(".json").read_text())["calibration"]["views"] == 4
    tiny_val = [
        "--cache", str(tmp_path / "cache"), "--val-cities", "1", "--val-per-city", "4", "--per-vignette", "3",
        "--val-vignettes", "1", "--workers", "1",
    ]  # fmt: skip
    assert compare.main([str(merged.with_suffix(".onnx")), *tiny_val, "--views", "1,4"]) == 0
    with pytest.raises(SystemExit):
        ensemble.main([str(out.with_suffix(".onnx")), "--out", str(tmp_path / "alone")])  # one member: no

    # the bare head (landfall_train.bare) on each net, then merged: its logit is the members' mean too
    pytest.importorskip("sklearn", reason="the bare head needs scikit-learn: pip install -e '.[train]'")
    from landfall_train import bare

    data = [
        "--train-cities", "1", "--per-city", "4", "--vignettes", "4", "--samples", "80", "--rank-views", "2",
        *tiny_val,
    ]  # fmt: skip
    before = {0: tiny.read(img), 1: LandNet.load(other.with_suffix(".onnx")).read(img)}
    for seed, model in ((0, out), (1, other)):
        assert bare.main(["--out", str(model), "--seed", str(seed), *data]) == 0
        with_head = LandNet.load(model.with_suffix(".onnx"))
        assert with_head.has_bare
        side = json.loads(model.with_suffix(".json").read_text())
        assert side["format"] == "landfall-landnet/2"
        assert side["bare"]["samples"] == 80
        assert side["bare"]["fitted_views"] > 0
        assert 0.0 <= side["bare"]["held_out"]["auc_rank_all"] <= 1.0
        assert side["parity_max_abs_diff"] < 1e-3
        got = with_head.read(img)
        assert got.bare_p is not None
        assert 0.0 <= got.bare_p <= 1.0
        # the head adds an output and changes none of the others
        assert got.clear_p == pytest.approx(before[seed].clear_p, abs=1e-6)
        assert got.shares == before[seed].shares
    with pytest.raises(SystemExit):  # a second head on the same net: refused
        bare.main(["--out", str(out), "--seed", "0", *data])
    with pytest.raises(SystemExit):  # members with and without the head: refused
        ensemble.main([str(merged.with_suffix(".onnx")), str(out.with_suffix(".onnx")), "--out",
                       str(tmp_path / "mixed")])  # fmt: skip
    headed = tmp_path / "both-bare"
    assert (
        ensemble.main([str(out.with_suffix(".onnx")), str(other.with_suffix(".onnx")), "--out", str(headed)])
        == 0
    )
    both_bare = LandNet.load(headed.with_suffix(".onnx"))
    assert both_bare.has_bare
    assert json.loads(headed.with_suffix(".json").read_text())["format"] == "landfall-landnet/2"
    member_logits = [
        math.log(r.bare_p / (1 - r.bare_p))  # type: ignore[operator]
        for r in (LandNet.load(m.with_suffix(".onnx")).read(img, views=1) for m in (out, other))
    ]
    merged_p = both_bare.read(img, views=1).bare_p
    assert merged_p is not None
    assert math.log(merged_p / (1 - merged_p)) == pytest.approx(sum(member_logits) / 2, abs=1e-4)
    assert compare.main([str(headed.with_suffix(".onnx")), *tiny_val, "--views", "2", "--rank",
                         "--rank-weights", "0.5"]) == 0  # fmt: skip


def test_vignette_shards_asked_for_more_worlds_later_render_them(tmp_path: Path) -> None:
    """A cached shorter shard is not taken for a longer one (the bare head's data once were 1 vignette
    where 4 were asked)."""
    from landfall_train.patches import generate_vignettes, load_shards

    one = generate_vignettes(tmp_path, 0, 1, 2, seed=0)
    three = generate_vignettes(tmp_path, 0, 3, 2, seed=0)
    assert len(load_shards(one)[0]) == 2
    assert len(load_shards(three)[0]) == 6
    assert len(load_shards(generate_vignettes(tmp_path, 0, 1, 2, seed=0))[0]) == 2


def test_vignette_patches_are_labelled_varied_and_the_same_for_the_same_seed() -> None:
    from landfall_train.labels import CLASSES, IGNORE
    from landfall_train.patches import PATCH_PX, render_vignettes

    rgb, labels, meta = render_vignettes(3, 2, 4, seed=5)
    assert rgb.shape == (8, PATCH_PX, PATCH_PX, 3)
    assert labels.shape == (8, PATCH_PX, PATCH_PX)
    assert [m["vignette"] for m in meta] == [3] * 4 + [4] * 4
    assert all(0.015 <= m["gsd_m"] <= 0.15 for m in meta)
    assert set(np.unique(labels).tolist()) <= set(range(len(CLASSES))) | {IGNORE}
    assert all(float(img.std()) > 2.0 for img in rgb)  # a scene, not a blank
    again, labels_again, _ = render_vignettes(3, 2, 4, seed=5)
    assert np.array_equal(rgb, again)
    assert np.array_equal(labels, labels_again)
    other, _, _ = render_vignettes(3, 2, 4, seed=6)
    assert not np.array_equal(rgb, other)
