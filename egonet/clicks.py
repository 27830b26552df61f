"""Superpixels and click-to-soft-mask projection for the human study.

In the paper's human study a subject clicks the centre of each
action-object; every click becomes a Gaussian of width 60 px that is
projected onto superpixel regions (MCG regions in the paper), giving a soft
per-pixel mask that is scored like a machine's probability map.

Choices (see ``shared/docs/egonet-reference.md``):

* Regions: the paper projected clicks onto MCG regions (a hierarchy of
  regions merged along image boundaries, cut at one level). MCG itself is
  not available in Python; ``"hierarchical"`` (the default) is built the
  same way from scikit-image: a colour boundary map (Sobel of the CIELAB
  image), a fine watershed over-segmentation of it, and the regions merged
  in order of the mean boundary strength between them (a region adjacency
  graph) until every remaining boundary is stronger than ``level``. No
  region may cover more than ``max_region_share`` of the frame (default a
  quarter): where one does, its pixels fall to a finer level of the same
  hierarchy (``level`` halved, up to four times, then the watershed
  regions), so a wall merged with a desk and a keyboard does not give every
  click on it the same flat mask. ``regions`` says how many regions that
  split.
  ``"felzenszwalb"`` (graph segmentation) also follows boundaries;
  ``"slic"`` gives compact regions of similar size that ignore most
  boundaries. ``bench/bench_regions.py`` scores the maps of simulated
  clickers against known truth for each: SLIC barely changes the raw
  Gaussian's MF, the boundary methods raise it most (README, "Human-study
  soft masks"). Every method works on a copy downscaled to at most
  ``max_side`` pixels and the labels are upscaled with nearest neighbour.
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

__all__ = ["DEFAULT_SIGMA", "METHOD_OPTIONS", "REFERENCE_WIDTH", "SUPERPIXEL_DEFAULTS", "SUPERPIXEL_METHODS", "MaskMean", "Regions",
           "SuperpixelDefaults", "boundary_strength", "click_gaussian", "project_to_regions", "region_hierarchy", "regions",
           "points_mask", "scaled_sigma", "soft_mask", "superpixels"]

DEFAULT_SIGMA = 60.0
"""The paper's click width: standard deviation in native-resolution pixels."""
REFERENCE_WIDTH = 1280
"""The paper's frames are 1280x960: its 60 px click width is at this width."""


def scaled_sigma(width: int) -> float:
    """The paper's click width (60 px at 1280 px wide) scaled to a frame ``width`` px wide, to 0.01 px.

    Example:
        >>> scaled_sigma(1280), scaled_sigma(514)
        (60.0, 24.09)
    """
    return round(DEFAULT_SIGMA * width / REFERENCE_WIDTH, 2)

SUPERPIXEL_METHODS = ("hierarchical", "slic", "felzenszwalb")
METHOD_OPTIONS = {
    "hierarchical": ("fine_regions", "level", "max_region_share"),
    "slic": ("n_segments", "compactness"),
    "felzenszwalb": ("scale", "min_size"),
}
"""The options that apply to each method (the others are refused)."""


@dataclass(frozen=True)
class SuperpixelDefaults:
    """The one place the superpixel defaults live (``superpixels``, the
    study builder and its form all read them): the boundary-based
    hierarchy, as a stand-in for the paper's MCG regions, from about 1,000
    watershed regions merged up to boundary strength 0.35 (chosen with
    ``bench/bench_regions.py`` on frames apart from those it reports), no
    region over a quarter of the frame (a desk-work frame of the paper's
    merged wall, desk and keyboard into half the frame at 0.35; 1.0 turns
    the cap off, as in studies made before it);
    for SLIC about 400 regions of compactness 10; for Felzenszwalb, scale
    100 and regions of at least 50 pixels; all on a copy at most 640 px on
    its long side. Studies record the settings they were made with, so a
    new default never changes an existing study's masks."""

    method: str = "hierarchical"
    fine_regions: int = 1000
    level: float = 0.35
    max_region_share: float = 0.25
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


@dataclass(frozen=True)
class Regions:
    """A frame's partition (``regions``): ``labels`` 0..n-1, int32 (H, W),
    and ``capped``, the sorted ids of the regions that stand where a region
    of the merge level covered more than ``max_region_share`` of the frame
    (empty when none did, and always for SLIC and Felzenszwalb, which have
    no cap)."""

    labels: np.ndarray
    capped: np.ndarray


