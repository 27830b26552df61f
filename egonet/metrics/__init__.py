"""Maximum F-score (MF) and average precision (AP) of probability maps, with their uncertainty.

The paper scores a probability map by thresholding it "at small intervals",
building a precision/recall curve and reporting its best F-score (MF) and the
area under it (AP). This package fixes the details (see
``shared/docs/egonet-reference.md``, "Metrics"):

* ``T`` thresholds ``t_k = k / (T + 1)`` for ``k = 1..T`` (99 thresholds
  ``0.01 .. 0.99`` by default), each computed as a float64. A pixel is
  predicted positive at ``t_k`` when ``prob >= t_k``, compared exactly.
* Pooled mode (the default, as in the BSDS benchmark): ``TP_k``, ``FP_k`` and
  ``FN_k`` are summed over every pixel of every map, then
  ``P_k = TP_k / (TP_k + FP_k)``, or 1 when ``TP_k + FP_k = 0`` (nothing
  predicted); ``R_k = TP_k / (TP_k + FN_k)``, or 0 when there are no positive
  pixels.
* ``F_k = (1 + beta2) P_k R_k / (beta2 P_k + R_k)``, or 0 when
  ``P_k + R_k = 0``; ``MF = max_k F_k``.
* ``AP = sum_k (R_k - R_{k+1}) P_k`` with the thresholds in increasing order
  and ``R_{T+1} = 0``.
* ``score_maps(metric="mean-curve")``: the same counts per map, ``P_k``
  and ``R_k`` averaged over the maps at each threshold, then F, MF and AP
  from those averaged curves (maps without positive pixels: see ``frames``,
  ``empty=``). ``per_image=True`` is its old, deprecated spelling.

Maps are never normalised before thresholding.

Modules:

* ``thresholds``: the thresholds, :class:`Counts` and the parameter checks;
* ``curves``: counts to precision/recall curves, curves to F, MF and AP
  (:class:`Score`), iso-F curves;
* ``accumulate``: :func:`count_stats` (one histogram pass per map),
  :class:`ScoreAccumulator` (streams maps, merges, stores its state) and
  :func:`score_maps`;
* ``frames``: per-frame counts (:class:`FrameCounts`) and the conventions
  ``pooled``, ``ois-mean`` (mean of each frame's best F; old name
  ``per-image``), ``mean-curve`` and ``ods-ois`` (BSDS), scored on any
  weighting of the frames (:func:`score_frames`), with the policies for
  frames without positive pixels (``EMPTY_POLICIES``);
* ``bootstrap``: seeded resampling of frames (:class:`Resampler`), BCa
  95 % intervals and paired tests (:class:`Estimate`).
"""

from egonet.metrics.accumulate import ScoreAccumulator, count_stats, score_maps
from egonet.metrics.bootstrap import DEFAULT_RESAMPLES, MAX_RESAMPLES, MIN_FRAMES, Estimate, Resampler, jackknife_weights, p_floor, resample_weights
from egonet.metrics.curves import Score, average_precision, curve_from_counts, f_scores, iso_f_curve, precision_recall
from egonet.metrics.frames import (
    DEFAULT_EMPTY,
    EMPTY_POLICIES,
    METRIC_ALIASES,
    METRICS,
    PER_FRAME_MEANS,
    FrameCounts,
    frame_curves,
    frame_scores,
    metric_convention,
    reduce_sums,
    resolve_metric,
    score_frames,
    weighted_sums,
)
from egonet.metrics.thresholds import DEFAULT_THRESHOLDS, Counts, threshold_values

__all__ = [
    "DEFAULT_EMPTY",
    "DEFAULT_RESAMPLES",
    "DEFAULT_THRESHOLDS",
    "EMPTY_POLICIES",
    "MAX_RESAMPLES",
    "METRICS",
    "METRIC_ALIASES",
    "MIN_FRAMES",
    "PER_FRAME_MEANS",
    "Counts",
    "Estimate",
    "FrameCounts",
    "Resampler",
    "Score",
    "ScoreAccumulator",
    "average_precision",
    "count_stats",
    "curve_from_counts",
    "f_scores",
    "frame_curves",
    "frame_scores",
    "iso_f_curve",
    "jackknife_weights",
    "metric_convention",
    "p_floor",
    "precision_recall",
    "reduce_sums",
    "resample_weights",
    "resolve_metric",
    "score_frames",
    "score_maps",
    "threshold_values",
    "weighted_sums",
]
