"""Carry one object's mask to an adjacent frame of the same sequence.

``propagate(prev_rgb, prev_mask, next_rgb)`` returns the object's mask on
``next_rgb``. "Adjacent" means the next or the previous frame of a video (the
function is symmetric: it does not know which way time runs), so the object
moved a little: at 30 fps a hand-held object moves up to a few tens of pixels
and turns by a few degrees.

How, all inside one region of interest (ROI) at a reduced work size:

1. The ROI is the object's box in ``prev_rgb`` plus a margin of half its size
   (at least 5 % of the frame), the same rectangle in both frames: the object
   cannot move further than that between adjacent frames.
2. Motion: OpenCV's DIS optical flow on the grey ROIs, scaled so the long side
   is ``_WORK_SIZE`` pixels, from ``next_rgb`` to ``prev_rgb``, so every pixel
   of the next frame knows where it came from and the previous mask is pulled
   over (``cv2.remap``): the warped mask.
3. Refinement: ``cv2.grabCut`` seeded from the warped mask. Its eroded core is
   sure foreground, pixels beyond its dilated border are sure background. In
   the band between, the flow's answer stands where the flow is sure of
   itself (forward and backward flow agree), because where object and
   background look alike a good flow beats a colour model. It stands too
   where the flow is in doubt but agrees with the object's overall motion
   (an affine map fitted to the sure flow inside the object, applied to the
   previous mask): a leg or tail that keeps still while its flow is
   unsure, which the cut would clip off (thin parts cost it little to
   cut). Where the flow is in doubt and parts from the overall motion
   (occlusion, no texture, a smear), and on a one-pixel strip along the
   warped edge, the band is probable foreground inside the warped mask and
   probable background outside it, and the cut decides. The
   colour models are fitted on the previous frame with its exact mask (not
   the warp's guess), held for the first cut and re-fitted once, so colours
   the object shows only in the new frame can come in.
4. Depth (optional): where ``next_depth`` is given, depth overrules the flow.
   A pixel whose depth now differs from the depth at the point it came from
   (needs ``prev_depth``) no longer shows the object: probable background,
   colour decides. A pixel whose depth lies well outside the object's depth
   range (from ``prev_depth`` under the mask when given, else from
   ``next_depth`` under the warped core) is sure background, so the flow's
   smear onto a wall or table behind the object is cut away even where it
   has the object's colour. Missing readings (0 or NaN) change nothing.
5. The cut never overrules the flow where the image does not back it: each
   part the cut adds to the warped mask, and each it takes out, is kept
   only when at least half of it lies where the flow is in doubt, on the
   warped edge's strip (when the work grid is the frame's own pixels; on a
   reduced grid the warp's soft edge is finer), or where depth says the
   pixel left the object, and when three quarters of it changed colour
   along the flow towards the cut's side (a pixel taken out became more
   background-like than the point it came from, by more than the usual
   change along the flow's sure tracks; one added, more object-like), or
   lie well inside the object's edge where depth puts them outside its
   range; elsewhere the warped mask stands. A part of the object that looks
   like the background in both frames (a grey shoe on a grey road) keeps
   its colour along the flow, so it is not cut off.
6. Back to full resolution: where the cut agrees with the warp, the warp's
   soft values (sub-pixel); elsewhere the cut, smoothed; upsampled
   bilinearly. On a work grid coarser than the frame, around the cut's
   changes the session's guided filter (:mod:`egonet.grabcut.refine`)
   brings the cut's edge to the next frame's own edges. Then parts smaller
   than 2 % of the largest are dropped (one stray speck would ruin the
   mask's box), unless the flow carried the object there (a tail's tip, a
   foot past a thin ankle). Last, on a coarse grid, a side of the mask's
   box that the cut moved by less than one work-size pixel from the
   flow's is put back where the flow has it: the cut decides whole work
   pixels, the warp's soft values place the edge within one.

A cut that disagrees grossly with the warped mask (overlap below 0.5, or less
than half or more than twice its area) is a cut that failed (colours of the
object and its surroundings too alike), and the warped mask is returned
instead. ``carry`` also says how sure the result is (:class:`Carried`): the
smallest of the flow's consistency on the object, the area kept, the cut's
agreement with the flow and the object's colours kept (a histogram
intersection); below ``UNSURE`` a person should look before carrying on.
An empty ``prev_mask`` has nothing to carry: the result is an empty mask (no
error), so a caller can propagate every instance of a frame blindly.

Example:
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> frame = rng.integers(0, 255, (120, 160, 3)).astype(np.uint8)
    >>> frame[40:80, 50:100] = (220, 40, 40)
    >>> mask = np.zeros((120, 160), bool)
    >>> mask[40:80, 50:100] = True
    >>> moved = np.roll(frame, 6, axis=1)
    >>> out = propagate(frame, mask, moved)
    >>> bool(out[60, 104]), bool(out[60, 52])
    (True, False)
"""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np

from egonet.errors import EgonetError
from egonet.grabcut.colour import _costs, _fit_model
from egonet.grabcut.geometry import _Geometry
from egonet.grabcut.refine import _Guide, _upsample_mask

