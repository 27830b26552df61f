"""Per-frame counts and the four ways of turning them into an activity's scores.

:class:`FrameCounts` keeps every frame's per-threshold counts (N frames by
T thresholds), so a score can be computed on any subset of frames (the
frames two rows share), on resampled frames (the bootstrap), or per frame.

The conventions (``METRICS``), each with MF-like statistics and AP; one name
each, used by the API, the CLI, the page and every download:

* ``"pooled"`` (the default of the reference, as in the BSDS benchmark):
  TP, FP and FN summed over every pixel of every frame at each threshold,
  then P, R, F; ``max_f`` = MF = max over thresholds, ``ap`` = AP of that
  pooled curve.
* ``"ois-mean"``: each frame's own curve; ``max_f`` = the mean over frames
  of each frame's best F (its F at its own best threshold, as OIS takes
  it), ``ap`` = the mean of the frames' APs.
* ``"mean-curve"``: each frame's own P and R, averaged over frames at each
  threshold; ``max_f`` = the best F of that mean curve, ``ap`` = its AP
  (``score_maps(metric="mean-curve")``).
* ``"ods-ois"`` (BSDS): ``max_f`` = ODS, the best F at one threshold for
  the whole set (the same number as pooled MF); ``ois`` = OIS, F of the
  counts summed over frames each taken at *its own* best threshold (the
  highest one on ties, the fewest false positives); ``ap`` = the pooled AP.

``METRIC_ALIASES`` holds the old name ``"per-image"`` (now ``"ois-mean"``),
accepted with a logged deprecation line until the next release.

**Frames without action-object pixels** have no recall, so their own F is
undefined. The two per-frame means (``ois-mean``, ``mean-curve``) take one
of ``EMPTY_POLICIES`` (``empty=``): ``"leave-out"`` (the default, our
choice: the mean is over frames with something to find), ``"zero"`` (the
frame scores 0 whatever the map: P = R = 0) or ``"one-if-empty"`` (P = R =
1 at the thresholds where the map predicts nothing, else 0). Pooled counts
and ODS/OIS need no policy: such a frame adds its false positives.

Each convention splits into ``features`` (a vector per frame, (N, D)) and
``reduce`` (statistics from sums of those vectors, (B, D)), so that a
weighted sum over frames computes a score: weights of ones give the score
itself, bootstrap multiplicities a resampled score, and a thousand of them
go through one matrix product (:func:`score_frames`).

Example:
    Two frames at T = 3 thresholds (0.25, 0.5, 0.75): pooled over both, the
    best F is 0.8 at 0.25; each frame's own best F is 2/3 and 1 (mean 0.833);
    taken at their own best thresholds, their summed counts give OIS 0.857.

    >>> import numpy as np
    >>> from egonet.metrics import count_stats
    >>> a = count_stats(np.array([[0.9, 0.6, 0.4, 0.3]]), np.array([[True, False, True, False]]), thresholds=3)
    >>> b = count_stats(np.array([[0.3, 0.3]]), np.array([[True, True]]), thresholds=3)
    >>> counts = FrameCounts.stack([a, b])
    >>> {k: round(float(v[0]), 3) for k, v in score_frames(counts, metric="ods-ois").items()}
    {'max_f': 0.8, 'ap': 0.75, 'ois': 0.857}
    >>> round(float(score_frames(counts, metric="ois-mean")["max_f"][0]), 3)
    0.833
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from egonet.errors import EgonetError
from egonet.metrics.curves import average_precision, f_scores, precision_recall
from egonet.metrics.thresholds import Counts, check_beta2, check_thresholds

__all__ = [
    "DEFAULT_EMPTY", "EMPTY_POLICIES", "METRICS", "METRIC_ALIASES", "PER_FRAME_MEANS", "FrameCounts", "frame_curves", "frame_scores",
    "metric_convention", "reduce_sums", "resolve_metric", "score_frames", "weighted_sums",
]  # fmt: skip


@dataclass(frozen=True, eq=False)
class FrameCounts:
    """Every frame's counts at every threshold.

    Attributes:
        tp: True positives, int64 (N, T).
        fp: False positives, int64 (N, T).
        positives: Positive (action-object) pixels of each frame, int64 (N,);
            ``FN = positives - TP``.

    Raises:
        EgonetError: If the shapes disagree, a count is negative, or a frame
            has more true positives than positive pixels.
    """

    tp: np.ndarray
    fp: np.ndarray
    positives: np.ndarray

    def __post_init__(self) -> None:
        tp, fp = np.asarray(self.tp, dtype=np.int64), np.asarray(self.fp, dtype=np.int64)
        positives = np.asarray(self.positives, dtype=np.int64)
        if tp.ndim != 2 or fp.shape != tp.shape or positives.shape != tp.shape[:1] or tp.shape[1] < 1:
            raise EgonetError(
                f"counts: tp and fp must be (N, T) and positives (N,), got {tp.shape}, {fp.shape} and {positives.shape}",
                field="counts",
            )
        if tp.size and (tp.min() < 0 or fp.min() < 0 or (tp > positives[:, None]).any()):
            raise EgonetError("counts: negative counts, or more true positives than positive pixels", field="counts")
        for name, value in (("tp", tp), ("fp", fp), ("positives", positives)):
            value.setflags(write=False)
            object.__setattr__(self, name, value)

    @classmethod
    def stack(cls, counts: Sequence[Counts], *, thresholds: int | None = None) -> FrameCounts:
        """The counts of single maps (``count_stats``), one frame each, in order.

        Args:
            counts: One :class:`Counts` per frame, arrays (T,).
            thresholds: T, needed only when ``counts`` is empty.

        Returns:
            The :class:`FrameCounts` of those frames.
        """
        if not counts:
            if thresholds is None:
                raise EgonetError("counts: is empty; give thresholds to make empty frame counts", field="counts")
            t = check_thresholds(thresholds)
            return cls(np.zeros((0, t), np.int64), np.zeros((0, t), np.int64), np.zeros(0, np.int64))
        tp = np.stack([np.asarray(c.tp) for c in counts])
        return cls(tp, np.stack([np.asarray(c.fp) for c in counts]), tp[:, 0] + np.array([c.fn[0] for c in counts]))

    @classmethod
    def concat(cls, parts: Sequence[FrameCounts], *, thresholds: int) -> FrameCounts:
        """The frames of several :class:`FrameCounts` one after the other."""
        if any(p.thresholds != thresholds for p in parts):
            raise EgonetError(f"counts: every part must have {thresholds} thresholds", field="counts")
        if not parts:
            return cls.stack([], thresholds=thresholds)
        return cls(*(np.concatenate([getattr(p, k) for p in parts]) for k in ("tp", "fp", "positives")))

    @property
    def n(self) -> int:
        """The number of frames N."""
        return int(self.tp.shape[0])

    @property
    def thresholds(self) -> int:
        """The number of thresholds T."""
        return int(self.tp.shape[1])

    def take(self, index: np.ndarray) -> FrameCounts:
        """The frames at ``index`` (int positions or a bool mask, (N,)), in that order."""
        return FrameCounts(self.tp[index], self.fp[index], self.positives[index])

    def pooled(self) -> Counts:
        """The counts summed over the frames, arrays (T,)."""
        tp = self.tp.sum(axis=0)
        return Counts(tp, self.fp.sum(axis=0), np.int64(self.positives.sum()) - tp)


EMPTY_POLICIES = ("leave-out", "zero", "one-if-empty")
"""How the per-frame means count a frame without action-object pixels (see the module)."""
DEFAULT_EMPTY = "leave-out"
"""Our choice (the paper does not say): the per-frame means are over frames with something to find."""


def check_empty(empty: str) -> str:
    """``empty`` if it is one of :data:`EMPTY_POLICIES`, else an error listing them."""
    if empty not in EMPTY_POLICIES:
        raise EgonetError(f"empty: must be one of {', '.join(EMPTY_POLICIES)}, got {empty!r}", field="empty")
    return empty


def frame_curves(counts: FrameCounts, *, empty: str = DEFAULT_EMPTY) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each frame's precision and recall at every threshold, frames without positives as ``empty`` says.

    Args:
        counts: The frames' counts.
        empty: One of :data:`EMPTY_POLICIES`.

    Returns:
        ``(precision, recall, counted)``: float64 (N, T), (N, T) and bool
        (N,); ``counted`` is False for the frames ``"leave-out"`` leaves out
        (their curves are 0).
    """
    check_empty(empty)
    precision, recall = precision_recall(counts.tp, counts.fp, counts.positives[:, None])
    none = counts.positives == 0
    hit = (counts.fp[none] == 0).astype(np.float64) if empty == "one-if-empty" else 0.0
    precision[none] = recall[none] = hit
    return precision, recall, ~none if empty == "leave-out" else np.ones(counts.n, bool)


