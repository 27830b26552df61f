"""From counts to precision/recall curves, and from curves to F, MF and AP.

Every function here works on a single curve (T,) or on a stack of curves
(..., T) alike, so the bootstrap reduces a thousand resampled curves in one
call (:mod:`egonet.metrics.frames`).

* ``P = TP / (TP + FP)``, or 1 where nothing is predicted; ``R = TP / (TP +
  FN)``, or 0 where there are no positive pixels;
* ``F = (1 + beta2) P R / (beta2 P + R)``, or 0 where ``P + R = 0``;
  ``MF = max_k F_k``;
* ``AP = sum_k (R_k - R_{k+1}) P_k`` with increasing thresholds and
  ``R_{T+1} = 0``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from egonet.errors import EgonetError
from egonet.metrics.thresholds import Counts, check_beta2, threshold_values


def _floats(a: np.ndarray) -> np.ndarray:
    """``a`` as floats: float32 stays float32 (the bootstrap's fast rows), anything else becomes float64."""
    a = np.asarray(a)
    return a if a.dtype == np.float32 else np.asarray(a, dtype=np.float64)


def precision_recall(tp: np.ndarray, fp: np.ndarray, positives: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Precision and recall from true and false positives and the number of positive pixels.

    Args:
        tp: True positives, (..., T).
        fp: False positives, (..., T).
        positives: Positive pixels (``TP + FN``), broadcastable to ``tp``
            ((..., 1) or (..., T)).

    Returns:
        ``(precision, recall)``, float64 (..., T) (float32 for float32 counts).
    """
    tp = _floats(tp)
    predicted = tp + _floats(fp).astype(tp.dtype, copy=False)
    positives = np.broadcast_to(_floats(positives).astype(tp.dtype, copy=False), tp.shape)
    precision = np.divide(tp, predicted, out=np.ones_like(tp), where=predicted > 0)
    recall = np.divide(tp, positives, out=np.zeros_like(tp), where=positives > 0)
    return precision, recall


def curve_from_counts(counts: Counts) -> tuple[np.ndarray, np.ndarray]:
    """Precision and recall at each threshold from confusion counts.

    ``P = TP / (TP + FP)``, or 1 where nothing is predicted;
    ``R = TP / (TP + FN)``, or 0 where there are no positive pixels.

    Args:
        counts: Counts of one map or of pooled maps, arrays (T,).

    Returns:
        ``(precision, recall)``, float64 arrays (T,).
    """
    tp, fp, fn = (np.asarray(c, dtype=np.float64) for c in counts)
    return precision_recall(tp, fp, tp + fn)


def f_scores(precision: np.ndarray, recall: np.ndarray, *, beta2: float = 1.0) -> np.ndarray:
    """``F = (1 + beta2) P R / (beta2 P + R)``, 0 where ``P + R = 0``; float64 (float32 for float32 curves) of the curves' shape (..., T)."""
    p = _floats(precision)
    r = _floats(recall).astype(p.dtype, copy=False)
    return np.divide((1.0 + beta2) * p * r, beta2 * p + r, out=np.zeros_like(p), where=(p + r) > 0)


def average_precision(precision: np.ndarray, recall: np.ndarray) -> np.ndarray:
    """``AP = sum_k (R_k - R_{k+1}) P_k`` along the last axis (increasing thresholds, ``R_{T+1} = 0``); shape (...)."""
    p = _floats(precision)
    r = _floats(recall).astype(p.dtype, copy=False)
    drop = r.copy()
    drop[..., :-1] -= r[..., 1:]
    return np.sum(drop * p, axis=-1)


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=np.float64)
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class Score:
    """A precision/recall curve and its summary numbers.

    Attributes:
        max_f: Maximum F-score over the thresholds (MF).
        ap: Average precision, ``sum_k (R_k - R_{k+1}) P_k``.
        best_threshold: The threshold where F reaches ``max_f`` (the lowest
            one on ties; ``t_1`` when every F is 0).
        thresholds: Thresholds ``t_k``, increasing, float64 (T,).
        precision: Precision at each threshold, float64 (T,).
        recall: Recall at each threshold, float64 (T,).
        f: F-score at each threshold, float64 (T,).
        beta2: The beta squared the F-scores use.
        metric: ``"pooled"`` (the curve of counts summed over maps) or
            ``"mean-curve"`` (each map's P and R averaged over maps).
        n_maps: The number of maps scored.
        empty: For a mean curve, how maps without positive pixels counted
            (``egonet.metrics.frames.EMPTY_POLICIES``); None for pooled.
        empty_maps: How many of the maps had no positive pixels.
    """

    max_f: float
    ap: float
    best_threshold: float
    thresholds: np.ndarray = field(repr=False)
    precision: np.ndarray = field(repr=False)
    recall: np.ndarray = field(repr=False)
    f: np.ndarray = field(repr=False)
    beta2: float = 1.0
    metric: str = "pooled"
    n_maps: int = 0
    empty: str | None = None
    empty_maps: int = 0

    @property
    def per_image(self) -> bool:
        """Deprecated (goes in the next release): whether ``metric`` is ``"mean-curve"``."""
        return self.metric == "mean-curve"

    @classmethod
    def from_curves(
        cls,
        precision: np.ndarray,
        recall: np.ndarray,
        *,
        beta2: float = 1.0,
        metric: str = "pooled",
        n_maps: int = 0,
        empty: str | None = None,
        empty_maps: int = 0,
    ) -> Score:
        """Reduce a precision/recall curve to F, MF and AP.

        Args:
            precision: Precision at each threshold, increasing thresholds (T,).
            recall: Recall at each threshold (T,).
            beta2: Weight of recall in F (beta squared), > 0.
            metric, n_maps, empty, empty_maps: Recorded on the result (see
                the attributes).

        Returns:
            The :class:`Score`.

        Raises:
            EgonetError: If the curves are not 1-D of equal length or
                ``beta2`` is not positive.
        """
        beta2 = check_beta2(beta2)
        p = np.asarray(precision, dtype=np.float64)
        r = np.asarray(recall, dtype=np.float64)
        if p.ndim != 1 or p.shape != r.shape or p.size == 0:
            raise EgonetError(
                f"precision and recall must be non-empty 1-D arrays of equal length, got {p.shape} and {r.shape}",
                field="precision",
            )
        f = f_scores(p, r, beta2=beta2)
        best = int(np.argmax(f))
        t = threshold_values(p.size)
        return cls(
            max_f=float(f[best]),
            ap=float(average_precision(p, r)),
            best_threshold=float(t[best]),
            thresholds=t,
            precision=_readonly(p),
            recall=_readonly(r),
            f=_readonly(f),
            beta2=beta2,
            metric=metric,
            n_maps=int(n_maps),
            empty=empty,
            empty_maps=int(empty_maps),
        )

    @classmethod
    def from_counts(cls, counts: Counts, *, beta2: float = 1.0, n_maps: int = 0, empty_maps: int = 0) -> Score:
        """Score pooled counts (dataset-level precision and recall).

        Args:
            counts: TP/FP/FN summed over maps, arrays (T,).
            beta2: Weight of recall in F (beta squared), > 0.
            n_maps, empty_maps: Recorded on the result: how many maps were
                pooled, and how many of them had no positive pixels.

        Returns:
            The pooled :class:`Score`.
        """
        precision, recall = curve_from_counts(counts)
        return cls.from_curves(precision, recall, beta2=beta2, n_maps=n_maps, empty_maps=empty_maps)


def iso_f_curve(f: float, *, beta2: float = 1.0, points: int = 40) -> tuple[np.ndarray, np.ndarray]:
    """The precision-recall points where the F-score equals ``f`` (to draw under PR curves).

    Solving ``F = (1 + beta2) P R / (beta2 P + R)`` for P gives
    ``P = F R / ((1 + beta2) R - beta2 F)``, which lies in [0, 1] from
    ``R = beta2 F / (1 + beta2 - F)`` (where P = 1) up to R = 1 (where P is
    smallest).

    Args:
        f: The F-score, in (0, 1).
        beta2: Weight of recall in F (beta squared), > 0.
        points: How many points, evenly spaced in recall, >= 2.

    Returns:
        ``(recall, precision)``, float64 arrays (points,), recall increasing.

    Raises:
        EgonetError: If ``f`` is not in (0, 1) or ``points`` is below 2.

    Example:
        >>> recall, precision = iso_f_curve(0.5, points=3)
        >>> recall.round(3).tolist(), precision.round(3).tolist()
        ([0.333, 0.667, 1.0], [1.0, 0.4, 0.333])
    """
    beta2 = check_beta2(beta2)
    if isinstance(f, bool) or not isinstance(f, (int, float, np.integer, np.floating)) or not 0 < f < 1:
        raise EgonetError(f"f: must be an F-score between 0 and 1 (exclusive), got {f!r}", field="f")
    if isinstance(points, bool) or not isinstance(points, (int, np.integer)) or points < 2:
        raise EgonetError(f"points: must be an int of at least 2, got {points!r}", field="points")
    recall = np.linspace(beta2 * f / (1 + beta2 - f), 1.0, int(points))
    precision = f * recall / ((1 + beta2) * recall - beta2 * f)
    return recall, precision