_WORK_SIZE = 320  # long side of the ROI for flow and cut, pixels
_MARGIN = 0.5  # ROI margin around the object's box, fraction of its long side
_MIN_MARGIN = 0.05  # ... and at least this fraction of the frame's long side
_SEED_RADIUS = 0.08  # how far the cut may move the edge: this fraction of the object's size
_MIN_SEED_RADIUS = 2  # ... and at least this many work-size pixels
_EDGE = 1  # the warped edge's strip the cut always decides, work-size pixels each side
_DOUBT = 1.0  # forward-backward flow miss (work-size pixels) above which the flow is in doubt
_AFFINE_POINTS = 2000  # most flow vectors the object's affine motion is fitted on
_AFFINE_MISS = 1.0  # RANSAC inlier distance for that fit, work-size pixels
_ITERATIONS = 2  # graph cuts: one with the previous frame's models, one re-fitted
_SUPPORT = 0.5  # share of a part the cut changes that must lie where the flow is in doubt
_BACKED = 0.75  # ... and that its colours must have moved towards the cut's side (see _backed)
_NOISE_STRIDE = 2  # the usual colour change along the flow is measured on every 2nd row and column
_SPECK = 0.02  # parts smaller than this fraction of the largest are dropped
_MIN_SAMPLES = 40  # fewest pixels per side to fit a colour model on (5 components)
_DEPTH_TOL_M = 0.08  # depth slack around the object's range (motion, sensor noise), metres
_DEPTH_TOL_REL = 0.04  # ... plus this fraction of the object's depth (noise grows with distance)


