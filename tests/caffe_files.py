"""Hand-built Caffe ``.caffemodel`` files for tests: the protobuf wire format written directly, no Caffe.

:func:`write_caffemodel` writes layers (name, type, blobs) in the current
layout (``NetParameter.layer``, blobs with a ``shape``) or the legacy one
(``NetParameter.layers``, ``V1LayerParameter`` with an enum type, blobs sized
by num/channels/height/width), float data packed or not. It streams blob by
blob, so a full-size file never sits in memory twice.

:func:`release_layers` gives the layers of an ``egonet.caffe.Release`` with
its exact shapes (from the builder) and chosen values; :data:`TINY_RELEASES`
are the authors' two releases at 1/64 of every width (same layer names,
kernels and grid), which cost kilobytes. :func:`selector_layers` sets
weights that make the output follow one input channel, or one coordinate
map, so a test can see which channel reaches the network where.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path

import numpy as np

from egonet.caffe import RELEASES, Release

Layer = tuple[str, str, Sequence[np.ndarray]]

#: The authors' releases with every width divided by 64 (the loader accepts them only when asked to).
TINY_RELEASES: tuple[Release, ...] = tuple(
    dataclasses.replace(r, title=f"{r.title} at 1/64 width", options=dict(r.options) | {"width_divisor": 64})
    for r in RELEASES
)
TINY = {r.key: r for r in TINY_RELEASES}
FULL = {r.key: r for r in RELEASES}

_V1_TYPES = {"Convolution": 4, "ReLU": 18, "Data": 5, "InnerProduct": 14}


def _varint(value: int) -> bytes:
    out = bytearray()
    while True:
        byte = value & 0x7F
        value >>= 7
        if value:
            out.append(byte | 0x80)
        else:
            out.append(byte)
            return bytes(out)


def _key(number: int, wire: int) -> bytes:
    return _varint(number << 3 | wire)


def _delimited(number: int, payload: bytes) -> bytes:
    return _key(number, 2) + _varint(len(payload)) + payload


def _blob_parts(array: np.ndarray, *, legacy: bool, packed: bool) -> list[bytes | memoryview]:
    """A BlobProto's bytes, the float data as one (zero-copy) part."""
    data = np.ascontiguousarray(array, dtype="<f4")
    if legacy:
        shape = (1,) * (4 - data.ndim) + data.shape
        head = b"".join(_key(number, 0) + _varint(dim) for number, dim in zip((1, 2, 3, 4), shape))
    else:
        head = _delimited(7, _delimited(1, b"".join(_varint(d) for d in data.shape)))
    if packed:
        return [head, _key(5, 2) + _varint(data.nbytes), memoryview(data).cast("B")]
    records = np.empty((data.size, 5), np.uint8)
    records[:, 0] = 0x2D  # field 5, wire type 5 (fixed32), once per value
    records[:, 1:] = data.reshape(-1, 1).view(np.uint8).reshape(-1, 4)
    return [head, records.tobytes()]


def write_caffemodel(path: str | Path, layers: Iterable[Layer], *, legacy: bool = False, packed: bool = True,
                     name: str = "EgoNet") -> Path:
    """Write a ``.caffemodel`` of ``layers`` (name, type, blobs), in file order; returns the path."""
    path = Path(path)
    with path.open("wb") as fh:
        fh.write(_delimited(1, name.encode()))
        for layer_name, kind, blobs in layers:
            if legacy:
                head = _delimited(4, layer_name.encode()) + _key(5, 0) + _varint(_V1_TYPES.get(kind, 0))
            else:
                head = _delimited(1, layer_name.encode()) + _delimited(2, kind.encode())
            blob_parts = [_blob_parts(b, legacy=legacy, packed=packed) for b in blobs]
            blob_number = 6 if legacy else 7
            blob_heads = [_key(blob_number, 2) + _varint(sum(len(p) if isinstance(p, bytes) else p.nbytes for p in parts))
                          for parts in blob_parts]
            length = len(head) + sum(len(h) for h in blob_heads) + sum(
                len(p) if isinstance(p, bytes) else p.nbytes for parts in blob_parts for p in parts)
            fh.write(_key(2 if legacy else 100, 2) + _varint(length) + head)
            for blob_head, parts in zip(blob_heads, blob_parts):
                fh.write(blob_head)
                for part in parts:
                    fh.write(part)
    return path


