"""The authors' released EgoNet weights: a Caffe ``.caffemodel`` read without Caffe.

A ``.caffemodel`` is one protobuf message, Caffe's ``NetParameter``. This
module reads the few fields it needs straight from the protobuf wire format
(no Caffe, no generated code): the current layout (``layer``, field 100:
``LayerParameter`` with a string ``type`` and ``BlobProto`` blobs whose
``shape`` lists the dimensions) and the legacy one (``layers``, field 2:
``V1LayerParameter`` with an enum type and blobs sized by ``num``,
``channels``, ``height``, ``width``), float data packed or not. The file is
memory-mapped: a blob's array is a view of the mapping (copy-on-write, so
writing into one never changes the file), read from disk only when it is
used, so a 550 MB file costs no copy before the weights are copied into a
model::

    >>> from egonet.caffe import load_caffemodel, read_caffemodel
    >>> layers = read_caffemodel("egonet.caffemodel")  # doctest: +SKIP
    >>> layers["fc9"].type, [b.shape for b in layers["fc9"].blobs]  # doctest: +SKIP
    ('Convolution', [(1024, 8194, 1, 1), (1024,)])
    >>> model = load_caffemodel("egonet.caffemodel")  # doctest: +SKIP
    >>> model.predict(rgb, dhg).shape  # doctest: +SKIP
    torch.Size([1, 386, 514])

:func:`load_caffemodel` recognises the release from its layer names and
shapes (:data:`RELEASES`): RGB+DHG (``conv1_1`` ... ``fc7``, ``dhg_conv1_1``
... ``dhg_fc7``, ``fc9`` 1024 wide on 8194 channels, ``fc10_sal``) or RGB
only (``fc9`` 512 wide on 4098 channels, plus ``fc8_obj``, 41 outputs on
fc7, which nothing downstream uses: it is checked and left out). The
shapes a release must have come from the model builder itself
(:func:`egonet.network.builders.build_model` with the release's options), so the
loader and the network cannot disagree. Anything else (a missing layer, a
wrong shape, a truncated file) is refused with one line naming the layer
and both shapes.

The model it returns runs the release's preprocessing exactly (RGB to BGR,
x255, minus the means; the DHG file flipped, depth first, minus its means;
the row map, then the column map, shrunk like Caffe's ``Interp``): see
:mod:`egonet.network` and ``shared/docs/egonet-reference.md``, "Released
conventions".
"""

from __future__ import annotations

import hashlib
import math
import mmap
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch
from torch import nn

from egonet.checkpoint import TrainConfig, checkpoint_state
from egonet.errors import EgonetError
from egonet.network.builders import build_model
from egonet.network.model import EgoNetModel, TwoStreamEgoNet
from egonet.network.streams import VGGDeepLabStream

__all__ = [
    "DEPLOY_SIZE",
    "RELEASES",
    "CaffeLayer",
    "Release",
    "checkpoint_from_caffemodel",
    "identify_release",
    "load_caffemodel",
    "model_layers",
    "read_caffemodel",
    "stream_layers",
]

Progress = Callable[[int, int], None]
"""``progress(done, total)`` in bytes of the file."""

#: The released deploy size ``(H, W)``.
DEPLOY_SIZE = (481, 641)

# Protobuf wire types.
_VARINT, _FIXED64, _BYTES, _FIXED32 = 0, 1, 2, 5
# Field numbers of caffe.proto that are read here.
_NET_LAYERS_V1, _NET_LAYER = 2, 100
_LAYER_NAME, _LAYER_TYPE, _LAYER_BLOBS = 1, 2, 7
_V1_NAME, _V1_TYPE, _V1_BLOBS = 4, 5, 6
_BLOB_LEGACY_DIMS = {1: 0, 2: 1, 3: 2, 4: 3}  # num, channels, height, width -> position
_BLOB_DATA, _BLOB_SHAPE, _BLOB_DOUBLE_DATA = 5, 7, 8
_SHAPE_DIM = 1
#: V1LayerParameter.LayerType values -> the type names of the current layout.
V1_TYPES = {
    3: "Concat", 4: "Convolution", 5: "Data", 6: "Dropout", 12: "ImageData", 14: "InnerProduct",
    17: "Pooling", 18: "ReLU", 20: "Softmax", 21: "SoftmaxWithLoss", 22: "Split", 25: "Eltwise",
    29: "MemoryData", 33: "Slice", 36: "Silence", 39: "Deconvolution",
}


