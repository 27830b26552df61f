"""Proposals that need no trained model: where an action-object probably is.

Every source answers ``source_map(source, rgb, depth_m, K) -> float32 (H, W)``
in [0, 1], a map whose regions above one half are the proposals (the
labelling service cuts it into regions as it does a trained run's map):

* ``"depth"``: :func:`depth_objects`, the nearest compact surfaces in the
  lower-central part of the view, where the hands and what they hold are;
* ``"handled"``: the paper's "handled + viewed object" baseline
  (:class:`~egonet.baselines.HandledViewedObject`), the colour regions
  (each under 5 % of the frame) nearest the centre, kept apart by a
  seam so that neighbouring regions stay separate proposals,
  object-sized, instead of merging into one (:func:`handled_objects`);
* ``"saliency"``: spectral-residual saliency
  (:class:`~egonet.baselines.SpectralResidualSaliency`).

How :func:`depth_objects` finds objects, at ``WORK_WIDTH`` pixels wide:

1. Supports. ``egonet.dhg.estimate_height`` finds gravity and the height of
   every pixel; pixels whose surface normal is within ``SUPPORT_DEG`` of up
   are horizontal, and a horizontal patch covering at least
   ``SUPPORT_AREA`` of the frame (a table, a counter, the floor) is a support,
   never an object.
2. Parts. Neighbours whose depths differ by more than ``DEPTH_STEP`` (3 %)
   are apart; the deeper pixel of each such pair gives way (it is
   background seen past the nearer one's edge), so an object keeps its
   whole outline. What is left, without the supports, falls apart into
   connected parts.
3. A part larger than ``MAX_AREA`` of the frame is no object (a wall, a
   cupboard front): there, and only there, a Felzenszwalb segmentation of
   colour and depth together offers its segments instead.
4. Each candidate scores ``where x near x compact x size x stands_out``:
   ``where`` a Gaussian about the lower centre of the view (``WHERE``),
   ``near`` falls with its median depth (``NEAR_M``), ``compact`` is its
   area over the square of its long side (a strip, a forearm, a curtain's
   fold score low), ``size`` is 1 between ``SIZE_RANGE`` of the frame and
   falls outside it, ``stands_out`` is the share of its border where it
   ends at a depth step or on a support. The map holds each candidate's
   score over the best one's; the pixels that gave way at a step take the
   best score beside them, so the parts of one object (a chair's seat and back)
   touch again and become one proposal when both reach the threshold.
"""

import warnings

import cv2
import numpy as np

from egonet.baselines import HandledViewedObject, SpectralResidualSaliency
from egonet.dhg import estimate_height, normalised_coords
from egonet.errors import EgonetError
from egonet.saliency import check_frame

SOURCES = ("depth", "handled", "saliency")
"""The sources that need no trained model, in the order the page lists them."""
THRESHOLD = 0.5
"""Every source's proposals are the regions of its map at or above this."""

WORK_WIDTH = 160
"""Frames are read at this width (aspect kept): parts are blocks of a few pixels, GrabCut then finds the edge."""
DEPTH_STEP = 0.03
"""Neighbours whose depths differ by more than this share of the nearer one lie on different surfaces."""
SUPPORT_DEG = 20.0
"""A surface whose normal is within this of up is horizontal."""
SUPPORT_AREA = 0.04
"""A horizontal patch at least this share of the frame is a support (table, counter, floor)."""
MIN_AREA, MAX_AREA = 0.002, 0.25
"""Parts smaller than MIN_AREA of the frame are specks; larger than MAX_AREA, no object."""
SIZE_RANGE = (0.005, 0.15)
"""Candidates covering a share of the frame in this range score fully on size."""
WHERE = ((0.5, 0.6), (0.25, 0.25))
"""The lower-central prior: centre (x, y) and spread (x, y), as shares of the frame's width and height."""
NEAR_M = 1.0
"""``near`` falls by e for every NEAR_M metres of median depth."""
ASSUMED_HFOV_DEG = 60.0
"""The horizontal field of view assumed when a frame with depth has no intrinsics."""


def source_map(source: str, rgb: np.ndarray, depth_m: np.ndarray | None = None, K: np.ndarray | None = None) -> np.ndarray:
    """A source's map of where the frame's action-objects are.

    Args:
        source: One of :data:`SOURCES`.
        rgb: uint8 ``(H, W, 3)``.
        depth_m: float ``(H, W)`` metres, 0 or NaN where missing; ``"depth"`` needs it.
        K: ``(3, 3)`` camera matrix of the depth; None assumes ``ASSUMED_HFOV_DEG``.

    Returns:
        float32 ``(H, W)`` in [0, 1]: the proposals are its regions at or above 0.5.

    Raises:
        EgonetError: An unknown source (the message lists them), a bad
            frame, or ``"depth"`` without depth.
    """
    if source not in SOURCES:
        raise EgonetError(f"unknown source {source!r}; valid sources: {', '.join(SOURCES)}", field="source")
    check_frame(rgb, None)
    if source == "handled":
        return handled_objects(rgb)
    if source == "saliency":
        return SpectralResidualSaliency().predict(rgb)
    if depth_m is None:
        raise EgonetError("source 'depth' needs the frame's depth; this frame has none", field="source")
    return depth_objects(rgb, depth_m, K)