def release_layers(release: Release, values: Mapping[str, Sequence[np.ndarray]] | None = None, *,
                   seed: int | None = None) -> list[Layer]:
    """The release's layers in order (with a parameter-free ReLU among them, as a real net has).

    Blobs are ``values[name]`` when given, else zeros, or small Gaussian
    weights when ``seed`` is given.
    """
    rng = np.random.default_rng(seed) if seed is not None else None
    out: list[Layer] = [("data", "Data", [])]
    for layer_name, shapes in release.expected_shapes().items():
        if values is not None and layer_name in values:
            blobs = list(values[layer_name])
        elif rng is not None:
            blobs = [rng.normal(0, 0.05, shape).astype(np.float32) for shape in shapes]
        else:
            blobs = [np.zeros(shape, np.float32) for shape in shapes]
        out.append((layer_name, "Convolution", blobs))
        if layer_name == "conv1_1":
            out.append(("relu1_1", "ReLU", []))
    return out


def selector_layers(release: Release, *, stream: str = "rgb", channel: int = 0, coordinate: int | None = None,
                    gain: float = 0.01, offset: float = -2.0) -> list[Layer]:
    """Weights whose output follows one input channel of one stream (or one coordinate map).

    The path keeps channel 0 of every layer: ``conv1_1`` copies input
    channel ``channel`` (plus 200, so ReLU passes it whatever its sign),
    each 3x3 convolution its centre, fc6 the mean of four of its taps, fc7
    and fc9 their input; ``fc10_sal`` makes the action-object logit
    ``gain * x + offset`` and the background one 0. With ``coordinate``
    (0 or 1), fc9 reads that coordinate map (plus 200) instead. The action-
    object probability then rises with the chosen channel.
    """
    shapes = release.expected_shapes()
    values = {name: [np.zeros(shape, np.float32) for shape in blob_shapes] for name, blob_shapes in shapes.items()}
    prefix = "" if stream == "rgb" else "dhg_"
    fc9_in = values["fc9"][0].shape[1]
    streams = fc9_in - 2
    if coordinate is None:
        for name, (weight, bias) in values.items():
            if not name.startswith(prefix) or (prefix == "" and name.startswith("dhg_")) or name in ("fc9", "fc10_sal"):
                continue
            if name.startswith(f"{prefix}conv"):
                if name == f"{prefix}conv1_1":
                    weight[0, channel, 1, 1], bias[0] = 1.0, 200.0
                else:
                    weight[0, 0, 1, 1] = 1.0
            elif name == f"{prefix}fc6":
                weight[0, 0, 1:3, 1:3] = 0.25
            elif name == f"{prefix}fc7":
                weight[0, 0, 0, 0] = 1.0
        values["fc9"][0][0, 0 if stream == "rgb" else streams // 2, 0, 0] = 1.0
    else:
        values["fc9"][0][0, streams + coordinate, 0, 0] = 1.0
        values["fc9"][1][0] = 200.0
    values["fc10_sal"][0][1, 0, 0, 0] = gain
    values["fc10_sal"][1][1] = offset
    return release_layers(release, values)


def write_lying_blob(path: str | Path, dims: Sequence[int]) -> Path:
    """A ``.caffemodel`` whose one blob claims the shape ``dims`` and holds no data (a lie the reader must refuse)."""
    blob = _delimited(7, _delimited(1, b"".join(_varint(d) for d in dims)))
    layer = _delimited(1, b"conv1_1") + _delimited(2, b"Convolution") + _delimited(7, blob)
    path = Path(path)
    path.write_bytes(_delimited(1, b"EgoNet") + _delimited(100, layer))
    return path