class _Truncated(EgonetError):
    """The wire data ends inside a field."""

    def __init__(self):
        super().__init__("the wire data ends inside a field")


# --------------------------------------------------------------------------- reading


@dataclass(frozen=True)
class CaffeLayer:
    """One layer of a ``.caffemodel``.

    Attributes:
        name: The layer's name (``"conv1_1"``).
        type: Its type (``"Convolution"``; legacy files' enum values are
            named as in the current layout, unknown ones ``"V1:<n>"``).
        blobs: Its parameters as float32 arrays of the file's shapes (legacy
            blobs are 4-D: a bias is ``(1, 1, 1, n)``), usually views of the
            mapped file.
        end: Where the layer ends in the file, in bytes (for progress).
    """

    name: str
    type: str
    blobs: list[np.ndarray] = field(default_factory=list)
    end: int = 0


def read_caffemodel(path: str | Path, *, progress: Progress | None = None, name: str | None = None) -> dict[str, CaffeLayer]:
    """Every layer of a ``.caffemodel`` by name, blobs as arrays; no Caffe needed.

    Args:
        path: The ``.caffemodel`` file.
        progress: Called with ``(bytes read, file size)`` after each layer.
        name: The file's name in messages (default: ``path``), e.g. an upload's name as its user knows it.

    Returns:
        ``{name: CaffeLayer}`` in file order (layers without parameters
        included, with no blobs).

    Raises:
        EgonetError: The file cannot be read, is not a ``NetParameter``, is
            truncated, a blob's data does not fill its shape (or the shape is
            impossible), or a layer name holds weights twice; the message
            names the file and the layer.

    Example:
        >>> layers = read_caffemodel("deeplab.caffemodel")  # doctest: +SKIP
        >>> {name: [b.shape for b in layer.blobs] for name, layer in layers.items() if layer.blobs}  # doctest: +SKIP
    """
    return _read(Path(path), progress=progress, name=name)[0]


def _read(path: Path, *, progress: Progress | None = None, name: str | None = None) -> tuple[dict[str, CaffeLayer], mmap.mmap]:
    """:func:`read_caffemodel`, and the mapped file its arrays view."""
    shown = name or path  # the file in messages
    buffer = _map(path, shown)
    size = len(buffer)
    layers: dict[str, CaffeLayer] = {}
    pos = 0
    try:
        while pos < size:
            number, wire, value, pos = _field(buffer, pos, size)
            if wire != _BYTES or number not in (_NET_LAYER, _NET_LAYERS_V1):
                continue
            start, end = value
            layer = _layer(buffer, start, end, legacy=number == _NET_LAYERS_V1, path=shown)
            _add(layers, layer, shown)
            if progress is not None:
                progress(end, size)
    except _Truncated:
        raise EgonetError(
            f"{shown}: truncated: the file ends inside {_last_layer(layers)} at byte {size:,} (a partial download?)",
            field="path",
        ) from None
    except _WireError as exc:
        raise EgonetError(f"{shown}: not a Caffe .caffemodel (protobuf NetParameter): {exc}", field="path") from None
    except EgonetError:
        raise
    except (ValueError, OverflowError) as exc:  # numpy's refusal of a shape no array can have (a dimension of 2**63, say)
        raise EgonetError(f"{shown}: {_last_layer(layers)} has a blob of an impossible shape ({exc}): the file is damaged",
                          field="path") from None
    if not any(layer.blobs for layer in layers.values()):
        raise EgonetError(f"{shown}: no layer holds weights: not a .caffemodel (a .prototxt, or another file?)", field="path")
    return layers, buffer


class _WireError(EgonetError):
    """Bytes that are not protobuf wire data."""


def _map(path: Path, shown: str | Path) -> mmap.mmap:
    try:
        with path.open("rb") as fh:
            if path.stat().st_size == 0:
                raise EgonetError(f"{shown}: the file is empty", field="path")
            # Copy-on-write: arrays viewing it are writable, and writing never reaches the file.
            return mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_COPY)
    except OSError as exc:
        raise EgonetError(f"{shown}: cannot read ({exc.strerror or exc})", field="path") from None


def _add(layers: dict[str, CaffeLayer], layer: CaffeLayer, path: str | Path) -> None:
    """A train/test net may repeat a name for each phase: keep the one with weights, refuse two."""
    if layer.name in layers and layers[layer.name].blobs:
        if layer.blobs:
            raise EgonetError(f"{path}: layer {layer.name!r} holds weights twice", field=layer.name)
        return
    layers[layer.name] = layer


