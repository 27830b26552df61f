"""Start EgoNet's VGG streams from ImageNet: a torchvision VGG16 state dict or a DeepLab ``.caffemodel``.

The paper initialised both streams, the DHG one too, from DeepLab's ImageNet
VGG16. Two sources work offline, both supplied by the user (nothing is
downloaded):

* torchvision's VGG16 state dict (``vgg16-*.pth``): keys
  ``features.{0,2,5,...,28}.weight/bias`` for the 13 convolutions,
  ``classifier.0`` (fc6, 4096 x 25088 = 4096 x 512 x 7 x 7) and
  ``classifier.3`` (fc7, 4096 x 4096); ``classifier.6`` (fc8) is ignored.
  :func:`vgg16_to_deeplab` turns it into DeepLab's layers: fc6's 7x7 kernel
  becomes DeepLab's 4x4 dilation-4 kernel by keeping every other tap (rows
  and columns 0, 2, 4, 6), fc7 becomes a 1x1 convolution, and conv1_1 is
  rewritten for our input convention (BGR, 0-255 minus the Caffe means)
  instead of torchvision's (RGB, ``(x / 255 - mean) / std``), exactly for
  every pixel away from the zero padding.
* a DeepLab ``.caffemodel`` (VGG16 DeepLab-v2, layers ``conv1_1`` ...
  ``conv5_3``, ``fc6``, ``fc7``), already in our convention. A plain VGG16
  caffemodel, whose fc6 is a 4096 x 25088 inner product, is converted like
  torchvision's. EgoNet's table has fc6 4096 x 512 x 4 x 4: the
  DeepLab-LargeFOV release (fc6 1024 x 512 x 3 x 3, fc7 1024) does not fit
  and is refused with both shapes named.

:func:`initialise` reads a file and copies its layers into every VGG stream
of a model (``rgb_stream``, ``dhg_stream``, or the early-fusion ``stream``)::

    >>> from egonet.network.builders import build_model
    >>> model = build_model("egonet")                        # doctest: +SKIP
    >>> weights = initialise(model, "vgg16-397923af.pth")    # doctest: +SKIP
    >>> weights.name, weights.sha256[:8], weights.kind       # doctest: +SKIP
    ('vgg16-397923af.pth', '397923af', 'torchvision-vgg16')

The joint head (fc9, fc10) keeps its random initialisation, as in the paper.
"""

from __future__ import annotations

import hashlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from torch import Tensor, nn

from egonet.caffe import read_caffemodel
from egonet.errors import EgonetError
from egonet.network.model import EarlyFusionEgoNet, EgoNetModel, TwoStreamEgoNet
from egonet.network.streams import RELEASED_BGR_MEAN, VGGDeepLabStream

__all__ = [
    "DEEPLAB_LAYERS",
    "InitWeights",
    "check_init",
    "deeplab_layers",
    "initialise",
    "load_init",
    "vgg16_to_deeplab",
]

#: DeepLab VGG16 layer names, in order (the Caffe names of ``VGGDeepLabStream``).
DEEPLAB_LAYERS: tuple[str, ...] = (
    "conv1_1", "conv1_2", "conv2_1", "conv2_2", "conv3_1", "conv3_2", "conv3_3",
    "conv4_1", "conv4_2", "conv4_3", "conv5_1", "conv5_2", "conv5_3", "fc6", "fc7",
)
#: torchvision's ``vgg16().features`` indices of the 13 convolutions.
TORCHVISION_CONVS: tuple[int, ...] = (0, 2, 5, 7, 10, 12, 14, 17, 19, 21, 24, 26, 28)
#: torchvision's ImageNet normalisation (RGB, on the 0-1 scale).
TORCHVISION_MEAN = (0.485, 0.456, 0.406)
TORCHVISION_STD = (0.229, 0.224, 0.225)

Layers = dict[str, tuple[Tensor, Tensor]]
"""DeepLab layer name -> (weight OIHW, bias (O,)), float32, in our input convention."""