def handled_objects(rgb: np.ndarray) -> np.ndarray:
    """The handled + viewed object's map with a zero seam between neighbouring regions.

    :class:`~egonet.baselines.HandledViewedObject` scores each colour region
    under 5 % of the frame by its distance to the centre; several regions
    near the centre all reach one half, and side by side they would make one
    connected proposal several times an object's size (21 % of a real
    kitchen frame). The seam keeps each region its own proposal.

    Args:
        rgb: uint8 ``(H, W, 3)``.

    Returns:
        float32 ``(H, W)`` in [0, 1], 0 on the pixels where two regions meet.

    Example:
        >>> rgb = np.full((48, 64, 3), 200, np.uint8); rgb[18:30, 20:32] = (200, 40, 40); rgb[18:30, 32:44] = (40, 40, 200)
        >>> p = handled_objects(rgb)
        >>> apart = cv2.connectedComponents((p >= 0.5).astype(np.uint8))[1]  # the red and the blue square: two proposals
        >>> round(float(p[24, 26]), 2), round(float(p[24, 38]), 2), bool(apart[24, 26] != apart[24, 38])
        (0.97, 0.97, True)
    """
    h, w = rgb.shape[:2]
    baseline = HandledViewedObject()
    p = baseline.predict(rgb)
    labels = cv2.resize(baseline.regions(rgb).astype(np.float32), (w, h), interpolation=cv2.INTER_NEAREST)
    # Wherever a 3x3 neighbourhood holds two regions: a seam no 8-connected path crosses.
    kernel = np.ones((3, 3), np.uint8)
    seam = cv2.dilate(labels, kernel) != cv2.erode(labels, kernel)
    return np.where(seam, 0.0, p).astype(np.float32)


def depth_objects(rgb: np.ndarray, depth_m: np.ndarray, K: np.ndarray | None = None) -> np.ndarray:
    """The nearest compact surfaces standing out in the lower-central view, scored (see the module docstring).

    Args:
        rgb: uint8 ``(H, W, 3)``.
        depth_m: float ``(H, W)`` metres, 0 or NaN where missing.
        K: ``(3, 3)`` camera matrix; None assumes ``ASSUMED_HFOV_DEG``.

    Returns:
        float32 ``(H, W)`` in [0, 1]: each candidate's score over the best one's, 0 elsewhere.

    Raises:
        EgonetError: Depth not float ``(H, W)`` of the frame's size, or with no valid pixel.

    Example:
        >>> K = np.array([[100.0, 0, 80], [0, 100.0, 60], [0, 0, 1]])
        >>> v = np.arange(120.0)[:, None].repeat(160, axis=1)
        >>> depth = np.where(v > 60, 1.2 * 100 / np.maximum(v - 60, 1), 0).astype(np.float32)  # a floor 1.2 m below
        >>> depth[80:100, 70:90] = 1.0  # a box standing 1 m ahead
        >>> p = depth_objects(np.zeros((120, 160, 3), np.uint8), depth, K)
        >>> float(p[90, 80]), float(p[20, 20])
        (1.0, 0.0)
    """
    h, w = check_frame(rgb, None)
    depth = np.asarray(depth_m)
    if depth.shape != (h, w) or not np.issubdtype(depth.dtype, np.floating):
        raise EgonetError(f"depth_m must be float metres of the frame's size {(h, w)}, got {depth.dtype} {depth.shape}",
                          field="depth_m")
    if K is None:
        f = w / 2 / np.tan(np.radians(ASSUMED_HFOV_DEG) / 2)
        K = np.array([[f, 0, (w - 1) / 2], [0, f, (h - 1) / 2], [0, 0, 1]])
    scale = min(1.0, WORK_WIDTH / w)
    sw, sh = max(8, round(w * scale)), max(8, round(h * scale))
    small_k = np.diag([sw / w, sh / h, 1.0]) @ np.asarray(K, np.float64)
    z = cv2.resize(np.nan_to_num(depth.astype(np.float32), nan=0.0), (sw, sh), interpolation=cv2.INTER_NEAREST)
    colour = cv2.resize(rgb, (sw, sh), interpolation=cv2.INTER_AREA)
    steps = _steps(z)
    supports = _supports(z, small_k, steps)
    labels, n = _candidates(colour, z, steps | supports)
    scores = _scores(labels, n, z, steps | supports)
    out = np.zeros((sh, sw), np.float32)
    if scores.size and scores.max() > 0:
        inside = labels >= 0
        out[inside] = scores[labels[inside]] / scores.max()
        # The deeper pixel across a step joins its nearer neighbour: parts of one object touch again.
        gap = (labels < 0) & (z > 0) & ~supports
        out[gap] = cv2.dilate(out, np.ones((3, 3), np.uint8))[gap]
    return cv2.resize(out, (w, h), interpolation=cv2.INTER_NEAREST)


