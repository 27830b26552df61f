"""The graph cut at the work size: a box's first cut, its rescue, and re-cuts.

The cut runs on the ROI at low resolution (``_Guide.image``) and minimises
OpenCV grabCut's energy with the session's own minimum cut
(``graph._CutGraph``), iterating as ``cv2.grabCut`` in ``GC_EVAL`` mode
does: re-estimate the models from the current labels, cut. Results are bool
labels on the ROI's low-resolution grid; ``refine`` brings them back to
full resolution. With depth the same steps run on the colour-plus-depth
models of ``depth``.

What makes it faster than ``cv2.grabCut`` on the same grid, for the same
energy:

* only undecided pixels are nodes (the box's margin alone is a third of the
  ROI);
* a box's iterations cut the same graph again with new costs, reusing the
  previous flow (``_CutGraph.cut``);
* a box's first iterations, while the models settle, run on a grid of half
  the size (a quarter of the pixels); the last one re-estimates and cuts on
  the full grid, starting from the coarse label, and only within
  ``_FINE_BAND`` grid pixels of its edge (a banded cut: the rest keeps the
  coarse label);
* a stroke re-cuts only the side of the label it can change, and only near
  the stroke (``_STROKE_REACH``); its models are re-estimated from the
  whole ROI.

A box's cut then goes on with a foreground model of the pixels that are
clearly the object's (``_sharpened``), so the background the box holds
(the ground between legs) stops shaping it.

A box whose cut keeps little of it and misses one of its edges is cut
again with a path along the image's ridges to that edge as object
(``_crossing``, the box prior), when the path is of one material.

A box whose cut still keeps little of it, with no such path, may hold a
long thin straight object its grid cannot resolve (chopsticks across the
box): the strongest straight line from edge to edge (``_straight``) is
followed at full resolution instead (``fine._fine_cut``, in the session).

A colour stroke also flips the error region it lands in up to the image's
edges (``_flooded``: a watershed from the stroke against what surely has
the other label), not only what the re-cut's colour models move; and the
re-cut moves a pixel against its own colour (one the other side's model
explains at least as well, carried by the cut's smoothness) only if it is
like the stroke's colours (the fence beside a camel's head stays out). An
object stroke on a thin part of its colour (a leg) also takes that part
along itself (``_along``), where the flood stops short on the grid.

A background stroke gives back a long thin part it cut off that the
models learnt after it place on the object's side (``_restored``: a knife's
handle lying on the mug the stroke removed, which the grid's pairwise term
drops with the mug).

What a stroke changes is local (``_keep_connected``): only pixels within
``_NEAR_GRID`` of the stroke, or joined to it through pixels that changed
too, take a new label; every other pixel keeps its own, so re-estimated
models never drop a far part (the tip of a handle) that the labeller did
not touch.

On the real frames of ``bench/bench_grabcut.py --real-only`` the box's cut
matches ``cv2.grabCut``'s label exactly when run the same way (all five
iterations on the full grid); the coarse start and the stroke's reach are
what change it (see the README's Benchmarks).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import cv2
import numpy as np
from skimage.feature import hessian_matrix, hessian_matrix_eigvals
from skimage.graph import MCP_Geometric
from skimage.segmentation import watershed

from egonet.grabcut.colour import _costs, _first_models, _fit_model, _learn
from egonet.grabcut.depth import (_Z_SCALE, _depth_costs, _DepthGuide, _fallback_z, _first_model, _learn_depth)
from egonet.grabcut.fine import _joined, _like
from egonet.grabcut.geometry import _Geometry
from egonet.grabcut.graph import _CutGraph, _links
from egonet.grabcut.refine import _Guide
from egonet.grabcut.strokes import _Stroke

_BOX_ITERATIONS = 5  # graph-cut iterations for a new box (as plain GC_INIT_WITH_RECT)
_STROKE_ITERATIONS = 1  # re-estimation + cut per stroke
_CONVERGED = 0.005  # stop iterating when a cut changes at most this fraction of undecided pixels
_SPARSE = 0.25  # a box whose first cut keeps less than this fraction of it is cut again (``_rescue``)
_OUTSIDE_SAMPLES = 100_000  # most frame pixels read for the background model of that cut
_COARSE_MIN = 32  # a box's first iterations run at half the grid when that is at least this many pixels a side
_STROKE_REACH = 56  # a stroke re-cuts the label within this many grid pixels of itself (a fifth of the work size)
_NEAR_GRID = 2  # a stroke changes the grid's label only within this many grid pixels of itself, or connected to that
_FLOOD_SCALE = 2.0  # a stroke floods at most this many times its depth in its region (``_flooded``)
_FLOOD_MIN = 4  # ... or this many grid pixels, whichever is more
_FLOOD_SMOOTH = 0.7  # Gaussian sigma of the colours before the flood's gradient, grid pixels
_SURE_MARGIN = 4.0  # a pixel whose colour favours the other label by this much (-log p) stops the flood
_LONG = 8.0  # a background stroke gives back a thin part it cut off that is at least this many times as long as wide
_ALONG_WIDTH = 2.0  # an object stroke takes the part of its colour along itself this many times the part's half-width
_ALONG_SHARE = 0.9  # ... when at least this fraction of that part lies along the stroke (``_along``)
_ALONG_HALF = 8  # ... and the part is at most this many grid pixels from its edge at the stroke (thin)
_CROSSING_BAND = 0.1  # the box prior's bands along the box's edges, a fraction of its width or height (``_crossing``)
_COHERENT = 0.4  # ... a path counts if its colours spread at most this many times as much as the box's
_CROSSING_ITERATIONS = 2  # re-estimation + cut with the path as sure object
_LINE_STRENGTH = 3.0  # ... the straight line prior's line counts if its mean strength is this many times the box's
_LINE_MIDDLE = 0.5  # ... and the object is followed from this middle fraction of it (its ends may be the box's margin)
_LINE_KEPT = 0.5  # ... unless the box's label already holds more than this fraction of that middle
_FINE_BAND = 6  # a box's cut on the full grid moves the coarse label's edge by at most this many grid pixels
_SHARPEN_MARGIN = 2.0  # a box's cut goes on with a foreground model of pixels it favours by this much (nats)
_SHARPEN_ITERATIONS = 2  # ... for this many re-estimations and cuts (on the coarse grid: ``_sharpened``)
_SHARPEN_KEEP = 0.5  # ... and is taken only if it keeps at least this fraction of the label
_SHARPEN_EDGE = 0.02  # ... and not at all when the label covers more than this fraction of the box's outline

# OpenCV builds its 8-bit RGB -> Lab tables on the process's first such conversion (50-100 ms CPU, once): built at
# import, so that the first stroke that floods (``_flooded``) does not pay for them.
cv2.cvtColor(np.zeros((1, 1, 3), np.uint8), cv2.COLOR_RGB2LAB)

# The terms of one cut: ``learn(bg, fg, models) -> models`` re-estimates both
# models from the flat pixels ``bg`` and ``fg`` (bool masks); ``costs(models, pixels) -> (cost_bg, cost_fg)``
# are ``-log p`` of the flat pixels under each; ``links`` the pairwise links.
_Learn = Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]
_Costs = Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]


class _Terms:
    """What a cut needs of its grid: the pairwise links and the two models' learning and costs."""

    def __init__(self, links: tuple[np.ndarray, np.ndarray, np.ndarray], learn: _Learn, costs: _Costs) -> None:
        self.links, self.learn, self.costs = links, learn, costs

    @classmethod
    def colour(cls, guide: _Guide) -> _Terms:
        x = guide.pixels
        return cls(guide.links, lambda bg, fg, models: _learn(x, bg, fg, models),
                   lambda models, pixels: (_costs(models[0], x[pixels]), _costs(models[1], x[pixels])))

    @classmethod
    def of_image(cls, image: np.ndarray) -> _Terms:
        """Colour terms of a uint8 ``(h, w, 3)`` image that has no guide (a coarse grid, the whole frame)."""
        x = image.reshape(-1, 3).astype(np.float32)
        return cls(_links(image), lambda bg, fg, models: _learn(x, bg, fg, models),
                   lambda models, pixels: (_costs(models[0], x[pixels]), _costs(models[1], x[pixels])))

    @classmethod
    def depth(cls, guide: _DepthGuide) -> _Terms:
        return cls(guide.links, lambda bg, fg, models: _learn_depth(guide, bg, fg, models),
                   lambda models, pixels: _depth_costs(guide, models, pixels))


