"""LandNet-S: a small fully convolutional net that says what is where in an RGB image.

Input (N, 3, H, W) float32, RGB / 255 normalised by ``MEAN`` and ``STD``, H and W multiples of 16 (any
size: the net is fully convolutional). Outputs:

- ``cells`` (N, K, H/8, W/8): one logit per class (``landfall_train.labels.CLASSES``) per stride-8 cell,
  the class being present in that cell (multi-label: a vent on a roof is both);
- ``clear`` (N, 1, 1, 1): the logit that the whole image is a clear landing site.

Body: seven 3 x 3 convolutions (16-32-32-64-64-96-96 channels; strides 2, 2, 1, 2, 1, 2, 1, the last
dilated 2), batch norm (folded into the convolutions at export) and ReLU; the stride-16 map is upsampled
(nearest, x2) and joined to a 1 x 1 projection of the stride-8 map before one more convolution and the
cell head. The clear head reads two things pooled over the whole image (average and max): the
stride-16 features, and the cell head's own logits, so what the cells see (an object, a person, water,
a marking) bears on the verdict directly: a clear site is a roof with nothing on it, and the net is
built to say so by parts rather than by a holistic texture impression that a new domain shifts
(``fused=False`` gives the earlier head, features only). A 1 x 1 convolution of those gives the
logit. About 0.27 M parameters, 45 MMAC at 128 x 128.
"""

from __future__ import annotations

from typing import Any

import torch
from torch import nn

__all__ = ["MEAN", "MULTIPLE", "STD", "LandNetS"]

MEAN = (0.5, 0.5, 0.5)
STD = (0.25, 0.25, 0.25)
MULTIPLE = 16  # input sides must be multiples of this


def _cbr(cin: int, cout: int, stride: int = 1, dilation: int = 1) -> list[nn.Module]:
    return [
        nn.Conv2d(cin, cout, 3, stride, padding=dilation, dilation=dilation, bias=False),
        nn.BatchNorm2d(cout),
        nn.ReLU(inplace=True),
    ]


class LandNetS(nn.Module):  # type: ignore[misc]
    """The net (module docstring); ``classes`` is K."""

    def __init__(
        self, classes: int, widths: tuple[int, int, int, int] = (16, 32, 64, 96), fused: bool = True
    ) -> None:
        super().__init__()
        self.fused = fused
        a, b, c, d = widths
        self.stem = nn.Sequential(*_cbr(3, a, 2), *_cbr(a, b, 2), *_cbr(b, b))  # stride 4
        self.mid = nn.Sequential(*_cbr(b, c, 2), *_cbr(c, c))  # stride 8
        self.deep = nn.Sequential(*_cbr(c, d, 2), *_cbr(d, d, dilation=2))  # stride 16
        self.up = nn.Upsample(scale_factor=2.0, mode="nearest")
        self.skip = nn.Sequential(nn.Conv2d(c, d, 1, bias=False), nn.BatchNorm2d(d))
        self.fuse = nn.Sequential(*_cbr(d, c))
        self.cells = nn.Conv2d(c, classes, 1)
        self.avg = nn.AdaptiveAvgPool2d(1)
        self.max = nn.AdaptiveMaxPool2d(1)
        self.clear = nn.Conv2d(2 * d + (2 * classes if fused else 0), 1, 1)

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        s8 = self.mid(self.stem(x))
        s16 = self.deep(s8)
        fused = self.fuse(torch.relu(self.up(s16) + self.skip(s8)))
        cells = self.cells(fused)
        parts = [self.avg(s16), self.max(s16)]
        if self.fused:
            parts += [self.avg(cells), self.max(cells)]
        return cells, self.clear(torch.cat(parts, dim=1))


def count_params(net: Any) -> int:
    return int(sum(p.numel() for p in net.parameters()))
