"""EgoNet's VGG stream (DeepLab VGG16, the released table) and a stream's input normalisation."""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Sequence

import torch
from torch import Tensor, nn

from egonet.errors import EgonetError

__all__ = ["RELEASED_BGR_MEAN", "RELEASED_DHG_FLIPPED_MEAN", "InputNormalization", "VGGDeepLabStream"]

#: Widths of the faithful VGG stream: conv1..conv5, then fc6/fc7.
VGG_WIDTHS = (64, 128, 256, 512, 512)
VGG_FC_WIDTH = 4096

# Released EgoNet preprocessing (Caffe, 0-255 scale): the RGB image is fed as
# BGR minus these means; the DHG image is channel-flipped minus these means.
RELEASED_BGR_MEAN = (103.939, 116.779, 123.68)
RELEASED_DHG_FLIPPED_MEAN = (54.21, 82.37, 92.07)


class InputNormalization(nn.Module):
    """Map a ``[0, 1]`` image to a stream's input scale: reorder, x255, minus mean, over std.

    ``out[:, c] = (x[:, channel_order[c]] * 255 - mean[c]) / std[c]``. The
    constants are persistent buffers, so they travel with the ``state_dict``.

    Args:
        mean: Per-channel means on the 0-255 scale, length C.
        std: Per-channel standard deviations on the 0-255 scale, length C.
        channel_order: Input channel read for each output channel, length C
            (``(2, 1, 0)`` turns RGB into BGR).
    """

    def __init__(
        self,
        *,
        mean: Sequence[float],
        std: Sequence[float],
        channel_order: Sequence[int],
    ) -> None:
        super().__init__()
        if not (len(mean) == len(std) == len(channel_order)):
            raise EgonetError("mean, std and channel_order must have the same length", field="channel_order")
        if any(s <= 0 for s in std):
            raise EgonetError(f"std must be positive, got {tuple(std)}", field="std")
        c = len(mean)
        self.register_buffer("mean", torch.tensor(mean, dtype=torch.float32).view(1, c, 1, 1))
        self.register_buffer("std", torch.tensor(std, dtype=torch.float32).view(1, c, 1, 1))
        self.register_buffer("channel_order", torch.tensor(channel_order, dtype=torch.long))

    def forward(self, x: Tensor) -> Tensor:
        """Normalise ``x`` ``(N, C, H, W)`` in ``[0, 1]``; returns ``(N, C, H, W)``."""
        x = x.index_select(1, self.channel_order)
        return (x * 255.0 - self.mean.to(x.dtype)) / self.std.to(x.dtype)
class VGGDeepLabStream(nn.Module):
    """One EgoNet stream: DeepLab VGG16 conv1..conv5, pools, fc6 and fc7 (released table).

    Layer names follow the Caffe definition (``conv1_1`` ... ``fc7``) so
    released weights map one to one. Output stride 8; for an input side ``s``
    the grid side is ``g(g(g(s))) - 1`` with ``g(s) = s // 2 + 1``.

    Args:
        in_channels: Input channels (3 for RGB or DHG, 8 for early fusion).
        dropout: Dropout probability after fc6 and fc7.
        width_divisor: Every layer's width divided by this (1, the released
            network, up to 64); the layers, kernels and grid stay the same, so
            a small network of the same topology costs nothing to build or
            store (tests of the weight loader use one).

    Shapes:
        ``(N, in_channels, H, W)`` -> ``(N, out_channels, h, w)``, 4096
        channels at full width.
    """

    def __init__(self, *, in_channels: int = 3, dropout: float = 0.5, width_divisor: int = 1) -> None:
        super().__init__()
        divisor = _check_width_divisor(width_divisor)
        layers: OrderedDict[str, nn.Module] = OrderedDict()
        channels = in_channels
        dilations = (1, 1, 1, 1, 2)
        for block, (n_convs, width, dilation) in enumerate(zip((2, 2, 3, 3, 3), VGG_WIDTHS, dilations), start=1):
            for k in range(1, n_convs + 1):
                layers[f"conv{block}_{k}"] = _vgg_conv(channels, width // divisor, 3, padding=dilation, dilation=dilation)
                layers[f"relu{block}_{k}"] = nn.ReLU(inplace=True)
                channels = width // divisor
            if block <= 3:
                # max 2x2 stride 2 pad 1, sizes rounded up as in Caffe (s -> s // 2 + 1).
                layers[f"pool{block}"] = nn.MaxPool2d(2, stride=2, padding=1, ceil_mode=True)
            elif block == 4:
                layers["pool4"] = nn.MaxPool2d(2, stride=1)  # s -> s - 1
            else:
                layers["pool5"] = nn.MaxPool2d(3, stride=1, padding=1)
        fc = VGG_FC_WIDTH // divisor
        # fc6: 4x4 kernel, dilation 4 (13x13 footprint), pad 6: keeps the size.
        layers["fc6"] = _vgg_conv(channels, fc, 4, padding=6, dilation=4)
        layers["relu6"] = nn.ReLU(inplace=True)
        layers["drop6"] = nn.Dropout(dropout)
        layers["fc7"] = _vgg_conv(fc, fc, 1)
        layers["relu7"] = nn.ReLU(inplace=True)
        layers["drop7"] = nn.Dropout(dropout)
        self.layers = nn.Sequential(layers)
        self.in_channels = in_channels
        self.out_channels = fc

    def forward(self, x: Tensor) -> Tensor:
        """``(N, in_channels, H, W)`` -> ``(N, out_channels, h, w)``."""
        return self.layers(x)


def _vgg_conv(
    in_channels: int, out_channels: int, kernel_size: int, *, padding: int = 0, dilation: int = 1
) -> nn.Conv2d:
    """A VGG convolution with Kaiming-normal weights (fan out, as torchvision's VGG) and zero bias.

    ``skip_init`` avoids PyTorch's default initialisation, which would be
    overwritten anyway (it halves the build time of the 138 M parameter
    model); the current default device is kept, so building under
    ``torch.device("meta")`` still allocates nothing.
    """
    conv = nn.utils.skip_init(
        nn.Conv2d, in_channels, out_channels, kernel_size, padding=padding, dilation=dilation,
        device=torch.get_default_device(),
    )
    nn.init.kaiming_normal_(conv.weight, mode="fan_out", nonlinearity="relu")
    nn.init.zeros_(conv.bias)
    return conv

def _check_width_divisor(divisor: object) -> int:
    allowed = (1, 2, 4, 8, 16, 32, 64)
    if isinstance(divisor, bool) or divisor not in allowed or not isinstance(divisor, int):
        raise EgonetError(
            f"width_divisor must be one of {', '.join(map(str, allowed))} (1: the full network), got {divisor!r}",
            field="width_divisor",
        )
    return divisor
