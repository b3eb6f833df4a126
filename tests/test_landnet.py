"""The LandNet runtime (companion/reasoning/landnet.py) and the onboard tier with ``judge="landnet"``,
on the packaged LandNet-S, the default: loading and its errors, input validation, determinism (threads
included), any crop size, the onboard switch and its config, close-ups of simbridge scenes, and a
training smoke test (landfall_train; needs torch). The packaged LandNet-E with its whole read:
tests/test_landnet_e.py."""

from __future__ import annotations

import json
import shutil
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest

from companion.config import ConfigError
from companion.config_schema import ReasonerConfig
from companion.perception.surface_id import Candidate
from companion.reasoning.base import ConfirmRequest, Decision, RankRequest
from companion.reasoning.landnet import (
    DEFAULT_MODEL,
    OUTPUTS,
    PACKAGED,
    LandNet,
    LandNetError,
    SceneReading,
    average_views,
    model_outputs,
    model_path,
    rank_hazard,
    view_batch,
)
from companion.reasoning.onboard import OnboardReasoner
from companion.reasoning.tiers import build_cascade
from simbridge.world.live import LiveWorld
from tests.views import (
    close_up,
    open_field_toml,
    site_cut,
)

LIGHT = PACKAGED["landnet-s"]


@pytest.fixture(scope="module")
def net() -> LandNet:
    return LandNet.load(LIGHT)


@pytest.fixture(scope="module")
def judge(net: LandNet) -> OnboardReasoner:
    return OnboardReasoner(judge="landnet", landnet=net)


def _image(h: int, w: int, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 256, (h, w, 3), dtype=np.uint8)


# --- loading ------------------------------------------------------------------------------------------
def test_landnet_load_packaged_model_and_sidecar(net: LandNet) -> None:
    meta = json.loads(LIGHT.with_suffix(".json").read_text())
    assert net.classes == tuple(meta["classes"])
    assert {"roof", "object", "person", "vehicle", "water", "marking"} <= set(net.classes)
    assert 0.0 < net.clear_threshold < 1.0
    assert ((net.cell_thresholds > 0.0) & (net.cell_thresholds < 1.0)).all()
    assert meta["command"].startswith("python -m landfall_train")
    # the packaged model averages two nets trained from seeds 0 and 1 (landfall_train.ensemble)
    assert [m["seed"] for m in meta["members"]] == [0, 1]
    assert all(m["command"].startswith("python -m landfall_train --seed") for m in meta["members"])
    assert meta["calibration"]["views"] == net.views
    assert LIGHT.stat().st_size < 4_000_000


def test_a_packaged_model_is_named_and_a_path_is_a_file(tmp_path: Path) -> None:
    assert model_path(None) == model_path("") == model_path("landnet-e") == DEFAULT_MODEL
    assert PACKAGED["landnet-e"] == DEFAULT_MODEL
    assert model_path("landnet-s") == LIGHT
    onnx = tmp_path / "mine.onnx"
    shutil.copy(LIGHT, onnx)
    shutil.copy(LIGHT.with_suffix(".json"), onnx.with_suffix(".json"))
    assert model_path(str(onnx)) == onnx
    assert LandNet.load(str(onnx)).name == "landnet-s"  # the sidecar's name


def test_landnet_load_missing_file_is_an_error_naming_it(tmp_path: Path) -> None:
    missing = tmp_path / "nothing.onnx"
    with pytest.raises(LandNetError, match=r"nothing\.onnx: model file not found") as err:
        LandNet.load(missing)
    assert err.value.path == missing


def _copy_model(tmp_path: Path) -> Path:
    onnx = tmp_path / "m.onnx"
    shutil.copy(LIGHT, onnx)
    shutil.copy(LIGHT.with_suffix(".json"), onnx.with_suffix(".json"))
    return onnx


