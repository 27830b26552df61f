"""The thresholds every score uses, the per-threshold counts, and the checks of their parameters.

``T`` thresholds ``t_k = k / (T + 1)`` for ``k = 1..T`` (99 thresholds
``0.01 .. 0.99`` by default), each a float64.
"""

from __future__ import annotations

from functools import lru_cache
from typing import NamedTuple

import numpy as np

from egonet.errors import EgonetError

DEFAULT_THRESHOLDS = 99


class Counts(NamedTuple):
    """Per-threshold confusion counts of one map or of several pooled maps.

    Attributes:
        tp: True positives at each threshold, int64 (T,).
        fp: False positives at each threshold, int64 (T,).
        fn: False negatives at each threshold, int64 (T,).
    """

    tp: np.ndarray
    fp: np.ndarray
    fn: np.ndarray


def check_thresholds(thresholds: int) -> int:
    """``thresholds`` as an int, or an error naming it (a positive int up to 1,000,000)."""
    if isinstance(thresholds, bool) or not isinstance(thresholds, (int, np.integer)):
        raise EgonetError(
            f"thresholds must be a positive int (the number T of thresholds k/(T+1)), got {thresholds!r}", field="thresholds"
        )
    if thresholds < 1 or thresholds > 1_000_000:
        raise EgonetError(f"thresholds must be between 1 and 1000000, got {thresholds}", field="thresholds")
    return int(thresholds)


def check_beta2(beta2: float) -> float:
    """``beta2`` as a float, or an error naming it (a positive finite number)."""
    if isinstance(beta2, bool) or not isinstance(beta2, (int, float, np.integer, np.floating)):
        raise EgonetError(f"beta2 must be a positive number, got {beta2!r}", field="beta2")
    if not np.isfinite(beta2) or beta2 <= 0:
        raise EgonetError(f"beta2 must be a positive finite number, got {beta2}", field="beta2")
    return float(beta2)


@lru_cache(maxsize=16)
def thresholds_cached(thresholds: int) -> np.ndarray:
    """The thresholds of a checked ``thresholds``, read-only float64 (T,)."""
    t = np.arange(1, thresholds + 1, dtype=np.float64) / (thresholds + 1)
    t.setflags(write=False)
    return t


def threshold_values(thresholds: int = DEFAULT_THRESHOLDS) -> np.ndarray:
    """Return the thresholds ``t_k = k / (T + 1)``, ``k = 1..T``.

    Args:
        thresholds: The number T of thresholds.

    Returns:
        Increasing float64 thresholds, read-only, shape (T,).

    Raises:
        EgonetError: If ``thresholds`` is not a positive int.

    Example:
        >>> threshold_values(3)
        array([0.25, 0.5 , 0.75])
    """
    return thresholds_cached(check_thresholds(thresholds))