@dataclass(frozen=True)
class InitWeights:
    """An initialisation file, read and converted.

    Attributes:
        name: The file's name (no folder).
        sha256: Hex SHA-256 of the file's bytes.
        kind: ``"torchvision-vgg16"`` or ``"deeplab-caffemodel"``.
        layers: The RGB stream's layers (:data:`Layers`).
        dhg_layers: The DHG stream's own layers (``dhg_conv1_1`` ... in an
            EgoNet caffemodel), or ``None``: the DHG stream then gets ``layers``.
    """

    name: str
    sha256: str
    kind: str
    layers: Layers
    dhg_layers: Layers | None = None

    def record(self) -> dict[str, str]:
        """What a run's configuration keeps of the file: name, SHA-256 and kind."""
        return {"name": self.name, "sha256": self.sha256, "kind": self.kind}


# --------------------------------------------------------------------------- conversions


def vgg16_to_deeplab(state_dict: Mapping[str, Tensor], *, source: str = "state_dict") -> Layers:
    """Convert torchvision's VGG16 weights to DeepLab's layers in our input convention.

    Args:
        state_dict: torchvision ``vgg16()`` keys (``features.N.weight`` ...,
            ``classifier.0/3``); other keys (``classifier.6``, fc8) are ignored.
        source: The file, for error messages.

    Returns:
        ``conv1_1`` ... ``fc7`` as (weight OIHW, bias); fc6 is 4x4 (every
        other tap of the 7x7), fc7 1x1.

    Raises:
        EgonetError: A key missing, or a shape that does not follow from the
            previous layer (the message names the key and both shapes).

    Example:
        >>> sd = _tiny_vgg16()  # doctest: +SKIP
        >>> vgg16_to_deeplab(sd)["fc6"][0].shape  # doctest: +SKIP
        torch.Size([8, 4, 4, 4])
    """
    if not isinstance(state_dict, Mapping):
        raise EgonetError(f"{source}: expected a VGG16 state dict (a mapping of tensors), got {type(state_dict).__name__}", field="init")
    blobs: dict[str, list[Tensor]] = {}
    for name, index in zip(DEEPLAB_LAYERS[:13], TORCHVISION_CONVS, strict=True):
        blobs[name] = [_key(state_dict, f"features.{index}.{part}", source) for part in ("weight", "bias")]
    blobs["fc6"] = [_key(state_dict, f"classifier.0.{part}", source) for part in ("weight", "bias")]
    blobs["fc7"] = [_key(state_dict, f"classifier.3.{part}", source) for part in ("weight", "bias")]
    layers = _deeplab_layers(blobs, source=source, keys=_torchvision_keys())
    weight, bias = layers["conv1_1"]
    layers["conv1_1"] = _from_torchvision_input(weight, bias, source=source)
    return layers


def deeplab_layers(blobs: Mapping[str, Sequence[np.ndarray | Tensor]], *, source: str = "caffemodel") -> tuple[Layers, Layers | None]:
    """DeepLab layers from a caffemodel's blobs (``{layer name: [weight OIHW, bias]}``).

    Args:
        blobs: Layer name -> its blobs, as ``egonet.caffe.read_caffemodel``
            returns them. ``conv1_1`` ... ``fc7`` are required; ``dhg_conv1_1``
            ... ``dhg_fc7`` (an EgoNet model) are used for the DHG stream when
            all present. Other layers are ignored.
        source: The file, for error messages.

    Returns:
        ``(layers, dhg_layers or None)``.

    Raises:
        EgonetError: A layer missing, without two blobs, or of a shape that
            does not chain (named, with the shapes).
    """
    def pick(prefix: str) -> dict[str, list[Tensor]]:
        picked = {}
        for name in DEEPLAB_LAYERS:
            found = blobs.get(prefix + name)
            if found is None or len(found) < 2:
                raise EgonetError(
                    f"{source}: layer {prefix + name!r} is missing or lacks its weight and bias blobs"
                    f" ({'absent' if found is None else f'{len(found)} blob(s)'}): is it a DeepLab VGG16 model?",
                    field="init",
                )
            picked[name] = [torch.as_tensor(np.asarray(b, dtype=np.float32)) for b in found[:2]]
        return picked

    keys = {name: name for name in DEEPLAB_LAYERS}
    layers = _deeplab_layers(pick(""), source=source, keys=keys)
    dhg = None
    if all(("dhg_" + name) in blobs for name in DEEPLAB_LAYERS):
        dhg = _deeplab_layers(pick("dhg_"), source=source, keys={n: "dhg_" + n for n in DEEPLAB_LAYERS})
    return layers, dhg


