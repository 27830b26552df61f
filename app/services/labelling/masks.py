"""Masks as the labelling page and exports send them: COCO run-length
encodings (RLE, checked and decoded by ``egonet.rle``) and binary PNGs,
checked against the frame before decoding. A PNG's size is read from its
header first.
"""

import numpy as np

from app.errors import Problem
from app.validation import Field, Invalid
from egonet import io as egonet_io
from egonet import rle as egonet_rle
from egonet.errors import EgonetError


class Rle(Field):
    """A COCO run-length encoding: ``{"size": [h, w], "counts": ...}``.

    ``counts`` is COCO's compressed string or a list of run lengths; runs go
    down the columns (column-major), starting with background. The check
    only looks at the shape of the value: ``decode_rle`` checks the counts
    against the frame's size, before any of them is decoded.
    """

    def check(self, value):
        if not isinstance(value, dict) or set(value) != {"size", "counts"}:
            raise Invalid('must be {"size": [height, width], "counts": ...}')
        size = value["size"]
        if not (isinstance(size, list) and len(size) == 2 and all(type(v) is int and v > 0 for v in size)):
            raise Invalid("size must be [height, width] in pixels")
        if not isinstance(value["counts"], str | list):
            raise Invalid("counts must be a string (COCO compressed) or a list of run lengths")
        return value


def decode_rle(rle: dict, shape: tuple[int, int], *, field: str) -> np.ndarray:
    """A bool ``(H, W)`` mask from a checked ``Rle`` value (``egonet.rle.decode``).

    Raises:
        Problem: 400 naming ``field`` when the size is not the frame's or
            the runs do not cover the mask exactly.
    """
    try:
        return egonet_rle.decode(rle, shape, field=field)
    except EgonetError as exc:
        raise Problem.from_egonet(exc) from None


def decode_mask_png(data: bytes, shape: tuple[int, int], *, field: str = "mask") -> np.ndarray:
    """A bool mask from PNG bytes that must be binary and of the frame's size.

    The size is read from the PNG's header first, so a PNG of another size
    (or a decompression bomb) is refused without being decoded.

    Raises:
        Problem: 400 naming ``field`` for a PNG of another size.
        egonet.io.MediaError: naming ``field`` for bytes that are no binary
            PNG (the app answers it as a 400 like a Problem).
    """
    width, height = egonet_io.image_size(data, path=field)
    if (height, width) != shape:
        got = f"{width}x{height}"
        raise Problem(
            f"{field}: the PNG is {got}, the frame {shape[1]}x{shape[0]}",
            fields={field: f"must be {shape[1]}x{shape[0]} like the frame, got {got}"},
        )
    return egonet_io.decode_mask(data, path=field)