def _graph_for(terms: _Terms, gc: np.ndarray) -> _CutGraph:
    """The graph of ``gc``'s undecided pixels (``GC_PR_*``), the others fixed as they are."""
    flat = gc.reshape(-1)
    return _CutGraph(terms.links, (flat & 1).astype(bool), np.flatnonzero(flat >= cv2.GC_PR_BGD))


def _cut(terms: _Terms, gc: np.ndarray, models: np.ndarray, iterations: int, *, frozen: bool = False,
         graph: _CutGraph | None = None, sharpen: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Iterate re-estimation and the minimum cut, as ``cv2.grabCut`` in ``GC_EVAL`` mode.

    Each iteration re-estimates the models from the current labels
    (starting from ``models``, so their components carry over) and cuts the
    undecided pixels (``GC_PR_*``; ``GC_BGD``/``GC_FGD`` ones stay). Stops
    early once an iteration changes at most ``_CONVERGED`` of the undecided
    pixels: later iterations only nudge the boundary. The models stay as
    given when one side is empty (re-estimating from no pixels is undefined)
    or ``frozen``.

    Args:
        terms: The grid's links and the models' learning and costs.
        gc: uint8 ``(h, w)`` OpenCV GC_* labels; updated in place.
        models: The two models, background first.
        iterations: Most iterations to run.
        frozen: Keep ``models`` as given (no re-estimation).
        graph: A graph of the same grid made for the same undecided pixels
            and fixed labels (``_graph_for``), already cut with other costs:
            its flow is reused. None makes a new one.
        sharpen: Fit the foreground model only on its pixels that the
            current models place on the foreground's side by more than this
            (nats; ``_sharpened``). None: on all of them.

    Returns:
        ``(label, models)``: the bool foreground label and the new models.
    """
    flat = gc.reshape(-1)
    free = np.flatnonzero(flat >= cv2.GC_PR_BGD)
    if graph is None:
        graph = _graph_for(terms, gc)
    for _ in range(iterations):
        is_fg = (flat & 1).astype(bool)
        learn = not frozen and is_fg.any() and not is_fg.all()
        if learn:
            fg = is_fg
            if sharpen is not None:
                cost_bg, cost_fg = terms.costs(models, np.arange(is_fg.size))
                fg = is_fg & (cost_bg - cost_fg > sharpen)
                fg = fg if fg.any() else is_fg
            models = terms.learn(~is_fg, fg, models)
        before = flat[free] & 1
        flat[free] = np.where(graph.cut(*terms.costs(models, free)), cv2.GC_PR_FGD, cv2.GC_PR_BGD)
        if not learn or np.count_nonzero(before != (flat[free] & 1)) <= _CONVERGED * max(1, len(free)):
            break
    return (gc & 1).astype(bool), models


def _box_labels(geom: _Geometry) -> np.ndarray:
    """The GC_* labels a box starts from: ``GC_PR_FGD`` on the box, ``GC_BGD`` around it."""
    gc = np.full((geom.low_h, geom.low_w), cv2.GC_BGD, np.uint8)
    rows, cols = geom.box_low()
    gc[rows, cols] = cv2.GC_PR_FGD
    return gc


def _coarse(geom: _Geometry) -> tuple[_Geometry, np.ndarray] | None:
    """The half-size grid of ``geom`` and its box labels, or None when it would be too small."""
    coarse = _Geometry(geom.box, geom.roi, max(1, round(geom.low_w / 2)), max(1, round(geom.low_h / 2)))
    gc = _box_labels(coarse)
    if min(coarse.low_w, coarse.low_h) < _COARSE_MIN or not (gc == cv2.GC_BGD).any():
        return None
    return coarse, gc


def _upsampled_labels(geom: _Geometry, coarse_low: np.ndarray) -> np.ndarray:
    """The full grid's GC_* labels from a coarse label: the box undecided, as the coarse cut says.

    Only the box's pixels within ``_FINE_BAND`` grid pixels of the coarse
    label's edge stay undecided; the others keep the coarse label as
    sure (a banded cut: the full grid only moves the edge, on a fraction of
    the pixels).
    """
    rows, cols = geom.box_low()
    up = cv2.resize(coarse_low.astype(np.float32), (geom.low_w, geom.low_h), interpolation=cv2.INTER_LINEAR) >= 0.5
    gc = np.full((geom.low_h, geom.low_w), cv2.GC_BGD, np.uint8)
    band = _FINE_BAND
    if band is None:
        gc[rows, cols] = np.where(up[rows, cols], cv2.GC_PR_FGD, cv2.GC_PR_BGD)
        return gc
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * band + 1, 2 * band + 1))
    u8 = up.view(np.uint8)
    near = (cv2.dilate(u8, kernel) != cv2.erode(u8, kernel, borderType=cv2.BORDER_REPLICATE))
    gc[rows, cols] = np.where(near[rows, cols], np.where(up[rows, cols], cv2.GC_PR_FGD, cv2.GC_PR_BGD),
                              np.where(up[rows, cols], cv2.GC_FGD, cv2.GC_BGD))
    return gc


def _coarse_to_fine(fine: _Terms, geom: _Geometry, gc: np.ndarray, coarse: _Terms, coarse_gc: np.ndarray,
                    models: np.ndarray, iterations: int, *, sharpen: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """A box's iterations: all but the last on the coarse grid, the last on the full one.

    While the models settle, a cut on a quarter of the pixels does as well;
    the last iteration re-estimates them and cuts on the full grid, from the
    coarse label, only within ``_FINE_BAND`` of its edge.

    Args:
        fine: The full grid's terms.
        geom: The full grid's geometry.
        gc: The full grid's box labels; updated in place.
        coarse: The coarse grid's terms.
        coarse_gc: The coarse grid's box labels; updated in place.
        models: The models to start from.
        iterations: Iterations in all.
        sharpen: Continue the coarse cut with ``_sharpened`` before the full grid.

    Returns:
        ``(label, models)``.
    """
    coarse_low, models = _cut(coarse, coarse_gc, models, iterations - 1)
    if sharpen:
        coarse_low, models = _sharpened(coarse, coarse_gc, coarse_low, models)
    gc[...] = _upsampled_labels(geom, coarse_low)
    return _cut(fine, gc, models, 1)


def _sharpened(terms: _Terms, gc: np.ndarray, low: np.ndarray, models: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A box's cut continued with a foreground model of the pixels that are clearly the object's.

    A box's foreground model starts from everything in the box, so it also
    learns the background the box holds (the ground between an animal's
    legs, a fence behind its back); where that background is also in the
    margin, both models explain it and the cut keeps it. Here the
    foreground model is fitted only on the pixels of the label that the
    models place on the object's side by more than ``_SHARPEN_MARGIN`` nats
    (``_cut``'s ``sharpen``; the background model from all the others, as
    before), for ``_SHARPEN_ITERATIONS`` more re-estimations and cuts. An
    object of several colours can lose a whole colour that way (a goat's dark
    legs among dark rocks), or move the edge where the colours are alike: the
    continued cut is taken only if it keeps at least ``_SHARPEN_KEEP`` of the
    label and its own models place the pixels it dropped on the background's
    side by more than ``_SHARPEN_MARGIN`` nats on average. It trusts the
    margin as background, so a box whose label runs along more than
    ``_SHARPEN_EDGE`` of its outline (a box through the object, whose margin
    holds more of it) is not sharpened.

    Args:
        terms: The grid's terms.
        gc: The grid's labels after the box's cut (``low`` undecided in the box); not changed.
        low: The box's label on that grid.
        models: Its models.

    Returns:
        ``(label, models)``: the continued cut's, or ``low`` and ``models``.
    """
    if not low.any():
        return low, models
    ys, xs = np.nonzero(gc >= cv2.GC_PR_BGD)
    inner = low[ys.min() : ys.max() + 1, xs.min() : xs.max() + 1]
    ring = np.ones(inner.shape, bool)
    ring[1:-1, 1:-1] = False
    if inner[ring].mean() > _SHARPEN_EDGE:
        return low, models
    sharp, sharp_models = _cut(terms, gc.copy(), models, _SHARPEN_ITERATIONS, sharpen=_SHARPEN_MARGIN)
    if np.count_nonzero(sharp) < _SHARPEN_KEEP * np.count_nonzero(low):
        return low, models
    dropped = np.flatnonzero(low & ~sharp)
    if len(dropped):
        cost_bg, cost_fg = terms.costs(sharp_models, dropped)
        if float(np.mean(cost_bg - cost_fg)) > -_SHARPEN_MARGIN:
            return low, models
    return sharp, sharp_models


def _box_cut(frame: np.ndarray, guide: _Guide, gc: np.ndarray,
             work_size: int) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """A new box's cut, from first models; a box it keeps little of is cut again (``_rescue``).

    A box that every cut keeps little of, with no path of one material to
    the edges its label misses (``_crossing``), may be crossed by a long thin
    straight object (``_straight``): the middle ``_LINE_MIDDLE`` of that line
    is returned, for the session to follow the object from at full
    resolution.

    Args:
        frame: Full frame, uint8 ``(H, W, 3)``.
        guide: The low-resolution guide of the box's ROI.
        gc: The box's labels (``_box_labels``), with some background; updated in place.
        work_size: The session's work size.

    Returns:
        ``(label, models, line)``: the bool low-resolution label, the
        ``(2, 65)`` models, and the straight line's middle as ``(2, 2)``
        full-resolution ``(x, y)`` ends, or None.
    """
    geom = guide.geom
    rows, cols = geom.box_low()
    # Initial colour models from k-means on a fixed-seed sample of each side
    # (plain grabCut runs k-means on every pixel, which is most of its cost).
    start = gc.copy()
    coarse = _coarse(geom)
    terms = _Terms.colour(guide)
    graph = None
    if coarse is None:
        initial = _first_models(guide.image, gc, np.random.default_rng(0))
        graph = _graph_for(terms, gc)
        low, models = _cut(terms, gc, initial, _BOX_ITERATIONS, graph=graph)
    else:
        small_geom, small_gc = coarse
        image = _resize(frame, small_geom)
        initial = _first_models(image, small_gc, np.random.default_rng(0))
        low, models = _coarse_to_fine(terms, geom, gc, _Terms.of_image(image), small_gc, initial, _BOX_ITERATIONS,
                                      sharpen=True)
    if low[rows, cols].mean() < _SPARSE:
        low, models = _rescue(frame, guide, start, low, models, work_size, graph)
    if low[rows, cols].mean() < _SPARSE:
        path = _crossing(guide.image[rows, cols], low[rows, cols])
        if path is not None:
            gc = start.copy()
            view = gc[rows, cols]
            view[path] = cv2.GC_FGD
            gc[rows, cols] = view
            low, models = _cut(terms, gc, models, _CROSSING_ITERATIONS)
        else:
            ends = _straight(guide.image[rows, cols], low[rows, cols])
            if ends is not None:
                ends = ends + (cols.start, rows.start)
                middle = (1 - _LINE_MIDDLE) / 2
                return low, models, geom.to_full(ends + middle * (ends[::-1] - ends))
    return low, models, None


def _crossing(image: np.ndarray, low: np.ndarray) -> np.ndarray | None:
    """The box prior for a box its cut keeps little of: a path along the object to each edge band the label misses.

    A box drawn around an object touches it on all four sides (Lempitsky et
    al. 2009: every row and column of a tight box crosses the object), but
    the cut of a long thin object lying across its box (a knife) often keeps
    something else, of the colours the box holds most of. So, where the
    label misses the band along an edge of the box (``_CROSSING_BAND`` of its
    width or height), the cheapest path from the label to that band along
    ridges of the image (thin bright or dark lines: the Hessian's largest
    eigenvalue, as Sato's filter) is taken as the object's, and the box is
    cut again with it as sure object. Only a path of one material counts
    (its colours spread at most ``_COHERENT`` times as much as the box's):
    one that crosses table, plate and food is no object's.

    Args:
        image: uint8 ``(h, w, 3)``, the box on the grid.
        low: bool ``(h, w)``, the box's label.

    Returns:
        bool ``(h, w)``: the path, or None when the label reaches every band
        or the path is not of one material.
    """
    h, w = low.shape
    bh, bw = max(1, round(_CROSSING_BAND * h)), max(1, round(_CROSSING_BAND * w))
    bands = [np.zeros((h, w), bool) for _ in range(4)]
    bands[0][:, :bw] = bands[1][:, w - bw :] = bands[2][:bh] = bands[3][h - bh :] = True
    missing = [k for k, band in enumerate(bands) if not (low & band).any()]
    if not missing:
        return None
    ridge = _ridges(image, (1, 2, 3))
    cost = 1.0 / (ridge / (ridge.max() + 1e-9) + 0.05)
    path = np.zeros((h, w), bool)
    for k in missing:
        # From the label, or without one from the opposite band.
        starts = np.argwhere(low if low.any() else bands[k ^ 1])
        ends = np.argwhere(bands[k])
        mcp = MCP_Geometric(cost)
        cumulative, _ = mcp.find_costs([tuple(p) for p in starts], [tuple(p) for p in ends], find_all_ends=False)
        for p in mcp.traceback(tuple(ends[np.argmin(cumulative[bands[k]])])):
            path[p] = True
    return path if _spread(image, path) <= _COHERENT else None


def _spread(image: np.ndarray, where: np.ndarray | tuple[np.ndarray, np.ndarray]) -> float:
    """How far the colours of ``image``'s pixels ``where`` spread (Lab), as a fraction of the whole image's spread.

    A path or line of one material spreads little (the box priors' test, ``_COHERENT``).
    """
    lab = cv2.cvtColor(image, cv2.COLOR_RGB2LAB).astype(np.float32)
    return float(np.linalg.norm(lab[where].std(axis=0)) / max(1e-6, float(np.linalg.norm(lab.reshape(-1, 3).std(axis=0)))))


def _ridges(image: np.ndarray, sigmas: tuple[int, ...], *, lines_only: bool = False) -> np.ndarray:
    """Ridge strength of a uint8 ``(h, w, 3)`` image: thin bright or dark lines, best over ``sigmas`` grid pixels.

    The Hessian's eigenvalue of largest magnitude, scale-normalised (as
    Sato's filter). With ``lines_only``, less the gradient's magnitude at the
    same scale (the image's border repeated): a line's middle has no
    gradient, an edge's flanks (which the Hessian answers too) have much.
    """
    grey = image.astype(np.float32).mean(axis=2)
    ridge = np.zeros_like(grey)
    for sigma in sigmas:
        mode = "nearest" if lines_only else "constant"
        eigen = hessian_matrix_eigvals(hessian_matrix(grey, sigma, mode=mode, order="rc", use_gaussian_derivatives=False))
        strength = sigma * sigma * np.abs(eigen).max(axis=0)
        if lines_only:
            smooth = cv2.GaussianBlur(grey, (0, 0), sigma)
            strength -= sigma * np.hypot(cv2.Sobel(smooth, cv2.CV_32F, 1, 0, ksize=1),
                                         cv2.Sobel(smooth, cv2.CV_32F, 0, 1, ksize=1))
        ridge = np.maximum(ridge, strength)
    return ridge


def _straight(image: np.ndarray, low: np.ndarray) -> np.ndarray | None:
    """The box prior for a long thin straight object across its box: the strongest straight line edge to edge.

    A pair of chopsticks lying across a box is 2-3 grid pixels wide and of
    the table's colours: no cut on the grid keeps it, and a path along the
    image's ridges (``_crossing``) strays onto the edges of what lies
    beside it. But the box's edges are the object's ends, and it is
    straight: of the straight lines from the box's left edge to its right
    one and from its top to its bottom (ends every 2 grid pixels, read
    every 2, then the best one's to the pixel), the one of strongest mean line strength
    (``_ridges``) is the object's, if that is ``_LINE_STRENGTH`` times the
    box's mean and the line's middle ``_LINE_MIDDLE`` (its ends may lie in
    the box's margin) is of one material (``_COHERENT``, as ``_crossing``'s
    path) and not already the label's (a spoon's handle whose bowl the cut
    kept too: at most ``_LINE_KEPT`` of it).

    Args:
        image: uint8 ``(h, w, 3)``, the box on the grid.
        low: bool ``(h, w)``, the box's label.

    Returns:
        ``(2, 2)`` float ``(x, y)``: the line's two ends on ``image``, or None.
    """
    h, w = image.shape[:2]
    ridge = _ridges(image, (1, 2), lines_only=True)

    def strongest(across: bool, starts: np.ndarray, stops: np.ndarray, step: int) -> tuple[float, np.ndarray]:
        """The strongest line from a start to a stop (on the left and right edges, or top and bottom), read
        every ``step`` pixels along: its strength and its pixels' coordinates across."""
        m = h if across else w
        other = np.arange(0, m, step)
        t = other / max(1, m - 1)
        a, b = np.meshgrid(starts, stops, indexing="ij")
        along = np.rint(a[..., None] * (1 - t) + b[..., None] * t).astype(np.intp)
        strength = (ridge[other, along] if across else ridge[along, other]).mean(axis=-1)
        k = np.unravel_index(int(np.argmax(strength)), strength.shape)
        t = np.arange(m) / max(1, m - 1)
        return float(strength[k]), np.rint(starts[k[0]] * (1 - t) + stops[k[1]] * t).astype(np.intp)

    best = None
    for across in (False, True):  # left to right, then top to bottom
        n = w if across else h
        strength, along = strongest(across, np.arange(0, n, 2), np.arange(0, n, 2), 2)
        if best is None or strength > best[0]:
            near = [np.arange(max(0, e - 1), min(n, e + 2)) for e in (along[0], along[-1])]
            best = (*strongest(across, *near, 1), across)
    strength, along, across = best
    other = np.arange(len(along))
    ys, xs = (other, along) if across else (along, other)
    cut = round((1 - _LINE_MIDDLE) / 2 * len(along))
    middle = ys[cut : len(along) - cut], xs[cut : len(along) - cut]
    if low[middle].mean() > _LINE_KEPT:
        return None
    if _spread(image, middle) > _COHERENT or strength < _LINE_STRENGTH * float(np.maximum(ridge, 0).mean()):
        return None
    return np.array([[xs[0], ys[0]], [xs[-1], ys[-1]]], float)


def _resize(frame: np.ndarray, geom: _Geometry) -> np.ndarray:
    """``geom``'s ROI of ``frame`` on its grid (area averaging)."""
    rx0, ry0, rx1, ry1 = geom.roi
    return cv2.resize(frame[ry0:ry1, rx0:rx1], (geom.low_w, geom.low_h), interpolation=cv2.INTER_AREA)


def _outside_sample(frame: np.ndarray, geom: _Geometry) -> np.ndarray:
    """Pixels of ``frame`` outside ``geom``'s box, on a regular grid (at most ~``_OUTSIDE_SAMPLES``), ``(n, C)``."""
    h, w = frame.shape[:2]
    box = geom.box
    step = max(1, round(1 / min(geom.sx, geom.sy)), math.ceil(math.sqrt(h * w / _OUTSIDE_SAMPLES)))
    outside = np.ones((h, w), bool)
    outside[box[1] : box[3], box[0] : box[2]] = False
    return frame[::step, ::step][outside[::step, ::step]]


def _rescue(frame: np.ndarray, guide: _Guide, start: np.ndarray, low: np.ndarray, models: np.ndarray,
            work_size: int, graph: _CutGraph | None) -> tuple[np.ndarray, np.ndarray]:
    """Cut a box whose first cut kept little of it again; the cut that keeps most wins.

    That usually happens when the box cuts through an object that goes on
    into the margin: the margin's colours, the background model, then
    include the object's. Plain grabCut takes its background from the whole
    frame outside the box, where that continuation is a small part. So:
    first one cut with such a background model held fixed (and a foreground
    model of the box); if that too keeps little, plain grabCut on the whole
    frame at the work size, brought onto the ROI's grid. The first step is
    tried on the coarse grid first and run on the full one (within
    ``_FINE_BAND`` of the coarse cut's edge) only if it keeps more there.

    Args:
        frame: Full frame, uint8 ``(H, W, 3)``.
        guide: The low-resolution guide of the box's ROI.
        start: The box's labels before the first cut.
        low: The first cut's label.
        models: The first cut's models.
        work_size: The session's work size.
        graph: Without a coarse grid, the first cut's graph (the box's
            pixels undecided, as in ``start``): the held cut reuses its flow.
    """
    geom = guide.geom
    rows, cols = geom.box_low()
    # The box's first foreground model on the full grid, and a background
    # model of the frame outside the box (both k-means with fixed seeds).
    fgd = _first_models(guide.image, start, np.random.default_rng(0))[1:2]
    rng = np.random.default_rng(0)
    bgd = _fit_model(_outside_sample(frame, geom), rng)
    held = np.concatenate([bgd, fgd])
    held_low = None
    coarse = _coarse(geom)
    if coarse is not None:
        # The held cut on the full grid is slow (with models held fixed
        # nothing settles first), and it matters only if it keeps more than
        # the first cut: the coarse grid tells, at a quarter of the cost.
        small_geom, small_gc = coarse
        small_low = _cut(_Terms.of_image(_resize(frame, small_geom)), small_gc, held, 1, frozen=True)[0]
        share = (geom.low_w * geom.low_h) / (small_geom.low_w * small_geom.low_h)
        if np.count_nonzero(small_low) * share > np.count_nonzero(low):
            held_low = _cut(_Terms.colour(guide), _upsampled_labels(geom, small_low), held, 1, frozen=True)[0]
    else:
        held_low = _cut(_Terms.colour(guide), start.copy(), held, 1, frozen=True, graph=graph)[0]
    candidates = [(low, models)] if held_low is None else [(low, models), (held_low, held)]
    if len(candidates) == 1 or candidates[1][0][rows, cols].mean() < _SPARSE:
        whole = _whole_frame_cut(frame, geom, work_size, rng)
        if whole is not None:
            candidates.append(whole)
    return max(candidates, key=lambda c: np.count_nonzero(c[0]))


def _whole_frame_cut(frame: np.ndarray, geom: _Geometry, work_size: int,
                     rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray] | None:
    """Plain grabCut of ``geom``'s box on the whole frame at the work size, on the ROI's grid.

    Returns:
        ``(label, models)`` with the label on ``geom``'s low-resolution grid,
        or None when the box covers the whole reduced frame.
    """
    h, w = frame.shape[:2]
    scale = min(1.0, work_size / max(h, w))
    whole = _Geometry(geom.box, (0, 0, w, h), max(1, round(w * scale)), max(1, round(h * scale)))
    image = _resize(frame, whole)
    gc = _box_labels(whole)
    if not (gc == cv2.GC_BGD).any():
        return None
    terms = _Terms.of_image(image)
    cut, whole_models = _cut(terms, gc, _first_models(image, gc, rng), _BOX_ITERATIONS)
    full = cv2.resize(cut.view(np.uint8), (w, h), interpolation=cv2.INTER_NEAREST)
    rx0, ry0, rx1, ry1 = geom.roi
    share = cv2.resize(full[ry0:ry1, rx0:rx1] * np.uint8(255), (geom.low_w, geom.low_h),
                       interpolation=cv2.INTER_AREA)
    return share >= 128, whole_models


def _stroke_labels(guide: _Guide, strokes: tuple[_Stroke, ...], prior: np.ndarray) -> np.ndarray:
    """The GC_* labels of a re-cut: the box's pixels undecided as ``prior`` says, strokes hard."""
    geom = guide.geom
    rows, cols = geom.box_low()
    gc = np.full((geom.low_h, geom.low_w), cv2.GC_BGD, np.uint8)
    gc[rows, cols] = np.where(prior[rows, cols], cv2.GC_PR_FGD, cv2.GC_PR_BGD)
    for s in strokes:
        hit = guide.footprint(s)
        if hit is not None:
            crop, (y0, x0) = hit
            view = gc[y0 : y0 + crop.shape[0], x0 : x0 + crop.shape[1]]
            view[crop] = cv2.GC_FGD if s.fg else cv2.GC_BGD
    return gc


def _recut(terms: _Terms, guide: _Guide, models: np.ndarray, strokes: tuple[_Stroke, ...],
           prior: np.ndarray, *, reach: int | None = _STROKE_REACH,
           flood: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Cut again with ``strokes`` as hard labels, starting from the label ``prior``.

    The label only moves the last stroke's way (see ``GrabCutSession.stroke``),
    so the pixels on the other side stay fixed: a foreground stroke cuts only
    the background pixels again, a background stroke only the foreground
    ones, on a graph of those alone.

    Args:
        terms: The ROI's terms (colour, or with depth).
        guide: The ROI's guide (the strokes' low-resolution pixels).
        models: The current models.
        strokes: The object's strokes, the new one last.
        prior: The label before the stroke.
        reach: Grid pixels around the stroke that may change, or None for
            the whole box. Colour cuts on a white chair before a white wall
            are slow to solve over the whole box; with depth the cut is
            easy, and the whole box is cut.
        flood: Also flip what the stroke floods up to the image's edges
            (``_flooded``), within ``reach`` (``_STROKE_REACH`` if None).

    Returns:
        ``(label, models)``.
    """
    gc = _stroke_labels(guide, strokes, prior)
    if strokes[-1].fg:
        gc[gc == cv2.GC_PR_FGD] = cv2.GC_FGD
    else:
        gc[gc == cv2.GC_PR_BGD] = cv2.GC_BGD
    hit = guide.footprint(strokes[-1])
    if hit is not None and reach is not None:
        # Only near the stroke: further away the label stays as it was.
        crop, (y0, x0) = hit
        r = reach
        far = np.ones(gc.shape, bool)
        far[max(0, y0 - r) : y0 + crop.shape[0] + r, max(0, x0 - r) : x0 + crop.shape[1] + r] = False
        gc[far & (gc == cv2.GC_PR_FGD)] = cv2.GC_FGD
        gc[far & (gc == cv2.GC_PR_BGD)] = cv2.GC_BGD
    low, models = _cut(terms, gc, models, _STROKE_ITERATIONS)
    low = (low | prior) if strokes[-1].fg else (low & prior)
    if hit is not None and flood:
        last = strokes[-1]
        hits = [(*hit, True)] + [(*guide.footprint(s), s.fg == last.fg) for s in strokes[:-1]
                                 if guide.footprint(s) is not None]
        # What surely is of the other label: the sure pixels, and those its colour model clearly prefers
        # unless they are like the stroke's own colours (``_unlike``).
        cost_bg, cost_fg = terms.costs(models, np.arange(gc.size))
        favour = ((cost_fg - cost_bg) if last.fg else (cost_bg - cost_fg)).reshape(gc.shape)
        reach = _STROKE_REACH if reach is None else reach
        unlike = _unlike(guide.image, *hit, reach)
        sure = (gc == (cv2.GC_BGD if last.fg else cv2.GC_FGD)) | ((favour > _SURE_MARGIN) & unlike)
        region = _flooded(guide.image, ~prior if last.fg else prior, hits, reach, _FLOOD_SMOOTH, sure)
        low = (low | region) if last.fg else (low & ~region)
        # The cut's smoothness also carries pixels to the stroke's side against their own colour (the fence
        # beside a camel's head, a push bar beside the wall a background click clears): a pixel the other
        # side's model explains at least as well moves only if it is like the stroke's colours. What the
        # flood took, up to the image's edges, moves as it is.
        carried = (low != prior) & ~region & (gc != (cv2.GC_FGD if last.fg else cv2.GC_BGD)) & (favour >= 0) & unlike
        low = np.where(carried, prior, low)
        if last.fg:
            low |= _along(guide.image, ~prior & (gc != cv2.GC_BGD), hit, reach, region)
    if not strokes[-1].fg:
        low = _restored(terms, models, prior, low, gc)
    if hit is not None:
        low = _keep_connected(low, prior, *hit, _NEAR_GRID)
    return low, models


def _restored(terms: _Terms, models: np.ndarray, prior: np.ndarray, low: np.ndarray, gc: np.ndarray) -> np.ndarray:
    """A background stroke's label with the thin parts it cut off only for want of their neighbours given back.

    The stroke's re-cut learns its models from the label before the stroke,
    in which the region it was drawn on (a mug standing in the box) is still
    the object's: those models cannot tell that region from the object, and
    the stroke's pixels alone move the cut. A long thin part lying on the
    region (a knife's handle across the mug) then goes with it, though its
    colours are the object's: keeping it costs its whole outline against
    the region, which its few pixels' data does not pay (graph cuts'
    shrinking bias, worst where the grid leaves a part a few pixels wide).
    The next iteration's models, learnt on the label after the stroke, place
    the region on the background's side and the part on the object's. So the
    pixels the stroke removed that those models favour as object by more
    than ``_SURE_MARGIN`` nats (not the strokes' own, ``GC_BGD`` in ``gc``)
    are given back, joined to the label, where they make a thin part: at
    least ``_LONG`` times as long as wide (its pixels at least ``_LONG``
    times the square of its width, twice its largest distance to its edge).
    A wider or shorter piece (a blob of wall the colour of a white chair, a
    strip along the new edge, a few pixels of fur) stays removed: the cut's
    edge there is the pairwise term's call, not its bias.

    Args:
        terms: The ROI's terms.
        models: The re-cut's models.
        prior: The label before the stroke.
        low: The label after it (within ``prior``).
        gc: The re-cut's GC_* labels after its cut.

    Returns:
        bool ``(h, w)``: ``low`` with those parts back.
    """
    flat = low.ravel()
    removed = np.flatnonzero((prior & ~low).ravel() & (gc.ravel() != cv2.GC_BGD))
    if not len(removed) or not flat.any():
        return low
    cost_bg, cost_fg = terms.costs(terms.learn(~flat, flat, models), removed)
    back = np.zeros(flat.size, bool)
    back[removed[cost_bg - cost_fg > _SURE_MARGIN]] = True
    # Closed (a 3x3 closing, within what the stroke removed), so a few pixels of noise do not make a wide part thin.
    back = cv2.morphologyEx(back.reshape(low.shape).view(np.uint8), cv2.MORPH_CLOSE, np.ones((3, 3), np.uint8))
    back = (_joined(back.view(bool) & prior, low) & ~low).view(np.uint8)
    count, parts = cv2.connectedComponents(back, connectivity=8)
    half = cv2.distanceTransform(np.pad(back, 1), cv2.DIST_L2, 3)[1:-1, 1:-1]
    widest = np.zeros(count)
    np.maximum.at(widest, parts.ravel(), half.ravel())
    thin = np.bincount(parts.ravel(), minlength=count) >= _LONG * (2 * widest) ** 2
    thin[0] = False
    return low | thin[parts]


def _unlike(image: np.ndarray, crop: np.ndarray, origin: tuple[int, int], reach: int) -> np.ndarray:
    """The grid's pixels unlike the colours under a stroke (``fine._like``), tested within ``reach`` of it.

    Pixels further away, and all of them under a stroke of fewer than 2
    pixels, count as unlike.

    The flood stops at pixels the other label's colour model clearly
    prefers, but that model, learnt from the whole box, often holds the very
    colours the stroke was drawn on (a goat's white leg and the white rocks
    behind it, a driver's arm and the wall): a pixel like the stroke's own
    colours is no sure sign of the other label, so it does not stop the flood
    (it may still be cut off by the image's edges).
    """
    y0, x0 = origin
    pixels = image[y0 : y0 + crop.shape[0], x0 : x0 + crop.shape[1]][crop]
    unlike = np.ones(image.shape[:2], bool)
    if len(pixels) >= 2:
        r0, c0 = max(0, y0 - reach), max(0, x0 - reach)
        window = image[r0 : y0 + crop.shape[0] + reach, c0 : x0 + crop.shape[1] + reach]
        unlike[r0 : r0 + window.shape[0], c0 : c0 + window.shape[1]] = ~_like(pixels, window).reshape(window.shape[:2])
    return unlike


def _along(image: np.ndarray, against: np.ndarray, hit: tuple[np.ndarray, tuple[int, int]], reach: int,
           region: np.ndarray) -> np.ndarray:
    """The thin part of an object stroke's colour that runs along the stroke (a leg, a pole), or nothing.

    A click on a long missed part (a leg on a road) lies along it: the
    labelling page's stroke is dragged along the part. The flood stops where
    the part is narrow on the grid (both its edges blur into one ridge of the
    gradient, which the other side's seeds cross first), so it took little
    more than a disk around the stroke. Here the pixels like the stroke's
    colours (``fine._like``) that are labelled against it, joined to it, are
    followed within a strip along the stroke's long axis, ``_ALONG_WIDTH``
    times the part's half-width at the stroke each side of it. That is taken
    only when the part is thin there: its half-width is at most
    ``_ALONG_HALF`` grid pixels (the grid is the ROI's, so a part thin beside
    the object: a white chair's seat before a white wall is not), and at least
    ``_ALONG_SHARE`` of the part of the stroke's colour joined to it lies in
    the strip (on ground of the stroke's colour the part spreads beyond it,
    and nothing is taken).

    Args:
        image: uint8 ``(h, w, 3)`` RGB of the grid.
        against: bool ``(h, w)``, the pixels the stroke may give its label.
        hit: The stroke's footprint on the grid, ``(crop, (y, x))``.
        reach: Nothing further than this many grid pixels from the stroke is taken.
        region: bool ``(h, w)``, what the stroke already took (``_flooded``): the part may join through it.

    Returns:
        bool ``(h, w)``: the pixels taken (all of ``against``).
    """
    crop, (y0, x0) = hit
    h, w = against.shape
    taken = np.zeros_like(against)
    ys, xs = np.nonzero(crop)
    if len(ys) < 3:
        return taken
    spread, axes = np.linalg.eigh(np.cov(np.stack([ys, xs]).astype(np.float64)))
    if spread[1] < 2 * max(spread[0], 1e-6):
        return taken  # a dot: no direction
    r0, r1 = max(0, y0 - reach), min(h, y0 + crop.shape[0] + reach)
    c0, c1 = max(0, x0 - reach), min(w, x0 + crop.shape[1] + reach)
    window = image[r0:r1, c0:c1]
    stroke = image[y0 : y0 + crop.shape[0], x0 : x0 + crop.shape[1]][crop]
    like = _like(stroke, window).reshape(window.shape[:2]) & against[r0:r1, c0:c1]
    ys, xs = ys + y0 - r0, xs + x0 - c0
    on = np.zeros(like.shape, bool)
    on[ys, xs] = True
    part = _joined(like, on)
    half = max(1.0, float(cv2.distanceTransform(part.view(np.uint8), cv2.DIST_L2, 3)[on].max()))
    if half > _ALONG_HALF:
        return taken  # no thin part: a region of the stroke's colour
    dy, dx = axes[:, 1]
    gy, gx = np.mgrid[0 : like.shape[0], 0 : like.shape[1]]
    strip = np.abs((gy - ys.mean()) * dx - (gx - xs.mean()) * dy) <= _ALONG_WIDTH * half
    along = _joined(like & strip, on | region[r0:r1, c0:c1]) & like & strip
    if np.count_nonzero(along) < _ALONG_SHARE * np.count_nonzero(part):
        return taken
    taken[r0:r1, c0:c1] = along
    return taken


def _flooded(image: np.ndarray, against: np.ndarray, hits: list[tuple[np.ndarray, tuple[int, int], bool]],
             reach: int, smooth: float, sure: np.ndarray | None = None) -> np.ndarray:
    """The region of the last stroke's other side that it floods up to the image's edges (a watershed).

    A click flips the whole error region it lands in when that region is
    bounded by edges, not just the stroke's pixels (Bai & Sapiro 2007,
    Gulshan et al. 2010: a competition between seeds over the image's
    edges). Near the stroke, the pixels labelled against it (``against``)
    are flooded over the colour gradient from two sides: from
    the stroke (and the earlier strokes of its label), and from what is
    surely of that other label: its pixels ``_FLOOD_SCALE`` times the
    stroke's depth inside its region away (the depth: the distance from the
    stroke to the nearest pixel of its own label), or ``reach`` away, the
    other label's strokes, and ``sure`` pixels. The stroke keeps what it
    reaches first, so the two meet on the strongest edge between them.

    Args:
        image: uint8 ``(h, w, 3)`` RGB of the grid.
        against: bool ``(h, w)``, the pixels labelled against the stroke before it.
        hits: Every stroke's footprint on the grid, ``(crop, (y, x), same)``,
            the new stroke first; ``same``: of the new stroke's label.
        reach: The flood's most distance from the stroke, grid pixels.
        smooth: Gaussian sigma of the colours before the gradient, grid pixels.
        sure: bool ``(h, w)`` pixels surely of the other label, or None.

    Returns:
        bool ``(h, w)``: the pixels the stroke floods (all labelled against it).
    """
    crop, (y0, x0), _ = hits[0]
    h, w = against.shape
    r0, r1 = max(0, y0 - reach), min(h, y0 + crop.shape[0] + reach)
    c0, c1 = max(0, x0 - reach), min(w, x0 + crop.shape[1] + reach)
    other = against[r0:r1, c0:c1]
    markers = np.zeros(other.shape, np.int32)
    frame = np.zeros(other.shape, bool)
    frame[[0, -1], :] = frame[:, [0, -1]] = True
    on = np.zeros(other.shape, np.uint8)
    ys, xs = np.nonzero(crop)
    ys, xs = ys + y0 - r0, xs + x0 - c0
    inside = (ys >= 0) & (ys < other.shape[0]) & (xs >= 0) & (xs < other.shape[1])
    on[ys[inside], xs[inside]] = 1
    from_stroke = cv2.distanceTransform(1 - on, cv2.DIST_L2, 3)
    depth = cv2.distanceTransform(np.pad(other, 1).view(np.uint8), cv2.DIST_L2, 3)[1:-1, 1:-1]
    rho = float(depth[on.view(bool) | (from_stroke <= 1.5)].max())
    frame |= from_stroke >= max(_FLOOD_MIN, _FLOOD_SCALE * rho)
    markers[frame & other] = 2
    if sure is not None:
        markers[sure[r0:r1, c0:c1] & other] = 2
    for sc, (sy, sx), same in hits[::-1]:
        ys, xs = np.nonzero(sc)
        ys, xs = ys + sy - r0, xs + sx - c0
        inside = (ys >= 0) & (ys < other.shape[0]) & (xs >= 0) & (xs < other.shape[1])
        markers[ys[inside], xs[inside]] = 1 if same else 2
    region = np.zeros_like(against)
    if not (markers == 2).any():
        return region
    lab = cv2.cvtColor(image[r0:r1, c0:c1], cv2.COLOR_RGB2LAB).astype(np.float32)
    lab = cv2.GaussianBlur(lab, (0, 0), smooth)
    gx, gy = cv2.Sobel(lab, cv2.CV_32F, 1, 0), cv2.Sobel(lab, cv2.CV_32F, 0, 1)
    gradient = np.sqrt((gx * gx + gy * gy).sum(axis=2))
    flood = watershed(gradient, markers, mask=other | (markers == 1))
    region[r0:r1, c0:c1] = (flood == 1) & other
    return region


def _keep_connected(new: np.ndarray, old: np.ndarray, crop: np.ndarray, origin: tuple[int, int],
                    near: int, reach: int | None = None) -> np.ndarray:
    """``new`` where it changed in a part connected to a stroke, ``old`` elsewhere.

    A stroke's effect is local: a pixel may take a new label only if it lies
    within ``near`` pixels of the stroke's footprint (``crop`` placed at
    ``origin``, ``(y, x)``), or is joined to such a pixel through pixels that
    changed too (8-connected). Every other pixel keeps its label, so a
    background stroke never drops a far part (the tip of a handle) whose
    label the re-estimated models happen to flip.

    Args:
        new: bool ``(h, w)``, the label after the stroke.
        old: bool ``(h, w)``, the label before it.
        crop: bool, the stroke's footprint on this grid.
        origin: ``(y, x)`` of ``crop`` on the grid.
        near: The stroke's neighbourhood, pixels beyond its footprint.
        reach: Nothing further than this many pixels from the footprint
            changes (None: no such limit).

    Returns:
        bool ``(h, w)`` (``new`` itself when nothing had to be kept).
    """
    changed = new != old
    if reach is not None:
        # Nothing further than ``reach`` from the stroke's footprint (a window around it) changes.
        y0, x0 = origin
        window = np.zeros_like(changed)
        window[max(0, y0 - reach) : y0 + crop.shape[0] + reach, max(0, x0 - reach) : x0 + crop.shape[1] + reach] = True
        changed &= window
    kept = np.zeros_like(changed)
    rows, cols = np.flatnonzero(changed.any(axis=1)), np.flatnonzero(changed.any(axis=0))
    if len(rows):
        # Only the changed pixels' bounding box matters: no changed part leaves it.
        r0, r1, c0, c1 = int(rows[0]), int(rows[-1]) + 1, int(cols[0]), int(cols[-1]) + 1
        count, parts = cv2.connectedComponents(changed[r0:r1, c0:c1].view(np.uint8), connectivity=8)
        # The footprint grown by ``near`` (a dilation), on that box padded by ``near``.
        y0, x0 = origin
        hh, ww = r1 - r0 + 2 * near, c1 - c0 + 2 * near
        ys, xs = np.nonzero(crop)
        ys, xs = ys + y0 - r0 + near, xs + x0 - c0 + near
        inside = (ys >= 0) & (ys < hh) & (xs >= 0) & (xs < ww)
        seed = np.zeros((hh, ww), np.uint8)
        seed[ys[inside], xs[inside]] = 1
        if near > 0:
            seed = cv2.dilate(seed, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * near + 1, 2 * near + 1)))
        seed = seed[near : hh - near, near : ww - near].view(bool)
        joined = np.zeros(count, bool)
        joined[parts[seed]] = True
        joined[0] = False
        kept[r0:r1, c0:c1] = joined[parts]
    if np.array_equal(kept, new != old):
        return new
    return np.where(kept, new, old)


# ------------------------------------------------------------- with depth


def _depth_first_models(guide: _DepthGuide, gc: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """``(2, 105)`` first models of a box: from its ``GC_BGD`` and ``GC_PR_FGD`` pixels."""
    x = guide.features.reshape(-1, 4)
    valid = guide.valid.ravel()
    flat = gc.ravel()
    fallback = _fallback_z(guide)
    return np.stack([_first_model(x[flat == side], valid[flat == side], fallback, rng)
                     for side in (cv2.GC_BGD, cv2.GC_PR_FGD)])


def _depth_box_cut(frame: np.ndarray, depth: np.ndarray, guide: _DepthGuide,
                   gc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``_box_cut`` with depth: first models, the cut, and a rescue for a box it keeps little of.

    The rescue is ``_rescue``'s first step: a background model from the frame
    outside the box (colour and depth), held fixed with the first foreground
    model; the cut that keeps more wins.
    """
    geom = guide.geom
    rows, cols = geom.box_low()
    rng = np.random.default_rng(0)
    start = gc.copy()
    coarse = _coarse(geom)
    graph = small = None
    if coarse is not None:
        small_geom, small_gc = coarse
        small = _DepthGuide.build(small_geom, _resize(frame, small_geom), depth)
        initial = _depth_first_models(small, small_gc, rng)
        low, models = _coarse_to_fine(_Terms.depth(guide), geom, gc, _Terms.depth(small), small_gc.copy(), initial,
                                      _BOX_ITERATIONS)
    else:
        initial = _depth_first_models(guide, gc, rng)
        graph = _graph_for(_Terms.depth(guide), gc)
        low, models = _cut(_Terms.depth(guide), gc, initial, _BOX_ITERATIONS, graph=graph)
    if low[rows, cols].mean() >= _SPARSE:
        return low, models
    z = _outside_sample(depth[..., None], geom)[:, 0]
    valid = np.isfinite(z)
    x = np.concatenate([_outside_sample(frame, geom).astype(np.float64),
                        np.where(valid, z * _Z_SCALE, 0.0)[:, None]], axis=1)
    bgd = _first_model(x, valid, _fallback_z(guide), rng)
    held = np.stack([bgd, initial[1]])
    if small is None:
        rescued = _cut(_Terms.depth(guide), start, held, 1, frozen=True, graph=graph)
    else:
        # On the coarse grid first, then within ``_FINE_BAND`` of its edge on the full one.
        small_low = _cut(_Terms.depth(small), coarse[1], held, 1, frozen=True)[0]
        rescued = _cut(_Terms.depth(guide), _upsampled_labels(geom, small_low), held, 1, frozen=True)
    return max([(low, models), rescued], key=lambda c: np.count_nonzero(c[0]))


# ------------------------------------------------------------- from a mask


def _seed_labels(geom: _Geometry, seed: np.ndarray, band: int) -> np.ndarray:
    """The GC_* labels of a cut from a mask: its edge may move by ``band`` grid pixels.

    Inside the box, the seed is probable foreground and the rest probable
    background; with ``band`` > 0, the seed eroded by ``band`` is sure
    foreground and what lies beyond it dilated by ``band`` sure background.
    Outside the box everything is background.
    """
    rows, cols = geom.box_low()
    inside = np.where(seed, cv2.GC_PR_FGD, cv2.GC_PR_BGD).astype(np.uint8)
    if band > 0:
        kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * band + 1, 2 * band + 1))
        u8 = seed.view(np.uint8)
        inside[cv2.erode(u8, kernel, borderType=cv2.BORDER_REPLICATE).view(bool)] = cv2.GC_FGD
        inside[~cv2.dilate(u8, kernel).view(bool)] = cv2.GC_BGD
    gc = np.full(seed.shape, cv2.GC_BGD, np.uint8)
    gc[rows, cols] = inside[rows, cols]
    return gc


def _seed_cut(terms: _Terms, geom: _Geometry, seed: np.ndarray, band: int,
              first: Callable[[np.ndarray], np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Models (and, with ``band`` > 0, a cut) for an object given as a mask.

    The models start from k-means on each side of the seed (``first``, given
    labels with the seed as ``GC_PR_FGD`` and the rest as ``GC_BGD``) and
    take one learning step on it, so the next stroke re-cuts with models of
    this object. With ``band`` > 0 the cut then runs from the seed as a box's
    does (``_seed_labels``), so its edge can move to the image's.

    Args:
        terms: The ROI's terms.
        geom: The ROI's geometry.
        seed: bool ``(low_h, low_w)``, the mask on the grid (both sides non-empty).
        band: How far the cut may move the seed's edge, grid pixels (0: not at all).
        first: First models from such labels.

    Returns:
        ``(label, models)``: the seed itself when ``band`` is 0.
    """
    models = first(np.where(seed, cv2.GC_PR_FGD, cv2.GC_BGD).astype(np.uint8))
    models = terms.learn(~seed.ravel(), seed.ravel(), models)
    if band <= 0:
        return seed.copy(), models
    return _cut(terms, _seed_labels(geom, seed, band), models, _BOX_ITERATIONS)
