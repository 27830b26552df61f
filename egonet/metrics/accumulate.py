"""Counting a map's confusion counts at every threshold, streaming maps, and scoring them in one call.

A pixel is predicted positive at ``t_k`` when ``prob >= t_k``; the
comparison is exact (a float32 probability is compared with the float64
threshold without rounding either), so a probability exactly equal to
``t_k`` is positive at ``t_k``. Maps are never normalised before
thresholding: a map whose values all lie below 0.01 predicts nothing.

The work is split as in smp's ``get_stats`` / ``fbeta_score``: sufficient
statistics first (:func:`count_stats` gives per-threshold TP/FP/FN of one map
from a single histogram pass), then a reduction (:meth:`Score.from_counts`,
:meth:`Score.from_curves`). :class:`ScoreAccumulator` keeps each map's
counts (:class:`~egonet.metrics.frames.FrameCounts`), so a caller can stream
an activity, merge activities, and score under any convention at the end.
:func:`score_maps` is the one-call entry point.

Example:
    >>> import numpy as np
    >>> prob = np.array([[0.9, 0.2], [0.6, 0.0]], dtype=np.float32)
    >>> mask = np.array([[True, False], [True, False]])
    >>> s = score_maps([prob], [mask])
    >>> round(s.max_f, 3), round(s.ap, 3)
    (1.0, 1.0)
"""

from __future__ import annotations

import logging
from collections.abc import Iterable, Mapping

import numpy as np

from egonet.errors import EgonetError
from egonet.metrics.curves import Score
from egonet.metrics.frames import DEFAULT_EMPTY, FrameCounts, check_empty, frame_curves
from egonet.metrics.thresholds import DEFAULT_THRESHOLDS, Counts, check_beta2, check_thresholds, thresholds_cached

_STATE_KEYS = ("tp", "fp", "positives")
CURVE_METRICS = ("pooled", "mean-curve")
"""The conventions with one precision-recall curve, which :func:`score_maps` returns."""
_log = logging.getLogger(__name__)


def _bin_index(prob: np.ndarray, thresholds: int) -> np.ndarray:
    """Number of thresholds each probability reaches, ``#{k: t_k <= p}``.

    ``floor(p * (T + 1))`` is that number except where the rounded product
    lies within a few ulps of an integer ``k >= 1`` (a probability on or next
    to a threshold, or 1.0). Those few pixels are recomputed exactly with a
    float64 search, so the result is exact for every input while the common
    path costs a multiply and a cast in the map's own precision.

    Args:
        prob: Probabilities in [0, 1], float32 or float64, any shape.
        thresholds: The number T of thresholds.

    Returns:
        Bin indices in ``0..T``, flat, int16 when ``2 (T + 1)`` fits, else
        int64 (shape (prob.size,)).
    """
    flat = prob.reshape(-1)
    dtype = flat.dtype.type
    n_bins = thresholds + 1
    index_type = np.int16 if 2 * n_bins < np.iinfo(np.int16).max else np.int64
    scaled = np.multiply(flat, dtype(n_bins))
    bins = scaled.astype(index_type)
    # The rounding error of the product is at most half an ulp of T + 1; four
    # ulps is a safe margin for "close to an integer".
    eps = dtype(4 * np.spacing(dtype(n_bins)))
    nearest = np.rint(scaled)
    near = nearest >= 1
    np.subtract(scaled, nearest, out=nearest)
    np.abs(nearest, out=nearest)
    near &= nearest <= eps
    if near.any():
        where = np.flatnonzero(near)
        exact = np.searchsorted(thresholds_cached(thresholds), flat[where].astype(np.float64), side="right")
        bins[where] = exact
    np.minimum(bins, index_type(thresholds), out=bins)
    return bins


def _as_prob(prob: object, name: str) -> np.ndarray:
    arr = np.asarray(prob)
    if arr.ndim != 2:
        raise EgonetError(f"{name} must be a 2-D probability map (H, W), got shape {arr.shape}", field=name)
    if arr.dtype == np.float16:
        arr = arr.astype(np.float32)
    elif arr.dtype not in (np.float32, np.float64):
        raise EgonetError(
            f"{name} must be a float32 or float64 map of probabilities in [0, 1], got dtype {arr.dtype}; "
            "convert scores to probabilities first (never min-max normalise them)",
            field=name,
        )
    if arr.size:
        lo, hi = arr.min(), arr.max()
        if np.isnan(lo) or np.isnan(hi):
            raise EgonetError(f"{name} contains NaN", field=name)
        if lo < 0 or hi > 1:
            raise EgonetError(f"{name} must lie in [0, 1], got values in [{lo}, {hi}]", field=name)
    return arr