def superpixels(image: np.ndarray, **options) -> np.ndarray:
    """The labels of :func:`regions` (same arguments), int32 (H, W).

    Example:
        >>> img = np.zeros((60, 80, 3), dtype=np.uint8)
        >>> img[:, 40:] = 255
        >>> labels = superpixels(img, method="slic", n_segments=8)
        >>> labels.shape, labels.dtype.name, int(labels.min())
        ((60, 80), 'int32', 0)
    """
    return regions(image, **options).labels  # a misspelt option is regions()' TypeError


def regions(
    image: np.ndarray,
    *,
    method: str = SUPERPIXEL_DEFAULTS.method,
    fine_regions: int | None = None,
    level: float | None = None,
    max_region_share: float | None = None,
    n_segments: int | None = None,
    compactness: float | None = None,
    scale: float | None = None,
    min_size: int | None = None,
    max_side: int | None = SUPERPIXEL_DEFAULTS.max_side,
) -> Regions:
    """Partition a frame into superpixel regions.

    The frame is downscaled (area interpolation) so that its longer side is
    at most ``max_side`` pixels, segmented there, and the labels are resized
    back with nearest neighbour, so region borders are as coarse as the
    working resolution (2 px at 1280x960 with the default 640).

    Args:
        image: Frame, uint8 (H, W, 3), RGB.
        method: ``"hierarchical"`` (default; watershed regions merged along
            weak colour boundaries, see the module doc), ``"slic"`` (compact
            regions of similar size, in CIELAB) or ``"felzenszwalb"``
            (graph-based, follows edges, sizes vary).
        fine_regions: hierarchical only: watershed regions before merging
            (default 1000).
        level: hierarchical only: regions merge while the mean boundary
            strength between them is below ``level``, in units of the frame's
            99th-percentile boundary strength (default 0.35; higher merges more).
        max_region_share: hierarchical only: the largest fraction of the
            frame's pixels one region may cover (default 0.25); a region
            over it is replaced by its regions at ``level`` / 2, / 4, / 8,
            / 16 and at last the watershed regions, the first that brings
            every part under the cap. 1.0 turns it off.
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
        The labels (0..n-1, contiguous, int32 (H, W)) and the ids of the
        regions that stand where the cap split one.

    Raises:
        ValueError: If ``image`` is not uint8 (H, W, 3), ``method`` is
            unknown, an option does not apply to ``method`` or is out of
            range.

    Example:
        >>> img = np.zeros((60, 80, 3), dtype=np.uint8)
        >>> img[:, 40:] = 255
        >>> r = regions(img, max_region_share=0.3)
        >>> bool(np.bincount(r.labels.ravel()).max() <= 0.3 * 60 * 80), bool(len(r.capped) > 0)
        (True, True)
    """
    h, w = check_rgb(image, "image", min_side=2)
    if method not in SUPERPIXEL_METHODS:
        raise EgonetError(f"unknown method {method!r}; valid methods: {', '.join(SUPERPIXEL_METHODS)}", field="method")
    given = {"fine_regions": fine_regions, "level": level, "max_region_share": max_region_share, "n_segments": n_segments,
             "compactness": compactness, "scale": scale, "min_size": min_size}
    for name, value in given.items():
        if value is not None and name not in METHOD_OPTIONS[method]:
            raise EgonetError(f"{name} does not apply to method={method!r}", field=name)
    if max_side is not None and (isinstance(max_side, bool) or not isinstance(max_side, (int, np.integer)) or max_side < 8):
        raise EgonetError(f"max_side must be None or an int >= 8, got {max_side!r}", field="max_side")
    options = {name: getattr(SUPERPIXEL_DEFAULTS, name) if given[name] is None else given[name] for name in METHOD_OPTIONS[method]}
    _check_options(options)

    work = image
    if max_side is not None and max(h, w) > max_side:
        f = max_side / max(h, w)
        size = (max(2, round(w * f)), max(2, round(h * f)))
        work = cv2.resize(image, size, interpolation=cv2.INTER_AREA)
    labels, capped = _SEGMENTERS[method](work, **options)
    labels = np.asarray(labels, dtype=np.int32)
    if labels.shape != (h, w):
        labels, capped = _upscale_nearest(labels, (h, w)), _upscale_nearest(capped, (h, w))
    labels = _relabel(labels)
    return Regions(labels, np.unique(labels[capped]).astype(np.int32))


