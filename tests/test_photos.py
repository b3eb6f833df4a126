"""Learning from photographs (landfall_train.photo_set, .photos, .folds) and saying how sure the
judgement is."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from companion.reasoning.base import ConfirmRequest
from companion.reasoning.landnet import PACKAGED, LandNet, SceneReading
from companion.reasoning.net_judge import UNSURE_MARGIN, UNSURE_SPREAD, unsure
from companion.reasoning.onboard import OnboardReasoner

LIGHT = PACKAGED["landnet-s"]  # one file (LandNet-E's whole read is a second)

torch = pytest.importorskip("torch", reason="the training extra: pip install -e '.[train]'")

from landfall_train.folds import scores  # noqa: E402
from landfall_train.photo_set import (  # noqa: E402
    Photo,
    load_photos,
    photo_view,
    photo_view_middle,
    roof_surfaces,
    split,
    trainable,
)
from landfall_train.photos import _views, from_onnx, interpolate, pitched, with_real_roof  # noqa: E402


def _reading(clear_p: float, spread: float = 0.0) -> SceneReading:
    return SceneReading("landnet-s", (64, 64), (8, 8), clear_p, (("roof", 1.0),), (), (), clear_spread=spread)


def test_unsure_near_the_threshold_or_when_the_views_disagree() -> None:
    assert unsure(_reading(0.9), 0.4) == ""
    assert unsure(_reading(0.05), 0.4) == ""
    near = unsure(_reading(0.4 + UNSURE_MARGIN / 2), 0.4)
    assert near.startswith("unsure: ")
    assert "near its threshold 0.40" in near
    assert "near" in unsure(_reading(0.4 - UNSURE_MARGIN / 2), 0.4)  # an unsure "no" says so too
    split_views = unsure(_reading(0.95, UNSURE_SPREAD + 0.1), 0.4)
    assert "views disagree" in split_views
    assert "near" not in split_views


def _model_with_threshold(tmp_path: Path, threshold: float) -> LandNet:
    onnx = tmp_path / "m.onnx"
    shutil.copy(LIGHT, onnx)
    meta = json.loads(LIGHT.with_suffix(".json").read_text())
    meta["thresholds"]["clear"] = threshold
    onnx.with_suffix(".json").write_text(json.dumps(meta))
    return LandNet.load(onnx)


def test_an_unsure_confirm_says_so_in_its_rationale_record_and_decision(tmp_path: Path) -> None:
    flat = np.full((96, 96, 3), 118, np.uint8)  # mirror-symmetric: its views agree exactly
    p = LandNet.load(LIGHT).read(flat).clear_p
    transcript: list[dict[str, object]] = []
    guess = OnboardReasoner(judge="landnet", landnet=_model_with_threshold(tmp_path, p)).confirm_sync(
        ConfirmRequest(flat, transcript=transcript)
    )
    assert guess.unsure
    assert "unsure: clear-site confidence" in guess.rationale, guess.rationale
    assert transcript[-1]["unsure"] is True
    far = max(0.0, p - 3 * UNSURE_MARGIN) if p > 0.5 else min(1.0, p + 3 * UNSURE_MARGIN)
    sure = OnboardReasoner(judge="landnet", landnet=_model_with_threshold(tmp_path, far)).confirm_sync(
        ConfirmRequest(flat)
    )
    assert not sure.unsure
    assert "unsure" not in sure.rationale, sure.rationale


def test_members_read_back_from_the_merged_model_give_its_outputs() -> None:
    members = [from_onnx(f"{LIGHT}#m{k}/") for k in (0, 1)]
    net = LandNet.load(LIGHT, backend="onnxruntime")
    img = np.random.default_rng(3).integers(0, 256, (128, 160, 3), dtype=np.uint8)
    x = torch.from_numpy(((img.astype(np.float32) / 255 - 0.5) / 0.25).transpose(2, 0, 1)[None].copy())
    with torch.no_grad():
        clear = torch.stack([m(x)[1].reshape(()) for m in members]).mean()
    assert float(torch.sigmoid(clear)) == pytest.approx(net.read(img, 1).clear_p, abs=1e-4)


def test_interpolate_moves_the_weights_that_share_of_the_way() -> None:
    net = from_onnx(f"{LIGHT}#m0/")
    start = {k: v.clone() for k, v in net.state_dict().items()}
    with torch.no_grad():
        for p in net.parameters():
            p.add_(1.0)
    tuned = {k: v.clone() for k, v in net.state_dict().items()}
    interpolate(net, start, 0.25)
    w = "clear.weight"
    assert torch.allclose(net.state_dict()[w], start[w] + 0.25 * (tuned[w] - start[w]), atol=1e-6)
    interpolate(net, start, 0.0)
    assert torch.equal(net.state_dict()[w], start[w])


def _folder(root: Path, name: str, entries: list[dict[str, object]], imagery: str = "") -> Path:
    d = root / name
    (d / "images").mkdir(parents=True)
    rng = np.random.default_rng(len(name))
    for e in entries:
        cv2.imwrite(str(d / str(e["file"])), rng.integers(0, 256, (40, 60, 3), dtype=np.uint8))
    (d / "labels.json").write_text(json.dumps(entries))
    prov = [{"file": e["file"], "imagery": imagery} for e in entries]
    (d / "provenance.json").write_text(json.dumps(prov))
    return d


def test_photos_by_source_and_never_learnt_from_a_barred_licence(tmp_path: Path) -> None:
    oam = _folder(
        tmp_path, "oam",
        [{"file": "images/a.jpg", "label": "clear_roof", "land": True, "source_repo": "hotosm/fAIr-utilities",
          "license": "AGPL-3.0"},
         {"file": "images/b.jpg", "label": "not_roof", "land": None, "source_repo": "hotosm/fAIr-utilities",
          "license": "AGPL-3.0"}],
        imagery="drone orthophoto, Zanzibar, Tanzania",
    )  # fmt: skip
    other = _folder(
        tmp_path, "other",
        [{"file": "images/c.jpg", "label": "cluttered_roof", "land": False, "source_repo": "x/kite",
          "license": "CC-BY-3.0"},
         {"file": "images/d.jpg", "label": "clear_roof", "land": True, "source_repo": "y/sdd",
          "license": "terms allow non-commercial research/education use only"}],
    )  # fmt: skip
    photos = load_photos([oam, other])
    assert [p.source for p in photos] == ["Zanzibar", "Zanzibar", "kite", "sdd"]
    assert [trainable(p) for p in photos] == [True, True, True, False]
    learn, held = split(photos, ["kite"])
    assert [p.path.name for p in learn] == ["a.jpg", "b.jpg"]
    assert [p.path.name for p in held] == ["c.jpg", "d.jpg"]  # the held-out source and the barred licence


def test_photo_views_are_seeded_square_and_keep_the_picture() -> None:
    rgb = np.zeros((90, 200, 3), np.uint8)
    rgb[:, :, 0] = 200  # a red picture stays mostly red through the colour jitter
    a = photo_view(rgb, np.random.default_rng(1))
    assert a.shape == (128, 128, 3)
    assert a.dtype == np.uint8
    assert np.array_equal(a, photo_view(rgb, np.random.default_rng(1)))
    assert a[:, :, 0].mean() > a[:, :, 2].mean() + 60


def test_a_views_middle_mask_follows_the_crop_turn_and_mirror() -> None:
    # the photograph's middle painted white on black: the mask must cover what is white in the view
    h, w = 300, 400
    rgb = np.zeros((h, w, 3), np.uint8)
    rgb[h // 4 : 3 * h // 4, w // 4 : 3 * w // 4] = 255
    for seed in range(20):
        view, middle = photo_view_middle(rgb, np.random.default_rng(seed))
        assert np.array_equal(view, photo_view(rgb, np.random.default_rng(seed)))  # the same draws
        assert middle.shape == (128, 128)
        assert ((view.mean(axis=2) > 128) != middle).mean() < 0.03  # a pixel's border, no more


def test_cell_targets_only_where_the_label_speaks_of_the_middle(tmp_path: Path) -> None:
    rgb = np.full((64, 64, 3), 128, np.uint8)
    photos = [
        Photo(tmp_path / "clear.jpg", "clear_roof", True, "a", "CC0"),
        Photo(tmp_path / "cluttered.jpg", "cluttered_roof", False, "a", "CC0"),
        Photo(tmp_path / "road.jpg", "not_roof", False, "a", "CC0"),
    ]
    images = {p.path: rgb for p in photos}
    seen = set()
    for seed in range(30):
        picks = np.random.default_rng(seed).integers(0, 3, 4).tolist()  # what _views will draw first
        _img, clear, free, roof = _views(photos, images, np.random.default_rng(seed), 4)
        for k, i in enumerate(picks):
            seen.add(i)
            assert clear[k] == (1.0 if i == 0 else 0.0)
            assert free[k].any() == (i == 0)  # no hazard: only in a clear photograph's middle
            known = roof[k][roof[k] >= 0]
            assert set(known.tolist()) <= ({1.0} if i == 0 else {0.0} if i == 2 else set())
            assert (roof[k] >= 0).any() == (i != 1)  # a cluttered roof says nothing of a cell
            if i == 0:
                assert np.array_equal(free[k], roof[k] == 1.0)
    assert seen == {0, 1, 2}


def test_a_real_roof_replaces_the_renders_roof_only_and_keeps_its_light(tmp_path: Path) -> None:
    # a render: grey roof on the left half, lit on top and in shadow below; green ground on the right
    rgb = np.zeros((96, 96, 3), np.uint8)
    rgb[:, 48:] = (40, 160, 40)
    rgb[:48, :48], rgb[48:, :48] = 200, 80
    labels = np.full((96, 96), 10, np.uint8)
    labels[:, :48] = 0  # roof
    # photographs: a clear red roof (with a dark margin left out) and a cluttered blue one (never used)
    red, blue = np.zeros((60, 80, 3), np.uint8), np.full((60, 80, 3), (0, 0, 255), np.uint8)
    red[9:51, 12:68] = (220, 30, 30)
    photos = [Photo(tmp_path / "clear.jpg", "clear_roof", True, "a", "CC0"),
              Photo(tmp_path / "cluttered.jpg", "cluttered_roof", False, "a", "CC0")]  # fmt: skip
    surfaces = roof_surfaces(photos, {photos[0].path: red, photos[1].path: blue})
    assert len(surfaces) == 1
    assert surfaces[0].shape == (42, 56, 3)  # the margins left out
    for seed in range(10):
        out = with_real_roof(rgb, labels, surfaces, np.random.default_rng(seed))
        assert out.shape == rgb.shape
        assert out.dtype == np.uint8
        assert np.array_equal(out[:, 48:], rgb[:, 48:])  # the ground untouched
        roof = out[:, :48].astype(float)
        assert (roof[..., 0] > roof[..., 2] + 40).mean() > 0.95  # the photographed roof's red
        assert roof[4:40, 4:44, 0].mean() > roof[56:92, 4:44, 0].mean() + 40  # lit above, shadow below
        again = with_real_roof(rgb, labels, surfaces, np.random.default_rng(seed))
        assert np.array_equal(out, again)
    little = labels.copy()
    little[:, 8:] = 10  # under REAL_ROOF_MIN of roof: the render keeps its own
    assert with_real_roof(rgb, little, surfaces, np.random.default_rng(0)) is rgb
    assert with_real_roof(rgb, labels, [], np.random.default_rng(0)) is rgb


def test_a_pitched_roof_is_planes_of_two_or_more_tones_on_the_roof_only() -> None:
    rgb = np.full((96, 96, 3), 120, np.uint8)
    rgb[:, 64:] = (40, 160, 40)
    labels = np.full((96, 96), 10, np.uint8)
    labels[:, :64] = 0  # roof
    tones = set()
    for seed in range(20):
        out = pitched(rgb, labels, np.random.default_rng(seed))
        assert np.array_equal(out, pitched(rgb, labels, np.random.default_rng(seed)))
        assert np.array_equal(out[:, 64:], rgb[:, 64:])  # the ground untouched
        roof = out[:, :64, 0].astype(int)
        assert roof.max() - roof.min() >= 0.2 * 120  # a lit plane and a shaded one
        tones.add(len(np.unique(roof)))
    assert max(tones) > 2  # hipped end planes or a ridge cap, in some of them
    little = labels.copy()
    little[:, 8:] = 10
    assert pitched(rgb, little, np.random.default_rng(0)) is rgb


def test_fold_scores_count_each_answerable_confirm_and_each_clear_cluttered_pair_once() -> None:
    def ph(name: str, label: str, land: bool | None) -> Photo:
        return Photo(Path(name), label, land, "s", "CC0")

    photos = [ph("a", "clear_roof", True), ph("b", "cluttered_roof", False), ph("c", "not_roof", None)]
    verdicts = {"a": (True, 0.9), "b": (True, 0.2), "c": (False, 0.0)}
    assert scores(photos, verdicts) == {
        "confirm_right": 1,
        "confirm_cases": 2,
        "rank_right": 1,
        "rank_cases": 1,
    }


def _gravel(seed: int, stone_px: tuple[float, float]) -> np.ndarray:
    """A frame-filling gravel roof as a close-up shows it: pebbles of one tone, lit from one side."""
    rng = np.random.default_rng(seed)
    base = rng.uniform(90, 170) * np.array([1.0, 0.97, 0.9])
    img = np.ones((192, 192, 3)) * base
    for _ in range(int(192 * 192 / np.mean(stone_px) ** 2)):
        x, y = (int(v) for v in rng.integers(0, 192, 2))
        r = rng.uniform(*stone_px)
        axes = (int(r), int(r * rng.uniform(0.6, 1.0)))
        angle = float(rng.uniform(0, 180))
        cv2.ellipse(img, (x + 1, y + 1), axes, angle, 0, 360, base * 0.45, -1)
        cv2.ellipse(img, (x, y), axes, angle, 0, 360, base * rng.uniform(0.6, 1.35), -1)
    return np.asarray(np.clip(cv2.GaussianBlur(img, (0, 0), 0.7), 0, 255), np.uint8)


def _membrane(seed: int) -> np.ndarray:
    """A frame-filling single-ply membrane roof: pale, faintly mottled, with its seams."""
    rng = np.random.default_rng(seed)
    img = np.ones((192, 192, 3)) * rng.uniform(150, 230)
    img += cv2.GaussianBlur(rng.normal(0, 12, (192, 192)), (0, 0), 8)[:, :, None]
    for x in range(int(rng.integers(20, 60)), 192, int(rng.integers(50, 90))):
        img[:, x : x + 2] *= 0.85
    return np.asarray(np.clip(img + rng.normal(0, 3, img.shape), 0, 255), np.uint8)


@pytest.mark.parametrize("model", ["landnet-e", "landnet-s"])
@pytest.mark.parametrize("seed", range(3))
def test_the_packaged_nets_confirm_clear_gravel_and_membrane_roof_close_ups(seed: int, model: str) -> None:
    """The study's close-ups of clear roofs are gravel and membrane: the net must not refuse those
    surfaces for their texture (pebbles of 1-6 px, 0.5-2 cm gravel at 0.3-1 cm per pixel). This
    generator is not the one training draws from (landfall_train.closeups). Coarser stones (4-9 px)
    still read as painted markings now and then: docs/reasoning.md, "Learning from photographs"."""
    judge = OnboardReasoner(judge="landnet", landnet=LandNet.load(PACKAGED[model]))
    for img in (_gravel(seed, (1.0, 3.0)), _gravel(seed, (2.0, 6.0)), _membrane(seed)):
        d = judge.confirm_sync(ConfirmRequest(img))
        assert d.accept, d.rationale


def test_closeups_are_roof_with_objects_labelled_where_they_stand_and_seeded() -> None:
    from landfall_train.augment import targets
    from landfall_train.closeups import OBJECT, ROOF, closeup, closeups

    x, y = closeups(4, 12, 96)
    assert x.shape == (12, 96, 96, 3)
    assert y.shape == (12, 96, 96)
    assert set(np.unique(y)) <= {ROOF, OBJECT}
    clear = [targets(lab)[2] for lab in y]
    assert 0 < sum(clear) < len(clear)  # some bare, some with objects on them
    for img, lab, c in zip(x, y, clear, strict=True):
        assert c == float(not (lab == OBJECT).any())
        assert img.std() > 3  # a textured surface, not a flat fill
    again = closeup(4, 3, 96)
    assert np.array_equal(again[0], x[3])
    assert np.array_equal(again[1], y[3])


def test_a_views_clear_site_target_follows_the_roof_share_fine_tuning_asks_for() -> None:
    """Training calls a render view a clear site at 85 % roof and no hazard pixel; fine-tuning on
    photographs, whose clear roofs show ground at their margins, may ask for less (--clear-share). No
    share makes a view with a hazard pixel clear."""
    from landfall_train.augment import targets
    from landfall_train.labels import CLASSES, CLEAR_ROOF_SHARE

    lab = np.full((64, 64), CLASSES.index("roof"), np.uint8)
    lab[:, :19] = CLASSES.index("ground")  # 70 % roof
    assert targets(lab)[2] == 0.0
    assert targets(lab, CLEAR_ROOF_SHARE)[2] == 0.0
    assert targets(lab, 0.6)[2] == 1.0
    assert targets(lab, 0.75)[2] == 0.0
    lab[40, 40] = CLASSES.index("object")
    assert targets(lab, 0.6)[2] == 0.0
    assert targets(lab, 0.0)[2] == 0.0


@pytest.mark.parametrize("share", ["0", "1.5", "-0.2"])
def test_a_clear_share_outside_the_view_is_refused_with_a_clear_error(
    share: str, capsys: pytest.CaptureFixture[str]
) -> None:
    from landfall_train.photos import build_parser

    argv = ["--member", "m.onnx", "--seed", "0", "--out", "o", "--clear-share", share]
    with pytest.raises(SystemExit):
        build_parser().parse_args(argv)
    assert "a share of the view" in capsys.readouterr().err
    assert build_parser().parse_args([*argv[:-1], "0.6"]).clear_share == 0.6