def _last_layer(layers: Mapping[str, CaffeLayer]) -> str:
    return f"the layer after {list(layers)[-1]!r}" if layers else "its first layer"


def _varint(buffer, pos: int, end: int) -> tuple[int, int]:
    value = shift = 0
    while True:
        if pos >= end:
            raise _Truncated
        byte = buffer[pos]
        pos += 1
        value |= (byte & 0x7F) << shift
        if byte < 0x80:
            return value, pos
        shift += 7
        if shift > 63:
            raise _WireError(f"a varint longer than 10 bytes at byte {pos:,}")


def _field(buffer, pos: int, end: int) -> tuple[int, int, object, int]:
    """The field at ``pos``: ``(number, wire type, value, next position)``.

    The value is an int for varints, ``(start, end)`` for length-delimited
    fields and the start of the 4 or 8 bytes for fixed-size ones.
    """
    tag, pos = _varint(buffer, pos, end)
    number, wire = tag >> 3, tag & 7
    if number == 0:
        raise _WireError(f"field number 0 at byte {pos:,}")
    if wire == _VARINT:
        value, pos = _varint(buffer, pos, end)
        return number, wire, value, pos
    if wire == _BYTES:
        length, pos = _varint(buffer, pos, end)
        if pos + length > end:
            raise _Truncated
        return number, wire, (pos, pos + length), pos + length
    if wire in (_FIXED32, _FIXED64):
        width = 4 if wire == _FIXED32 else 8
        if pos + width > end:
            raise _Truncated
        return number, wire, pos, pos + width
    raise _WireError(f"wire type {wire} (field {number}) at byte {pos:,}")


def _layer(buffer, start: int, end: int, *, legacy: bool, path: str | Path) -> CaffeLayer:
    """A ``LayerParameter`` (or legacy ``V1LayerParameter``) between ``start`` and ``end``."""
    name_field, type_field, blobs_field = (_V1_NAME, _V1_TYPE, _V1_BLOBS) if legacy else (_LAYER_NAME, _LAYER_TYPE, _LAYER_BLOBS)
    name, kind, blob_spans = None, "", []
    pos = start
    while pos < end:
        number, wire, value, pos = _field(buffer, pos, end)
        if number == name_field and wire == _BYTES:
            name = bytes(buffer[value[0]:value[1]]).decode("utf-8", "replace")
        elif number == type_field and legacy and wire == _VARINT:
            kind = V1_TYPES.get(value, f"V1:{value}")
        elif number == type_field and not legacy and wire == _BYTES:
            kind = bytes(buffer[value[0]:value[1]]).decode("utf-8", "replace")
        elif number == blobs_field and wire == _BYTES:
            blob_spans.append(value)
    if name is None:
        raise _WireError(f"a layer without a name at byte {start:,} (Caffe's oldest V0 layout is not read)")
    blobs = [_blob(buffer, s, e, layer=name, index=i, path=path) for i, (s, e) in enumerate(blob_spans)]
    return CaffeLayer(name=name, type=kind, blobs=blobs, end=end)


def _blob(buffer, start: int, end: int, *, layer: str, index: int, path: str | Path) -> np.ndarray:
    """A ``BlobProto``: its float data (packed, unpacked or double) shaped by ``shape`` or num/channels/height/width."""
    dims: list[int] | None = None
    legacy = [0, 0, 0, 0]
    chunks: list[np.ndarray] = []
    pos = start
    while pos < end:
        tag_start = pos
        number, wire, value, pos = _field(buffer, pos, end)
        if number == _BLOB_SHAPE and wire == _BYTES:
            dims = _dims(buffer, *value)
        elif number in _BLOB_LEGACY_DIMS and wire == _VARINT:
            legacy[_BLOB_LEGACY_DIMS[number]] = value
        elif number == _BLOB_DATA and wire == _BYTES:
            chunks.append(_packed(buffer, *value, np.dtype("<f4"), layer=layer, path=path))
        elif number == _BLOB_DATA and wire == _FIXED32:
            values, pos = _unpacked_floats(buffer, tag_start, end)
            chunks.append(values)
        elif number == _BLOB_DOUBLE_DATA and wire == _BYTES:
            chunks.append(_packed(buffer, *value, np.dtype("<f8"), layer=layer, path=path).astype(np.float32))
    shape = tuple(dims) if dims is not None else tuple(legacy)
    data = chunks[0] if len(chunks) == 1 else np.concatenate(chunks) if chunks else np.zeros(0, np.float32)
    if data.size != math.prod(shape):
        raise EgonetError(
            f"{path}: layer {layer!r} blob {index} holds {data.size:,} values, its shape {shape} needs "
            f"{math.prod(shape):,}: the file is damaged",
            field=layer,
        )
    return data.reshape(shape)