def _as_mask(mask: object, name: str, shape: tuple[int, ...]) -> np.ndarray:
    arr = np.asarray(mask)
    if arr.dtype != np.bool_:
        raise EgonetError(f"{name} must be a bool mask, got dtype {arr.dtype}; pass mask > 0 or mask.astype(bool)", field=name)
    if arr.shape != shape:
        raise EgonetError(f"{name} has shape {arr.shape} but its probability map has shape {shape}", field=name)
    return arr


def _count(prob: np.ndarray, mask: np.ndarray, thresholds: int) -> Counts:
    n_bins = thresholds + 1
    bins = _bin_index(prob, thresholds)
    # One histogram for negatives (bins 0..T) and positives (T+1..2T+1).
    offset = mask.reshape(-1).view(np.int8).astype(bins.dtype)
    offset *= bins.dtype.type(n_bins)
    bins += offset
    hist = np.bincount(bins, minlength=2 * n_bins).reshape(2, n_bins)
    # Reverse cumulative sums: pixels reaching at least threshold k.
    above = np.cumsum(hist[:, ::-1], axis=1)[:, ::-1]
    tp = above[1, 1:].astype(np.int64)
    fp = above[0, 1:].astype(np.int64)
    fn = np.int64(above[1, 0]) - tp
    return Counts(tp, fp, fn)


def count_stats(prob: np.ndarray, mask: np.ndarray, *, thresholds: int = DEFAULT_THRESHOLDS, name: str = "prob") -> Counts:
    """Count TP, FP and FN of one map at every threshold in one pass.

    Args:
        prob: Probability map in [0, 1], float (H, W). Not normalised.
        mask: Ground truth, bool (H, W).
        thresholds: The number T of thresholds ``k / (T + 1)``.
        name: How error messages name the map (e.g. ``"prob of frame 3"``).

    Returns:
        :class:`Counts` with int64 arrays of shape (T,); sum several with
        ``np.add`` (or a :class:`ScoreAccumulator`) to pool maps.

    Raises:
        ValueError: If ``prob`` is not a 2-D float map in [0, 1] (or holds
            NaN), ``mask`` is not bool of the same shape, or ``thresholds`` is
            not a positive int.

    Example:
        >>> prob = np.array([[0.25, 0.5], [0.75, 1.0]])
        >>> mask = np.array([[False, True], [True, True]])
        >>> count_stats(prob, mask, thresholds=3).tp
        array([3, 3, 2])
    """
    thresholds = check_thresholds(thresholds)
    prob = _as_prob(prob, name)
    mask = _as_mask(mask, _mask_name(name), prob.shape)
    return _count(prob, mask, thresholds)


def _mask_name(name: str) -> str:
    return name.replace("prob", "mask", 1) if name.startswith("prob") else f"mask of {name}"


