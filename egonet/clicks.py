"""Superpixels and click-to-soft-mask projection for the human study.

In the paper's human study a subject clicks the centre of each
action-object; every click becomes a Gaussian of width 60 px that is
projected onto superpixel regions (MCG regions in the paper), giving a soft
per-pixel mask that is scored like a machine's probability map.

Choices (see ``shared/docs/egonet-reference.md``):

* Regions: SLIC superpixels from scikit-image by default (about 400 regions
  per frame, i.e. ~55x55 px regions at 1280x960, on the order of the click
  Gaussian's width), or Felzenszwalb's graph segmentation, which follows
  object boundaries more closely but gives irregular sizes. MCG itself is
  not available in Python; SLIC at this granularity is a stand-in for the
  fine level of its hierarchy. Both are computed on a copy downscaled to at
  most ``max_side`` pixels (SLIC at full 1280x960 takes over 1.5 s) and the
  labels are upscaled with nearest neighbour.
* Width: the Gaussian's standard deviation, in pixels of the frame's native
  resolution (``exp(-d^2 / (2 sigma^2))``, peak 1).
* Several clicks combine by pixel-wise maximum, before projection.
* Projection: each region takes the mean of the Gaussian over its pixels.

Example:
    >>> import numpy as np
    >>> labels = np.repeat(np.arange(4, dtype=np.int32), 4).reshape(4, 4)
    >>> m = soft_mask((4, 4), [(1.0, 0.0)], sigma=2.0, labels=labels)
    >>> bool(m[0, 0] == m[0, 3]), bool(m[0, 0] > m[3, 0])
    (True, True)
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from egonet.errors import EgonetError
from egonet.io import check_rgb

__all__ = ["DEFAULT_SIGMA", "SUPERPIXEL_DEFAULTS", "MaskMean", "SuperpixelDefaults", "click_gaussian",
           "project_to_regions", "soft_mask", "superpixels"]

DEFAULT_SIGMA = 60.0
"""The paper's click width: standard deviation in native-resolution pixels."""

SUPERPIXEL_METHODS = ("slic", "felzenszwalb")


@dataclass(frozen=True)
class SuperpixelDefaults:
    """The one place the superpixel defaults live (``superpixels``, the
    study builder and its form all read them): SLIC with about 400 regions
    of compactness 10, as a stand-in for the paper's MCG regions; for
    Felzenszwalb, scale 100 and regions of at least 50 pixels; both on a
    copy at most 640 px on its long side."""

    method: str = "slic"
    n_segments: int = 400
    compactness: float = 10.0
    scale: float = 100.0
    min_size: int = 50
    max_side: int = 640


SUPERPIXEL_DEFAULTS = SuperpixelDefaults()


def _relabel(labels: np.ndarray) -> np.ndarray:
    """Map labels to contiguous 0..n-1, preserving their order."""
    flat = labels.reshape(-1)
    present = np.bincount(flat) > 0
    table = (np.cumsum(present) - 1).astype(np.int32)
    return table[labels]


