"""The whole-image read, a confirmation's second opinion (companion.reasoning.landnet and
landfall_train.whole_read)."""

from __future__ import annotations

import hashlib
import json
import shutil
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from companion.reasoning.base import ConfirmRequest
from companion.reasoning.cue_params import CueParams
from companion.reasoning.landnet import PACKAGED, LandNet, LandNetError
from companion.reasoning.net_judge import confirm_reading
from companion.reasoning.onboard_params import ConfirmParams

LIGHT = PACKAGED["landnet-s"]  # one file: the tests attach their own whole read to it

torch = pytest.importorskip("torch", reason="the training extra: pip install -e '.[train]'")

from landfall_train.photo_set import Photo  # noqa: E402
from landfall_train.whole_read import (  # noqa: E402
    closeup_features,
    fit,
    fold_report,
    held_out,
    mixed,
    probability,
    whole_blob,
)

MEAN = np.array([0.485, 0.456, 0.406], np.float32)
STD = np.array([0.229, 0.224, 0.225], np.float32)


class _MeanRed(torch.nn.Module):  # type: ignore[misc]
    """A stand-in whole read: ``gain`` x the mean of the normalised red channel + ``bias``."""

    def __init__(self, gain: float, bias: float) -> None:
        super().__init__()
        self.gain, self.bias = gain, bias

    def forward(self, x: Any) -> Any:
        return self.gain * x[:, 0:1].mean(dim=(2, 3)) + self.bias


def _export(path: Path, gain: float, bias: float) -> None:
    torch.onnx.export(
        _MeanRed(gain, bias), (torch.zeros(1, 3, 64, 64),), str(path), input_names=["image"],
        output_names=["whole"], dynamic_axes={"image": {0: "n"}, "whole": {0: "n"}}, opset_version=13,
        dynamo=False,
    )  # fmt: skip


def _with_whole_read(tmp_path: Path, gain: float, bias: float, **entry: Any) -> Path:
    """The packaged LandNet-S copied to ``tmp_path`` with a whole read attached to its sidecar."""
    onnx = tmp_path / "m.onnx"
    shutil.copy(LIGHT, onnx)
    whole = tmp_path / "m-whole.onnx"
    with warnings.catch_warnings():  # the TorchScript exporter (dynamo=False) is deprecated, and works
        warnings.simplefilter("ignore", DeprecationWarning)
        _export(whole, gain, bias)
    meta = json.loads(LIGHT.with_suffix(".json").read_text())
    meta["thresholds"]["net_clear"] = meta["thresholds"]["clear"]
    meta["thresholds"]["clear"] = 0.42
    meta["whole_read"] = {
        "file": whole.name, "sha256": hashlib.sha256(whole.read_bytes()).hexdigest(),
        "side_px": 64, "views": 2, "weight": 0.5, "mean": MEAN.tolist(), "std": STD.tolist(),
    } | entry  # fmt: skip
    onnx.with_suffix(".json").write_text(json.dumps(meta))
    return onnx


def _red_logit(rgb: np.ndarray, gain: float, bias: float) -> float:
    import cv2

    x = cv2.resize(rgb, (64, 64), interpolation=cv2.INTER_AREA).astype(np.float32) / np.float32(255)
    return float(gain * ((x[..., 0] - MEAN[0]) / STD[0]).mean() + bias)