class ScoreAccumulator:
    """Streams maps in, keeps each map's counts, scores at the end.

    Holds every map's per-threshold counts (a few kilobytes a map), so the
    pooled curve, the mean curve and the per-frame conventions
    (:func:`~egonet.metrics.score_frames` on :meth:`frames`) all come from
    the same pass, and accumulators of several activities can be merged.

    Args:
        thresholds: The number T of thresholds ``k / (T + 1)``.

    Example:
        >>> acc = ScoreAccumulator(thresholds=3)
        >>> _ = acc.add(np.array([[0.8, 0.1]]), np.array([[True, False]]))
        >>> acc.score().max_f
        1.0
    """

    def __init__(self, *, thresholds: int = DEFAULT_THRESHOLDS) -> None:
        self.thresholds = check_thresholds(thresholds)
        self._maps: list[Counts] = []

    @property
    def n_maps(self) -> int:
        """How many maps were added."""
        return len(self._maps)

    @property
    def counts(self) -> Counts:
        """The counts pooled over every map, int64 (T,) each."""
        return self.frames().pooled()

    def frames(self) -> FrameCounts:
        """Every map's counts, in the order they were added."""
        return FrameCounts.stack(self._maps, thresholds=self.thresholds)

    def add(self, prob: np.ndarray, mask: np.ndarray, *, name: str = "prob") -> Counts:
        """Count one map and add it.

        Args:
            prob: Probability map in [0, 1], float (H, W).
            mask: Ground truth, bool (H, W).
            name: How error messages name the map (e.g. ``"probs[3]"``).

        Returns:
            The map's own :class:`Counts`.

        Raises:
            ValueError: As :func:`count_stats`.
        """
        prob = _as_prob(prob, name)
        mask = _as_mask(mask, _mask_name(name), prob.shape)
        counts = _count(prob, mask, self.thresholds)
        self.add_counts(counts)
        return counts

    def add_counts(self, counts: Counts) -> None:
        """Add the counts of one map computed elsewhere (e.g. a worker).

        Args:
            counts: Counts of a single map, arrays (T,).

        Raises:
            ValueError: If the counts do not have T entries.
        """
        arrays = [np.array(c, dtype=np.int64) for c in counts]
        if any(a.shape != (self.thresholds,) for a in arrays):
            raise EgonetError(f"counts must hold arrays of shape ({self.thresholds},)", field="counts")
        self._maps.append(Counts(*arrays))

    def merge(self, other: ScoreAccumulator) -> None:
        """Add everything another accumulator has seen (e.g. another activity).

        Args:
            other: An accumulator with the same number of thresholds.

        Raises:
            ValueError: If the numbers of thresholds differ.
        """
        if other.thresholds != self.thresholds:
            raise EgonetError(f"other has {other.thresholds} thresholds, this accumulator {self.thresholds}", field="other")
        self._maps.extend(other._maps)

    def state(self) -> dict[str, np.ndarray]:
        """The maps' counts as plain arrays, to store and restore later.

        Returns:
            ``{"tp", "fp"}``: int64 (N, T) and ``"positives"``: int64 (N,),
            copies; :meth:`from_state` turns them back into an accumulator.

        Example:
            >>> acc = ScoreAccumulator(thresholds=3)
            >>> _ = acc.add(np.array([[0.8, 0.1]]), np.array([[True, False]]))
            >>> acc.state()["tp"], acc.state()["positives"]
            (array([[1, 1, 1]]), array([1]))
        """
        frames = self.frames()
        return {key: getattr(frames, key).copy() for key in _STATE_KEYS}

    @classmethod
    def from_state(cls, state: Mapping[str, object], *, thresholds: int = DEFAULT_THRESHOLDS) -> ScoreAccumulator:
        """An accumulator holding the counts :meth:`state` returned.

        Args:
            state: ``tp``, ``fp`` ((N, T) array-likes; lists read back from
                JSON do) and ``positives`` ((N,)).
            thresholds: The number T of thresholds the counts must have.

        Returns:
            The accumulator, ready to add, merge or score.

        Raises:
            EgonetError: If a key is missing or the counts do not have T
                thresholds (saved with another number of thresholds).
        """
        missing = [key for key in _STATE_KEYS if key not in state]
        if missing:
            raise EgonetError(f"state: has no {missing[0]!r}; pass what ScoreAccumulator.state() returned", field="state")
        acc = cls(thresholds=thresholds)
        tp, fp, positives = (np.array(state[key], dtype=np.int64) for key in _STATE_KEYS)
        if tp.size == 0:
            return acc
        if tp.ndim != 2 or tp.shape[1] != acc.thresholds:
            raise EgonetError(f"state: the counts do not have {acc.thresholds} thresholds", field="state")
        frames = FrameCounts(tp, fp, positives)  # checks the shapes
        acc._maps = [Counts(frames.tp[i], frames.fp[i], frames.positives[i] - frames.tp[i]) for i in range(frames.n)]
        return acc

    def score(self, *, beta2: float = 1.0, metric: str = "pooled", empty: str = DEFAULT_EMPTY, per_image: bool | None = None) -> Score:
        """Reduce the counts to a :class:`Score` (one curve: ``"pooled"`` or ``"mean-curve"``).

        Args:
            beta2: Weight of recall in F (beta squared), > 0.
            metric: ``"pooled"`` (counts summed over maps) or
                ``"mean-curve"`` (each map's P and R averaged over maps).
            empty: How the mean curve counts a map without positives
                (``egonet.metrics.frames.EMPTY_POLICIES``).
            per_image: Deprecated (goes in the next release): True is
                ``metric="mean-curve"``, False ``"pooled"``.

        Returns:
            The score.

        Raises:
            ValueError: If no map was added, ``beta2`` is not positive,
                ``metric`` has no single curve, or every map of a
                ``"leave-out"`` mean curve is without positives.
        """
        if per_image is not None:
            metric = "mean-curve" if per_image else "pooled"
            _log.warning("per_image= is deprecated and goes in the next release: use metric=%r", metric)
        if metric not in CURVE_METRICS:
            raise EgonetError(
                f"metric: must be one of {', '.join(CURVE_METRICS)} for one curve, got {metric!r}; "
                "score_frames scores the other conventions",
                field="metric",
            )
        if self.n_maps == 0:
            raise EgonetError("no maps were added; score at least one map", field="probs")
        frames = self.frames()
        no_positives = int(np.count_nonzero(frames.positives == 0))
        if metric == "pooled":
            return Score.from_counts(frames.pooled(), beta2=beta2, n_maps=self.n_maps, empty_maps=no_positives)
        precision, recall, counted = frame_curves(frames, empty=check_empty(empty))
        if not counted.any():
            raise EgonetError(
                "empty: every map is without positive pixels, so leaving them out leaves nothing to average; "
                "use empty='zero' or 'one-if-empty'",
                field="empty",
            )
        return Score.from_curves(
            precision[counted].mean(axis=0), recall[counted].mean(axis=0), beta2=beta2, metric=metric,
            n_maps=self.n_maps, empty=empty, empty_maps=no_positives,
        )  # fmt: skip