@dataclasses.dataclass(frozen=True)
class _Roi:
    """The ROI in both frames and its work-size grid.

    Attributes:
        x0, y0, x1, y1: Full-resolution rectangle (slice convention).
        w, h: Size of the work-size grid.
    """

    x0: int
    y0: int
    x1: int
    y1: int
    w: int
    h: int

    def crop(self, image: np.ndarray, interpolation: int = cv2.INTER_AREA) -> np.ndarray:
        """``image``'s ROI at the work size."""
        part = image[self.y0 : self.y1, self.x0 : self.x1]
        if part.shape[1] == self.w and part.shape[0] == self.h:
            return np.ascontiguousarray(part)
        return cv2.resize(part, (self.w, self.h), interpolation=interpolation)

    @property
    def coarse(self) -> bool:
        """Whether the work grid is coarser than the frame's own pixels."""
        return (self.w, self.h) != (self.x1 - self.x0, self.y1 - self.y0)

    def paste(self, low: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
        """A float work-size map in [0, 1] upsampled into a bool full-frame mask (threshold 0.5)."""
        full = np.zeros(shape, bool)
        w, h = self.x1 - self.x0, self.y1 - self.y0
        up = low if (w, h) == (self.w, self.h) else cv2.resize(low, (w, h), interpolation=cv2.INTER_LINEAR)
        full[self.y0 : self.y1, self.x0 : self.x1] = up >= 0.5
        return full


def _check_rgb(value: object, name: str) -> np.ndarray:
    if not isinstance(value, np.ndarray):
        raise EgonetError(f"{name}: expected a numpy array, got {type(value).__name__}", field=name)
    if value.dtype != np.uint8 or value.ndim != 3 or value.shape[2] != 3:
        raise EgonetError(f"{name}: expected RGB uint8 of shape (H, W, 3), got {value.dtype} {value.shape}",
                          field=name)
    if value.shape[0] < 8 or value.shape[1] < 8:
        raise EgonetError(f"{name}: needs at least 8x8 pixels, got {value.shape[1]}x{value.shape[0]}", field=name)
    return value


def _check_mask(value: object, shape: tuple[int, int]) -> np.ndarray:
    if not isinstance(value, np.ndarray):
        raise EgonetError(f"prev_mask: expected a numpy array, got {type(value).__name__}", field="prev_mask")
    if value.dtype != bool and not np.issubdtype(value.dtype, np.integer):
        raise EgonetError(f"prev_mask: expected bool or 0/1 integers, got {value.dtype}", field="prev_mask")
    if value.shape != shape:
        raise EgonetError(f"prev_mask: expected shape {shape} (prev_rgb's height and width), got {value.shape}",
                          field="prev_mask")
    if value.dtype != bool:
        if ((value != 0) & (value != 1)).any():
            raise EgonetError("prev_mask: integer masks must hold only 0 and 1", field="prev_mask")
        value = value.astype(bool)
    return value


def _check_depth(value: object, name: str, shape: tuple[int, int]) -> np.ndarray | None:
    if value is None:
        return None
    if not isinstance(value, np.ndarray):
        raise EgonetError(f"{name}: expected a numpy array, got {type(value).__name__}", field=name)
    if not np.issubdtype(value.dtype, np.floating):
        raise EgonetError(f"{name}: expected float depth in metres, got {value.dtype} "
                          "(divide millimetre images by 1000)", field=name)
    if value.shape != shape:
        raise EgonetError(f"{name}: expected shape {shape} (the frames' height and width), got {value.shape}",
                          field=name)
    depth = value.astype(np.float32)
    # 0 and NaN both mean "no reading"; negative or infinite depth is garbage, treated the same.
    return np.where(np.isfinite(depth) & (depth > 0), depth, 0).astype(np.float32)


def _roi(box: tuple[int, int, int, int], shape: tuple[int, int]) -> _Roi:
    """The object's box plus the motion margin, clipped, with its work-size grid."""
    x0, y0, x1, y1 = box
    h, w = shape
    m = int(np.ceil(max(_MARGIN * max(x1 - x0, y1 - y0), _MIN_MARGIN * max(h, w))))
    rx0, ry0, rx1, ry1 = max(0, x0 - m), max(0, y0 - m), min(w, x1 + m), min(h, y1 + m)
    scale = min(1.0, _WORK_SIZE / max(rx1 - rx0, ry1 - ry0))
    return _Roi(rx0, ry0, rx1, ry1, max(8, round((rx1 - rx0) * scale)), max(8, round((ry1 - ry0) * scale)))


def _box(mask: np.ndarray) -> tuple[int, int, int, int]:
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    return int(cols[0]), int(rows[0]), int(cols[-1]) + 1, int(rows[-1]) + 1


def _flows(prev_low: np.ndarray, next_low: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Dense flow both ways between the ROIs.

    Args:
        prev_low, next_low: uint8 ``(h, w, 3)`` ROIs at the work size.

    Returns:
        ``(back, forth)``, float32 ``(h, w, 2)`` displacements ``(dx, dy)`` in
        work-size pixels: ``next(p) ~ prev(p + back(p))`` and
        ``prev(q) ~ next(q + forth(q))``.
    """
    dis = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM)
    prev_grey = cv2.cvtColor(prev_low, cv2.COLOR_RGB2GRAY)
    next_grey = cv2.cvtColor(next_low, cv2.COLOR_RGB2GRAY)
    return dis.calc(next_grey, prev_grey, None), dis.calc(prev_grey, next_grey, None)


def _pull(values: np.ndarray, back: np.ndarray, interpolation: int = cv2.INTER_LINEAR) -> np.ndarray:
    """``values`` of the previous ROI brought to the next ROI's pixels along ``back`` (0 off the ROI)."""
    h, w = back.shape[:2]
    gx, gy = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    return cv2.remap(values, gx + back[..., 0], gy + back[..., 1], interpolation,
                     borderMode=cv2.BORDER_CONSTANT, borderValue=0.0)


@dataclasses.dataclass(frozen=True)
class _Warp:
    """What the flow step leaves for the cut.

    Attributes:
        roi: The ROI and its work-size grid.
        prev_low, next_low: uint8 ``(h, w, 3)`` ROIs at the work size.
        prev_mask_low: float32 ``(h, w)``, the previous mask's share of each pixel.
        warped_low: float32 ``(h, w)`` in [0, 1], the previous mask pulled along the flow.
        back: float32 ``(h, w, 2)``, the flow from the next ROI to the previous one.
        mismatch: float32 ``(h, w)``, forward-backward disagreement of the
            flow at each next pixel, work-size pixels: large where the flow
            is unreliable (occlusion, no texture, non-rigid motion).
    """

    roi: _Roi
    prev_low: np.ndarray
    next_low: np.ndarray
    prev_mask_low: np.ndarray
    warped_low: np.ndarray
    back: np.ndarray
    forth: np.ndarray
    mismatch: np.ndarray


def _warp(prev_rgb: np.ndarray, prev_mask: np.ndarray, next_rgb: np.ndarray) -> _Warp:
    """The flow step: ROI, work-size crops, flows, and the warped mask (``prev_mask`` not empty)."""
    roi = _roi(_box(prev_mask), prev_mask.shape)
    prev_low, next_low = roi.crop(prev_rgb), roi.crop(next_rgb)
    # Area averaging keeps the fraction of object in each work-size pixel: a soft edge to warp.
    mask_low = roi.crop(prev_mask.astype(np.float32))
    back, forth = _flows(prev_low, next_low)
    # Going back then forth should return to the start: the miss measures the flow's doubt.
    mismatch = np.linalg.norm(back + _pull(forth, back), axis=2)
    return _Warp(roi, prev_low, next_low, mask_low, _pull(mask_low, back), back, forth, mismatch)


def warp_mask(prev_rgb: np.ndarray, prev_mask: np.ndarray, next_rgb: np.ndarray) -> np.ndarray:
    """The flow step of :func:`propagate` alone: ``prev_mask`` moved by optical flow, no cut.

    A baseline for benchmarks and a fallback; same arguments and checks as
    :func:`propagate` (without depth).

    Returns:
        Bool ``(H, W)`` warped mask.
    """
    prev_rgb = _check_rgb(prev_rgb, "prev_rgb")
    next_rgb = _check_rgb(next_rgb, "next_rgb")
    _check_same_size(prev_rgb, next_rgb)
    prev_mask = _check_mask(prev_mask, prev_rgb.shape[:2])
    if not prev_mask.any():
        return np.zeros(prev_mask.shape, bool)
    warp = _warp(prev_rgb, prev_mask, next_rgb)
    return warp.roi.paste(warp.warped_low, prev_mask.shape)


def _check_same_size(prev_rgb: np.ndarray, next_rgb: np.ndarray) -> None:
    if next_rgb.shape != prev_rgb.shape:
        raise EgonetError(f"next_rgb: expected the size of prev_rgb {prev_rgb.shape}, got {next_rgb.shape}",
                          field="next_rgb")


def _disk(radius: int) -> np.ndarray:
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))