def test_a_confirmation_weighs_the_whole_read_into_the_clear_probability(tmp_path: Path) -> None:
    net = LandNet.load(_with_whole_read(tmp_path, 2.0, -0.5), backend="onnxruntime")
    packaged = json.loads(LIGHT.with_suffix(".json").read_text())["thresholds"]["clear"]
    assert (net.clear_threshold, net.net_clear_threshold) == (0.42, packaged)
    rng = np.random.default_rng(3)
    rgb = rng.integers(0, 256, (90, 120, 3), dtype=np.uint8)
    plain = net.read(rgb)
    mixed_reading = net.confirmation(plain, rgb)
    whole_p = 1.0 / (1.0 + np.exp(-_red_logit(rgb, 2.0, -0.5)))  # a mirror image has the same mean red
    assert mixed_reading.whole_p == pytest.approx(whole_p, abs=1e-4)
    assert mixed_reading.net_clear_p == plain.clear_p
    assert mixed_reading.clear_p == pytest.approx(0.5 * plain.clear_p + 0.5 * whole_p, abs=1e-4)
    assert mixed_reading.shares == plain.shares  # the cells are the net's alone
    record = mixed_reading.to_json()
    assert record["net_clear_p"] == round(plain.clear_p, 4)
    assert record["whole_p"] == round(whole_p, 4)
    assert "whole image" in mixed_reading.observations()[-1]
    # a rank reads no whole image: its reading is the net's
    assert net.read_rank(rgb).whole_p is None
    assert "net_clear_p" not in net.read_rank(rgb).to_json()


def test_confirm_reading_judges_the_mean_and_the_whole_read_can_refuse(tmp_path: Path) -> None:
    rgb = np.full((96, 96, 3), 128, np.uint8)
    params = ConfirmParams(site_window=CueParams().site_window_crop)
    net = LandNet.load(_with_whole_read(tmp_path, 0.0, -30.0, weight=1.0), backend="onnxruntime")
    vetoes, _categorical, _note, r, _open = confirm_reading(
        net, ConfirmRequest(rgb), params, lidar_vetoes=[], street_level=False, where=""
    )
    assert r.clear_p == pytest.approx(0.0, abs=1e-6)
    assert r.net_clear_p is not None
    assert [kind for kind, _text in vetoes]
    assert r.clear_p < net.clear_threshold


def test_plain_models_are_unchanged_by_a_confirmation() -> None:
    net = LandNet.load(LIGHT, backend="onnxruntime")
    rgb = np.full((64, 64, 3), 90, np.uint8)
    r = net.read(rgb)
    assert net.confirmation(r, rgb) is r
    assert net.net_clear_threshold == net.clear_threshold


@pytest.mark.parametrize(
    ("entry", "match"),
    [
        ({"views": 3}, "whole_read.views"),
        ({"weight": 1.5}, "whole_read.weight"),
        ({"side_px": 16}, "whole_read.side_px"),
        ({"file": "../elsewhere.onnx"}, "whole_read.file"),
        ({"std": [0.2, 0.0, 0.2]}, "whole_read.std"),
    ],
)
def test_a_bad_whole_read_entry_is_an_error_naming_the_sidecar(
    tmp_path: Path, entry: dict[str, Any], match: str
) -> None:
    onnx = _with_whole_read(tmp_path, 1.0, 0.0, **entry)
    with pytest.raises(LandNetError, match=rf"m\.json: unreadable model sidecar: .*{match}"):
        LandNet.load(onnx)


