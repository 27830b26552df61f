"""EgoNet's models: coordinate maps, the joint head, and late (two-stream) or early fusion under one base."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Literal

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from egonet.errors import EgonetError
from egonet.network.streams import InputNormalization

__all__ = ["MIN_SIDE", "CoordinateMaps", "EarlyFusionEgoNet", "EgoNetModel", "JointHead", "ModelConfig", "action_object_probability",
           "TwoStreamEgoNet"]

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
Geometry = Literal["input", "zoom8"]
GEOMETRIES: tuple[str, ...] = ("input", "zoom8")
# Released coordinate maps: column / W * 255 - 127.25 and row / H * 255 - 127.16.
RELEASED_COORD_OFFSET = (127.25, 127.16)


@dataclasses.dataclass(frozen=True)
class ModelConfig:
    """What a checkpoint needs to rebuild a model: the variant and its options.

    Attributes:
        name: A key of :data:`egonet.network.builders.MODELS`.
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
                for a 386x514 frame); see :mod:`egonet.network` for how the two
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
            ``(N, H, W)`` action-object probability in ``[0, 1]``
            (:func:`action_object_probability`).
        """
        was_training = self.training
        self.eval()
        try:
            with torch.no_grad():
                logits = self(rgb, dhg, geometry=geometry)
        finally:
            self.train(was_training)
        return action_object_probability(logits)


def action_object_probability(logits: Tensor) -> Tensor:
    """``(N, C, H, W)`` logits -> ``(N, H, W)``: one minus the background's softmax probability.

    For the two-class models this is class 1's probability (computed as the
    sum of the non-background classes, so exactly it); for an object-class
    model (DeepLab-Obj) it is the probability that the pixel belongs to *some*
    labelled object, whatever its class.
    """
    return logits.softmax(dim=1)[:, 1:].sum(dim=1)


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


def _check_choice(value: object, choices: Sequence[str], field: str) -> None:
    if value not in choices:
        raise EgonetError(f"{field} must be one of {', '.join(map(repr, choices))}, got {value!r}", field=field)


def _check_coords(coords: object) -> None:
    if coords not in COORD_CONVENTIONS:
        raise EgonetError(
            f"coords must be one of {', '.join(map(repr, COORD_CONVENTIONS))}, got {coords!r}", field="coords"
        )


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