def _torchvision_keys() -> dict[str, str]:
    keys = {name: f"features.{i}" for name, i in zip(DEEPLAB_LAYERS[:13], TORCHVISION_CONVS, strict=True)}
    return keys | {"fc6": "classifier.0", "fc7": "classifier.3"}


def _key(state_dict: Mapping[str, Tensor], key: str, source: str) -> Tensor:
    if key not in state_dict:
        raise EgonetError(f"{source}: no {key!r}: not a torchvision VGG16 state dict (vgg16-*.pth)", field="init")
    value = state_dict[key]
    if not isinstance(value, Tensor):
        raise EgonetError(f"{source}: {key!r} is a {type(value).__name__}, not a tensor", field="init")
    return value.float()


def _deeplab_layers(blobs: Mapping[str, list[Tensor]], *, source: str, keys: Mapping[str, str]) -> Layers:
    """Check the chain of shapes (3x3 convs, fc6, fc7) and turn dense fc6/fc7 into convolutions."""
    layers: Layers = {}
    channels = None
    for name in DEEPLAB_LAYERS:
        weight, bias = blobs[name]
        if name == "fc6" and weight.ndim == 2:
            weight = _dense_fc6(weight, channels=channels, source=source, key=keys[name])
        elif name == "fc7" and weight.ndim == 2:
            weight = weight.reshape(*weight.shape, 1, 1)
        expected_kernel = {"fc6": (4, 4), "fc7": (1, 1)}.get(name, (3, 3))
        if weight.ndim != 4 or tuple(weight.shape[2:]) != expected_kernel or (channels is not None and weight.shape[1] != channels):
            want = f"({'O' if name != 'conv1_1' else '64'}, {channels or 'C'}, {expected_kernel[0]}, {expected_kernel[1]})"
            hint = " (DeepLab-LargeFOV's 3x3 fc6 of 1024 does not fit EgoNet's 4096 x 512 x 4 x 4)" if name == "fc6" else ""
            raise EgonetError(
                f"{source}: {keys[name]} weight has shape {tuple(weight.shape)}, {name} needs {want}{hint}", field="init"
            )
        if bias.reshape(-1).shape[0] != weight.shape[0]:
            raise EgonetError(
                f"{source}: {keys[name]} bias has shape {tuple(bias.shape)}, {name} needs ({weight.shape[0]},)", field="init"
            )
        layers[name] = (weight.contiguous(), bias.reshape(-1).contiguous())
        channels = weight.shape[0]
    return layers


def _dense_fc6(weight: Tensor, *, channels: int | None, source: str, key: str) -> Tensor:
    """VGG's fc6 (O, C*7*7) as DeepLab's 4x4 dilated kernel: taps 0, 2, 4, 6 of the 7x7 in each direction."""
    if channels is None or weight.shape[1] != channels * 49:
        raise EgonetError(
            f"{source}: {key} weight has shape {tuple(weight.shape)}, fc6 needs (O, {channels} x 7 x 7 = {(channels or 0) * 49})",
            field="init",
        )
    return weight.reshape(weight.shape[0], channels, 7, 7)[:, :, ::2, ::2]