def test_landnet_load_corrupt_weights_are_an_error_naming_the_file(tmp_path: Path) -> None:
    onnx = _copy_model(tmp_path)
    blob = bytearray(onnx.read_bytes())
    blob[len(blob) // 2] ^= 0xFF
    onnx.write_bytes(bytes(blob))
    with pytest.raises(LandNetError, match=r"m\.onnx: sha256 .* does not match"):
        LandNet.load(onnx)
    # a sidecar that vouches for garbage: the runtime's error, still naming the file
    onnx.write_bytes(b"not an onnx model")
    meta = json.loads(onnx.with_suffix(".json").read_text())
    import hashlib

    meta["sha256"] = hashlib.sha256(b"not an onnx model").hexdigest()
    onnx.with_suffix(".json").write_text(json.dumps(meta))
    with pytest.raises(LandNetError, match=r"m\.onnx: OpenCV cannot load"):
        LandNet.load(onnx, backend="opencv")
    with pytest.raises(LandNetError, match=r"m\.onnx: ONNX Runtime cannot load"):
        LandNet.load(onnx, backend="onnxruntime")


def test_landnet_onnxruntime_and_opencv_read_alike(net: LandNet) -> None:
    """The default runtime (ONNX Runtime) and the fallback (OpenCV's DNN module) give the same reading."""
    assert net.backend == "onnxruntime"
    cv = LandNet.load(LIGHT, backend="opencv")
    for h, w in ((96, 96), (240, 320), (540, 960)):
        img = _image(h, w)
        a, b = net.read(img), cv.read(img)
        assert a.clear_p == pytest.approx(b.clear_p, abs=1e-5)
        assert dict(a.shares) == pytest.approx(dict(b.shares), abs=0.02)  # a cell on a threshold may flip


def test_landnet_without_onnxruntime_falls_back_to_opencv(monkeypatch: pytest.MonkeyPatch) -> None:
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(
        importlib.util, "find_spec", lambda name, *a: None if name == "onnxruntime" else real(name, *a)
    )
    assert LandNet.load().backend == "opencv"
    with pytest.raises(ValueError, match="backend must be one of"):
        LandNet.load(backend="tensorrt")


def test_landnet_load_bad_sidecar_is_an_error_naming_it(tmp_path: Path) -> None:
    onnx = _copy_model(tmp_path)
    meta = json.loads(onnx.with_suffix(".json").read_text())
    del meta["thresholds"]["cells"]["water"]
    onnx.with_suffix(".json").write_text(json.dumps(meta))
    with pytest.raises(LandNetError, match=r"m\.json: unreadable model sidecar"):
        LandNet.load(onnx)
    meta = json.loads(LIGHT.with_suffix(".json").read_text())
    meta["input"]["views"] = 3
    onnx.with_suffix(".json").write_text(json.dumps(meta))
    with pytest.raises(LandNetError, match=r"m\.json: .*input\.views must be one of \(1, 2, 4\), got 3"):
        LandNet.load(onnx)
    meta = json.loads(LIGHT.with_suffix(".json").read_text())
    meta["hazard_classes"] = ["object", "lava"]
    onnx.with_suffix(".json").write_text(json.dumps(meta))
    with pytest.raises(LandNetError, match=r"m\.json: .*hazard_classes must be a non-empty list"):
        LandNet.load(onnx)
    for key in ("confirm_short_side_px", "rank_short_side_px"):
        for bad in (16, "96", 96.0, True):
            meta = json.loads(LIGHT.with_suffix(".json").read_text())
            meta["input"][key] = bad
            onnx.with_suffix(".json").write_text(json.dumps(meta))
            with pytest.raises(LandNetError, match=rf"m\.json: .*input\.{key} must be an integer"):
                LandNet.load(onnx)
    meta = json.loads(LIGHT.with_suffix(".json").read_text())
    del meta["input"]["confirm_short_side_px"]  # an older sidecar: both read at short_side_px
    del meta["input"]["rank_short_side_px"]
    onnx.with_suffix(".json").write_text(json.dumps(meta))
    older = LandNet.load(onnx)
    assert older.confirm_short_side_px == older.rank_short_side_px == meta["input"]["short_side_px"]


# --- views: the image and its mirror images ------------------------------------------------------------
def test_average_views_flips_each_reading_back_before_averaging() -> None:
    rng = np.random.default_rng(3)
    base = rng.random((2, 11, 6, 9))  # two images' cell probabilities
    flips = (lambda a: a, lambda a: a[..., ::-1], lambda a: a[..., ::-1, :], lambda a: a[..., ::-1, ::-1])
    readings = np.stack([f(b) for b in base for f in flips])  # as a net would answer view_batch's input
    clear = np.array([0.1, 0.3, 0.5, 0.7, 0.2, 0.2, 0.2, 0.2])
    cells, clear_p = average_views(readings, clear, 4)
    np.testing.assert_allclose(cells, base)
    np.testing.assert_allclose(clear_p, [0.4, 0.2])
    chw = rng.random((3, 4, 6))
    batch = view_batch(chw, 4)
    assert batch.shape == (4, 3, 4, 6)
    np.testing.assert_array_equal(batch[3], chw[:, ::-1, ::-1])
    assert view_batch(chw, 1).shape == (1, 3, 4, 6)
    two = view_batch(chw, 2)
    np.testing.assert_array_equal(two[1], chw[:, :, ::-1])
    pairs = np.stack([f(b) for b in base for f in flips[:2]])
    cells, clear_p = average_views(pairs, np.array([0.2, 0.4, 0.6, 0.6]), 2)
    np.testing.assert_allclose(cells, base)
    np.testing.assert_allclose(clear_p, [0.3, 0.6])


def test_landnet_views_four_average_the_mirror_images_and_one_reads_alone(tmp_path: Path) -> None:
    onnx = _copy_model(tmp_path)
    four = LandNet.load(onnx)
    assert four.views == 4  # the packaged model reads with its mirror images
    meta = json.loads(onnx.with_suffix(".json").read_text())
    meta["input"]["views"] = 1
    onnx.with_suffix(".json").write_text(json.dumps(meta))
    one = LandNet.load(onnx)
    img = _image(96, 128, 5)
    mirrored = [img, img[:, ::-1], img[::-1], img[::-1, ::-1]]
    mean_of_ones = float(np.mean([one.read(np.ascontiguousarray(m)).clear_p for m in mirrored]))
    assert four.read(img).clear_p == pytest.approx(mean_of_ones, abs=1e-5)
    assert one.read(img).clear_p != pytest.approx(four.read(img).clear_p, abs=1e-6)
    flat = np.full((64, 64, 3), 128, np.uint8)  # mirror-symmetric: every view is the same image
    assert four.read(flat).clear_p == pytest.approx(one.read(flat).clear_p, abs=1e-5)
    two = (img, img[:, ::-1])
    assert four.read(img, 2).clear_p == pytest.approx(
        float(np.mean([one.read(np.ascontiguousarray(m)).clear_p for m in two])), abs=1e-5
    )


def test_landnet_ranks_read_with_rank_views(net: LandNet, monkeypatch: pytest.MonkeyPatch) -> None:
    """Ranks read each crop with the sidecar's rank_views (2 for the packaged model: five crops where a
    confirmation reads one image) at its rank_short_side_px (144), confirmations with its views (4) at
    its confirm_short_side_px (96; the input's own short side is 128)."""
    assert (net.views, net.rank_views) == (4, 2)
    assert (net.short_side_px, net.confirm_short_side_px, net.rank_short_side_px) == (128, 96, 144)
    asked: list[int | None] = []
    sides: list[int | None] = []
    read = LandNet.read

    def spy(
        self: LandNet,
        rgb: np.ndarray,
        views: int | None = None,
        short_side: int | None = None,
        rank: bool = False,
    ) -> SceneReading:
        asked.append(views)
        sides.append(short_side)
        return read(self, rgb, views, short_side, rank)

    monkeypatch.setattr(LandNet, "read", spy)
    judge = OnboardReasoner(judge="landnet", landnet=net)
    crops = (_image(40, 60, 1), _image(50, 50, 2))
    judge.rank_sync(RankRequest(crops))
    cands = tuple(Candidate(k, (0, 0, 10, 10), (5.0, 5.0), area_m2=100.0) for k in range(2))
    judge.rank_sync(RankRequest(crops, cands))
    assert asked == [2, 2, 2, 2]
    assert sides == [144] * 4
    asked.clear()
    sides.clear()
    judge.confirm_sync(ConfirmRequest(_image(90, 160, 3)))
    assert asked == [None]  # the sidecar's views
    assert sides == [96]


@pytest.mark.parametrize(
    ("h", "w", "at_128", "at_96"),
    [((90, 160, (128, 224), (96, 176))), (300, 300, (128, 128), (96, 96)), (200, 1000, (48, 256), (32, 192))],
)
def test_landnet_reads_smaller_at_a_given_short_side(
    net: LandNet, h: int, w: int, at_128: tuple[int, int], at_96: tuple[int, int]
) -> None:
    """A short side of 96 scales the image by 96 / 128 of what 128 does, the longer side's cap (256 at
    128) too, sides still multiples of 16; the reading's grid follows."""
    assert net.input_size(h, w) == at_128
    assert net.input_size(h, w, 96) == at_96
    assert net.read(_image(h, w), short_side=96).grid == (at_96[0] // 8, at_96[1] // 8)


def test_landfall_train_refuses_a_confirm_side_the_companion_would_refuse(
    capsys: pytest.CaptureFixture[str],
) -> None:
    pytest.importorskip("torch", reason="training needs torch: pip install -e '.[train]'")
    from landfall_train.train import main

    for flag in ("--confirm-side", "--rank-side"):
        with pytest.raises(SystemExit):
            main(["--recalibrate", flag, "16", "--out", "nowhere"])
        assert f"{flag} must be at least 32 px, got 16" in capsys.readouterr().err


# --- reading --------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "bad",
    [
        [[1, 2, 3]],
        np.zeros((10, 10), np.uint8),
        np.zeros((10, 10, 4), np.uint8),
        np.zeros((10, 10, 3), np.float32),
        np.zeros((0, 10, 3), np.uint8),
    ],
)
def test_landnet_read_rejects_bad_input(net: LandNet, bad: object) -> None:
    with pytest.raises(ValueError, match="expected"):
        net.read(bad)  # type: ignore[arg-type]


@pytest.mark.parametrize(("h", "w"), [(1, 1), (5, 3), (37, 101), (128, 128), (540, 960), (1000, 200)])
def test_landnet_read_any_size(net: LandNet, h: int, w: int) -> None:
    r = net.read(_image(h, w))
    ih, iw = net.input_size(h, w)
    assert ih % 16 == 0
    assert iw % 16 == 0
    assert r.grid == (ih // 8, iw // 8)
    assert r.size_px == (h, w)
    assert 0.0 <= r.clear_p <= 1.0
    assert all(0.0 <= s <= 1.0 for _c, s in r.shares)
    assert 0.0 <= r.hazard_peak <= 1.0
    assert 0.0 <= r.hazard <= 3.0
    for k, c in enumerate(net.classes):  # a hazard class seen: its cell probability reached its threshold
        if c in ("object", "person", "vehicle", "water", "marking") and r.share(c) > 0.0:
            assert r.hazard_peak >= net.cell_thresholds[k]


def test_landnet_read_is_deterministic_across_threads(net: LandNet) -> None:
    images = [_image(96 + 16 * k, 160, seed=k) for k in range(6)]
    first = [net.read(img) for img in images]
    with ThreadPoolExecutor(max_workers=4) as pool:
        again = list(pool.map(net.read, images * 3))
    for k, r in enumerate(again):
        assert r == first[k % len(images)]


def test_scene_reading_phrases_say_what_and_where() -> None:
    r = SceneReading(
        "landnet-s", (100, 100), (16, 16), 0.2, (("roof", 0.7), ("object", 0.05), ("water", 0.0)),
        (("roof", ("centre",)), ("object", ("upper left", "centre"))), (("object", 2),),
    )  # fmt: skip
    assert r.phrase("object") == "objects on the surface (2: upper left, centre)"
    assert r.observations()[0] == "objects on the surface (2: upper left, centre)"
    assert "roof surface 70 %" in r.observations()
    assert r.hazard_peak == 0.0
    assert r.hazard == pytest.approx(1.2)  # 3 x (0.5 x (1 - 0.2) + 0.5 x 0)


def test_scene_reading_hazard_weighs_the_clear_probability_and_the_hazard_peak() -> None:
    """A rank's hazard: half the clear-site probability's shortfall, half the likeliest hazard cell."""

    def reading(clear_p: float, peak: float) -> SceneReading:
        return SceneReading("landnet-s", (64, 64), (8, 8), clear_p, (("roof", 1.0),), (), (), peak)

    assert reading(1.0, 0.0).hazard == 0.0
    assert reading(0.0, 1.0).hazard == pytest.approx(3.0)
    assert reading(0.4, 0.1).hazard == pytest.approx(3.0 * (0.5 * 0.6 + 0.5 * 0.1))
    # the same clear-site probability: the roof whose likeliest hazard cell is likelier ranks lower
    assert reading(0.4, 0.9).hazard > reading(0.4, 0.1).hazard
    assert reading(0.4, 0.9).to_json()["hazard_peak"] == 0.9


def test_scene_reading_hazard_with_the_bare_head_weighs_it_and_not_the_peak() -> None:
    """A model with the bare head (landfall-landnet/2): a quarter the clear-site probability, three
    quarters the probability that nothing stands on the surface; the hazard peak is reported only."""

    def reading(clear_p: float, peak: float, bare: float | None) -> SceneReading:
        return SceneReading("landnet-s", (64, 64), (8, 8), clear_p, (("roof", 1.0),), (), (), peak, bare)

    assert reading(0.4, 0.9, 0.8).hazard == pytest.approx(3.0 * (1.0 - (0.25 * 0.4 + 0.75 * 0.8)))
    assert reading(0.4, 0.9, 0.8).hazard == reading(0.4, 0.1, 0.8).hazard
    assert reading(0.4, 0.1, 0.2).hazard > reading(0.4, 0.1, 0.8).hazard
    assert reading(1.0, 1.0, 1.0).hazard == 0.0
    assert reading(0.4, 0.9, 0.8).to_json()["bare_p"] == 0.8
    assert reading(0.4, 0.9, None).to_json()["bare_p"] is None
    assert reading(0.4, 0.9, None).hazard == pytest.approx(3.0 * (0.5 * 0.6 + 0.5 * 0.9))
    # the array form scores held-out renders alike (landfall_train.compare --rank)
    clear, peak, bare = np.array([0.4, 0.9]), np.array([0.9, 0.2]), np.array([0.8, 0.1])
    assert rank_hazard(clear, peak, bare) == pytest.approx([reading(0.4, 0.9, 0.8).hazard,
                                                            reading(0.9, 0.2, 0.1).hazard])  # fmt: skip
    assert rank_hazard(clear, peak, None, 1.0) == pytest.approx(3.0 * (1.0 - clear))


def test_landnet_sidecar_format_names_the_outputs(tmp_path: Path) -> None:
    assert model_outputs({"format": "landfall-landnet/1"}) == OUTPUTS
    assert model_outputs({}) == OUTPUTS
    assert model_outputs({"format": "landfall-landnet/2", "outputs": {"bare": "..."}}) == (*OUTPUTS, "bare")
    assert model_outputs({"rank_cells": {}}) == (*OUTPUTS, "cells_rank")  # LandNet-E's second cell head
    with pytest.raises(ValueError, match=r"names outputs\.bare"):
        model_outputs({"format": "landfall-landnet/2", "outputs": {}})
    with pytest.raises(ValueError, match="unknown model format 'landfall-landnet/9'"):
        model_outputs({"format": "landfall-landnet/9"})
    # a sidecar that promises the bare head over a graph without it: refused at load, naming the file
    onnx = _copy_model(tmp_path)
    meta = json.loads(onnx.with_suffix(".json").read_text())
    meta["format"] = "landfall-landnet/2"
    meta["outputs"]["bare"] = "(N, 1, 1, 1) logit"
    onnx.with_suffix(".json").write_text(json.dumps(meta))
    for backend in ("onnxruntime", "opencv"):
        with pytest.raises(LandNetError, match=r"m\.onnx: the ONNX model does not give what its sidecar"):
            LandNet.load(onnx, backend=backend)
    meta["format"] = "landfall-landnet/9"
    onnx.with_suffix(".json").write_text(json.dumps(meta))
    with pytest.raises(LandNetError, match=r"m\.json: unreadable model sidecar: .*unknown model format"):
        LandNet.load(onnx)
    meta["format"] = "landfall-landnet/1"
    meta["rank_cells"] = {"output": "cells_rank", "thresholds": {"roof": 0.5}}
    onnx.with_suffix(".json").write_text(json.dumps(meta))
    with pytest.raises(LandNetError, match=r"classes and rank_cells\.thresholds do not match"):
        LandNet.load(onnx)


def test_bare_head_fit_reads_the_parts_and_refuses_one_sided_data() -> None:
    pytest.importorskip("sklearn", reason="the bare head needs scikit-learn: pip install -e '.[train]'")
    pytest.importorskip("onnx", reason="landfall_train.bare needs onnx: pip install -e '.[train]'")
    from landfall_train.bare import fit, used_columns
    from landfall_train.labels import CLASSES

    rng = np.random.default_rng(0)
    n_feat = 30
    features = rng.normal(0.0, 1.0, (400, n_feat)).astype(np.float32)
    bare = features[:, -1] + 0.3 * rng.normal(0.0, 1.0, 400) > 0.0  # the last part decides
    weight, bias = fit(features, bare, 1.0, "parts")
    assert (weight[: n_feat - 2 * len(CLASSES)] == 0.0).all()  # the pooled features are not read
    assert weight[-1] > 0.0
    logit = features @ weight + bias
    assert ((logit > 0) == bare).mean() > 0.85
    assert (fit(features, bare, 1.0, "all")[0] != 0.0).all()
    assert list(used_columns(30, "parts")) == list(range(30 - 2 * len(CLASSES), 30))
    with pytest.raises(ValueError, match="all bare or none is"):
        fit(features, np.ones(400, bool), 1.0)
    with pytest.raises(ValueError, match="inputs must be"):
        used_columns(30, "texture")


# --- the onboard switch ---------------------------------------------------------------------------------
def test_the_open_ground_keys_reach_the_onboard_confirmation() -> None:
    default = build_cascade(ReasonerConfig()).onboard.confirm_params
    assert (default.open_ground_area_m2, default.open_ground_edge_m) == (600.0, 10.0)
    set_ = build_cascade(ReasonerConfig(open_ground_area_m2=900.0, open_ground_edge_m=12.5)).onboard
    assert (set_.confirm_params.open_ground_area_m2, set_.confirm_params.open_ground_edge_m) == (900.0, 12.5)


def test_companion_defaults_to_landnet_the_class_to_cues_and_unknown_is_refused() -> None:
    # The companion's configuration picks the learned judge; a bare OnboardReasoner (library use,
    # the cue tests) keeps the hand-written cues.
    assert ReasonerConfig().onboard_judge == "landnet"
    assert build_cascade(ReasonerConfig()).onboard.judge == "landnet"
    assert OnboardReasoner().judge == "cues"
    assert OnboardReasoner().landnet is None
    with pytest.raises(ValueError, match="unknown onboard judge 'net'"):
        OnboardReasoner(judge="net")


def test_onboard_landnet_missing_weights_fail_start_up_naming_the_file(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    monkeypatch.setitem(PACKAGED, "landnet-e", tmp_path / "gone.onnx")  # the default
    with pytest.raises(
        ConfigError,
        match=r"onboard_judge = 'landnet', onboard_model = 'landnet-e': .*gone.onnx: model file not found",
    ):
        build_cascade(ReasonerConfig(onboard_judge="landnet"))
    assert build_cascade(ReasonerConfig(onboard_judge="cues")).onboard is not None  # cues need no file


def test_onboard_landnet_rank_images_only(judge: OnboardReasoner) -> None:
    crops = [_image(60, 90, 1), _image(120, 120, 2), _image(30, 30, 3)]
    transcript: list[dict[str, object]] = []
    ranking = judge.rank_sync(RankRequest(crops, transcript=transcript))
    assert sorted(ranking.order) == [0, 1, 2]
    assert ranking.rationale.startswith(f"site {ranking.order[0]}: ")
    assert "LandNet-S reading only" in ranking.rationale
    assert transcript[0]["judge"] == "landnet"
    again = judge.rank_sync(RankRequest(crops))
    assert (again.order, again.rationale) == (ranking.order, ranking.rationale)
    with pytest.raises(ValueError, match="expected"):
        judge.rank_sync(RankRequest([np.zeros((4, 4), np.uint8)]))


# --- close-ups of simbridge's scenario1 (tests/views.py) -----------------------------------------------
HEIGHT_M = 20.0


def _cut_decision(
    judge: OnboardReasoner, city: LiveWorld, ne: tuple[float, float], up_m: float
) -> tuple[bool, str]:
    frame, _check = close_up(city, ne, up_m, HEIGHT_M)
    d = judge.confirm_sync(ConfirmRequest(site_cut(city, frame, HEIGHT_M)))
    assert d.tier == "onboard"
    name = judge.landnet.name if judge.landnet is not None else ""
    assert f"[{name}" in d.rationale or d.rationale.startswith("rejected: ")
    return d.accept, d.rationale


def test_landnet_confirm_accepts_the_clear_gravel_roof(judge: OnboardReasoner, city: LiveWorld) -> None:
    accept, why = _cut_decision(judge, city, (0.0, -27.0), 22.0)
    assert accept, why


def test_landnet_confirm_rejects_water(judge: OnboardReasoner, city: LiveWorld) -> None:
    accept, why = _cut_decision(judge, city, (0.0, 150.0), -0.8)
    assert not accept, why


def test_landnet_confirm_rejects_the_cluttered_roof(judge: OnboardReasoner, city: LiveWorld) -> None:
    accept, why = _cut_decision(judge, city, (0.0, 29.0), 18.0)
    assert not accept, why


def test_landnet_confirm_open_country_field_passes_but_not_among_buildings(
    judge: OnboardReasoner, tmp_path: Path
) -> None:
    # The net's clear-site probability means a clear roof; a bare field measured at street level with
    # no roof measured in the recovery (open country) passes when nothing stands on it. Among
    # buildings the same field is a last resort (street level), as with the cues.
    from simbridge.world.scenario_file import load_scenario_file

    path = tmp_path / "open_field.toml"
    path.write_text(open_field_toml(60.0, 60.0))
    field = LiveWorld(load_scenario_file(path))
    frame, check = close_up(field, (0.0, 0.0), 0.0, HEIGHT_M)
    image = site_cut(field, frame, HEIGHT_M)
    d = judge.confirm_sync(ConfirmRequest(image, check=check, site_up_m=0.0, built_up=False))
    assert d.accept, d.rationale
    assert "open country" in d.rationale
    d = judge.confirm_sync(ConfirmRequest(image, check=check, site_up_m=0.0, built_up=True))
    assert not d.accept
    assert d.binding
    assert "street_level" in d.hazards
    d = judge.confirm_sync(ConfirmRequest(image))  # no geometry: the image alone, a clear roof or nothing
    assert not d.accept, d.rationale
    # open country too keeps open ground's margins where Surface ID measured them: the field's edge is
    # a road or a path, and a small field is all edge
    for area_m2, edge_m, why in ((3000.0, 4.0, "4 m from its edge (at least 10 m)"),
                                 (300.0, 12.0, "300 m2 of it (at least 600 m2)")):  # fmt: skip
        d = judge.confirm_sync(
            ConfirmRequest(image, check=check, site_up_m=0.0, site_area_m2=area_m2, site_edge_m=edge_m)
        )
        assert not d.accept
        assert d.hazards == ("cramped",)  # open ground, but a small one: before a sidewalk in the ledger
        assert f"open ground, but {why}" in d.rationale
    wide = ConfirmRequest(image, check=check, site_up_m=0.0, site_area_m2=3000.0, site_edge_m=12.0)
    assert judge.confirm_sync(wide).accept


def test_landnet_confirm_takes_a_wide_lawn_among_buildings_but_not_a_small_one_or_its_edge(
    judge: OnboardReasoner, tmp_path: Path
) -> None:
    """Among buildings street level is a last resort, but for open ground: a grass surface Surface ID
    measured large (``open_ground_area_m2``), the site far from its edge (``open_ground_edge_m``), is
    judged as open country is. The same lawn measured small, or the site near its edge, stays a last
    resort; a bare soil field among buildings too (not grass: a plaza or a yard reads so)."""
    from simbridge.world.scenario_file import load_scenario_file

    path = tmp_path / "lawn.toml"
    path.write_text(open_field_toml(60.0, 60.0).replace('ground = "soil"', 'ground = "grass"'))
    lawn = LiveWorld(load_scenario_file(path))
    frame, check = close_up(lawn, (0.0, 0.0), 0.0, HEIGHT_M)
    image = site_cut(lawn, frame, HEIGHT_M)

    def confirm(area_m2: float | None, edge_m: float | None) -> Decision:
        return judge.confirm_sync(
            ConfirmRequest(
                image, check=check, site_up_m=0.0, built_up=True, site_area_m2=area_m2, site_edge_m=edge_m
            )
        )

    wide = confirm(3200.0, 16.0)
    assert wide.accept, wide.rationale
    assert "open ground among buildings: 3,200 m2 of it, 16 m from its edge" in wide.rationale
    for area_m2, edge_m in ((400.0, 16.0), (3200.0, 6.0), (None, None)):
        d = confirm(area_m2, edge_m)
        assert not d.accept, (area_m2, edge_m, d.rationale)
        assert "street_level" in d.hazards
    soil = LiveWorld(load_scenario_file(_write(tmp_path / "soil.toml", open_field_toml(60.0, 60.0))))
    frame, check = close_up(soil, (0.0, 0.0), 0.0, HEIGHT_M)
    d = judge.confirm_sync(
        ConfirmRequest(
            site_cut(soil, frame, HEIGHT_M), check=check, site_up_m=0.0, built_up=True,
            site_area_m2=3200.0, site_edge_m=16.0,
        )
    )  # fmt: skip
    assert not d.accept
    assert "street_level" in d.hazards


def test_landnet_confirm_takes_wide_grass_above_its_surroundings_as_open_ground(
    judge: OnboardReasoner, tmp_path: Path
) -> None:
    """On a slope a meadow or a terrace measures well above its surroundings (the ground falls away on
    one side), as a roof does; the clear-site probability, which means a clear roof, refuses grass. Wide
    grass there is judged as open ground (and the descent then watches for people, ``open_ground``);
    the same lawn measured small or near its edge is still refused as a roof would be."""
    from simbridge.world.scenario_file import load_scenario_file

    lawn = LiveWorld(
        load_scenario_file(
            _write(
                tmp_path / "lawn.toml",
                open_field_toml(60.0, 60.0).replace('ground = "soil"', 'ground = "grass"'),
            )
        )
    )
    frame, check = close_up(lawn, (0.0, 0.0), 0.0, HEIGHT_M)
    image = site_cut(lawn, frame, HEIGHT_M)

    def confirm(area_m2: float, edge_m: float) -> Decision:
        return judge.confirm_sync(
            ConfirmRequest(image, check=check, site_up_m=9.0, site_area_m2=area_m2, site_edge_m=edge_m)
        )

    wide = confirm(5600.0, 29.0)
    assert wide.accept, wide.rationale
    assert wide.open_ground
    assert (
        "open ground 9 m above its surroundings, a terrace or a green roof: 5,600 m2 of it" in wide.rationale
    )
    for area_m2, edge_m in ((400.0, 29.0), (5600.0, 6.0)):
        d = confirm(area_m2, edge_m)
        assert not d.accept, (area_m2, edge_m, d.rationale)
        assert not d.open_ground
    on_roof = judge.confirm_sync(ConfirmRequest(image, check=check, site_up_m=9.0))  # nothing measured
    assert not on_roof.accept, on_roof.rationale


def _write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


@pytest.mark.parametrize("weather", ["clear", "fog"])
@pytest.mark.parametrize("ground", ["soil", "paving"])
def test_landnet_confirm_refuses_a_plain_road_at_street_level_in_open_country(
    judge: OnboardReasoner, tmp_path: Path, ground: str, weather: str
) -> None:
    """A wide asphalt road with no markings through open country: from above it looks like a tar roof
    (the net may read it so, with a high clear-site probability), but Surface ID measured it at street
    level, where roof-like paving is a road or a car park. Never a landing site, with or without a clear
    LiDAR disc, in clear air or fog (whose light must not tint grey asphalt); the same window off a roof
    (no geometry) is the net's to judge."""
    from simbridge.world.scenario_file import load_scenario_file

    path = tmp_path / "open_road.toml"
    path.write_text(
        open_field_toml(60.0, 60.0).replace('ground = "soil"', f'ground = "{ground}"')
        + '\n[[roads]]\nkind = "road"\npoints = [[-60.0, 0.0], [60.0, 0.0]]\nwidth_m = 40.0\n'
        "markings = false\n"
    )
    road = LiveWorld(load_scenario_file(path))
    frame, check = close_up(road, (0.0, 0.0), 0.0, HEIGHT_M, weather=weather)
    assert check.clear  # flat, smooth, nothing in the rotor disc: only what it is says no
    image = site_cut(road, frame, HEIGHT_M)
    d = judge.confirm_sync(ConfirmRequest(image, check=check, site_up_m=0.0, built_up=False))
    assert not d.accept, d.rationale
    assert "street_asphalt" in d.hazards, d.rationale
    assert d.binding  # street level: no remote tier's yes overrules it
    assert "a road or a car park" in d.rationale or "paving" in d.rationale
