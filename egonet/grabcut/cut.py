"""The graph cut at the work size: a box's first cut, its rescue, and re-cuts.

The cut runs on the ROI at low resolution (``_Guide.image``) with
``cv2.grabCut`` in ``GC_EVAL`` mode and colour models the session keeps
between calls, so a stroke costs one re-estimation and one cut. Results are
bool labels on the ROI's low-resolution grid; ``refine`` brings them back to
full resolution.

With depth (``_depth_box_cut``, ``_depth_recut``) the same steps run on the
colour-plus-depth models of ``depth`` with the session's own minimum cut
(PyMaxflow), which is also faster where it can be: only undecided pixels are
nodes, a box's first iterations run on a grid of half the size, and a stroke
re-cuts only the side of the label it can change.
"""

from __future__ import annotations

import math

import cv2
import maxflow
import numpy as np

from egonet.grabcut.colour import _first_models, _fit_model
from egonet.grabcut.depth import (_GAMMA, _Z_SCALE, _component_scores, _DepthGuide, _fallback_z, _first_model,
                                  _fit_components, _neg_log_likelihood)
from egonet.grabcut.geometry import _Geometry
from egonet.grabcut.refine import _Guide
from egonet.grabcut.strokes import _Stroke

_BOX_ITERATIONS = 5  # graph-cut iterations for a new box (as plain GC_INIT_WITH_RECT)
_STROKE_ITERATIONS = 1  # re-estimation + cut per stroke
_CONVERGED = 0.005  # stop iterating when a cut changes at most this fraction of undecided pixels
_SPARSE = 0.25  # a box whose first cut keeps less than this fraction of it is cut again (``_rescue``)
_OUTSIDE_SAMPLES = 100_000  # most frame pixels read for the background model of that cut


def _cut(image: np.ndarray, gc: np.ndarray, models: np.ndarray, iterations: int) -> tuple[np.ndarray, np.ndarray]:
    """Run the graph cut on the low-resolution ROI.

    Each iteration re-estimates the colour models from the current labels
    (starting from ``models``, so their components carry over) and cuts.
    Stops early once an iteration changes at most ``_CONVERGED`` of the
    undecided pixels: later iterations only nudge the boundary.

    Args:
        image: uint8 ``(h, w, 3)`` low-resolution ROI.
        gc: uint8 ``(h, w)`` OpenCV GC_* labels; updated in place.
        models: ``(2, 65)`` background and foreground models.
        iterations: Most iterations to run.

    Returns:
        ``(label, models)``: the bool foreground label and the new models.
    """
    bgd = models[0:1].copy()
    fgd = models[1:2].copy()
    undecided = max(1, np.count_nonzero(gc >= cv2.GC_PR_BGD))
    for _ in range(iterations):
        is_fg = (gc & 1).astype(bool)
        # Re-estimating a model from no pixels is undefined (OpenCV asserts),
        # so the models stay fixed when one side is empty.
        mode = cv2.GC_EVAL if is_fg.any() and not is_fg.all() else cv2.GC_EVAL_FREEZE_MODEL
        cv2.grabCut(image, gc, None, bgd, fgd, 1, mode)
        if mode != cv2.GC_EVAL or np.count_nonzero(is_fg != (gc & 1)) <= _CONVERGED * undecided:
            break
    return (gc & 1).astype(bool), np.concatenate([bgd, fgd])


def _box_labels(geom: _Geometry) -> np.ndarray:
    """The GC_* labels a box starts from: ``GC_PR_FGD`` on the box, ``GC_BGD`` around it."""
    gc = np.full((geom.low_h, geom.low_w), cv2.GC_BGD, np.uint8)
    rows, cols = geom.box_low()
    gc[rows, cols] = cv2.GC_PR_FGD
    return gc


