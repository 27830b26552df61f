"""A small monocular depth network: the lite stream's encoder and a light decoder, log-depth out.

For RGB-only frames (GTEA Gaze+, the children's data) the paper predicts
depth with a monocular network (Liu et al. 2015) and makes DHG from it. This
is our stand-in: egonet-lite's EfficientNet-Lite0 stream (output stride 8)
as the encoder, then three x2 upsampling steps of 3x3 convolutions to the
input size, ending in one channel read as log metres.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from egonet.errors import EgonetError
from egonet.network.lite import LITE_MEAN, LITE_STD, LiteStream

__all__ = ["DepthNet"]


def _up_block(in_channels: int, out_channels: int) -> nn.Sequential:
    return nn.Sequential(
        nn.Conv2d(in_channels, out_channels, 3, padding=1, bias=False),
        nn.BatchNorm2d(out_channels),
        nn.ReLU(inplace=True),
    )


class DepthNet(nn.Module):
    """Monocular depth: ``(N, 3, H, W)`` uint8-range RGB -> ``(N, 1, H, W)`` log-depth in metres.

    Args:
        width: Channels of the encoder's 1x1 projection; the decoder halves
            them at each of its three x2 steps.

    The RGB normalisation of the lite stream lives in the model (buffers), so
    callers pass RGB in 0..255, channel order R, G, B.

    Example:
        >>> net = DepthNet(width=32).eval()
        >>> net(torch.zeros(1, 3, 48, 64)).shape
        torch.Size([1, 1, 48, 64])
    """

    def __init__(self, *, width: int = 128) -> None:
        super().__init__()
        if not isinstance(width, int) or width < 8:
            raise EgonetError(f"width must be an integer >= 8, got {width!r}", field="width")
        self.encoder = LiteStream(out_channels=width, dropout=0.0)
        self.decoder = nn.Sequential(
            _up_block(width, width // 2), _up_block(width // 2, width // 4), _up_block(width // 4, width // 8)
        )
        self.head = nn.Conv2d(width // 8, 1, 3, padding=1)
        # Start near 1.5 m (log 0.4): the loss is scale-invariant, but the metrics are not.
        nn.init.zeros_(self.head.weight)
        nn.init.constant_(self.head.bias, 0.4)
        self.register_buffer("mean", torch.tensor(LITE_MEAN).view(1, 3, 1, 1), persistent=False)
        self.register_buffer("std", torch.tensor(LITE_STD).view(1, 3, 1, 1), persistent=False)
        self.width = width

    def forward(self, rgb: Tensor) -> Tensor:
        """``(N, 3, H, W)`` RGB in 0..255 -> ``(N, 1, H, W)`` log-depth (metres)."""
        if rgb.ndim != 4 or rgb.shape[1] != 3:
            raise EgonetError(f"rgb must be (N, 3, H, W), got {tuple(rgb.shape)}", field="rgb")
        size = rgb.shape[-2:]
        x = self.encoder((rgb - self.mean) / self.std)
        for block in self.decoder:
            x = block(F.interpolate(x, scale_factor=2.0, mode="bilinear", align_corners=False))
        # The stride-8 grid is ceil(s / 8) per side, so x8 can overshoot by a few pixels.
        return F.interpolate(self.head(x), size=size, mode="bilinear", align_corners=False)
