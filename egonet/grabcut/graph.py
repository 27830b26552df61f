"""The minimum cut: pairwise links of the ROI's grid and a graph over its undecided pixels.

Both cuts of the session, colour only and with depth, minimise OpenCV
grabCut's energy: a per-pixel cost of each label (``-log`` of the side's
mixture) plus, for every pair of 8-neighbours that take different labels,
the pair's link weight ``gamma * exp(-beta * |dc|^2) / distance``
(``_links``; with depth times a factor that falls where depth jumps). The
cut itself is Boykov and Kolmogorov's max-flow (PyMaxflow).

``_CutGraph`` builds the graph once over the pixels that may change (a
pixel fixed as object or background is no node: its links are folded into
its free neighbours' costs, the same minimum cut on a smaller graph) and
cuts it again with new costs reusing the previous flow and search trees
(Kohli and Torr's dynamic graph cuts): a box's later iterations change the
costs a little and cost a fraction of the first cut.
"""

from __future__ import annotations

import math

import maxflow
import numpy as np

_GAMMA = 50.0  # weight of the pairwise term (OpenCV grabCut's)
_JUMP = 0.02  # depth jump, as a fraction of the depth, at which the pairwise weight falls to 1/e


def _links(colour: np.ndarray, z: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pairwise links of the 8-neighbour grid: flat indices ``p``, ``q`` and weights.

    ``gamma * exp(-beta * |dc|^2) / distance`` as OpenCV's grabCut, with
    ``beta`` from the mean squared colour difference over all pairs; with
    ``z`` (metres, NaN where unknown) times ``exp(-(dz / (_JUMP * z))^2)``
    where both pixels have depth.

    Args:
        colour: ``(h, w, 3)`` colours (any numeric type, 0-255).
        z: Optional float ``(h, w)`` depth in metres, NaN where missing.

    Returns:
        ``(p, q, weight)``: int32 flat pixel indices ``(M,)`` of each linked
        pair (each pair once) and its float64 weight ``(M,)`` (computed in
        float32).
    """
    h, w = colour.shape[:2]
    c = colour.astype(np.float32)
    index = np.arange(h * w, dtype=np.int32).reshape(h, w)
    shifts = (((slice(None), slice(0, w - 1)), (slice(None), slice(1, w)), 1.0),  # right
              ((slice(0, h - 1), slice(None)), (slice(1, h), slice(None)), 1.0),  # below
              ((slice(0, h - 1), slice(0, w - 1)), (slice(1, h), slice(1, w)), math.sqrt(2)),  # below right
              ((slice(0, h - 1), slice(1, w)), (slice(1, h), slice(0, w - 1)), math.sqrt(2)))  # below left
    diffs = []
    for a, b, _ in shifts:
        d = c[a] - c[b]
        diffs.append(np.einsum("...k,...k->...", d, d))  # float32: exact for 8-bit colours
    total = sum(float(d.sum(dtype=np.float64)) for d in diffs)
    count = sum(d.size for d in diffs)
    beta = 0.0 if total <= 0 else 1.0 / (2.0 * total / count)
    ps, qs, weights = [], [], []
    for (a, b, dist), d2 in zip(shifts, diffs):
        d2 *= np.float32(-beta)
        weight = np.exp(d2, out=d2)
        weight *= np.float32(_GAMMA / dist)
        if z is not None:
            near = np.fmin(z[a], z[b])
            jump = np.abs(z[a] - z[b]) / (_JUMP * np.maximum(near, 1e-3))
            # NaN where either pixel lacks depth: no depth factor there.
            weight *= np.where(np.isnan(jump), 1.0, np.exp(-np.nan_to_num(jump) ** 2)).astype(np.float32)
        ps.append(index[a].ravel())
        qs.append(index[b].ravel())
        weights.append(weight.ravel())
    return np.concatenate(ps), np.concatenate(qs), np.concatenate(weights).astype(np.float64)


class _CutGraph:
    """The graph of one cut's free pixels, cut again as their costs change.

    Args:
        links: The ROI's ``(p, q, weight)`` (``_links``).
        fixed_fg: bool ``(N,)`` over the ROI's flat pixels: the label of the
            pixels that are not free (ignored at the free ones).
        free: Flat indices of the pixels to cut (``(n,)``).
    """

    def __init__(self, links: tuple[np.ndarray, np.ndarray, np.ndarray], fixed_fg: np.ndarray,
                 free: np.ndarray) -> None:
        p, q, weight = links
        n = len(free)
        node = np.full(fixed_fg.size, -1, np.int32)
        node[free] = np.arange(n, dtype=np.int32)
        np_, nq = node[p], node[q]
        free_p, free_q = np_ >= 0, nq >= 0
        both = free_p & free_q
        # A free pixel linked to a fixed one pays the link when it takes the
        # other label: part of its cost of that label.
        self._fold_bg = np.zeros(n)
        self._fold_fg = np.zeros(n)
        for one, ours, theirs in ((free_p & ~free_q, np_, q), (free_q & ~free_p, nq, p)):
            pick = np.flatnonzero(one)
            at, w = ours[pick], weight[pick]
            fg = fixed_fg[theirs[pick]]
            self._fold_bg += np.bincount(at, np.where(fg, w, 0.0), minlength=n)
            self._fold_fg += np.bincount(at, np.where(fg, 0.0, w), minlength=n)
        pick = np.flatnonzero(both)
        w = weight[pick]
        self.size = n
        self._graph = maxflow.Graph[float](max(n, 1), len(pick))
        self._ids = self._graph.add_nodes(n)
        if n:
            self._graph.add_edges(np_[pick], nq[pick], w, w)
        self._caps: tuple[np.ndarray, np.ndarray] | None = None

    def cut(self, cost_bg: np.ndarray, cost_fg: np.ndarray) -> np.ndarray:
        """The minimum cut with these label costs of the free pixels; bool ``(n,)``, True = foreground.

        The first call cuts from scratch; later ones change the terminal
        capacities by the difference and reuse the flow (the same minimum
        cut, found faster when the costs moved little).
        """
        if self.size == 0:
            return np.zeros(0, bool)
        # Source = foreground: a pixel cut off the source (background) pays its
        # source capacity, so that is its cost as background, and vice versa.
        # Only the difference of a pixel's two costs matters.
        shift = np.minimum(cost_bg, cost_fg)
        source = cost_bg - shift + self._fold_bg
        sink = cost_fg - shift + self._fold_fg
        if self._caps is None:
            self._graph.add_grid_tedges(self._ids, source, sink)
            self._graph.maxflow()
        else:
            d_source, d_sink = source - self._caps[0], sink - self._caps[1]
            changed = np.flatnonzero((d_source != 0) | (d_sink != 0))
            if not len(changed):
                return ~self._graph.get_grid_segments(self._ids)
            # Adding the same amount to both capacities changes no cut: keep both additions >= 0.
            lift = np.maximum(0.0, -np.minimum(d_source[changed], d_sink[changed]))
            self._graph.add_grid_tedges(self._ids[changed], d_source[changed] + lift, d_sink[changed] + lift)
            self._graph.mark_grid_nodes(self._ids[changed])
            self._graph.maxflow(reuse_trees=True)
        self._caps = (source, sink)
        return ~self._graph.get_grid_segments(self._ids)