def frame_scores(counts: FrameCounts, *, beta2: float = 1.0, empty: str = DEFAULT_EMPTY) -> dict[str, np.ndarray]:
    """Each frame's own scores: its best F, its AP and the threshold index of its best F.

    Args:
        counts: The frames' counts.
        beta2: Weight of recall in F (beta squared), > 0.
        empty: How a frame without positives scores (:data:`EMPTY_POLICIES`).

    Returns:
        ``{"max_f": float64 (N,), "ap": float64 (N,), "best": int (N,),
        "counted": bool (N,)}``; ``best`` is the index of the highest
        threshold reaching the frame's best F (the fewest false positives
        among the ties); frames left out (``counted`` False) have NaN scores.
    """
    beta2 = check_beta2(beta2)
    precision, recall, counted = frame_curves(counts, empty=empty)
    f = f_scores(precision, recall, beta2=beta2)
    best = counts.thresholds - 1 - np.argmax(f[:, ::-1], axis=1)
    out = {"max_f": f.max(axis=1, initial=0.0), "ap": average_precision(precision, recall), "best": best, "counted": counted}
    for key in ("max_f", "ap"):
        out[key][~counted] = np.nan
    return out


def _divide(sums: np.ndarray, counted: np.ndarray) -> np.ndarray:
    """Sums (B, D) over the counted frames (B,); NaN where no frame counted."""
    return np.divide(sums, counted[:, None], out=np.full(sums.shape, np.nan, sums.dtype), where=counted[:, None] > 0)