def test_a_missing_or_altered_whole_read_is_an_error_naming_its_file(tmp_path: Path) -> None:
    onnx = _with_whole_read(tmp_path, 1.0, 0.0)
    whole = tmp_path / "m-whole.onnx"
    blob = bytearray(whole.read_bytes())
    blob[len(blob) // 2] ^= 0xFF
    whole.write_bytes(bytes(blob))
    with pytest.raises(LandNetError, match=r"m-whole\.onnx: sha256 .* does not match"):
        LandNet.load(onnx)
    whole.unlink()
    with pytest.raises(LandNetError, match=r"m-whole\.onnx: the whole read's file is missing"):
        LandNet.load(onnx)


def test_the_folded_regression_reads_raw_features_as_the_fitted_pipeline_does() -> None:
    from sklearn.linear_model import LogisticRegression
    from sklearn.preprocessing import StandardScaler

    rng = np.random.default_rng(0)
    x = rng.normal(5.0, 3.0, (80, 12))
    y = (x[:, 0] + 0.5 * rng.normal(size=80) > 5.0).astype(float)
    w, b = fit(x, y, 0.3)
    scale = StandardScaler().fit(x)
    ref = LogisticRegression(C=0.3, max_iter=5000).fit(scale.transform(x), y)
    assert np.allclose(probability(x, w, b), ref.predict_proba(scale.transform(x))[:, 1], atol=1e-9)
    assert mixed(0.9, 0.3) == pytest.approx(0.6)
    assert mixed(0.9, 0.3, 0.0) == pytest.approx(0.9)


def _photos(n_per_place: int = 20) -> tuple[list[Photo], np.ndarray]:
    rng = np.random.default_rng(1)
    photos, x = [], []
    for place in ("Kampala", "Banepa", "Zanzibar"):
        for k in range(n_per_place):
            land = k % 2 == 0
            photos.append(Photo(Path(f"/sets/a/images/{place}-{k}.jpg"), "clear_roof" if land else
                                "cluttered_roof", land, place, "CC-BY-4.0"))  # fmt: skip
            x.append(rng.normal(1.0 if land else -1.0, 1.0, 6))
    return photos, np.array(x)


def test_held_out_reads_never_learn_from_the_place_they_judge() -> None:
    photos, x = _photos()
    folds = [["Kampala"], ["Banepa"], ["Zanzibar"]]
    before = held_out(photos, x, folds)
    flipped = [
        Photo(p.path, p.label, (not p.land) if p.source == "Kampala" else p.land, p.source, p.licence)
        for p in photos
    ]
    after = held_out(flipped, x, folds)
    kampala = np.array([p.source == "Kampala" for p in photos])
    assert np.array_equal(before[kampala], after[kampala])  # its own labels never reached its fold
    assert not np.allclose(before[~kampala], after[~kampala])  # they did reach the other folds'
    assert np.all((before >= 0) & (before <= 1))


def test_the_fold_report_chooses_the_mean_threshold_under_the_false_accept_limit() -> None:
    photos, x = _photos()
    folds_places = [["Kampala"], ["Banepa"], ["Zanzibar"]]
    whole = held_out(photos, x, folds_places)
    seen = {
        str(p.path): {"confirmed": bool(p.land), "clear_p": 0.95 if p.land or k % 10 == 1 else 0.05,
                      "rank_score": 1.0 if p.land else 0.0}
        for k, p in enumerate(photos)
    }  # fmt: skip
    folds = {"photos": seen, "chosen_threshold": 0.9,
             "folds": [{"places": names, "threshold": 0.5} for names in folds_places]}  # fmt: skip
    report = fold_report(photos, folds, whole, max_false_accept=0.1)
    pooled = report["pooled"]
    assert pooled["false_accepts"] <= 0.1 * pooled["unsafe"]
    assert pooled["confirm_cases"] == len(photos)
    assert set(report["per_place"]) == {"Kampala", "Banepa", "Zanzibar"}
    assert report["photos"][str(photos[0].path)]["mixed"] == pytest.approx(
        mixed(0.95, float(whole[0])), abs=1e-4
    )


def test_whole_blob_is_the_normalised_square_and_its_mirror() -> None:
    rgb = np.zeros((30, 50, 3), np.uint8)
    rgb[:, :25] = 255
    blob = whole_blob(rgb, side=32, views=2)
    assert blob.shape == (2, 3, 32, 32)
    assert blob.dtype == np.float32
    assert np.allclose(blob[1], blob[0][:, :, ::-1])
    assert blob[0, 0, 0, 0] == pytest.approx((1.0 - MEAN[0]) / STD[0], abs=1e-5)


def test_roof_close_ups_join_every_fold_fit_and_are_never_scored() -> None:
    """landfall_train.whole_read --closeups: procedural roof close-ups read as photographs are, labelled
    clear when nothing stands on them, enter each fold's fit; the held-out probabilities are still one
    per photograph, and the close-ups move them."""
    from landfall_train.closeups import OBJECT, closeup
    from landfall_train.whole_read import CLOSEUP_PX, CLOSEUP_SEED

    x, y = closeup_features(4)
    assert x.shape == (4, 1280)
    labels = [0.0 if (closeup(CLOSEUP_SEED, k, CLOSEUP_PX)[1] == OBJECT).any() else 1.0 for k in range(4)]
    assert y.tolist() == labels
    assert closeup_features(0)[0].shape == (0, 1280)
    rng = np.random.default_rng(0)
    photos = [Photo(Path(f"/p/{k}.jpg"), "roof_clear" if k % 2 else "road", bool(k % 2), f"s{k % 3}", "CC0")
              for k in range(12)]  # fmt: skip
    feats = rng.normal(0.0, 1.0, (12, 1280))
    folds = [["s0"], ["s1"], ["s2"]]
    alone = held_out(photos, feats, folds)
    both = held_out(photos, feats, folds, extra=(rng.normal(0.0, 1.0, (4, 1280)), np.array([1.0, 0, 1, 0])))
    assert alone.shape == both.shape == (12,)
    assert not np.isnan(both).any()
    assert not np.allclose(alone, both)


def test_the_nested_figures_choose_each_folds_threshold_without_it() -> None:
    """whole_read's ``nested`` entry: a fold's threshold is chosen on the other folds' photographs, their
    whole reads fitted without it, so its own labels never move it; every labelled photograph is judged
    once."""
    from landfall_train.whole_read import nested

    photos, x = _photos()
    names = [["Kampala"], ["Banepa"], ["Zanzibar"]]

    def report(ps: list[Photo]) -> dict[str, Any]:
        whole = held_out(ps, x, names)
        seen = {
            str(p.path): {"confirmed": True, "clear_p": 0.9 if p.land else 0.3 + 0.02 * k,
                          "rank_score": 1.0 if p.land else 0.0}
            for k, p in enumerate(ps)
        }  # fmt: skip
        folds = {"photos": seen, "chosen_threshold": 0.9,
                 "folds": [{"places": n, "threshold": 0.5} for n in names]}  # fmt: skip
        return nested(ps, folds, x, whole, max_false_accept=0.05)

    before = report(photos)
    assert before["confirm_cases"] == len(photos)
    assert len(before["thresholds"]) == 3
    flipped = [
        Photo(p.path, p.label, (not p.land) if p.source == "Kampala" else p.land, p.source, p.licence)
        for p in photos
    ]
    after = report(flipped)
    assert after["thresholds"][0] == before["thresholds"][0]  # Kampala's labels never chose its threshold
    assert after["thresholds"][1:] != before["thresholds"][1:]  # they did choose the others'


@pytest.mark.parametrize(
    ("flags", "says"),
    [
        (["--side", "200"], "--side must be a multiple of 16"),
        (["--weight", "1.5"], "--weight must lie in 0..1"),
    ],
)
def test_a_bad_side_or_weight_is_refused_before_anything_is_read(
    tmp_path: Path, flags: list[str], says: str
) -> None:
    from landfall_train.whole_read import main

    with pytest.raises(SystemExit, match=says):
        main(["--folds", str(tmp_path / "absent.json"), *flags])


def test_the_whole_read_is_exported_and_named_at_the_side_and_views_it_was_fitted_at(tmp_path: Path) -> None:
    """``--side`` / ``--views``: the exported graph reads that side, and the sidecar says so, as the
    companion reads it back (LandNet.whole_side_px)."""
    from landfall_train.whole_read import attach, export

    model = tmp_path / "m"
    for suffix in (".onnx", ".json"):
        shutil.copy(LIGHT.with_suffix(suffix), model.with_suffix(suffix))
    w = np.random.default_rng(1).normal(0.0, 0.01, 1280)
    onnx, worst = export(w, 0.2, tmp_path / "m-whole.onnx", side=160, views=1)
    assert worst < 1e-3
    attach(model.with_suffix(".onnx"), onnx, {"weight": 0.5}, 0.6, "test", side=160, views=1)
    net = LandNet.load(model.with_suffix(".onnx"))
    assert net.whole_side_px == 160
    rgb = np.random.default_rng(3).integers(0, 256, (120, 200, 3), dtype=np.uint8)
    reading = net.read(rgb)
    assert net.confirmation(reading, rgb).whole_p is not None