def _from_torchvision_input(weight: Tensor, bias: Tensor, *, source: str) -> tuple[Tensor, Tensor]:
    """conv1_1 for BGR minus the Caffe means (0-255) instead of RGB ``(x / 255 - mean) / std``.

    With ``x_tv[c] = (v[c] / 255 - m[c]) / s[c]`` and our ``x[k] = v[2 - k] - M[k]``
    (k in BGR order), ``x_tv[2 - k] = (x[k] + M[k] - 255 m[2 - k]) / (255 s[2 - k])``,
    so the weights are flipped and divided by ``255 s`` and the bias absorbs the
    means' difference. Exact wherever the 3x3 window holds no padding.
    """
    if weight.shape[1] != 3:
        raise EgonetError(f"{source}: features.0 weight has shape {tuple(weight.shape)}, conv1_1 needs 3 input channels", field="init")
    std = torch.tensor(TORCHVISION_STD[::-1], dtype=torch.float32).view(1, 3, 1, 1) * 255.0
    mean = torch.tensor(TORCHVISION_MEAN[::-1], dtype=torch.float32) * 255.0
    ours = weight.flip(1) / std
    shift = torch.tensor(RELEASED_BGR_MEAN, dtype=torch.float32) - mean  # M[k] - 255 m[2 - k]
    return ours.contiguous(), bias + (ours.sum(dim=(2, 3)) * shift).sum(dim=1)


# --------------------------------------------------------------------------- files


def load_init(path: str | Path) -> InitWeights:
    """Read an initialisation file: ``*.caffemodel`` (DeepLab) or a torchvision VGG16 ``.pth``.

    Args:
        path: The file.

    Returns:
        The converted layers with the file's name, SHA-256 and kind.

    Raises:
        EgonetError: The file is missing or unreadable, or not one of the two
            kinds (the message names the key or layer and the shapes).
    """
    path = Path(path)
    if not path.is_file():
        raise EgonetError(f"{path}: no such file (give a vgg16-*.pth state dict or a DeepLab .caffemodel)", field="init")
    sha256 = _sha256(path)
    if path.suffix.lower() == ".caffemodel":
        layers, dhg = deeplab_layers(_read_caffemodel(path), source=path.name)
        return InitWeights(path.name, sha256, "deeplab-caffemodel", layers, dhg)
    try:
        state = torch.load(path, map_location="cpu", weights_only=True, mmap=True)
    except Exception as exc:  # noqa: BLE001 - torch.load raises many kinds for bad files
        raise EgonetError(f"{path.name}: cannot read it as a PyTorch state dict ({exc})", field="init") from None
    return InitWeights(path.name, sha256, "torchvision-vgg16", vgg16_to_deeplab(state, source=path.name))