class _Pooled:
    statistics = ("max_f", "ap")

    def features(self, counts: FrameCounts, *, beta2: float, empty: str) -> np.ndarray:
        return np.hstack([counts.tp, counts.fp, counts.positives[:, None]]).astype(np.float64)

    def reduce(self, sums: np.ndarray, *, thresholds: int, beta2: float) -> dict[str, np.ndarray]:
        t = thresholds
        precision, recall = precision_recall(sums[:, :t], sums[:, t : 2 * t], sums[:, 2 * t, None])
        return {"max_f": f_scores(precision, recall, beta2=beta2).max(axis=1), "ap": average_precision(precision, recall)}


class _OisMean:
    statistics = ("max_f", "ap")

    def features(self, counts: FrameCounts, *, beta2: float, empty: str) -> np.ndarray:
        own = frame_scores(counts, beta2=beta2, empty=empty)
        return np.nan_to_num(np.stack([own["max_f"], own["ap"], own["counted"]], axis=1))

    def reduce(self, sums: np.ndarray, *, thresholds: int, beta2: float) -> dict[str, np.ndarray]:
        means = _divide(sums[:, :2], sums[:, 2])
        return {"max_f": means[:, 0], "ap": means[:, 1]}


class _MeanCurve:
    statistics = ("max_f", "ap")

    def features(self, counts: FrameCounts, *, beta2: float, empty: str) -> np.ndarray:
        precision, recall, counted = frame_curves(counts, empty=empty)
        return np.hstack([precision, recall, counted[:, None]])

    def reduce(self, sums: np.ndarray, *, thresholds: int, beta2: float) -> dict[str, np.ndarray]:
        curves = _divide(sums[:, :-1], sums[:, -1])
        precision, recall = curves[:, :thresholds], curves[:, thresholds:]
        best = np.where(sums[:, -1] > 0, f_scores(precision, recall, beta2=beta2).max(axis=1), np.nan)
        return {"max_f": best, "ap": average_precision(precision, recall)}