# Each option: (integer?, lowest allowed value).
_OPTION_RULES = {"fine_regions": (True, 1), "n_segments": (True, 1), "min_size": (True, 1),
                 "level": (False, 0.0), "max_region_share": (False, 0.0), "compactness": (False, 0.0), "scale": (False, 0.0)}


def _check_options(options: dict[str, float]) -> None:
    for name, value in options.items():
        integer, low = _OPTION_RULES[name]
        if integer and (isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low):
            raise EgonetError(f"{name} must be a positive int, got {value!r}", field=name)
        if not integer and (isinstance(value, bool) or not isinstance(value, (int, float, np.number))
                            or not np.isfinite(value) or value <= low):
            raise EgonetError(f"{name} must be a positive number, got {value!r}", field=name)
    if options.get("max_region_share", 1.0) > 1.0:
        raise EgonetError(f"max_region_share must be in (0, 1], got {options['max_region_share']!r}", field="max_region_share")


# scikit-image is imported inside the segmenters: it is slow to import, and
# soft_mask (scoring a study) does not need it.


# Each segmenter returns the labels and where the cap split a region (bool, same shape).


def _slic(work: np.ndarray, *, n_segments: int, compactness: float) -> tuple[np.ndarray, np.ndarray]:
    from skimage.segmentation import slic

    labels = slic(work, n_segments=int(n_segments), compactness=float(compactness), start_label=0, channel_axis=-1)
    return labels, np.zeros(labels.shape, bool)


def _felzenszwalb(work: np.ndarray, *, scale: float, min_size: int) -> tuple[np.ndarray, np.ndarray]:
    from skimage.segmentation import felzenszwalb

    labels = felzenszwalb(work, scale=float(scale), sigma=0.8, min_size=int(min_size), channel_axis=-1)
    return labels, np.zeros(labels.shape, bool)


def boundary_strength(image: np.ndarray) -> np.ndarray:
    """Colour boundary strength: the Sobel gradient magnitude of the lightly smoothed CIELAB image,
    in units of its 99th percentile (so levels mean the same on dull and vivid frames).

    Args:
        image: uint8 (H, W, 3), RGB.

    Returns:
        float64 (H, W), >= 0 (1 at the 99th percentile).
    """
    from skimage.color import rgb2lab
    from skimage.filters import sobel

    lab = rgb2lab(cv2.GaussianBlur(image, (0, 0), 1.0))
    strength = np.sqrt(sum(sobel(lab[..., c]) ** 2 for c in range(3)))
    return strength / max(float(np.percentile(strength, 99)), 1e-6)


_FINER_STEPS = 4
"""Times the merge level is halved for a region over the cap before it falls to the watershed regions."""


def _hierarchical(work: np.ndarray, *, fine_regions: int, level: float, max_region_share: float) -> tuple[np.ndarray, np.ndarray]:
    """Fine watershed regions of the boundary map, merged weakest shared boundary first up to ``level``;
    a region over ``max_region_share`` of the frame takes its regions of a finer level (see ``regions``)."""
    from skimage.segmentation import watershed

    strength = boundary_strength(work)
    fine = watershed(strength, markers=int(fine_regions))
    labels = _merge(fine, strength, float(level))
    limit = max_region_share * labels.size
    over = np.bincount(labels.reshape(-1)) > limit
    capped = over[labels]
    for step in range(1, _FINER_STEPS + 2):
        if not over.any():
            break
        finer = _merge(fine, strength, float(level) / 2**step) if step <= _FINER_STEPS else fine
        inside = over[labels]
        # A finer region keeps the coarse region it lies in as part of its name, so parts never join across regions.
        labels = _relabel(np.where(inside, (finer.astype(np.int64) + 1) * (int(labels.max()) + 1) + labels, labels))
        over = np.bincount(labels.reshape(-1)) > limit
    return labels, capped