def _box_cut(frame: np.ndarray, guide: _Guide, gc: np.ndarray, work_size: int) -> tuple[np.ndarray, np.ndarray]:
    """A new box's cut, from first models; a box it keeps little of is cut again (``_rescue``).

    Args:
        frame: Full frame, uint8 ``(H, W, 3)``.
        guide: The low-resolution guide of the box's ROI.
        gc: The box's labels (``_box_labels``), with some background; updated in place.
        work_size: The session's work size.

    Returns:
        ``(label, models)``: the bool low-resolution label and the ``(2, 65)`` models.
    """
    rows, cols = guide.geom.box_low()
    # Initial colour models from k-means on a fixed-seed sample of each side
    # (plain grabCut runs k-means on every pixel, which is most of its cost).
    initial = _first_models(guide.image, gc, np.random.default_rng(0))
    start = gc.copy()
    low, models = _cut(guide.image, gc, initial, _BOX_ITERATIONS)
    if low[rows, cols].mean() < _SPARSE:
        low, models = _rescue(frame, guide, start, initial, low, models, work_size)
    return low, models


def _rescue(frame: np.ndarray, guide: _Guide, start: np.ndarray, initial: np.ndarray, low: np.ndarray,
            models: np.ndarray, work_size: int) -> tuple[np.ndarray, np.ndarray]:
    """Cut a box whose first cut kept little of it again; the cut that keeps most wins.

    That usually happens when the box cuts through an object that goes on
    into the margin: the margin's colours, the background model, then
    include the object's. Plain grabCut takes its background from the whole
    frame outside the box, where that continuation is a small part. So:
    first one cut with such a background model held fixed (and the box's
    first foreground model); if that too keeps little, plain grabCut on the
    whole frame at the work size, brought onto the ROI's grid.

    Args:
        frame: Full frame, uint8 ``(H, W, 3)``.
        guide: The low-resolution guide of the box's ROI.
        start: The box's labels before the first cut.
        initial: The first cut's initial ``(2, 65)`` models.
        low: The first cut's label.
        models: The first cut's models.
        work_size: The session's work size.
    """
    geom = guide.geom
    box = geom.box
    rows, cols = geom.box_low()
    h, w = frame.shape[:2]
    rng = np.random.default_rng(0)
    step = max(1, round(1 / min(geom.sx, geom.sy)), math.ceil(math.sqrt(h * w / _OUTSIDE_SAMPLES)))
    outside = np.ones((h, w), bool)
    outside[box[1] : box[3], box[0] : box[2]] = False
    bgd = _fit_model(frame[::step, ::step][outside[::step, ::step]], rng)
    fgd = initial[1:2].copy()
    gc = start.copy()
    cv2.grabCut(guide.image, gc, None, bgd, fgd, 1, cv2.GC_EVAL_FREEZE_MODEL)
    candidates = [(low, models), ((gc & 1).astype(bool), np.concatenate([bgd, fgd]))]
    if candidates[1][0][rows, cols].mean() < _SPARSE:
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
    image = cv2.resize(frame, (whole.low_w, whole.low_h), interpolation=cv2.INTER_AREA)
    gc = _box_labels(whole)
    if not (gc == cv2.GC_BGD).any():
        return None
    cut, whole_models = _cut(image, gc, _first_models(image, gc, rng), _BOX_ITERATIONS)
    full = cv2.resize(cut.view(np.uint8), (w, h), interpolation=cv2.INTER_NEAREST)
    rx0, ry0, rx1, ry1 = geom.roi
    share = cv2.resize(full[ry0:ry1, rx0:rx1] * np.uint8(255), (geom.low_w, geom.low_h),
                       interpolation=cv2.INTER_AREA)
    return share >= 128, whole_models


