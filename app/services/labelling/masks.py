"""Masks as the labelling page and exports send them: COCO run-length
encodings (RLE) and binary PNGs, checked against the frame before decoding.

A hostile RLE string costs no more than a frame's worth of work: its length,
alphabet, number widths, signs and total are checked before pycocotools
decodes it (pycocotools leaves the rest of a mask uninitialised when the
runs fall short). A PNG's size is read from its header first.
"""

import warnings

import numpy as np
import pycocotools.mask as coco_mask

from app.errors import Problem
from app.validation import Field, Invalid
from egonet import io as egonet_io


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


def max_rle_chars(pixels: int) -> int:
    """The longest compressed counts string of a mask of ``pixels`` pixels.

    pycocotools and the page write each count in as few characters as it
    takes, and no empty run but the first, so a mask has at most pixels + 1
    counts of at least one character each. A count written as a difference
    ``d`` in k >= 2 characters has ``|d| >= 2**(5k - 6)``, and the
    differences add up to at most 2 * pixels (each is at most the sum of
    the two runs it compares), so at most 2 * pixels / 2**(5k - 6) counts
    take a k-th character: 2 * pixels * (1/16 + 1/512 + ...) = 4 * pixels / 31
    characters beyond one per count.
    """
    return pixels + 1 + 4 * pixels // 31


def _count_chars(pixels: int) -> int:
    """The most characters one count of such a mask takes (a difference in [-pixels, pixels])."""
    k = 1
    while 2 ** (5 * k - 1) <= pixels:
        k += 1
    return k


def _bad_counts(where: str, reason: str) -> Problem:
    return Problem(f"{where}: {reason}", fields={where: reason})


def _string_runs(text: str, pixels: int, *, where: str) -> np.ndarray:
    """Run lengths from COCO's compressed string, checked: pycocotools leaves
    the rest of the mask uninitialised when the runs fall short, and older
    versions read past a string that ends inside a number.

    Each count is written in 5-bit groups, least significant first (6 bits
    per character offset by 48: 0x20 says another group follows, 0x10 of the
    last group is the sign), from the fourth count on as the difference to
    the count two places before.

    Raises:
        Problem: 400 naming ``where`` (the counts' field).
    """
    if len(text) > max_rle_chars(pixels):
        raise _bad_counts(where, f"{len(text)} characters, more than a mask of {pixels} pixels takes "
                                 f"({max_rle_chars(pixels)} at most)")
    codes = np.frombuffer(text.encode("ascii", "replace"), np.uint8) - np.uint8(48)  # the alphabet is 0..63
    if not text.isascii() or (codes >= 64).any():
        wide = np.frombuffer(text.encode("utf-32-le", "surrogatepass"), np.uint32)
        first = text[np.argmax((wide < 48) | (wide >= 112))]
        raise _bad_counts(where, f"character {first!r} is not part of COCO's RLE alphabet")
    if not codes.size:
        return codes.astype(np.int64)
    last = (codes & 0x20) == 0  # the last character of a number
    if not last[-1]:
        raise _bad_counts(where, "the string ends inside a number")
    ends = np.flatnonzero(last)
    widths = np.empty_like(ends)
    widths[0] = ends[0] + 1
    np.subtract(ends[1:], ends[:-1], out=widths[1:])
    if widths.max() > _count_chars(pixels):
        raise _bad_counts(where, f"a number of {widths.max()} characters; no count of this mask takes more than "
                                 f"{_count_chars(pixels)}")
    if len(ends) > pixels + 1:
        raise _bad_counts(where, f"{len(ends)} runs, more than a mask of {pixels} pixels has ({pixels + 1} at most)")
    return _unpack_counts(codes, ends, widths)


def _unpack_counts(codes: np.ndarray, ends: np.ndarray, widths: np.ndarray) -> np.ndarray:
    """The run lengths of checked codes, given where each number ends and how wide it is."""
    # Horner's rule from each number's last (most significant) group back, on
    # the numbers that still have groups left.
    values = (codes[ends] & 0x1F).astype(np.int64)
    longer = np.flatnonzero(widths > 1)
    for j in range(1, int(widths.max())):
        longer = longer[widths[longer] > j]
        values[longer] = (values[longer] << 5) | (codes[ends[longer] - j] & 0x1F)
    negative = np.flatnonzero(codes[ends] & 0x10)
    values[negative] -= np.left_shift(1, 5 * widths[negative])
    runs = values.copy()
    runs[1::2] = np.cumsum(values[1::2])  # counts[i] = values[i] + counts[i - 2] from i = 3 on
    runs[2::2] = np.cumsum(values[2::2])
    return runs


def _list_runs(counts: list, pixels: int, *, where: str) -> np.ndarray:
    if len(counts) > pixels + 1:  # before looking at each
        raise _bad_counts(where, f"{len(counts)} runs, more than a mask of {pixels} pixels has ({pixels + 1} at most)")
    if not set(map(type, counts)) <= {int}:
        raise _bad_counts(where, "must be non-negative integers")
    try:
        return np.array(counts, np.int64)
    except OverflowError:
        raise _bad_counts(where, f"a run is longer than the mask's {pixels} pixels") from None


def coco_decode(rle: dict) -> np.ndarray:
    """A bool ``(H, W)`` mask from a compressed COCO RLE, with pycocotools."""
    with warnings.catch_warnings():
        # pycocotools' decoder predates numpy 2's __array__(copy=...) and says so.
        warnings.simplefilter("ignore", DeprecationWarning)
        return np.ascontiguousarray(coco_mask.decode(rle), dtype=bool)


def decode_rle(rle: dict, shape: tuple[int, int], *, field: str) -> np.ndarray:
    """A bool ``(H, W)`` mask from a checked ``Rle`` value.

    The counts are checked (length, alphabet, signs, total) before
    pycocotools decodes them, so a hostile string costs no more than a
    frame's worth of work.

    Raises:
        Problem: 400 naming ``field`` when the size is not the frame's or
            the runs do not cover the mask exactly.
    """
    h, w = shape
    if list(rle["size"]) != [h, w]:
        raise Problem(
            f"{field}: the mask is {rle['size'][1]}x{rle['size'][0]}, the frame {w}x{h}",
            fields={f"{field}.size": f"must be [{h}, {w}] (the frame's height and width)"},
        )
    counts, where = rle["counts"], f"{field}.counts"
    if isinstance(counts, str):
        runs = _string_runs(counts, h * w, where=where)
    else:
        runs = _list_runs(counts, h * w, where=where)
    if (runs < 0).any():
        raise _bad_counts(where, "a run length is negative")
    total = int(runs.sum())
    if total != h * w:
        raise Problem(f"{where}: the runs cover {total} pixels, the mask has {h * w}",
                      fields={where: f"must add up to {h * w} pixels"})
    if isinstance(counts, str):
        return coco_decode({"size": [h, w], "counts": counts.encode()})
    return coco_decode(coco_mask.frPyObjects({"size": [h, w], "counts": counts}, h, w))


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
