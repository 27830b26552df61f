"""A stroke on a thin part, cut at full resolution along that part.

The session's cut runs on a grid a few times coarser than the frame, where
an 8-10 px chopstick is 2 px wide and blurred into the table: a click on it
took little more than its own pixels, and the grid's flood leaked from it
into the table. So a colour stroke narrower than ``_THIN`` grid pixels that
lies on a thin part of its colour (``_fine_cut``: the pixels like the
stroke's, joined to it, are at most ``_WIDER`` times its radius wide there)
is cut at full resolution instead: within ``_REACH`` pixels of it, the
pixels labelled against it that its side's colours prefer, joined to it
through such pixels and themselves thin, are cut with OpenCV grabCut's
energy (the contrast-sensitive links of ``graph._links``; two colour
mixtures learnt within ``_MODEL_REACH`` pixels of the stroke: its side's
from the pixels that have its label, the other side's from the rest less
the pixels like the stroke, which may be the very part it was drawn on).
Pixels of mixed colour on the part's edge lean ``_BIAS`` nats to the
stroke's side. A thin part is followed along its length as far as its
colour holds.
"""

from __future__ import annotations

import cv2
import numpy as np

from egonet.grabcut.colour import _costs, _fit_model
from egonet.grabcut.graph import _CutGraph, _links

_THIN = 2.0  # a colour stroke narrower than this many grid pixels (radius) may be on a part the grid cannot resolve
_WIDER = 2.0  # ... it is, where the part of its colour is at most this many times its radius wide (+2 px)
_MIN_PIXELS = 20  # a stroke of fewer pixels (a dot on an edge) has no colour to follow: left to the grid's cut
_REACH = 360  # full-resolution pixels around the stroke that its cut may change
_FIRST_REACH = 120  # ... first within this many (the window grows to the reach only if the part leaves it)
_MODEL_REACH = 50  # ... and whose colours, within this many of it, train the two mixtures
_LIKE = 11.3  # squared Mahalanobis distance to the stroke's colours of a pixel like them (chi-squared, 3 dof, 99 %)
_BIAS = 4.0  # nats the stroke's side is favoured by, for the part's edge (pixels of mixed colour)
_TILE = 48  # full-resolution pixels: the part's costs are computed a square of this side at a time (``_likely_part``)


def _joined(part: np.ndarray, seed: np.ndarray) -> np.ndarray:
    """The pixels of ``part | seed`` 8-connected to ``seed``."""
    count, parts = cv2.connectedComponents((part | seed).view(np.uint8), connectivity=8)
    joined = np.zeros(count, bool)
    joined[parts[seed]] = True
    joined[0] = False
    return joined[parts]


def _like(stroke: np.ndarray, pixels: np.ndarray) -> np.ndarray:
    """Which ``pixels`` (``(n, 3)``) are like the colours of a stroke's ``stroke`` (``(k, 3)``, k >= 2).

    Like them: within ``_LIKE`` (squared Mahalanobis distance) of their mean,
    under their covariance widened by 4 (2 levels of noise each channel).
    """
    stroke = stroke.astype(np.float64)
    inverse = np.linalg.inv(np.cov(stroke.T) + 4.0 * np.eye(3))
    d = pixels.reshape(-1, 3) - stroke.mean(axis=0)
    return np.einsum("ni,ij,nj->n", d, inverse, d) < _LIKE