def _steps(z: np.ndarray) -> np.ndarray:
    """The deeper pixel of every neighbouring pair across a depth step, and missing depth: bool ``(h, w)``."""
    valid = z > 0
    out = ~valid
    for axis in (0, 1):
        a, b = (z[:-1], z[1:]) if axis == 0 else (z[:, :-1], z[:, 1:])
        step = (np.abs(a - b) > DEPTH_STEP * np.minimum(a, b)) & (a > 0) & (b > 0)
        if axis == 0:
            out[1:] |= step & (b > a)
            out[:-1] |= step & (a > b)
        else:
            out[:, 1:] |= step & (b > a)
            out[:, :-1] |= step & (a > b)
    return out


def _supports(z: np.ndarray, K: np.ndarray, steps: np.ndarray) -> np.ndarray:
    """Large horizontal patches (tables, counters, the floor) between the depth ``steps``: bool ``(h, w)``."""
    up = estimate_height(z, K).up
    x, y = normalised_coords(K, z.shape)
    points = np.stack([x * z, y * z, z], axis=-1)
    normal = np.cross(np.gradient(points, axis=1), np.gradient(points, axis=0))
    length = np.linalg.norm(normal, axis=-1)
    cosine = np.abs(normal @ up) / np.maximum(length, 1e-12)
    flat = ((cosine > np.cos(np.radians(SUPPORT_DEG))) & ~steps).astype(np.uint8)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(flat, connectivity=4)
    large = np.flatnonzero(stats[:, cv2.CC_STAT_AREA] >= SUPPORT_AREA * z.size)
    return np.isin(labels, large[large > 0])


def _candidates(colour: np.ndarray, z: np.ndarray, apart: np.ndarray) -> tuple[np.ndarray, int]:
    """The parts between the ``apart`` pixels (depth steps, supports), the large ones split by colour and
    depth: labels int32 ``(h, w)``, -1 where no candidate is, and how many there are."""
    from skimage.segmentation import felzenszwalb

    free = (~apart).astype(np.uint8)
    n, parts, stats, _ = cv2.connectedComponentsWithStats(free, connectivity=4)
    area = stats[:, cv2.CC_STAT_AREA] / z.size
    labels = np.full(z.shape, -1, np.int32)
    count = 0
    large = np.zeros(z.shape, bool)
    for k in range(1, n):
        if area[k] > MAX_AREA:
            large |= parts == k
        elif area[k] >= MIN_AREA:
            labels[parts == k] = count
            count += 1
    if large.any():
        depth_channel = np.clip(z / max(float(z[large].max()), 1e-6) * 255, 0, 255)[..., None]
        with warnings.catch_warnings():  # scikit-image doubts every 4-channel image: this one is RGB + depth
            warnings.simplefilter("ignore", RuntimeWarning)
            segments = felzenszwalb(np.concatenate([colour, depth_channel], axis=-1), scale=100, sigma=0.5,
                                    min_size=max(4, round(MIN_AREA * z.size)), channel_axis=-1)
        segments = np.where(large, segments, -1)
        for s in np.unique(segments[segments >= 0]):
            mask = segments == s
            if MIN_AREA <= mask.sum() / z.size <= MAX_AREA:
                labels[mask] = count
                count += 1
    return labels, count


def _scores(labels: np.ndarray, n: int, z: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Each candidate's ``where x near x compact x size x stands_out`` (see the module docstring)."""
    h, w = z.shape
    (cx, cy), (sx, sy) = WHERE
    lo, hi = SIZE_RANGE
    kernel = np.ones((3, 3), np.uint8)
    scores = np.zeros(n)
    for k in range(n):
        mask = labels == k
        ys, xs = np.nonzero(mask)
        share = mask.sum() / mask.size
        where = np.exp(-(((xs.mean() + 0.5) / w - cx) ** 2) / (2 * sx**2) - (((ys.mean() + 0.5) / h - cy) ** 2) / (2 * sy**2))
        depth = z[mask]
        near = np.exp(-np.median(depth[depth > 0]) / NEAR_M) if (depth > 0).any() else 0.0
        (_, _), (a, b), _ = cv2.minAreaRect(np.stack([xs, ys], 1).astype(np.float32))
        compact = min(1.0, mask.sum() / (max(a, b) + 1) ** 2)
        size = min(1.0, share / lo, hi / share)
        ring = cv2.dilate(mask.view(np.uint8), kernel).view(bool) & ~mask
        stands_out = edges[ring].mean() if ring.any() else 0.0
        scores[k] = where * near * compact * size * stands_out
    return scores
