"""Depth Anything V2 as a depth source, with a tiny randomly initialised model of the real architecture
saved to a temporary directory: loading from a path, the local-cache-only rule, errors, shapes."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch", reason="the optional 'depth' extra (make test installs it)")
transformers = pytest.importorskip("transformers")

from companion.guidance.frames import PinholeCamera  # noqa: E402
from companion.perception.depth import DepthError, FirstAvailable, LidarDepth  # noqa: E402
from companion.perception.mono_depth import DepthAnythingV2, preprocess  # noqa: E402
from companion.perception.surface_id import propose  # noqa: E402

CAM = PinholeCamera.from_hfov(320, 180, 90.0)


def tiny_config(image_size: int = 56) -> object:
    """A small Depth Anything V2 configuration of the real architecture, randomly initialised in tests."""
    backbone = transformers.Dinov2Config(
        hidden_size=32,
        num_hidden_layers=4,
        num_attention_heads=2,
        mlp_ratio=2,
        image_size=image_size,
        patch_size=14,
        out_indices=[1, 2, 3, 4],
        reshape_hidden_states=False,
        apply_layernorm=True,
    )
    return transformers.DepthAnythingConfig(
        backbone_config=backbone,
        patch_size=14,
        reassemble_hidden_size=32,
        neck_hidden_sizes=[8, 16, 32, 32],
        fusion_hidden_size=16,
        head_hidden_size=8,
        depth_estimation_type="relative",
    )


@pytest.fixture(scope="module")
def tiny_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    torch.manual_seed(0)
    net = transformers.DepthAnythingForDepthEstimation(tiny_config())
    out = tmp_path_factory.mktemp("da2-tiny")
    net.save_pretrained(out)
    return out


def _image(seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 255, (CAM.height, CAM.width, 3), dtype=np.uint8)


def test_preprocess_matches_the_model_input_rules() -> None:
    x = preprocess(_image(), 518)
    assert x.shape[:2] == (1, 3)
    assert x.shape[2] % 14 == 0
    assert x.shape[3] % 14 == 0
    assert x.shape[2] == pytest.approx(518, abs=7)  # the shorter side
    assert x.shape[3] / x.shape[2] == pytest.approx(320 / 180, rel=0.03)
    flat = preprocess(np.full((180, 320, 3), 124, np.uint8), 56)
    assert np.allclose(flat[0, 0], (124 / 255 - 0.485) / 0.229, atol=1e-4)  # ImageNet normalisation


def test_a_local_checkpoint_gives_relative_depth_on_the_cell_grid(tiny_dir: Path) -> None:
    src = DepthAnythingV2(tiny_dir, cell_px=4, input_size=56)
    dm = src.depth_map(CAM, image=_image())
    assert dm.shape == (45, 80)
    assert not dm.metric
    assert dm.source == "depth-anything-v2"
    assert np.isfinite(dm.depth).all()
    assert float(dm.depth.min()) >= 0.0
    assert float(dm.depth.max()) <= 1.0
    again = src.depth_map(CAM, image=_image())
    assert np.array_equal(dm.depth, again.depth)  # inference is deterministic (eval mode)
    cands, _ = propose(src, CAM, image=_image())
    assert 1 <= len(cands) <= 5  # candidates or the fallback: always a next step


def test_missing_weights_are_a_clear_error_and_nothing_is_downloaded(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("HF_HUB_CACHE", str(tmp_path / "empty-cache"))
    monkeypatch.setenv("HF_HOME", str(tmp_path / "empty-home"))
    with pytest.raises(DepthError, match="not in the local Hugging Face cache"):
        DepthAnythingV2("depth-anything/Depth-Anything-V2-Small-hf")
    assert not any((tmp_path / "empty-cache").glob("**/*.safetensors"))
    with pytest.raises(DepthError, match="holds no usable checkpoint"):
        DepthAnythingV2(tmp_path)  # an empty directory
    with pytest.raises(DepthError, match="not a directory"):
        DepthAnythingV2(tmp_path / "no-such-dir")


def test_bad_images_are_refused(tiny_dir: Path) -> None:
    src = DepthAnythingV2(tiny_dir, input_size=56)
    with pytest.raises(DepthError, match="needs the camera image"):
        src.depth_map(CAM, image=None)
    with pytest.raises(DepthError, match="180 x 320 x 3 uint8"):
        src.depth_map(CAM, image=np.zeros((180, 320), np.uint8))


def test_auto_falls_back_to_the_image_when_the_lidar_has_nothing(tiny_dir: Path) -> None:
    auto = FirstAvailable((LidarDepth(), DepthAnythingV2(tiny_dir, input_size=56)))
    dm = auto.depth_map(CAM, image=_image(), lidar_frd=np.empty((0, 4), np.float32))
    assert dm.source == "depth-anything-v2"
    pts = np.array([[0.0, 0.0, 50.0, 1.0]] * 10, np.float32)
    assert auto.depth_map(CAM, image=_image(), lidar_frd=pts).source == "lidar"
    with pytest.raises(DepthError, match=r"lidar: .*; depth-anything-v2: .*image"):
        auto.depth_map(CAM, image=None, lidar_frd=None)
