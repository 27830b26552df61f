"""Run-length encodings of bool masks: COCO's RLE (on top of pycocotools) and plain row-major runs.

COCO's RLE is ``{"size": [h, w], "counts": ...}``: runs down the columns
(column-major) starting with background, ``counts`` COCO's compressed string
or a list of run lengths. :func:`decode` checks the counts (length, alphabet,
number widths, signs, total) before pycocotools decodes them, so a hostile
string costs no more than a frame's worth of work (pycocotools leaves the
rest of a mask uninitialised when the runs fall short)::

    >>> mask = np.eye(3, dtype=bool)
    >>> rle = encode(mask)
    >>> rle, area(rle), bbox(rle)
    ({'size': [3, 3], 'counts': '013000'}, 3, [0.0, 0.0, 3.0, 3.0])
    >>> bool((decode(rle, (3, 3), field="mask") == mask).all())
    True

:func:`runs` and :func:`from_runs` are the same runs along the rows, as a
uint32 array (GrabCut's saved state keeps its masks so).
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence

import numpy as np
import pycocotools.mask as coco_mask

from egonet.errors import EgonetError

__all__ = ["area", "bbox", "decode", "encode", "from_polygons", "from_runs", "max_chars", "runs"]


def encode(mask: np.ndarray) -> dict:
    """A bool ``(H, W)`` mask as COCO's RLE with the compressed counts string (JSON-ready)."""
    rle = coco_mask.encode(np.asfortranarray(mask.astype(np.uint8)))
    return {"size": [int(v) for v in rle["size"]], "counts": rle["counts"].decode("ascii")}


def area(rle: Mapping) -> int:
    """The foreground pixels of an :func:`encode` RLE."""
    return int(coco_mask.area(_compressed(rle)))


def bbox(rle: Mapping) -> list[float]:
    """The ``[x, y, width, height]`` box of an :func:`encode` RLE's foreground (zeros when empty)."""
    return [float(v) for v in coco_mask.toBbox(_compressed(rle))]


def from_polygons(polygons: Sequence[Sequence[float]], height: int, width: int) -> np.ndarray:
    """A bool ``(H, W)`` mask of COCO polygons (``[x0, y0, x1, y1, ...]`` each), their union.

    Raises:
        TypeError, ValueError, IndexError: pycocotools' own, for a polygon it cannot read.
    """
    return _decode(coco_mask.merge(coco_mask.frPyObjects([list(map(float, p)) for p in polygons], height, width)))


def decode(rle: Mapping, shape: tuple[int, int] | None = None, *, field: str = "mask") -> np.ndarray:
    """A bool ``(H, W)`` mask from COCO's RLE (counts a string or a list), checked before decoding.

    Args:
        rle: ``{"size": [h, w], "counts": str | list[int]}``.
        shape: The ``(H, W)`` the mask must have (the frame's); ``None``: the RLE's size.
        field: The input it came from, for messages (``"<field>.size"``, ``"<field>.counts"``).

    Raises:
        EgonetError: The size is not ``shape``, or the counts do not cover the
            mask exactly (too long, a character outside the alphabet, a
            number wider than any count, a negative run, a wrong total).
    """
    h, w = shape if shape is not None else rle["size"]
    if list(rle["size"]) != [h, w]:
        raise EgonetError(f"{field}: the mask is {rle['size'][1]}x{rle['size'][0]}, the frame {w}x{h}",
                          field=f"{field}.size", reason=f"must be [{h}, {w}] (the frame's height and width)")
    counts, where = rle["counts"], f"{field}.counts"
    found = _string_runs(counts, h * w, where=where) if isinstance(counts, str) else _list_runs(counts, h * w, where=where)
    if (found < 0).any():
        raise EgonetError(f"{where}: a run length is negative", field=where)
    total = int(found.sum())
    if total != h * w:
        raise EgonetError(f"{where}: the runs cover {total} pixels, the mask has {h * w}", field=where,
                          reason=f"must add up to {h * w} pixels")
    if isinstance(counts, str):
        return _decode({"size": [h, w], "counts": counts.encode()})
    return _decode(coco_mask.frPyObjects({"size": [h, w], "counts": counts}, h, w))


def max_chars(pixels: int) -> int:
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