def _recut(guide: _Guide, models: np.ndarray, strokes: tuple[_Stroke, ...],
           prior: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cut again with ``strokes`` as hard labels, starting from the label ``prior``.

    Returns:
        ``(label, models)``. The label moves only the last stroke's way from
        ``prior`` (see ``GrabCutSession.stroke``).
    """
    gc = _stroke_labels(guide, strokes, prior)
    low, models = _cut(guide.image, gc, models, _STROKE_ITERATIONS)
    # A stroke only moves the label its own way (see ``GrabCutSession.stroke``).
    low = (low | prior) if strokes[-1].fg else (low & prior)
    return low, models


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


# ------------------------------------------------------------- with depth
#
# ``cv2.grabCut`` takes 8-bit colour only, so with depth the session runs its
# own graph cut (PyMaxflow) over the colour-plus-depth models of ``depth``,
# in the same steps: iterations of re-estimation and cut for a box, one per
# stroke.

_HARD = 9 * _GAMMA  # a terminal weight no cut pays (as OpenCV: 9 * gamma)
_COARSE_MIN = 32  # a box's first iterations run at half the grid when that is at least this many pixels a side


def _depth_cut(guide: _DepthGuide, gc: np.ndarray, models: np.ndarray, iterations: int,
               *, frozen: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """``_cut`` with depth: re-estimate the colour-plus-depth models, then cut.

    Args:
        guide: The ROI's features and pairwise weights.
        gc: uint8 ``(h, w)`` OpenCV GC_* labels; updated in place. Only the
            undecided pixels (``GC_PR_*``) are cut; ``GC_BGD``/``GC_FGD``
            ones stay as they are.
        models: ``(2, 105)`` background and foreground models.
        iterations: Most iterations to run (stops early as ``_cut`` does).
        frozen: Keep ``models`` as given (no re-estimation).

    Returns:
        ``(label, models)``: the bool foreground label and the new models.
    """
    x = guide.features.reshape(-1, 4)
    valid = guide.valid.ravel()
    flat = gc.reshape(-1)
    free = np.flatnonzero(flat >= cv2.GC_PR_BGD)
    fallback = _fallback_z(guide)
    bgd, fgd = models[0].copy(), models[1].copy()
    for _ in range(iterations):
        is_fg = (flat & 1).astype(bool)
        learn = not frozen and is_fg.any() and not is_fg.all()
        if learn:
            # Each pixel joins its most likely component of its own side; the
            # models are refitted from those (OpenCV's learning step).
            bg, fg = ~is_fg, is_fg
            bgd = _fit_components(x[bg], valid[bg], _component_scores(bgd, x[bg], valid[bg]).argmax(axis=1),
                                  fallback)
            fgd = _fit_components(x[fg], valid[fg], _component_scores(fgd, x[fg], valid[fg]).argmax(axis=1),
                                  fallback)
        before = flat[free] & 1
        xf, vf = x[free], valid[free]
        _maxflow(guide, flat, free, _neg_log_likelihood(_component_scores(bgd, xf, vf)),
                 _neg_log_likelihood(_component_scores(fgd, xf, vf)))
        if not learn or np.count_nonzero(before != (flat[free] & 1)) <= _CONVERGED * max(1, len(free)):
            break
    return (gc & 1).astype(bool), np.stack([bgd, fgd])


def _maxflow(guide: _DepthGuide, flat: np.ndarray, free: np.ndarray, cost_bg: np.ndarray,
             cost_fg: np.ndarray) -> None:
    """One minimum cut over the pixels ``free``; they become GC_PR_FGD or GC_PR_BGD in ``flat``.

    Only the free pixels are nodes: a link to a fixed neighbour always
    costs its weight when the free pixel takes the other label, so it is
    folded into that pixel's terminal weights (the same minimum cut on a
    smaller graph; the box's margin alone is a third of the ROI).

    Args:
        guide: The ROI's pairwise links (``guide.links``).
        flat: uint8 GC_* labels of the ROI, flattened; updated in place.
        free: Flat indices of the pixels to cut.
        cost_bg: ``-log p`` of each free pixel under the background model.
        cost_fg: The same under the foreground model.
    """
    n = len(free)
    if n == 0:
        return
    node = np.full(flat.size, -1, np.int64)
    node[free] = np.arange(n)
    # Source = foreground: a pixel cut from the source (background) pays its
    # source capacity, so that is its cost as background, and vice versa.
    shift = np.minimum(cost_bg, cost_fg)  # only the difference matters; keeps capacities small
    source = cost_bg - shift
    sink = cost_fg - shift
    p, q, weight = guide.links
    np_, nq = node[p], node[q]
    both = (np_ >= 0) & (nq >= 0)
    for a, b in ((np_, q), (nq, p)):
        # A free pixel linked to a fixed one: pays the link if it takes the other label.
        one = (a >= 0) & (node[b] < 0)
        fixed_fg = (flat[b[one]] & 1).astype(bool)
        source += np.bincount(a[one][fixed_fg], weight[one][fixed_fg], minlength=n)
        sink += np.bincount(a[one][~fixed_fg], weight[one][~fixed_fg], minlength=n)
    graph = maxflow.Graph[float](n, int(np.count_nonzero(both)))
    ids = graph.add_nodes(n)
    graph.add_edges(np_[both], nq[both], weight[both], weight[both])
    graph.add_grid_tedges(ids, source, sink)
    graph.maxflow()
    is_bg = graph.get_grid_segments(ids)
    flat[free] = np.where(is_bg, cv2.GC_PR_BGD, cv2.GC_PR_FGD)


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
    coarse = _Geometry(geom.box, geom.roi, max(1, round(geom.low_w / 2)), max(1, round(geom.low_h / 2)))
    coarse_gc = _box_labels(coarse)
    if min(coarse.low_w, coarse.low_h) >= _COARSE_MIN and (coarse_gc == cv2.GC_BGD).any():
        # The models settle over the first iterations, on a grid of half the
        # size (a quarter of the pixels); the last iteration re-estimates and
        # cuts on the full grid, starting from the coarse label.
        rx0, ry0, rx1, ry1 = geom.roi
        image = cv2.resize(frame[ry0:ry1, rx0:rx1], (coarse.low_w, coarse.low_h), interpolation=cv2.INTER_AREA)
        small = _DepthGuide.build(coarse, image, depth)
        initial = _depth_first_models(small, coarse_gc, rng)
        coarse_low, start_models = _depth_cut(small, coarse_gc, initial, _BOX_ITERATIONS - 1)
        up = cv2.resize(coarse_low.astype(np.float32), (geom.low_w, geom.low_h), interpolation=cv2.INTER_LINEAR)
        gc[rows, cols] = np.where(up[rows, cols] >= 0.5, cv2.GC_PR_FGD, cv2.GC_PR_BGD)
        low, models = _depth_cut(guide, gc, start_models, 1)
    else:
        initial = _depth_first_models(guide, gc, rng)
        low, models = _depth_cut(guide, gc, initial, _BOX_ITERATIONS)
    if low[rows, cols].mean() >= _SPARSE:
        return low, models
    h, w = frame.shape[:2]
    box = geom.box
    step = max(1, round(1 / min(geom.sx, geom.sy)), math.ceil(math.sqrt(h * w / _OUTSIDE_SAMPLES)))
    outside = np.ones((h, w), bool)
    outside[box[1] : box[3], box[0] : box[2]] = False
    outside = outside[::step, ::step]
    z = depth[::step, ::step][outside]
    valid = np.isfinite(z)
    x = np.concatenate([frame[::step, ::step][outside].astype(np.float64),
                        np.where(valid, z * _Z_SCALE, 0.0)[:, None]], axis=1)
    bgd = _first_model(x, valid, _fallback_z(guide), rng)
    rescued = _depth_cut(guide, start, np.stack([bgd, initial[1]]), 1, frozen=True)
    return max([(low, models), rescued], key=lambda c: np.count_nonzero(c[0]))


def _depth_recut(guide: _DepthGuide, models: np.ndarray, strokes: tuple[_Stroke, ...], prior: np.ndarray,
                 footprints: _Guide) -> tuple[np.ndarray, np.ndarray]:
    """``_recut`` with depth (``footprints`` gives the strokes' low-resolution pixels)."""
    gc = _stroke_labels(footprints, strokes, prior)
    # The label only moves the stroke's way (see ``GrabCutSession.stroke``),
    # so the pixels on the other side stay fixed: a foreground stroke cuts
    # only the background pixels again, a background stroke only the
    # foreground ones, on a graph of those alone.
    if strokes[-1].fg:
        gc[gc == cv2.GC_PR_FGD] = cv2.GC_FGD
    else:
        gc[gc == cv2.GC_PR_BGD] = cv2.GC_BGD
    low, models = _depth_cut(guide, gc, models, _STROKE_ITERATIONS)
    low = (low | prior) if strokes[-1].fg else (low & prior)
    return low, models