def _likely_part(win: np.ndarray, side: np.ndarray, hard: np.ndarray,
                 models: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The pixels against the stroke that its side's colours prefer, joined to it, and their two costs.

    The costs are computed a ``_TILE`` square at a time, only on the tiles
    the joined part reaches (the stroke's first, then every tile beside a
    pixel of the part, until the part grows no more): most of a large
    window lies beyond the part, and its costs were most of a stroke's time.
    The part is the same as with the costs over the whole window, since
    every pixel beside it had its costs computed.

    Args:
        win: uint8 ``(h, w, 3)`` window of the frame.
        side: bool ``(h, w)``, the pixels of the stroke's label (the stroke's included).
        hard: bool ``(h, w)``, the stroke's pixels.
        models: The stroke's side's mixture and the other side's.

    Returns:
        ``(cost_own, cost_other, part)``: float ``(h, w)`` costs, set only on
        the tiles reached (the part's pixels among them; ``cost_other``
        with ``_BIAS``), and bool ``(h, w)``, the part (not ``side``).
    """
    h, w = side.shape
    t = _TILE
    ny, nx = -(-h // t), -(-w // t)

    def tiles(pixels: np.ndarray) -> np.ndarray:
        """bool ``(ny, nx)``: the tiles holding any of ``pixels``."""
        padded = np.zeros((ny * t, nx * t), bool)
        padded[:h, :w] = pixels
        return padded.reshape(ny, t, nx, t).any(axis=(1, 3))

    cost_own, cost_other = np.zeros((h, w)), np.zeros((h, w))
    likely = np.zeros((h, w), bool)
    inner = np.zeros((h, w), bool)  # the window's edge is never likely
    inner[1:-1, 1:-1] = True
    done = np.zeros((ny, nx), bool)
    todo = tiles(hard)
    while True:
        done |= todo
        pick = np.flatnonzero((np.kron(todo, np.ones((t, t), bool))[:h, :w] & ~side & inner).ravel())
        if len(pick):
            x = win.reshape(-1, 3)[pick].astype(np.float32)
            own = _costs(models[0], x)
            other = _costs(models[1], x) + _BIAS
            cost_own.ravel()[pick], cost_other.ravel()[pick] = own, other
            likely.ravel()[pick] = own < other
        # Joined within the tiles done (nothing beyond them is likely), and the tiles beside the part.
        rows, cols = np.flatnonzero(done.any(axis=1)), np.flatnonzero(done.any(axis=0))
        a0, a1, b0, b1 = rows[0] * t, min(h, (rows[-1] + 1) * t), cols[0] * t, min(w, (cols[-1] + 1) * t)
        part = np.zeros((h, w), bool)
        part[a0:a1, b0:b1] = _joined(likely[a0:a1, b0:b1], hard[a0:a1, b0:b1])
        a0, a1, b0, b1 = max(0, a0 - 1), min(h, a1 + 1), max(0, b0 - 1), min(w, b1 + 1)
        beside = np.zeros((h, w), bool)
        beside[a0:a1, b0:b1] = cv2.dilate(part[a0:a1, b0:b1].view(np.uint8), np.ones((3, 3), np.uint8)).view(bool)
        todo = tiles(beside) & ~done
        if not todo.any():
            return cost_own, cost_other, part & ~side


def _fine_cut(image: np.ndarray, mask: np.ndarray, own: np.ndarray, origin: tuple[int, int], fg: bool,
              radius: float, reach: int = _REACH, *, thin: bool = False) -> np.ndarray | None:
    """What a stroke on a thin part gives its label at full resolution, or None when it is on no thin part.

    Args:
        image: uint8 ``(H, W, 3)`` frame.
        mask: bool ``(H, W)`` mask with the stroke's pixels applied.
        own: bool footprint of the stroke, its box at ``origin``.
        origin: ``(y, x)`` of the footprint's box.
        fg: The stroke's label.
        radius: The stroke's radius, pixels.
        reach: Pixels around the stroke that its cut may change.
        thin: The stroke is known to lie on a thin part (the box's straight
            line, ``cut._straight``): it is not tested.

    Returns:
        bool ``(H, W)``: the pixels labelled against the stroke to give its
        label; None when the part it lies on is wider than ``_WIDER`` times
        its radius (the grid's cut resolves it) or the stroke has fewer than
        ``_MIN_PIXELS`` pixels.
    """
    h, w = mask.shape
    y0, x0 = origin
    if np.count_nonzero(own) < _MIN_PIXELS:
        return None
    flip = np.zeros((h, w), bool)
    limit = _WIDER * radius + 2
    stroke = image[y0 : y0 + own.shape[0], x0 : x0 + own.shape[1]][own]

    def window(reach: int) -> tuple[int, int, int, int, np.ndarray, np.ndarray]:
        """``(r0, c0, r1, c1)``, the stroke's label and the stroke, within ``reach``."""
        r0, r1 = max(0, y0 - reach), min(h, y0 + own.shape[0] + reach)
        c0, c1 = max(0, x0 - reach), min(w, x0 + own.shape[1] + reach)
        hard = np.zeros((r1 - r0, c1 - c0), bool)
        hard[y0 - r0 : y0 - r0 + own.shape[0], x0 - c0 : x0 - c0 + own.shape[1]] = own
        return r0, c0, r1, c1, (mask[r0:r1, c0:c1] == fg) | hard, hard

    # Thin where the part of the stroke's colour around it is at most ``limit`` wide.
    r0, c0, r1, c1, side, hard = window(int(limit) + 2)
    like = _like(stroke, image[r0:r1, c0:c1]).reshape(hard.shape)
    width = cv2.distanceTransform(_joined(like & ~side, hard).view(np.uint8), cv2.DIST_L2, 3)
    if not thin and width[hard].max() > limit:
        return None
    size = 2 * int(limit) + 1
    models = None
    # The part is followed within a window that grows to ``reach`` only while the part comes near its edge: the
    # costs over the whole window were most of a stroke's time, and a part inside a smaller window, farther than
    # the opening's size from every side the window could still grow on, is the same part in the larger one.
    for grow in (min(reach, max(_MODEL_REACH, _FIRST_REACH)), reach):
        r0, c0, r1, c1, side, hard = window(grow)
        win = image[r0:r1, c0:c1]
        if models is None:
            m = _MODEL_REACH
            a0, b0 = max(0, y0 - r0 - m), max(0, x0 - c0 - m)
            a1, b1 = y0 - r0 + own.shape[0] + m, x0 - c0 + own.shape[1] + m
            near, near_side = win[a0:a1, b0:b1].reshape(-1, 3), side[a0:a1, b0:b1].ravel()
            if near_side.all():
                return flip
            rest = ~near_side & ~_like(stroke, near)
            rng = np.random.default_rng(0)
            other_model = _fit_model(near[rest if rest.any() else ~near_side], rng)[0]
            models = (_fit_model(near[near_side], rng)[0], other_model)
        cost_own, cost_other, free = _likely_part(win, side, hard, models)
        if grow < reach:
            margin = size + 2
            rows, cols = np.flatnonzero(free.any(axis=1)), np.flatnonzero(free.any(axis=0))
            if len(rows) and ((r0 > 0 and rows[0] < margin) or (r1 < h and rows[-1] >= r1 - r0 - margin)
                              or (c0 > 0 and cols[0] < margin) or (c1 < w and cols[-1] >= c1 - c0 - margin)):
                continue
        break
    # Less what is wider than ``limit`` (an opening finds it; opened within ``size`` of the part's bounds, the same
    # opening as the whole window's, which is empty beyond them).
    rows, cols = np.flatnonzero(free.any(axis=1)), np.flatnonzero(free.any(axis=0))
    if len(rows):
        a0, a1 = max(0, rows[0] - size), min(free.shape[0], rows[-1] + 1 + size)
        b0, b1 = max(0, cols[0] - size), min(free.shape[1], cols[-1] + 1 + size)
        free[a0:a1, b0:b1] &= ~cv2.morphologyEx(free[a0:a1, b0:b1].view(np.uint8), cv2.MORPH_OPEN,
                                                cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (size, size))).view(bool)
    free = _joined(free, hard) & ~side
    if not free.any():
        return flip
    rows, cols = np.flatnonzero(free.any(axis=1)), np.flatnonzero(free.any(axis=0))
    p0, p1, q0, q1 = max(0, rows[0] - 1), rows[-1] + 2, max(0, cols[0] - 1), cols[-1] + 2
    at = np.flatnonzero(free[p0:p1, q0:q1])
    graph = _CutGraph(_links(win[p0:p1, q0:q1]), side[p0:p1, q0:q1].ravel(), at)
    cut = np.zeros((p1 - p0) * (q1 - q0), bool)
    cut[at] = graph.cut(cost_other[p0:p1, q0:q1].ravel()[at], cost_own[p0:p1, q0:q1].ravel()[at])
    flip[r0 + p0 : r0 + p1, c0 + q0 : c0 + q1] = cut.reshape(p1 - p0, q1 - q0)
    return flip