def region_hierarchy(image: np.ndarray, *, levels: Sequence[float], fine_regions: int = SUPERPIXEL_DEFAULTS.fine_regions,
                     strength: np.ndarray | None = None) -> list[np.ndarray]:
    """The hierarchy of the ``"hierarchical"`` superpixels, cut at several levels in one pass.

    Fine watershed regions of the boundary map (:func:`boundary_strength`)
    are merged, weakest shared boundary first, up to each level in turn
    (increasing): every level's regions are unions of the previous level's,
    as MCG's hierarchy is. The region proposals of the FP-MCG and
    salObj+depth baselines are these regions (``egonet.baselines.regions``).

    Args:
        image: uint8 (H, W, 3), RGB, at the working resolution (no resizing here).
        levels: Merge thresholds, increasing, in units of the frame's
            99th-percentile boundary strength (as ``superpixels``' ``level``).
        fine_regions: Watershed regions before merging.
        strength: The boundary map of ``image`` if the caller has it already.

    Returns:
        One label map per level, int32 (H, W) each (labels need not be contiguous).

    Example:
        >>> img = np.zeros((20, 20, 3), np.uint8); img[:, 10:] = 200
        >>> fine, coarse = region_hierarchy(img, levels=(0.1, 5.0), fine_regions=8)
        >>> len(np.unique(fine)) >= len(np.unique(coarse))
        True
    """
    from skimage.segmentation import watershed

    if list(levels) != sorted(levels) or not len(levels):
        raise EgonetError(f"levels must be increasing and not empty, got {levels!r}", field="levels")
    if strength is None:
        strength = boundary_strength(image)
    labels = watershed(strength, markers=int(fine_regions))
    out = []
    for level in levels:
        # A new graph per level: its boundary weights are again the mean strength along each boundary.
        labels = _merge(labels, strength, float(level))
        out.append(np.asarray(labels, dtype=np.int32))
    return out


def _merge(fine: np.ndarray, strength: np.ndarray, level: float) -> np.ndarray:
    """Regions merged weakest shared boundary first while the boundary is below ``level``."""
    from skimage import graph

    rag = graph.rag_boundary(fine, strength)

    def keep_nothing(rag, src, dst):  # the merged node needs no attributes of its own
        pass

    def merged_weight(rag, src, dst, neighbour):
        # The merged region's boundary with a neighbour is both boundaries: their pixel-weighted mean.
        edges = [rag[node][neighbour] for node in (src, dst) if neighbour in rag[node]]
        count = sum(e["count"] for e in edges)
        return {"count": count, "weight": sum(e["weight"] * e["count"] for e in edges) / max(count, 1)}

    return graph.merge_hierarchical(fine, rag, thresh=level, rag_copy=False, in_place_merge=True,
                                    merge_func=keep_nothing, weight_func=merged_weight)


_SEGMENTERS = {"hierarchical": _hierarchical, "slic": _slic, "felzenszwalb": _felzenszwalb}


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


POINTS_LEVEL = float(np.exp(-0.5))
"""A unit-peak Gaussian's value one standard deviation from its centre: ``points_mask``'s cut."""


def points_mask(
    shape: tuple[int, int],
    points: Sequence[Sequence[float]] | np.ndarray,
    *,
    sigma: float = DEFAULT_SIGMA,
) -> np.ndarray:
    """Ground truth from attention points, as the paper's Table 4: a fixed-size Gaussian around each point, binarised.

    *Choice* (the paper scores MF and AP against "a fixed size Gaussian
    around the ground truth attention location" without saying how it
    became binary): a pixel is positive where :func:`click_gaussian` is at
    least ``exp(-1/2)``, that is within one ``sigma`` of a point: a disc of
    radius ``sigma`` around each point, their union for several.

    Args:
        shape: Frame size (H, W).
        points: Points (x, y) in pixels, as :func:`click_gaussian`'s clicks;
            none gives an all-false mask (a frame without an action-object).
        sigma: The Gaussian's standard deviation in pixels.

    Returns:
        bool (H, W).

    Example:
        >>> m = points_mask((5, 7), [(3.0, 2.0)], sigma=1.0)
        >>> int(m.sum()), bool(m[2, 3]), bool(m[2, 4]), bool(m[3, 4])
        (5, True, True, False)
    """
    return click_gaussian(shape, points, sigma=sigma) >= np.float32(POINTS_LEVEL) * np.float32(1 - 1e-6)


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