def _dims(buffer, start: int, end: int) -> list[int]:
    """``BlobShape.dim``: packed (or unpacked) varints."""
    dims, pos = [], start
    while pos < end:
        number, wire, value, pos = _field(buffer, pos, end)
        if number == _SHAPE_DIM and wire == _BYTES:
            inner = value[0]
            while inner < value[1]:
                dim, inner = _varint(buffer, inner, value[1])
                dims.append(dim)
        elif number == _SHAPE_DIM and wire == _VARINT:
            dims.append(value)
    return dims


def _packed(buffer, start: int, end: int, dtype: np.dtype, *, layer: str, path: str | Path) -> np.ndarray:
    if (end - start) % dtype.itemsize:
        raise EgonetError(f"{path}: layer {layer!r} has float data of {end - start} bytes: the file is damaged", field=layer)
    return np.frombuffer(buffer, dtype=dtype, count=(end - start) // dtype.itemsize, offset=start)


def _unpacked_floats(buffer, pos: int, end: int) -> tuple[np.ndarray, int]:
    """A run of unpacked ``data`` floats (each: tag byte 0x2d, then 4 bytes) from ``pos``, read at once."""
    tag = (_BLOB_DATA << 3) | _FIXED32
    records = np.frombuffer(buffer, np.uint8, count=(end - pos) // 5 * 5, offset=pos).reshape(-1, 5)
    other = np.flatnonzero(records[:, 0] != tag)
    run = int(other[0]) if other.size else len(records)
    values = np.ascontiguousarray(records[:run, 1:]).view("<f4").reshape(-1)
    return values.astype(np.float32), pos + 5 * run


# --------------------------------------------------------------------------- releases


@dataclass(frozen=True)
class Release:
    """One of the authors' released models: which builder makes it, and layers it has but does not use.

    Attributes:
        key: ``"rgb+dhg"`` or ``"rgb"``.
        title: How messages name it (``"the authors' RGB+DHG release"``).
        model: The :data:`egonet.network.builders.MODELS` name.
        options: The builder options that give the released shapes and conventions.
        unused: Layers in the file that the output does not use, by name, with
            their number of outputs (a 1x1 convolution on fc7): read, checked
            and left out.
    """

    key: str
    title: str
    model: str
    options: Mapping[str, object]
    unused: Mapping[str, int] = field(default_factory=dict)

    def build(self) -> EgoNetModel:
        """The model with the release's architecture and conventions, randomly initialised."""
        return build_model(self.model, **self.options)

    def expected_shapes(self) -> dict[str, list[tuple[int, ...]]]:
        """Every layer the file must hold, with its blobs' shapes (weights OIHW, bias), from the builder."""
        with torch.device("meta"):  # shapes only: instant even for the 138 M parameter model
            model = self.build()
        shapes = {name: [tuple(conv.weight.shape), tuple(conv.bias.shape)] for name, conv in model_layers(model).items()}
        fc7 = model.rgb_stream.out_channels
        for name, outputs in self.unused.items():
            shapes[name] = [(outputs, fc7, 1, 1), (outputs,)]
        return shapes


_RELEASED = {"coords": "released", "coord_order": "rows-first"}

#: The authors' two releases, as this loader recognises them.
RELEASES: tuple[Release, ...] = (
    Release("rgb+dhg", "the authors' RGB+DHG release", "egonet", _RELEASED | {"dhg_order": "gray-height-depth"}),
    Release("rgb", "the authors' RGB release", "egonet-rgb", _RELEASED | {"fc9_width": 512}, unused={"fc8_obj": 41}),
)


def stream_layers(stream: VGGDeepLabStream, *, prefix: str = "") -> dict[str, nn.Conv2d]:
    """A VGG stream's convolutions by Caffe layer name (``prefix + "conv1_1"`` ... ``prefix + "fc7"``).

    Its layers are named as in the released definition, so this is also the
    map for DeepLab's VGG16 weights.
    """
    return {prefix + name: module for name, module in stream.layers.named_children() if isinstance(module, nn.Conv2d)}


def model_layers(model: EgoNetModel) -> dict[str, nn.Conv2d]:
    """A two-stream VGG model's convolutions by the release's layer names.

    ``conv1_1`` ... ``fc7`` (RGB stream), ``dhg_conv1_1`` ... ``dhg_fc7``,
    ``fc9`` and ``fc10_sal``.

    Raises:
        EgonetError: If the model is not a two-stream model of VGG streams.
    """
    streams = (getattr(model, "rgb_stream", None), getattr(model, "dhg_stream", None))
    if not isinstance(model, TwoStreamEgoNet) or not all(s is None or isinstance(s, VGGDeepLabStream) for s in streams):
        raise EgonetError(f"{model.config.name!r} is not a two-stream VGG model: no released layer names", field="model")
    layers: dict[str, nn.Conv2d] = {}
    for stream, prefix in zip(streams, ("", "dhg_")):
        if stream is not None:
            layers |= stream_layers(stream, prefix=prefix)
    if model.head.fc9 is not None:
        layers["fc9"] = model.head.fc9
    layers["fc10_sal"] = model.head.fc10
    return layers


def identify_release(
    layers: Mapping[str, CaffeLayer], *, releases: Sequence[Release] = RELEASES, path: str | Path = "<layers>"
) -> Release:
    """The release whose every layer and shape the file has (and no weights more).

    Args:
        layers: From :func:`read_caffemodel`.
        releases: The releases to accept (the authors' two by default).
        path: The file, for messages.

    Raises:
        EgonetError: One line naming the first layer at fault against the
            closest release (the one with DHG layers when the file has
            ``dhg_*`` layers), and both shapes when they differ.
    """
    expected = {release.key: release.expected_shapes() for release in releases}
    problems = {release.key: _mismatches(layers, release, expected[release.key]) for release in releases}
    for release in releases:
        if not problems[release.key]:
            return release
    has_dhg = any(name.startswith("dhg_") for name in layers)

    def distance(release: Release) -> tuple[bool, int]:
        uses_dhg = any(name.startswith("dhg_") for name in expected[release.key])
        return uses_dhg != has_dhg, len(problems[release.key])

    closest = min(releases, key=distance)
    raise EgonetError(f"{path}: not {closest.title}: {problems[closest.key][0]}", field="path")


def _mismatches(layers: Mapping[str, CaffeLayer], release: Release, expected: Mapping[str, list]) -> list[str]:
    """What keeps ``layers`` from being ``release`` (whose blob shapes are ``expected``), in layer order."""
    found = []
    for name, shapes in expected.items():
        layer = layers.get(name)
        if layer is None:
            found.append(f"layer {name!r} is missing")
            continue
        if len(layer.blobs) != len(shapes):
            found.append(f"layer {name!r} has {len(layer.blobs)} blobs, {release.title} has {len(shapes)} (weights, bias)")
            continue
        for blob, shape, what in zip(layer.blobs, shapes, ("weights", "bias")):
            if not _same_shape(blob.shape, shape):
                found.append(f"layer {name!r} {what} have shape {blob.shape} in the file, {shape} in {release.title}")
    found += [f"layer {name!r} has weights {release.title} does not have" for name, layer in layers.items()
              if layer.blobs and name not in expected]
    return found


def _same_shape(actual: tuple[int, ...], expected: tuple[int, ...]) -> bool:
    """Equal, or a legacy 4-D blob of the same values (a bias ``(1, 1, 1, n)`` is ``(n,)``), as Caffe reads them."""
    if actual == expected:
        return True
    return len(actual) == 4 and len(expected) < 4 and actual == (1,) * (4 - len(expected)) + expected


# --------------------------------------------------------------------------- loading


def load_caffemodel(
    path: str | Path, *, releases: Sequence[Release] = RELEASES, progress: Progress | None = None
) -> EgoNetModel:
    """The authors' released model from its ``.caffemodel``, in eval mode; no Caffe needed.

    The model is :func:`egonet.network.builders.build_model` of the release's builder
    (``egonet`` for RGB+DHG, ``egonet-rgb`` with a 512-wide fc9 for RGB) with
    the release's conventions. Its ``predict(rgb, dhg)`` takes ``rgb``
    ``(N, 3, H, W)`` RGB in ``[0, 1]`` and ``dhg`` ``(N, 3, H, W)`` as the
    authors' DHG files are stored (read as RGB: gray, height, depth) in
    ``[0, 1]`` (ignored by the RGB release), and returns the action-object
    probability ``(N, H, W)`` at the input size; ``geometry="zoom8"`` gives
    the release's own output size, ``8 (h - 1) + 1`` rows for an fc grid of
    ``h`` (385x513 for a 386x514 frame). See :meth:`EgoNetModel.forward`.

    Args:
        path: The ``.caffemodel``.
        releases: The releases to accept (the authors' two by default;
            tests pass small ones of the same topology).
        progress: Called with ``(bytes done, file size)`` while the weights
            are copied.

    Returns:
        The model, weights loaded, in eval mode, on the CPU.

    Raises:
        EgonetError: A file that is not one of ``releases`` (see
            :func:`identify_release`) or cannot be read.

    Example:
        >>> model = load_caffemodel("EgoNet_rgb_dhg.caffemodel")  # doctest: +SKIP
        >>> model.config.name, model.config.options["coords"]  # doctest: +SKIP
        ('egonet', 'released')
    """
    model, _, _ = _load(path, releases=releases, progress=progress)
    return model


def checkpoint_from_caffemodel(
    path: str | Path,
    *,
    size: tuple[int, int] = DEPLOY_SIZE,
    releases: Sequence[Release] = RELEASES,
    progress: Progress | None = None,
    name: str | None = None,
) -> dict:
    """A checkpoint (``egonet.checkpoint`` format) of a released model, for everything that reads checkpoints.

    :func:`egonet.checkpoint.model_from_checkpoint` and
    ``egonet.predictor.NetworkPredictor.from_checkpoint`` read it like a
    trained one: frames are resized to ``size`` for the forward pass and the
    maps back to each frame's size. It records where it came from under
    ``"released"`` (the release, the file's name, size and SHA-256); it has
    no training state, so it cannot be trained on.

    Args:
        path: The ``.caffemodel``.
        size: ``(H, W)`` frames are run at (the release's deploy size by default).
        releases: The releases to accept.
        progress: Called with ``(bytes done, file size)``.
        name: The file's name, recorded and in messages (default: ``path``'s).

    Returns:
        The checkpoint dict (plain types and tensors; ``torch.save`` it).
    """
    path = Path(path)
    model, release, digest = _load(path, releases=releases, progress=progress, name=name)
    config = TrainConfig(model=release.model, model_options=dict(model.config.options), height=size[0], width=size[1],
                         epochs=1, augment=None, device="cpu")
    released = {"release": release.key, "title": release.title, "file": name or path.name, "bytes": path.stat().st_size,
                "sha256": digest}
    return checkpoint_state(model, config, fold="released", train_keys=[], test_keys=[], epoch=0, iteration=0,
                            complete=True, metrics={}, history=[], extra={"released": released})


def _load(path: str | Path, *, releases: Sequence[Release], progress: Progress | None,
          name: str | None = None) -> tuple[EgoNetModel, Release, str]:
    """Read, identify, build and copy; returns the model, its release and the file's SHA-256."""
    path = Path(path)
    layers, buffer = _read(path, name=name)
    release = identify_release(layers, releases=releases, path=name or path)
    model = release.build()
    digest = hashlib.sha256()
    done = 0
    with torch.no_grad():
        for name, conv in _in_file_order(model_layers(model), layers):
            layer = layers[name]
            for parameter, blob in zip((conv.weight, conv.bias), layer.blobs):
                parameter.copy_(torch.from_numpy(blob).reshape(parameter.shape))
            done = _hash_to(digest, buffer, done, layer.end, progress)
    _hash_to(digest, buffer, done, len(buffer), progress)
    return model.eval(), release, digest.hexdigest()


def _in_file_order(convs: Mapping[str, nn.Conv2d], layers: Mapping[str, CaffeLayer]) -> Iterator[tuple[str, nn.Conv2d]]:
    """The model's layers in the order they lie in the file (so reading and hashing go forward)."""
    return iter(sorted(convs.items(), key=lambda item: layers[item[0]].end))


def _hash_to(digest, buffer: mmap.mmap, done: int, end: int, progress: Progress | None) -> int:
    """Hash the file's bytes ``[done, end)`` and report progress; returns ``end``."""
    if end <= done:
        return done
    view = memoryview(buffer)
    for start in range(done, end, 1 << 24):
        digest.update(view[start:min(end, start + (1 << 24))])
    view.release()
    if progress is not None:
        progress(end, len(buffer))
    return end
