"""Monocular relative depth with Depth Anything V2 (the optional ``depth`` extra: torch + transformers).

For a drone whose LiDAR failed, or has none. The network (a DINOv2 encoder with a DPT head) predicts
relative inverse depth from the image alone; it is turned into relative depth in [0, 1] (0 nearest)
on Surface ID's cell grid, and Surface ID then uses its gradient test (no metres exist).

Weights are never downloaded at run time: ``model`` is a local directory holding a Hugging Face
checkpoint (``config.json`` + ``model.safetensors``), or a Hub id looked up in the local Hugging Face
cache only (``HF_HOME`` / ``HF_HUB_CACHE``). Fetch them once on a connected machine, for example
``huggingface-cli download depth-anything/Depth-Anything-V2-Small-hf``, and copy the cache or the
directory to the drone. A missing extra or missing weights raise :class:`DepthError` saying which.

Pre-processing follows the model's own: the image is resized (bicubic, aspect kept) so its shorter
side is ``input_size`` (518) rounded to a multiple of the 14-pixel patch, scaled to [0, 1] and
normalised with the ImageNet mean and standard deviation.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from companion.config_schema import DEFAULTS
from companion.guidance.frames import PinholeCamera
from companion.perception.depth import DepthError, DepthMap, normalise_relative, to_cells

__all__ = ["DEFAULT_MODEL", "DepthAnythingV2"]

DEFAULT_MODEL = "depth-anything/Depth-Anything-V2-Small-hf"
_MEAN = np.array([0.485, 0.456, 0.406], np.float32)
_STD = np.array([0.229, 0.224, 0.225], np.float32)
_PATCH = 14


def _import() -> tuple[Any, Any]:
    try:
        import torch
        from transformers import DepthAnythingForDepthEstimation
    except ImportError as exc:
        raise DepthError(
            "monocular depth needs the optional 'depth' extra (torch and transformers): "
            f"pip install 'landfall[depth]' ({exc})"
        ) from exc
    return torch, DepthAnythingForDepthEstimation


def load_model(model: str | Path) -> Any:
    """The network from a local directory or the local Hugging Face cache; never from the network."""
    _torch, cls = _import()
    where = Path(model).expanduser()
    local = where.is_dir()
    if not local and (where.is_absolute() or str(model).startswith((".", "~")) or where.exists()):
        raise DepthError(f"Depth Anything V2 weights: {where} is not a directory holding a checkpoint")
    os.environ.setdefault("HF_HUB_OFFLINE", "1")
    from transformers.utils import logging as hf_logging

    hf_logging.disable_progress_bar()
    try:
        net = cls.from_pretrained(str(where) if local else str(model), local_files_only=True)
    except (OSError, ValueError) as exc:
        hint = (
            f"{where} holds no usable checkpoint (config.json and model.safetensors)"
            if local
            else f"{model!r} is not in the local Hugging Face cache (HF_HUB_CACHE); it is never downloaded "
            "at run time: fetch it once on a connected machine, or set perception.depth_model to a "
            "local directory"
        )
        raise DepthError(f"Depth Anything V2 weights not found: {hint}") from exc
    net.eval()
    return net


def preprocess(image_rgb: np.ndarray, input_size: int) -> np.ndarray:
    """(1, 3, h, w) float32 network input; h and w multiples of 14, the shorter side ~input_size."""
    h, w = image_rgb.shape[:2]
    scale = input_size / min(h, w)
    nh = max(_PATCH, round(h * scale / _PATCH) * _PATCH)
    nw = max(_PATCH, round(w * scale / _PATCH) * _PATCH)
    resized = cv2.resize(image_rgb, (nw, nh), interpolation=cv2.INTER_CUBIC).astype(np.float32) / 255.0
    x = (resized - _MEAN) / _STD
    return np.ascontiguousarray(x.transpose(2, 0, 1)[None])


class DepthAnythingV2:
    """Relative depth from one RGB image (a :class:`~companion.perception.depth.DepthSource`)."""

    name = "depth-anything-v2"

    def __init__(
        self,
        model: str | Path = DEFAULT_MODEL,
        *,
        cell_px: int = DEFAULTS.perception.cell_px,
        input_size: int = 518,
        net: Any = None,
    ) -> None:
        if input_size < _PATCH:
            raise DepthError(f"input_size must be >= {_PATCH}, got {input_size}")
        self.cell_px = cell_px
        self.input_size = input_size
        self._torch, _ = _import()
        self.net = net if net is not None else load_model(model)

    def depth_map(
        self, camera: PinholeCamera, *, image: np.ndarray | None = None, lidar_frd: np.ndarray | None = None
    ) -> DepthMap:
        if image is None:
            raise DepthError("monocular depth needs the camera image; this frame has none")
        img = np.asarray(image)
        if img.shape != (camera.height, camera.width, 3) or img.dtype != np.uint8:
            raise DepthError(
                f"the image must be {camera.height} x {camera.width} x 3 uint8 RGB, "
                f"got {img.shape} {img.dtype}"
            )
        x = self._torch.from_numpy(preprocess(img, self.input_size))
        with self._torch.inference_mode():
            out = self.net(pixel_values=x).predicted_depth
        disparity = out[0].float().numpy()
        if not np.isfinite(disparity).all():
            raise DepthError("the depth network returned non-finite values")
        full = cv2.resize(disparity, (camera.width, camera.height), interpolation=cv2.INTER_LINEAR)
        # Inverse depth -> relative depth: nearest 0, farthest 1.
        rel = 1.0 - normalise_relative(full)
        cells = to_cells(rel, camera, self.cell_px)
        return DepthMap(cells, False, self.cell_px, self.name, None)