def runs(mask: np.ndarray) -> np.ndarray:
    """Run lengths of a bool array in row-major order, starting with a False run (uint32)."""
    flat = mask.ravel()
    if flat.size == 0:
        return np.zeros(0, np.uint32)
    change = np.flatnonzero(flat[1:] != flat[:-1]) + 1
    found = np.diff(np.concatenate([[0], change, [flat.size]]))
    if flat[0]:
        found = np.concatenate([[0], found])
    return found.astype(np.uint32)


def from_runs(found: np.ndarray, shape: tuple[int, int], *, field: str) -> np.ndarray:
    """The bool ``shape`` mask of :func:`runs`.

    Raises:
        EgonetError: (``field``) if the runs do not add up to the mask's pixels.
    """
    values = np.arange(len(found)) % 2 == 1
    flat = np.repeat(values, found.astype(np.int64))
    if flat.size != shape[0] * shape[1]:
        raise EgonetError(f"{field}: mask run lengths sum to {flat.size}, expected {shape[0] * shape[1]}", field=field)
    return flat.reshape(shape)


def _compressed(rle: Mapping) -> dict:
    return {"size": list(rle["size"]), "counts": rle["counts"].encode("ascii")}


def _decode(rle: dict) -> np.ndarray:
    with warnings.catch_warnings():
        # pycocotools' decoder predates numpy 2's __array__(copy=...) and says so.
        warnings.simplefilter("ignore", DeprecationWarning)
        return np.ascontiguousarray(coco_mask.decode(rle), dtype=bool)


def _count_chars(pixels: int) -> int:
    """The most characters one count of such a mask takes (a difference in [-pixels, pixels])."""
    k = 1
    while 2 ** (5 * k - 1) <= pixels:
        k += 1
    return k


def _string_runs(text: str, pixels: int, *, where: str) -> np.ndarray:
    """Run lengths from COCO's compressed string, checked: pycocotools leaves
    the rest of the mask uninitialised when the runs fall short, and older
    versions read past a string that ends inside a number.

    Each count is written in 5-bit groups, least significant first (6 bits
    per character offset by 48: 0x20 says another group follows, 0x10 of the
    last group is the sign), from the fourth count on as the difference to
    the count two places before.

    Raises:
        EgonetError: naming ``where`` (the counts' field).
    """
    if len(text) > max_chars(pixels):
        raise EgonetError(f"{where}: {len(text)} characters, more than a mask of {pixels} pixels takes "
                          f"({max_chars(pixels)} at most)", field=where)
    codes = np.frombuffer(text.encode("ascii", "replace"), np.uint8) - np.uint8(48)  # the alphabet is 0..63
    if not text.isascii() or (codes >= 64).any():
        wide = np.frombuffer(text.encode("utf-32-le", "surrogatepass"), np.uint32)
        first = text[np.argmax((wide < 48) | (wide >= 112))]
        raise EgonetError(f"{where}: character {first!r} is not part of COCO's RLE alphabet", field=where)
    if not codes.size:
        return codes.astype(np.int64)
    last = (codes & 0x20) == 0  # the last character of a number
    if not last[-1]:
        raise EgonetError(f"{where}: the string ends inside a number", field=where)
    ends = np.flatnonzero(last)
    widths = np.empty_like(ends)
    widths[0] = ends[0] + 1
    np.subtract(ends[1:], ends[:-1], out=widths[1:])
    if widths.max() > _count_chars(pixels):
        raise EgonetError(f"{where}: a number of {widths.max()} characters; no count of this mask takes more than "
                          f"{_count_chars(pixels)}", field=where)
    _check_run_count(len(ends), pixels, where=where)
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
    found = values.copy()
    found[1::2] = np.cumsum(values[1::2])  # counts[i] = values[i] + counts[i - 2] from i = 3 on
    found[2::2] = np.cumsum(values[2::2])
    return found


def _list_runs(counts: list, pixels: int, *, where: str) -> np.ndarray:
    _check_run_count(len(counts), pixels, where=where)  # before looking at each
    if not set(map(type, counts)) <= {int}:
        raise EgonetError(f"{where}: must be non-negative integers", field=where)
    try:
        return np.array(counts, np.int64)
    except OverflowError:
        raise EgonetError(f"{where}: a run is longer than the mask's {pixels} pixels", field=where) from None


def _check_run_count(n: int, pixels: int, *, where: str) -> None:
    if n > pixels + 1:
        raise EgonetError(f"{where}: {n} runs, more than a mask of {pixels} pixels has ({pixels + 1} at most)",
                          field=where)