def _affine_moved(warp: _Warp, sure: np.ndarray) -> np.ndarray | None:
    """The previous mask moved by the object's overall motion, or None without enough sure flow.

    An affine map from the next ROI to the previous one, fitted (RANSAC) on
    the flow at ``sure`` pixels, so a limb that moves on its own or a bad
    patch of flow does not bend it.

    Returns:
        float32 ``(h, w)`` in [0, 1], like ``warp.warped_low``.
    """
    ys, xs = np.nonzero(sure)
    if xs.size < _MIN_SAMPLES:
        return None
    step = -(-xs.size // _AFFINE_POINTS)
    xs, ys = xs[::step], ys[::step]
    at = np.stack([xs, ys], axis=1).astype(np.float32)
    affine, _ = cv2.estimateAffine2D(at, at + warp.back[ys, xs], method=cv2.RANSAC,
                                     ransacReprojThreshold=_AFFINE_MISS)
    if affine is None:
        return None
    h, w = sure.shape
    return cv2.warpAffine(warp.prev_mask_low, affine, (w, h), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP)


def _doubt(warp: _Warp) -> np.ndarray:
    """Bool ``(h, w)``: where the flow's answer is in doubt, so the cut should decide.

    The forward-backward miss is above ``_DOUBT`` (or next to such a pixel)
    and the warped mask differs there from the previous mask moved by the
    object's overall motion: two motions that agree are trusted even where
    the flow alone is unsure.
    """
    doubt = cv2.dilate((warp.mismatch > _DOUBT).view(np.uint8), _disk(1)).astype(bool)
    warped = warp.warped_low >= 0.5
    moved = _affine_moved(warp, warped & ~doubt)
    return doubt if moved is None else doubt & (warped != (moved >= 0.5))


def _trimap(warp: _Warp, doubt: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """GC_* seeds from the warped mask: uint8 ``(h, w)`` labels, the bool core and the bool band around the edge.

    The eroded core is sure foreground and pixels beyond the dilated border
    sure background (both by ``_SEED_RADIUS`` of the object's size). In the
    band between, the flow's answer stands except where it is in doubt
    (:func:`_doubt`), since a good flow is better than a colour model where
    object and background look alike; pixels in doubt, and a thin strip
    along the warped edge, are probable foreground inside the warped mask
    and probable background outside: the cut decides those.
    """
    warped = warp.warped_low >= 0.5
    ys, xs = np.nonzero(warped)
    size = max(xs.max() - xs.min() + 1, ys.max() - ys.min() + 1)
    radius = max(_MIN_SEED_RADIUS, round(_SEED_RADIUS * size))
    as_u8 = warped.view(np.uint8)
    reach = cv2.dilate(as_u8, _disk(radius)).astype(bool)
    core = cv2.erode(as_u8, _disk(radius)).astype(bool)
    edge = cv2.morphologyEx(as_u8, cv2.MORPH_GRADIENT, _disk(_EDGE)).astype(bool)
    gc = np.full(warped.shape, cv2.GC_BGD, np.uint8)
    gc[warped] = cv2.GC_FGD
    unsure = reach & ~core & (edge | doubt)
    gc[unsure] = np.where(warped[unsure], cv2.GC_PR_FGD, cv2.GC_PR_BGD)
    return gc, core, reach & ~core


def _depth_range(depth: np.ndarray, where: np.ndarray) -> tuple[float, float] | None:
    """The object's depth range plus slack, or None without enough readings.

    Nearly the whole range (0.5th-99.5th percentile): a handle or a rim is a
    small share of an object's pixels but reaches far in depth, and must not
    fall outside. ``where`` should hold pixels well inside the object, so
    edge pixels that mix in the background's depth do not widen the range.
    """
    values = depth[where & (depth > 0)]
    if values.size < _MIN_SAMPLES:
        return None
    lo, mid, hi = np.percentile(values, (0.5, 50, 99.5))
    slack = _DEPTH_TOL_M + _DEPTH_TOL_REL * float(mid)
    return float(lo) - slack, float(hi) + slack


def _apply_depth(gc: np.ndarray, core: np.ndarray, warp: _Warp, prev_depth: np.ndarray | None,
                 next_depth: np.ndarray) -> None:
    """Let depth overrule the flow and hand pixels to background (``gc`` updated in place).

    * Inside the warped mask, a pixel whose depth now differs from the depth
      at the point it came from (by more than the slack) shows something else
      than the object did: probable background, so colour decides. Needs
      ``prev_depth``.
    * Any pixel whose depth lies outside the object's depth range (with the
      slack) is sure background: the flow's smear onto the wall or table
      behind, even where it has the object's colour. The range comes from
      ``prev_depth`` under the previous mask, else from ``next_depth`` under
      the warped mask's ``core``.

    Missing readings (0) change nothing. The slack (``_DEPTH_TOL_M`` plus
    ``_DEPTH_TOL_REL`` of the depth) covers an object moving towards the
    camera at 30 fps and the sensor's noise, so a sound reading does not
    punch a hole in the object.
    """
    roi = warp.roi
    # Nearest neighbour: averaging depth across an edge makes depths no surface has.
    now = roi.crop(next_depth, cv2.INTER_NEAREST)
    if prev_depth is not None:
        before = roi.crop(prev_depth, cv2.INTER_NEAREST)
        # Work-size pixels wholly inside the mask: no edge pixel mixes in the background's depth.
        span = _depth_range(before, warp.prev_mask_low >= 0.999)
        came = _pull(before, warp.back, cv2.INTER_NEAREST)
        inside = (warp.warped_low >= 0.5) & (now > 0) & (came > 0)
        moved_off = inside & (np.abs(now - came) > _DEPTH_TOL_M + _DEPTH_TOL_REL * came)
        gc[moved_off] = cv2.GC_PR_BGD
    else:
        span = _depth_range(now, core)
    if span is not None:
        away = (now > 0) & ((now < span[0]) | (now > span[1]))
        gc[away] = cv2.GC_BGD


def _models(image: np.ndarray, fg: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """Background and foreground colour models of ``image`` split by ``fg``, or None if a side is too small.

    Fitted with the package's fixed-seed k-means, so ``propagate`` gives the
    same mask for the same input (``cv2.grabCut``'s own initialisation draws
    from OpenCV's global random state).
    """
    if min(np.count_nonzero(fg), np.count_nonzero(~fg)) < _MIN_SAMPLES:
        return None
    rng = np.random.default_rng(0)
    return _fit_model(image[~fg], rng), _fit_model(image[fg], rng)


def _cut(next_low: np.ndarray, gc: np.ndarray, models: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """The graph cut on the next ROI; returns the bool label (``gc`` is updated in place)."""
    bgd, fgd = models[0].copy(), models[1].copy()
    # First pass with the models as given (the previous frame's, fitted on
    # exact labels, so the warp's mistakes cannot leak into them) ...
    cv2.grabCut(next_low, gc, None, bgd, fgd, 1, cv2.GC_EVAL_FREEZE_MODEL)
    for _ in range(_ITERATIONS - 1):
        fg = (gc & 1).astype(bool)
        if fg.all() or not fg.any():
            break
        # ... then re-fitted on this frame's cut, for colours that changed (light, turning object).
        cv2.grabCut(next_low, gc, None, bgd, fgd, 1, cv2.GC_EVAL)
    return (gc & 1).astype(bool)


def _drop_specks(mask: np.ndarray, warped: np.ndarray) -> np.ndarray:
    """``mask`` without the cut's stray specks: parts smaller than ``_SPECK`` of its largest part.

    A small part mostly inside the ``warped`` mask is kept: the flow carried
    the object there (a tail's tip, a foot beyond a thin ankle, a piece seen
    past an occluder), so it is the object, not the cut's stray.
    """
    n, labels, stats, _ = cv2.connectedComponentsWithStats(mask.view(np.uint8), connectivity=8)
    if n <= 2:
        return mask
    areas = stats[1:, cv2.CC_STAT_AREA]
    carried = np.bincount(labels[warped], minlength=n)[1:]
    keep = np.concatenate([[False], (areas >= _SPECK * areas.max()) | (carried >= 0.5 * areas)])
    return keep[labels]


def _iou(a: np.ndarray, b: np.ndarray) -> float:
    return np.count_nonzero(a & b) / max(1, np.count_nonzero(a | b))


@dataclasses.dataclass(frozen=True)
class Carried:
    """A carried mask and how far to trust it.

    Attributes:
        mask: Bool ``(H, W)``, the object in the new frame.
        confidence: In [0, 1]: the smallest of the flow's consistency (share
            of the carried object where the flow is not in doubt), its
            area kept (smaller over larger of the carried and the previous
            area), the cut's agreement with the flow (IoU) and its look (the
            intersection of the object's colour histograms before and after);
            1 for an empty ``prev_mask`` (nothing to carry, nothing to doubt).
        unsure: True when ``confidence`` is below ``UNSURE``: a person should
            look at this frame before carrying further.
        reason: Why it is unsure, in words for the annotator that follow
            "the object" ("no longer looks like itself: hidden, or out of
            view"); "" when sure.
    """

    mask: np.ndarray
    confidence: float
    unsure: bool
    reason: str


UNSURE = 0.6  # confidence below which a carried mask is unsure (every bench pair is at least 0.80)
_REASONS = {
    "consistency": "moved too much or too fast to follow",
    "area": "changed size a lot: partly hidden, or leaving the frame",
    "cut": "has no outline the cut could find again",
    "look": "no longer looks like itself: hidden, or out of view",
}


def _colours(image: np.ndarray, where: np.ndarray, offset: float) -> np.ndarray:
    """The share of ``where``'s pixels in each of 17x17 chromaticity bins (r and g of
    ``rgb / (r + g + b)``, 1/16 wide, shifted by ``offset`` of a bin): colour without
    brightness, so a turn into the shade or a lamp does not count as a change."""
    rgb = image[where].astype(np.float32) + 1.0
    rg = rgb[:, :2] / rgb.sum(axis=1, keepdims=True)
    bins = np.minimum((rg * 16 + offset).astype(np.int32), 16) @ np.array([17, 1], np.int32)
    return np.bincount(bins, minlength=289) / max(1, bins.size)


def _look(warp: _Warp, result: np.ndarray) -> float:
    """How much of the object's colours the carried mask still holds: the
    intersection of the chromaticity histograms before and after, on two
    grids half a bin apart (the better one), so a colour lying on a bin's
    edge does not jump bins."""
    before = warp.prev_mask_low >= 0.5
    return max(float(np.minimum(_colours(warp.prev_low, before, k), _colours(warp.next_low, result, k)).sum())
               for k in (0.0, 0.5))


def _guard(label: np.ndarray, warped: np.ndarray, support: np.ndarray, backed: np.ndarray) -> np.ndarray:
    """The cut where the image supports it, else the flow's mask (bool, work size).

    ``support`` is where the flow may be overruled: where it is in doubt
    (:func:`_doubt`), on the thin strip along the warped edge when the work
    grid is the frame's own (where the cut snaps the edge to the image's),
    and where depth says a pixel left the object. ``backed`` is where the
    image backs the cut's label against the flow's (:func:`_backed`). Each
    part the cut adds, and each it removes (apart: a limb the cut moves is
    an addition beside a removal, each judged on its own), is kept when at
    least ``_SUPPORT`` of it lies where the flow may be overruled and at
    least ``_BACKED`` of it is backed, and undone otherwise: where the flow
    is confident, or where the colours do not say the flow went wrong, a
    colour model that cannot tell the object from its surroundings (a dark
    mug against a dark hand, a grey shoe on a grey road) does not cut a
    piece off or add one.
    """
    added, added_parts = cv2.connectedComponents((label & ~warped).view(np.uint8), connectivity=8)
    removed, removed_parts = cv2.connectedComponents((warped & ~label).view(np.uint8), connectivity=8)
    n = added + removed - 1
    if n <= 1:
        return label
    parts = np.where(removed_parts > 0, removed_parts + (added - 1), added_parts)
    size = np.bincount(parts.ravel(), minlength=n)
    keep = (np.bincount(parts[support], minlength=n) >= _SUPPORT * size) & (
        np.bincount(parts[backed], minlength=n) >= _BACKED * size)
    keep[0] = False
    return np.where(keep[parts], label, warped)


def _backed(warp: _Warp, models: tuple[np.ndarray, np.ndarray], label: np.ndarray, warped: np.ndarray,
            doubt: np.ndarray, band: np.ndarray) -> np.ndarray:
    """Bool ``(h, w)``: pixels the cut relabelled whose colour moved towards the cut's side along the flow.

    Each pixel of the next ROI came, by the flow, from a point of the
    previous one. Where the flow is right the colour stays (it is the same
    surface), so the colour models' verdict (the log-likelihood ratio of
    background to object) stays too, however alike object and background
    look. Where the flow is wrong (the object uncovered the background, a
    limb moved off its track) the pixel now shows something else: a pixel
    the cut takes out must have become more background-like than the point
    it came from, and one the cut adds more object-like, by more than the
    usual change along tracks the flow is sure of (the median over the
    ``band`` pixels not in ``doubt``, on a grid of every ``_NOISE_STRIDE``-th
    row and column: noise, blur, light). A grey shoe on a grey road looks
    like the road in both frames: the colour models call it background, but
    nothing changed along its track, so the flow's answer stands.
    """
    changed = np.flatnonzero(label != warped)
    sample = np.zeros_like(band)
    sample[::_NOISE_STRIDE, ::_NOISE_STRIDE] = True
    trusted = np.flatnonzero(band & ~doubt & sample)
    at = np.concatenate([changed, trusted])
    came = _pull(warp.prev_low.astype(np.float32), warp.back).reshape(-1, 3)[at]
    now = warp.next_low.reshape(-1, 3)[at].astype(np.float32)
    bgd, fgd = models
    rise = (_costs(fgd[0], now) - _costs(bgd[0], now)) - (_costs(fgd[0], came) - _costs(bgd[0], came))
    usual = float(np.median(np.abs(rise[changed.size :]))) if trusted.size else 0.0
    towards = np.where(label.ravel()[changed], -1.0, 1.0) * rise[: changed.size]
    backed = np.zeros(label.size, bool)
    backed[changed[towards > usual]] = True
    return backed.reshape(label.shape)


def _confidence(warp: _Warp, result: np.ndarray, doubt: np.ndarray, cut: np.ndarray | None = None) -> tuple[float, str]:
    """``(confidence, reason)`` of a carried work-size mask (see :class:`Carried`); ``cut``: the
    graph cut's own label when it differs from ``result`` (a failed cut), else ``result`` is it."""
    warped = warp.warped_low >= 0.5
    before = np.count_nonzero(warp.prev_mask_low >= 0.5)
    if not warped.any() or not result.any():
        return 0.0, _REASONS["area"]
    terms = {
        # Doubt, not the bare forward-backward miss: a plain object's inside has no texture for the
        # flow to agree on, yet it moves with the rest (:func:`_doubt`).
        "consistency": 1.0 - np.count_nonzero(warped & doubt) / np.count_nonzero(warped),
        "area": min(before, np.count_nonzero(result)) / max(1, before, np.count_nonzero(result)),
        "cut": _iou(result if cut is None else cut, warped),
        # Histogram intersection of the object's colours before and after: a hand over it, or the object gone.
        "look": _look(warp, result),
    }
    worst = min(terms, key=terms.get)
    return float(terms[worst]), _REASONS[worst] if terms[worst] < UNSURE else ""


def carry(prev_rgb: np.ndarray, prev_mask: np.ndarray, next_rgb: np.ndarray, *,
          prev_depth: np.ndarray | None = None, next_depth: np.ndarray | None = None) -> Carried:
    """:func:`propagate` with its confidence: whether the carried mask needs a person's look.

    Same arguments and errors as :func:`propagate`.

    Returns:
        A :class:`Carried`.
    """
    prev_rgb = _check_rgb(prev_rgb, "prev_rgb")
    next_rgb = _check_rgb(next_rgb, "next_rgb")
    _check_same_size(prev_rgb, next_rgb)
    shape = prev_rgb.shape[:2]
    prev_mask = _check_mask(prev_mask, shape)
    prev_depth = _check_depth(prev_depth, "prev_depth", shape)
    next_depth = _check_depth(next_depth, "next_depth", shape)
    if not prev_mask.any():
        return Carried(np.zeros(shape, bool), 1.0, False, "")

    warp = _warp(prev_rgb, prev_mask, next_rgb)
    roi = warp.roi
    warped = warp.warped_low >= 0.5
    fallback = roi.paste(warp.warped_low, shape)

    doubt = _doubt(warp)

    def flow_only(cut: np.ndarray | None = None) -> Carried:
        # A failed cut still says something: its agreement with the flow counts.
        confidence, reason = _confidence(warp, warped, doubt, cut)
        return Carried(fallback, confidence, confidence < UNSURE, reason)

    if np.count_nonzero(warped) < _MIN_SAMPLES:
        return flow_only()  # too small at the work size to cut: the flow's answer stands
    gc, core, band = _trimap(warp, doubt)
    # The cut's to decide: where the flow is in doubt, and, when the work grid is the frame's own
    # pixels, the strip along the warped edge (snapping it to the image's edge). On a reduced grid
    # the warp's soft values place the edge finer than the cut's coarse pixels can.
    support = doubt.copy()
    if not roi.coarse:
        support |= cv2.morphologyEx(warped.view(np.uint8), cv2.MORPH_GRADIENT, _disk(_EDGE)).astype(bool)
    away = np.zeros_like(warped)
    if next_depth is not None:
        _apply_depth(gc, core, warp, prev_depth, next_depth)
        # Inside the warped mask only depth hands pixels to the background: the image's support too.
        support |= warped & ((gc == cv2.GC_BGD) | (gc == cv2.GC_PR_BGD))
        # Depth outside the object's range backs the cut whatever the colours say, but not on the
        # warped edge's own pixels: there the depth and colour images may disagree by a pixel.
        away = cv2.erode(warped.view(np.uint8), _disk(1)).astype(bool) & (gc == cv2.GC_BGD)
    if min(np.count_nonzero(gc & 1), np.count_nonzero(~gc & 1)) < _MIN_SAMPLES:
        return flow_only()
    models = _models(warp.prev_low, warp.prev_mask_low >= 0.5) or _models(warp.next_low, (gc & 1).astype(bool))
    if models is None:
        return flow_only()
    label = _cut(warp.next_low, gc, models)
    area, warped_area = np.count_nonzero(label), np.count_nonzero(warped)
    if _iou(label, warped) < 0.5 or not 0.5 * warped_area <= area <= 2 * warped_area:
        return flow_only(label)  # a failed cut (colours too alike): trust the flow
    guarded = _guard(label, warped, support, _backed(warp, models, label, warped, doubt, band) | away)
    # Where the result agrees with the warp, the warp's soft values place the edge
    # to a fraction of a work-size pixel; elsewhere the cut, smoothed so the
    # bilinear upsample gives a clean edge instead of work-size stairs ...
    soft = np.where(guarded == warped, warp.warped_low, cv2.GaussianBlur(guarded.astype(np.float32), (0, 0), 0.7))
    mask = roi.paste(soft, shape)
    if roi.coarse:
        # ... and on a coarse grid brought to the frame's own edges by the guided filter.
        mask = _sharpened(mask, guarded, warped, roi, next_rgb)
    mask = _drop_specks(mask, fallback)
    if roi.coarse and mask.any() and fallback.any():
        mask = _flow_extent(mask, fallback, roi)
    confidence, reason = _confidence(warp, guarded, doubt)
    return Carried(mask, confidence, confidence < UNSURE, reason)


def _sharpened(mask: np.ndarray, guarded: np.ndarray, warped: np.ndarray, roi: _Roi,
               next_rgb: np.ndarray) -> np.ndarray:
    """``mask`` with the cut's changes to the warped mask refined at full resolution.

    Around each work-size pixel where ``guarded`` differs from ``warped`` (and
    one pixel beyond), the full-resolution mask is the session's guided-filter
    upsampling of ``guarded`` (:func:`egonet.grabcut.refine._upsample_mask`):
    the cut's edge follows the next frame's colours instead of the work grid.
    Elsewhere the warp's soft edge stands.
    """
    near = cv2.dilate((guarded != warped).view(np.uint8), _disk(1))
    if not near.any():
        return mask
    x, y, w, h = cv2.boundingRect(near)
    rect = (roi.x0, roi.y0, roi.x1, roi.y1)
    guide = _Guide.build(_Geometry(rect, rect, roi.w, roi.h), next_rgb)
    part, (oy, ox) = _upsample_mask(guide, next_rgb, guarded, (y, y + h, x, x + w))
    # The full-resolution pixels whose nearest work-size pixel is near a change (as _upsample_mask maps them).
    near_c = np.minimum(((np.arange(ox, ox + part.shape[1]) - roi.x0 + 0.5) * guide.geom.sx).astype(np.intp), roi.w - 1)
    near_r = np.minimum(((np.arange(oy, oy + part.shape[0]) - roi.y0 + 0.5) * guide.geom.sy).astype(np.intp), roi.h - 1)
    take = near[np.ix_(near_r, near_c)].astype(bool)
    out = mask.copy()
    out[oy : oy + part.shape[0], ox : ox + part.shape[1]][take] = part[take]
    return out


def _flow_extent(mask: np.ndarray, fallback: np.ndarray, roi: _Roi) -> np.ndarray:
    """``mask`` with each side of its box the flow's where the cut moved it by less than a work-size pixel.

    On a coarse grid the cut decides whole work-size pixels, while the warp's
    soft values place the flow's edge to a fraction of one: a side of the
    carried mask's box within one work-size pixel of the flow's
    (``fallback``'s) is a disagreement below the cut's own resolution, and
    the flow's pixels between the two sides stand (only within the mask's
    extent along the side, so they cannot widen the other sides). This
    keeps the box from ever being worse than the flow's by the cut's
    quantisation; it gives up the cut's sub-pixel moves that were right
    (more than those that were wrong; docs/benchmarks.md has the cost). A
    side the cut moved by a work-size pixel or more is a change the guard
    (:func:`_guard`) judged; it stays.
    """
    box, flow = _box(mask), _box(fallback)
    step = ((roi.x1 - roi.x0) / roi.w, (roi.y1 - roi.y0) / roi.h)
    out = mask.copy()
    for side in range(4):
        gap = box[side] - flow[side]
        if gap == 0 or abs(gap) >= step[side % 2]:
            continue
        lo, hi = sorted((box[side], flow[side]))
        # Columns lo:hi within the mask's rows (x sides), or rows lo:hi within its columns (y sides).
        strip = (np.s_[box[1] : box[3], lo:hi] if side % 2 == 0 else np.s_[lo:hi, box[0] : box[2]])
        out[strip] = fallback[strip]
    return out


def propagate(prev_rgb: np.ndarray, prev_mask: np.ndarray, next_rgb: np.ndarray, *,
              prev_depth: np.ndarray | None = None, next_depth: np.ndarray | None = None) -> np.ndarray:
    """Carry one object's mask from a frame to an adjacent frame (either direction).

    Optical flow moves the mask, then GrabCut, seeded from the moved mask,
    snaps it to the object in the new frame where the flow is in doubt (see
    the module's docstring); :func:`carry` also says how sure it is.

    Args:
        prev_rgb: RGB uint8 ``(H, W, 3)``, the frame the mask belongs to.
        prev_mask: Bool (or 0/1 integer) ``(H, W)``, the object in ``prev_rgb``.
        next_rgb: RGB uint8 ``(H, W, 3)``, the adjacent frame (next or previous).
        prev_depth: Optional float ``(H, W)`` depth of ``prev_rgb`` in metres
            (0 or NaN where missing), registered to the colour image.
        next_depth: Optional float ``(H, W)`` depth of ``next_rgb``, the same way.
            Depth is used only when ``next_depth`` is given (``prev_depth``
            then gives the object's depth range; without it the range comes
            from ``next_depth`` under the moved mask's core).

    Returns:
        Bool ``(H, W)`` mask of the object in ``next_rgb``; all False when
        ``prev_mask`` is empty.

    Raises:
        EgonetError: Naming the argument, if a frame is not RGB uint8, the
            frames differ in size, the mask is not ``(H, W)`` bool/0-1, or a
            depth map is not float ``(H, W)``.

    Example:
        >>> frame = np.zeros((64, 64, 3), np.uint8)
        >>> bool(propagate(frame, np.zeros((64, 64), bool), frame).any())
        False
    """
    return carry(prev_rgb, prev_mask, next_rgb, prev_depth=prev_depth, next_depth=next_depth).mask
