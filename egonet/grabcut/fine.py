"""A thin stroke's cut at full resolution, along what it lands on.

The session's cut runs on a grid a few times coarser than the frame, where
an 8-10 px chopstick is 2 px wide and blurred into the table: a click on it
takes little more than its own pixels, and the grid's flood leaks past it.
So a colour stroke thinner than ``_THIN`` grid pixels is cut at full
resolution instead of flooded on the grid (``_fine_cut``): within ``_REACH``
pixels of it, the pixels labelled against it that its side's colours
prefer and that join it are cut by OpenCV grabCut's energy (the
contrast-sensitive links of ``graph._links``), with two colour mixtures
learnt within ``_MODEL_REACH`` pixels of it: its side's from the pixels
that have its label, the other side's from the rest, less the pixels whose
colour is like the stroke's (they may be the very part it was drawn on).
A thin part is followed along its length as far as its colour holds.
"""

from __future__ import annotations

import cv2
import numpy as np

from egonet.grabcut.colour import _costs, _fit_model
from egonet.grabcut.graph import _CutGraph, _links

_THIN = 2.5  # a colour stroke narrower than this many grid pixels (radius) is cut at full resolution
_REACH = 240  # full-resolution pixels around the stroke that its cut may change
_MODEL_REACH = 50  # ... and around it whose colours train the two mixtures
_LIKE = 11.3  # squared Mahalanobis distance to the stroke's colours (chi-squared, 3 dof, 99 %) of a pixel like them


def _fine_cut(image: np.ndarray, mask: np.ndarray, own: np.ndarray, origin: tuple[int, int],
              fg: bool) -> np.ndarray:
    """The pixels labelled against a thin stroke that its full-resolution cut gives it.

    Args:
        image: uint8 ``(H, W, 3)`` frame.
        mask: bool ``(H, W)`` mask with the stroke's pixels applied.
        own: bool footprint of the stroke, its box at ``origin``.
        origin: ``(y, x)`` of the footprint's box.
        fg: The stroke's label.

    Returns:
        bool ``(H, W)``: the pixels to give the stroke's label (joined to it).
    """
    h, w = mask.shape
    y0, x0 = origin
    r0, r1 = max(0, y0 - _REACH), min(h, y0 + own.shape[0] + _REACH)
    c0, c1 = max(0, x0 - _REACH), min(w, x0 + own.shape[1] + _REACH)
    win = image[r0:r1, c0:c1]
    side = mask[r0:r1, c0:c1] == fg
    hard = np.zeros_like(side)
    hard[y0 - r0 : y0 - r0 + own.shape[0], x0 - c0 : x0 - c0 + own.shape[1]] = own
    side |= hard
    flip = np.zeros((h, w), bool)
    m = _MODEL_REACH
    a0, a1 = max(0, y0 - r0 - m), y0 - r0 + own.shape[0] + m
    b0, b1 = max(0, x0 - c0 - m), x0 - c0 + own.shape[1] + m
    near, near_side = win[a0:a1, b0:b1].reshape(-1, 3), side[a0:a1, b0:b1].ravel()
    if near_side.all():
        return flip
    stroke = win[hard].astype(np.float64)
    cov = (np.cov(stroke.T) if len(stroke) > 3 else 100.0 * np.eye(3)) + 4.0 * np.eye(3)
    d = near - stroke.mean(axis=0)
    like = np.einsum("ni,ij,nj->n", d, np.linalg.inv(cov), d) < _LIKE
    rest = ~near_side & ~like
    rng = np.random.default_rng(0)
    other_model = _fit_model(near[rest if rest.any() else ~near_side], rng)[0]
    own_model = _fit_model(near[near_side], rng)[0]
    x = win.reshape(-1, 3).astype(np.float32)
    cost_own, cost_other = _costs(own_model, x).reshape(side.shape), _costs(other_model, x).reshape(side.shape)
    likely = (cost_own < cost_other) & ~side
    likely[[0, -1], :] = likely[:, [0, -1]] = False
    # Only the likely pixels joined to the stroke: a thin part is followed along its length.
    count, parts = cv2.connectedComponents((likely | hard).view(np.uint8), connectivity=8)
    joined = np.zeros(count, bool)
    joined[parts[hard]] = True
    joined[0] = False
    free = joined[parts] & ~side
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