class _OdsOis:
    statistics = ("max_f", "ap", "ois")

    def features(self, counts: FrameCounts, *, beta2: float, empty: str) -> np.ndarray:
        best = frame_scores(counts, beta2=beta2, empty="zero")["best"]
        rows = np.arange(counts.n)
        at_best = np.stack([counts.tp[rows, best], counts.fp[rows, best], counts.positives], axis=1)
        return np.hstack([_Pooled().features(counts, beta2=beta2, empty=empty), at_best.astype(np.float64)])

    def reduce(self, sums: np.ndarray, *, thresholds: int, beta2: float) -> dict[str, np.ndarray]:
        out = _Pooled().reduce(sums[:, :-3], thresholds=thresholds, beta2=beta2)
        precision, recall = precision_recall(sums[:, -3], sums[:, -2], sums[:, -1])
        out["ois"] = f_scores(precision, recall, beta2=beta2)
        return out


METRICS = {"pooled": _Pooled(), "ois-mean": _OisMean(), "mean-curve": _MeanCurve(), "ods-ois": _OdsOis()}
"""The conventions by name; ``METRICS[name].statistics`` are the keys its scores have."""
PER_FRAME_MEANS = ("ois-mean", "mean-curve")
"""The conventions that average over frames, where :data:`EMPTY_POLICIES` apply."""
METRIC_ALIASES = {"per-image": "ois-mean"}
"""Old names, accepted until the next release: old name -> name."""

_log = logging.getLogger(__name__)


def resolve_metric(metric: str) -> tuple[str, str | None]:
    """``(name, deprecation line)``: the convention's name for ``metric`` and, for an old name, a line saying so (else None).

    Raises:
        EgonetError: If ``metric`` is neither a convention nor an old name, listing the conventions.
    """
    if isinstance(metric, str) and metric in METRIC_ALIASES:
        name = METRIC_ALIASES[metric]
        return name, f"metric {metric!r} is deprecated and goes in the next release: it is now called {name!r}"
    if not isinstance(metric, str) or metric not in METRICS:
        raise EgonetError(f"metric: must be one of {', '.join(METRICS)}, got {metric!r}", field="metric")
    return metric, None


def metric_convention(metric: str) -> _Pooled | _OisMean | _MeanCurve | _OdsOis:
    """The convention called ``metric`` (an old name logs its deprecation line), or an error listing the valid names."""
    name, deprecated = resolve_metric(metric)
    if deprecated:
        _log.warning(deprecated)
    return METRICS[name]