def score_maps(
    probs: Iterable[np.ndarray],
    masks: Iterable[np.ndarray],
    *,
    thresholds: int = DEFAULT_THRESHOLDS,
    beta2: float = 1.0,
    metric: str = "pooled",
    empty: str = DEFAULT_EMPTY,
    per_image: bool | None = None,
) -> Score:
    """Score probability maps against ground-truth masks (MF and AP).

    Definitions (see the module docstring for the full statement):
    thresholds ``t_k = k / (T + 1)``, ``k = 1..T`` (float64), a pixel is
    positive at ``t_k`` when ``prob >= t_k``; ``"pooled"`` sums TP/FP/FN over
    all pixels of all maps, ``P = TP / (TP + FP)`` (1 when nothing is
    predicted), ``R = TP / (TP + FN)`` (0 when there are no positives);
    ``F = (1 + beta2) P R / (beta2 P + R)`` (0 when ``P + R = 0``),
    ``MF = max F``; ``AP = sum_k (R_k - R_{k+1}) P_k`` with increasing
    thresholds and ``R_{T+1} = 0``; ``"mean-curve"`` averages each map's P
    and R over the maps at each threshold before computing F and AP (maps
    without positives as ``empty`` says). Maps are never normalised.

    Both arguments are consumed lazily, one pair at a time, so a generator
    can stream a whole activity through without holding it in memory. Map
    sizes may differ between pairs.

    Args:
        probs: Probability maps in [0, 1], float (H, W) each.
        masks: Ground-truth masks, bool (H, W) each, the same size as the
            paired map.
        thresholds: The number T of thresholds (99 gives 0.01 .. 0.99).
        beta2: Weight of recall in F (beta squared); 1 gives F1.
        metric: ``"pooled"`` (default) or ``"mean-curve"``.
        empty: For ``"mean-curve"``, how a map without positive pixels
            counts: ``"leave-out"`` (default), ``"zero"`` or ``"one-if-empty"``.
        per_image: Deprecated (goes in the next release): True is
            ``metric="mean-curve"``.

    Returns:
        The :class:`Score`; its ``empty_maps`` says how many maps had no
        positive pixels.

    Raises:
        ValueError: If there are no maps, the two iterables differ in length,
            a map is not a 2-D float map in [0, 1] (or holds NaN), a mask is
            not bool or not the size of its map (the message names the index),
            or ``thresholds`` / ``beta2`` / ``metric`` / ``empty`` are invalid.

    Example:
        >>> probs = [np.array([[0.9, 0.4, 0.2, 0.0]])]
        >>> masks = [np.array([[True, True, False, False]])]
        >>> s = score_maps(probs, masks)
        >>> s.max_f, s.best_threshold
        (1.0, 0.21)
    """
    beta2 = check_beta2(beta2)
    acc = ScoreAccumulator(thresholds=thresholds)
    prob_iter, mask_iter = iter(probs), iter(masks)
    sentinel = object()
    index = 0
    while True:
        prob = next(prob_iter, sentinel)
        mask = next(mask_iter, sentinel)
        if prob is sentinel and mask is sentinel:
            break
        if prob is sentinel or mask is sentinel:
            longer = "masks" if prob is sentinel else "probs"
            raise EgonetError(f"probs and masks differ in length: {longer} has more than {index} items", field=longer)
        acc.add(prob, mask, name=f"probs[{index}]")
        index += 1
    if index == 0:
        raise EgonetError("probs is empty: score at least one map", field="probs")
    return acc.score(beta2=beta2, metric=metric, empty=empty, per_image=per_image)