def _read_caffemodel(path: Path) -> dict[str, list[np.ndarray]]:
    """The caffemodel's blobs by layer name, through ``egonet.caffe`` (the project's one Caffe reader).

    An inner product's weight comes back 2-D (legacy files store it as
    ``(1, 1, O, I)``), so a plain VGG16's dense fc6/fc7 convert as torchvision's do.
    """
    blobs = {}
    for name, layer in read_caffemodel(path).items():
        if not layer.blobs:
            continue
        found = list(layer.blobs)
        if layer.type == "InnerProduct" and found[0].ndim == 4 and found[0].shape[:2] == (1, 1):
            found[0] = found[0].reshape(found[0].shape[2:])
        blobs[name] = found
    return blobs


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with path.open("rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            digest.update(chunk)
    return digest.hexdigest()


# --------------------------------------------------------------------------- into a model


def _streams(model: EgoNetModel) -> list[tuple[str, VGGDeepLabStream, bool]]:
    """The model's VGG streams as ``(attribute, stream, is_dhg)``; refuses models without one."""
    found = []
    if isinstance(model, TwoStreamEgoNet):
        for attribute, is_dhg in (("rgb_stream", False), ("dhg_stream", True)):
            stream = getattr(model, attribute)
            if isinstance(stream, VGGDeepLabStream):
                found.append((attribute, stream, is_dhg))
    elif isinstance(model, EarlyFusionEgoNet) and isinstance(model.stream, VGGDeepLabStream):
        found.append(("stream", model.stream, False))
    if not found:
        raise EgonetError(
            f"{model.config.name!r} has no VGG stream to initialise from ImageNet VGG16/DeepLab"
            " (egonet-lite starts from ImageNet with --pretrained)",
            field="init",
        )
    return found


def _fitted(stream: VGGDeepLabStream, name: str, weight: Tensor, bias: Tensor) -> tuple[Tensor, Tensor]:
    """The blob as the stream's layer needs it: the early-fusion conv1_1 reads 8 channels."""
    conv = getattr(stream.layers, name)
    if name == "conv1_1" and conv.in_channels == 8 and weight.shape[1] == 3:
        # rgb(3), dhg(3), x, y: each image gets half the filter (the sum over two
        # alike images answers as one would), the coordinate channels start at zero.
        extra = torch.zeros(weight.shape[0], 2, *weight.shape[2:], dtype=weight.dtype)
        weight = torch.cat([weight / 2, weight / 2, extra], dim=1)
    return weight, bias


def check_init(model: EgoNetModel, weights: InitWeights) -> list[str]:
    """Check that every layer fits the model's streams, without copying (works on the ``meta`` device).

    Returns:
        The stream attributes that would be initialised (``["rgb_stream", "dhg_stream"]``).

    Raises:
        EgonetError: A model without VGG streams, or a layer whose shape
            differs (naming the layer, the file's shape and the model's).
    """
    names = []
    for attribute, stream, is_dhg in _streams(model):
        layers = weights.dhg_layers if is_dhg and weights.dhg_layers is not None else weights.layers
        for name in DEEPLAB_LAYERS:
            weight, bias = _fitted(stream, name, *layers[name])
            conv: nn.Conv2d = getattr(stream.layers, name)
            if tuple(weight.shape) != tuple(conv.weight.shape) or tuple(bias.shape) != tuple(conv.bias.shape):
                raise EgonetError(
                    f"{weights.name}: layer {name} has weight {tuple(weight.shape)} and bias {tuple(bias.shape)}, "
                    f"{model.config.name}'s {attribute}.{name} needs {tuple(conv.weight.shape)} and {tuple(conv.bias.shape)}",
                    field="init",
                )
        names.append(attribute)
    return names


@torch.no_grad()
def initialise(model: EgoNetModel, path: str | Path, *, sha256: str | None = None) -> InitWeights:
    """Copy an ImageNet VGG16 / DeepLab file into every VGG stream of ``model`` (in place).

    Args:
        model: A VGG model (``egonet``, its ablations, ``deeplab-rgb/-dhg``).
        path: ``*.caffemodel`` or a torchvision VGG16 ``.pth`` (see :func:`load_init`).
        sha256: The file's expected SHA-256 (a run's recorded one): a file
            changed since is refused.

    Returns:
        The file's :class:`InitWeights` (its ``record()`` goes in a run's config).

    Raises:
        EgonetError: See :func:`load_init` and :func:`check_init`; or the file's
            SHA-256 differs from ``sha256``.
    """
    weights = load_init(path)
    if sha256 is not None and weights.sha256 != sha256:
        raise EgonetError(
            f"{weights.name}: SHA-256 {weights.sha256[:12]}... differs from the recorded {sha256[:12]}...: "
            "the file changed since the run was started",
            field="init",
        )
    check_init(model, weights)
    for _, stream, is_dhg in _streams(model):
        layers = weights.dhg_layers if is_dhg and weights.dhg_layers is not None else weights.layers
        for name in DEEPLAB_LAYERS:
            weight, bias = _fitted(stream, name, *layers[name])
            getattr(stream.layers, name).weight.copy_(weight)
            getattr(stream.layers, name).bias.copy_(bias)
    return weights