def weighted_sums(
    counts: FrameCounts,
    *,
    metric: str = "pooled",
    weights: np.ndarray | None = None,
    beta2: float = 1.0,
    empty: str = DEFAULT_EMPTY,
    resampled_in_float32: bool = False,
) -> np.ndarray:
    """The first half of :func:`score_frames`: the weighted sums of the frames' feature vectors.

    Sums of disjoint sets of frames add up: the sums of two activities'
    resamples, added, are those of their union resampled within each (the
    pooled ``all`` of a stratified bootstrap), reduced by :func:`reduce_sums`.

    Args:
        counts: The frames' counts (N >= 1).
        metric: The convention (see the module).
        weights: Float64 (B, N) with a positive sum per row; None: ones (1, N).
        beta2: Weight of recall in F (beta squared), > 0.
        empty: How the per-frame means count a frame without positives
            (:data:`EMPTY_POLICIES`).
        resampled_in_float32: Compute every row but the first in float32,
            several times faster: exact while a sum stays below 2^24 (16.7
            million pixels), about 1e-7 relative error above; meant for
            bootstrap rows, the first row (the sample) staying exact.

    Returns:
        The sums, float64 (B, D).

    Raises:
        EgonetError: If there are no frames, ``weights`` has another shape
            or a row without weight, or ``metric`` or ``empty`` is unknown.
    """
    convention = metric_convention(metric)
    beta2 = check_beta2(beta2)
    if counts.n == 0:
        raise EgonetError("counts: has no frames; score at least one frame", field="counts")
    w = np.ones((1, counts.n)) if weights is None else np.asarray(weights, dtype=np.float64)
    if w.ndim != 2 or w.shape[1] != counts.n or not (w.sum(axis=1) > 0).all():
        raise EgonetError(f"weights: must be (B, {counts.n}) with a positive sum per row, got shape {w.shape}", field="weights")
    features = convention.features(counts, beta2=beta2, empty=check_empty(empty))
    sums = np.empty((w.shape[0], features.shape[1]))
    first = 1 if resampled_in_float32 else w.shape[0]
    sums[:first] = w[:first] @ features
    if first < w.shape[0]:
        fast, fast_features = w[first:].astype(np.float32), features.astype(np.float32)
        out = np.empty((fast.shape[0], features.shape[1]), np.float32)
        # Blocks of ~200,000 products: OpenBLAS computes them on one thread (no spinning threads on a busy server).
        for rows in _blocks(fast.shape[0], size=200_000 // (counts.n * features.shape[1])):
            np.matmul(fast[rows], fast_features, out=out[rows])
        sums[first:] = out
    return sums


def _blocks(total: int, *, size: int) -> list[slice]:
    """Row blocks of ``size`` rows (clamped to 16..256).

    A thousand resamples at once make each temporary a few megabytes (fresh
    pages every time) and a matrix product big enough for OpenBLAS to start
    its threads; blocks keep both in cache and on one core, several times
    less CPU time at the page's sizes (``bench/bench_scores.py``).
    """
    size = int(min(256, max(16, size)))
    return [slice(start, min(start + size, total)) for start in range(0, total, size)]


def reduce_sums(
    sums: np.ndarray, *, metric: str, thresholds: int, beta2: float = 1.0, resampled_in_float32: bool = False
) -> dict[str, np.ndarray]:
    """The second half of :func:`score_frames`: a convention's statistics from weighted sums.

    Args:
        sums: Weighted sums of feature vectors, float64 (B, D), from :func:`weighted_sums`.
        metric: The convention the sums were made for.
        thresholds: The number T of thresholds of the counts.
        beta2: Weight of recall in F (beta squared), > 0.
        resampled_in_float32: Reduce every row but the first in float32
            (about 1e-7 relative error, meant for bootstrap rows).

    Returns:
        ``{statistic: float64 (B,)}``; NaN where a per-frame mean has no
        frame to average (every frame left out).
    """
    convention = metric_convention(metric)
    sums = np.asarray(sums, dtype=np.float64)
    thresholds, beta2 = check_thresholds(thresholds), check_beta2(beta2)
    first = min(1, sums.shape[0]) if resampled_in_float32 else sums.shape[0]
    parts = [convention.reduce(sums[:first], thresholds=thresholds, beta2=beta2)]
    fast = sums[first:].astype(np.float32)
    parts += [convention.reduce(fast[rows], thresholds=thresholds, beta2=beta2) for rows in _blocks(fast.shape[0], size=256)]
    return {key: np.concatenate([np.asarray(part[key], dtype=np.float64) for part in parts]) for key in parts[0]}


def score_frames(
    counts: FrameCounts,
    *,
    metric: str = "pooled",
    weights: np.ndarray | None = None,
    beta2: float = 1.0,
    empty: str = DEFAULT_EMPTY,
) -> dict[str, np.ndarray]:
    """Score the frames under a convention, once per row of ``weights``.

    Args:
        counts: The frames' counts (N >= 1).
        metric: ``"pooled"``, ``"ois-mean"``, ``"mean-curve"`` or
            ``"ods-ois"`` (see the module; ``"per-image"`` is the old name
            of ``"ois-mean"``).
        weights: How many times each frame counts, one score per row,
            float64 (B, N); None scores the frames once each (B = 1).
            Bootstrap multiplicities (:func:`egonet.metrics.resample_weights`)
            give resampled scores.
        beta2: Weight of recall in F (beta squared), > 0.
        empty: How ``ois-mean`` and ``mean-curve`` count a frame without
            positives: ``"leave-out"`` (default), ``"zero"`` or ``"one-if-empty"``.

    Returns:
        ``{statistic: float64 (B,)}``, the convention's statistics (NaN
        where a per-frame mean has no frame left to average).

    Raises:
        EgonetError: If there are no frames, ``weights`` is not (B, N) with
            a positive sum in every row, or ``metric`` or ``empty`` is unknown.
    """
    name, deprecated = resolve_metric(metric)
    if deprecated:
        _log.warning(deprecated)
    sums = weighted_sums(counts, metric=name, weights=weights, beta2=beta2, empty=empty)
    return reduce_sums(sums, metric=name, thresholds=counts.thresholds, beta2=beta2)