def _upscale_nearest(labels: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Nearest-neighbour resize: pixel (r, c) takes source pixel (floor((r + 0.5) h / H), ...)."""
    h, w = labels.shape
    rows = ((np.arange(shape[0]) + 0.5) * (h / shape[0])).astype(np.intp)
    cols = ((np.arange(shape[1]) + 0.5) * (w / shape[1])).astype(np.intp)
    np.minimum(rows, h - 1, out=rows)
    np.minimum(cols, w - 1, out=cols)
    return labels[rows[:, None], cols[None, :]]


def superpixels(
    image: np.ndarray,
    *,
    method: str = SUPERPIXEL_DEFAULTS.method,
    n_segments: int | None = None,
    compactness: float | None = None,
    scale: float | None = None,
    min_size: int | None = None,
    max_side: int | None = SUPERPIXEL_DEFAULTS.max_side,
) -> np.ndarray:
    """Partition a frame into superpixel regions.

    The frame is downscaled (area interpolation) so that its longer side is
    at most ``max_side`` pixels, segmented there, and the labels are resized
    back with nearest neighbour, so region borders are as coarse as the
    working resolution (2 px at 1280x960 with the default 640).

    Args:
        image: Frame, uint8 (H, W, 3), RGB.
        method: ``"slic"`` (default; compact regions of similar size, in
            CIELAB) or ``"felzenszwalb"`` (graph-based, follows edges, sizes
            vary).
        n_segments: SLIC only: approximate number of regions (default 400).
        compactness: SLIC only: colour against space trade-off, higher is
            more square (default 10).
        scale: Felzenszwalb only: larger gives larger regions (default 100,
            in working-resolution terms).
        min_size: Felzenszwalb only: smallest region in working pixels
            (default 50).
        max_side: Longest side of the working image; None segments at full
            resolution.

    Returns:
        Labels 0..n-1, contiguous, int32 (H, W).

    Raises:
        ValueError: If ``image`` is not uint8 (H, W, 3), ``method`` is
            unknown, an option does not apply to ``method`` or is out of
            range.

    Example:
        >>> img = np.zeros((60, 80, 3), dtype=np.uint8)
        >>> img[:, 40:] = 255
        >>> labels = superpixels(img, n_segments=8)
        >>> labels.shape, labels.dtype.name, int(labels.min())
        ((60, 80), 'int32', 0)
    """
    # Imported here: scikit-image is slow to import and soft_mask (scoring a
    # study) does not need it.
    from skimage.segmentation import felzenszwalb, slic

    h, w = check_rgb(image, "image", min_side=2)
    if method not in SUPERPIXEL_METHODS:
        raise EgonetError(f"unknown method {method!r}; valid methods: {', '.join(SUPERPIXEL_METHODS)}", field="method")
    slic_only = {"n_segments": n_segments, "compactness": compactness}
    felz_only = {"scale": scale, "min_size": min_size}
    not_applicable = felz_only if method == "slic" else slic_only
    for name, value in not_applicable.items():
        if value is not None:
            raise EgonetError(f"{name} does not apply to method={method!r}", field=name)
    if max_side is not None and (isinstance(max_side, bool) or not isinstance(max_side, (int, np.integer)) or max_side < 8):
        raise EgonetError(f"max_side must be None or an int >= 8, got {max_side!r}", field="max_side")

    work = image
    if max_side is not None and max(h, w) > max_side:
        f = max_side / max(h, w)
        size = (max(2, round(w * f)), max(2, round(h * f)))
        work = cv2.resize(image, size, interpolation=cv2.INTER_AREA)

    if method == "slic":
        n = SUPERPIXEL_DEFAULTS.n_segments if n_segments is None else n_segments
        c = SUPERPIXEL_DEFAULTS.compactness if compactness is None else compactness
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
            raise EgonetError(f"n_segments must be a positive int, got {n!r}", field="n_segments")
        if not np.isfinite(c) or c <= 0:
            raise EgonetError(f"compactness must be a positive number, got {c!r}", field="compactness")
        labels = slic(work, n_segments=int(n), compactness=float(c), start_label=0, channel_axis=-1)
    else:
        s = SUPERPIXEL_DEFAULTS.scale if scale is None else scale
        m = SUPERPIXEL_DEFAULTS.min_size if min_size is None else min_size
        if not np.isfinite(s) or s <= 0:
            raise EgonetError(f"scale must be a positive number, got {s!r}", field="scale")
        if isinstance(m, bool) or not isinstance(m, (int, np.integer)) or m < 1:
            raise EgonetError(f"min_size must be a positive int, got {m!r}", field="min_size")
        labels = felzenszwalb(work, scale=float(s), sigma=0.8, min_size=int(m), channel_axis=-1)

    labels = np.asarray(labels, dtype=np.int32)
    if labels.shape != (h, w):
        labels = _upscale_nearest(labels, (h, w))
    return _relabel(labels)


def _check_shape(shape: Sequence[int]) -> tuple[int, int]:
    if (
        not isinstance(shape, (tuple, list))
        or len(shape) != 2
        or any(isinstance(s, bool) or not isinstance(s, (int, np.integer)) or s < 1 for s in shape)
    ):
        raise EgonetError(f"shape must be (H, W) with positive ints, got {shape!r}", field="shape")
    return int(shape[0]), int(shape[1])


def _check_sigma(sigma: float) -> float:
    if isinstance(sigma, bool) or not isinstance(sigma, (int, float, np.integer, np.floating)):
        raise EgonetError(f"sigma must be a positive number of pixels, got {sigma!r}", field="sigma")
    if not np.isfinite(sigma) or sigma <= 0:
        raise EgonetError(f"sigma must be a positive finite number of pixels, got {sigma}", field="sigma")
    return float(sigma)


def _check_clicks(clicks: Sequence[Sequence[float]] | np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    arr = np.asarray(clicks, dtype=np.float64) if len(clicks) else np.zeros((0, 2))
    if arr.ndim != 2 or arr.shape[1] != 2:
        raise EgonetError(f"clicks must be a sequence of (x, y) pairs, shape (N, 2), got shape {arr.shape}", field="clicks")
    h, w = shape
    for i, (x, y) in enumerate(arr):
        if not (np.isfinite(x) and np.isfinite(y)):
            raise EgonetError(f"clicks[{i}] = ({x}, {y}) is not finite", field="clicks")
        if not (-0.5 <= x <= w - 0.5 and -0.5 <= y <= h - 0.5):
            raise EgonetError(
                f"clicks[{i}] = (x={x}, y={y}) lies outside the {w}x{h} frame "
                f"(x in [-0.5, {w - 0.5}], y in [-0.5, {h - 0.5}])",
                field="clicks",
            )
    return arr


def click_gaussian(
    shape: tuple[int, int],
    clicks: Sequence[Sequence[float]] | np.ndarray,
    *,
    sigma: float = DEFAULT_SIGMA,
) -> np.ndarray:
    """Pixel-wise maximum of one unit-peak Gaussian per click (no projection).

    Each Gaussian is computed separably as the outer product of two 1-D
    exponentials, ``exp(-(r - y)^2 / (2 sigma^2)) * exp(-(c - x)^2 / (2
    sigma^2))``.

    Args:
        shape: Frame size (H, W).
        clicks: Click positions (x, y) in pixels, x = column, y = row,
            shape (N, 2); pixel centres are at integer coordinates, so a
            click must lie in [-0.5, W - 0.5] x [-0.5, H - 0.5].
        sigma: Standard deviation in pixels.

    Returns:
        Values in [0, 1], float32 (H, W); zeros when there are no clicks.

    Raises:
        ValueError: As :func:`soft_mask`.
    """
    h, w = _check_shape(shape)
    return _gaussian((h, w), _check_clicks(clicks, (h, w)), _check_sigma(sigma))


def _gaussian(shape: tuple[int, int], arr: np.ndarray, sigma: float) -> np.ndarray:
    h, w = shape
    out = np.zeros((h, w), dtype=np.float32)
    if len(arr) == 0:
        return out
    rows = np.arange(h, dtype=np.float64)
    cols = np.arange(w, dtype=np.float64)
    scratch = np.empty((h, w), dtype=np.float32) if len(arr) > 1 else out
    inv = -1.0 / (2.0 * sigma * sigma)
    for i, (x, y) in enumerate(arr):
        gy = np.exp(inv * (rows - y) ** 2).astype(np.float32)
        gx = np.exp(inv * (cols - x) ** 2).astype(np.float32)
        target = out if i == 0 else scratch
        np.multiply(gy[:, None], gx[None, :], out=target)
        if i > 0:
            np.maximum(out, scratch, out=out)
    return out


def project_to_regions(values: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """Replace every pixel by the mean of ``values`` over its region.

    Args:
        values: Per-pixel values, float (H, W).
        labels: Region labels, non-negative ints (H, W); need not be
            contiguous.

    Returns:
        Region means, float32 (H, W).

    Raises:
        ValueError: If ``labels`` is not a non-negative integer map of the
            same shape as ``values``.
    """
    values = np.asarray(values)
    labels = _check_labels(labels, values.shape)
    flat = labels.reshape(-1)
    if flat.dtype.itemsize >= 8 and flat.dtype.kind == "u":
        flat = flat.astype(np.intp)  # bincount refuses uint64
    counts = np.bincount(flat)
    sums = np.bincount(flat, weights=values.reshape(-1))
    means = (sums / np.maximum(counts, 1)).astype(np.float32)
    return means.take(flat).reshape(labels.shape)


def _check_labels(labels: object, shape: tuple[int, ...]) -> np.ndarray:
    if not isinstance(labels, np.ndarray) or labels.dtype.kind not in "iu":
        desc = labels.dtype if isinstance(labels, np.ndarray) else type(labels).__name__
        raise EgonetError(f"labels must be an integer (H, W) array from superpixels(), got {desc}", field="labels")
    if labels.shape != tuple(shape):
        raise EgonetError(
            f"labels has shape {labels.shape} but shape is {tuple(shape)}; compute labels on this frame", field="labels"
        )
    if labels.size and labels.dtype.kind == "i" and labels.min() < 0:
        raise EgonetError("labels must be non-negative", field="labels")
    return labels


def soft_mask(
    shape: tuple[int, int],
    clicks: Sequence[Sequence[float]] | np.ndarray,
    *,
    sigma: float = DEFAULT_SIGMA,
    labels: np.ndarray | None,
) -> np.ndarray:
    """Turn a subject's clicks into a soft action-object mask.

    Each click (x, y) becomes ``exp(-d^2 / (2 sigma^2))`` (peak 1, ``d`` the
    distance in pixels); several clicks combine by pixel-wise maximum; the
    result is projected onto the superpixels, each region taking the mean
    of the Gaussian over its pixels.

    Args:
        shape: Frame size (H, W); clicks and labels are in this frame.
        clicks: Click positions (x, y) in pixels, x = column, y = row,
            shape (N, 2), possibly empty. Pixel centres are at integer
            coordinates: a click must lie in [-0.5, W - 0.5] x
            [-0.5, H - 0.5].
        sigma: Standard deviation of each Gaussian in pixels at this
            resolution (the paper's "width 60 px" at 1280x960).
        labels: Superpixel labels, int (H, W), e.g. cached output of
            :func:`superpixels`; ``None`` (must be said explicitly) returns
            the raw Gaussian map without projection.

    Returns:
        Soft mask in [0, 1], float32 (H, W), constant on every region;
        zeros when there are no clicks.

    Raises:
        ValueError: If ``shape`` is not two positive ints, ``sigma`` is not
            positive and finite, a click is not finite or lies outside the
            frame (the message names its index), or ``labels`` is not a
            non-negative integer map of size ``shape``.

    Example:
        >>> labels = np.zeros((3, 4), dtype=np.int32)
        >>> labels[:, 2:] = 1
        >>> float(soft_mask((3, 4), [], labels=labels).max())
        0.0
    """
    h, w = _check_shape(shape)
    sigma = _check_sigma(sigma)
    arr = _check_clicks(clicks, (h, w))
    if labels is not None:
        labels = _check_labels(labels, (h, w))
    gauss = _gaussian((h, w), arr, sigma)
    if labels is None or len(arr) == 0:
        return gauss
    out = project_to_regions(gauss, labels)
    return np.clip(out, 0.0, 1.0, out=out)


class MaskMean:
    """The pixel-wise mean of soft masks given one at a time (the paper's Fig. 5 mean map).

    Sums in float64, so the mean of many participants does not depend on
    their order beyond rounding; ``mean()`` is float32 like the masks.

    Example:
        >>> acc = MaskMean()
        >>> acc.add(np.ones((2, 2), np.float32))
        >>> acc.add(np.zeros((2, 2), np.float32))
        >>> acc.count, float(acc.mean()[0, 0])
        (2, 0.5)
    """

    def __init__(self) -> None:
        self.total: np.ndarray | None = None
        self.count = 0

    def add(self, mask: np.ndarray) -> None:
        """Add one soft mask, (H, W).

        Raises:
            EgonetError: If its shape differs from the first mask's.
        """
        mask = np.asarray(mask, dtype=np.float64)
        if self.total is not None and mask.shape != self.total.shape:
            raise EgonetError(f"mask: shape {mask.shape} differs from the first mask's {self.total.shape}", field="mask")
        self.total = mask.copy() if self.total is None else self.total + mask
        self.count += 1

    def mean(self) -> np.ndarray | None:
        """The mean so far, float32 (H, W); None before any mask was added."""
        if self.total is None:
            return None
        return (self.total / self.count).astype(np.float32)
