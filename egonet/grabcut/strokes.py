"""Brush strokes: checking them, their pixels on a grid, and the stroke record.

A stroke covers the pixels whose distance to its polyline is at most its
radius. The same rasterisation serves the full-resolution frame
(``stroke_footprint``, and the session's hard constraints) and the
low-resolution grid of the graph cut (``_Guide.footprint``).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np

from egonet.errors import EgonetError

#: Stroke labels accepted by ``GrabCutSession.stroke``.
LABELS = ("fg", "bg")


def _polyline_distance_mask(
    shape: tuple[int, int], points: np.ndarray, radius: float
) -> tuple[np.ndarray, tuple[int, int]] | None:
    """Pixels within ``radius`` of a polyline, as a crop and its origin.

    Args:
        shape: ``(H, W)`` of the pixel grid.
        points: ``(K, 2)`` float ``(x, y)`` in grid coordinates.
        radius: Distance in grid pixels.

    Returns:
        ``(crop, (y0, x0))`` with ``crop`` a bool array placed at ``(y0, x0)``,
        or ``None`` when no pixel of the grid is covered.
    """
    h, w = shape
    lo = np.floor(points.min(axis=0) - radius).astype(int)
    hi = np.ceil(points.max(axis=0) + radius).astype(int) + 1
    x0, y0 = max(int(lo[0]), 0), max(int(lo[1]), 0)
    x1, y1 = min(int(hi[0]), w), min(int(hi[1]), h)
    if x0 >= x1 or y0 >= y1:
        return None
    crop = np.zeros((y1 - y0, x1 - x0), bool)
    r2 = radius * radius
    segments = [(points[0], points[0])] if len(points) == 1 else zip(points[:-1], points[1:])
    for a, b in segments:
        # Each segment only touches its own bounding box (plus the radius).
        sx0 = max(int(math.floor(min(a[0], b[0]) - radius)), x0)
        sy0 = max(int(math.floor(min(a[1], b[1]) - radius)), y0)
        sx1 = min(int(math.ceil(max(a[0], b[0]) + radius)) + 1, x1)
        sy1 = min(int(math.ceil(max(a[1], b[1]) + radius)) + 1, y1)
        if sx0 >= sx1 or sy0 >= sy1:
            continue
        xs = np.arange(sx0, sx1, dtype=np.float64)[None, :] - a[0]
        ys = np.arange(sy0, sy1, dtype=np.float64)[:, None] - a[1]
        d = b - a
        dd = float(d @ d)
        if dd > 0:
            t = np.clip((xs * d[0] + ys * d[1]) / dd, 0.0, 1.0)
            dist2 = (xs - t * d[0]) ** 2 + (ys - t * d[1]) ** 2
        else:
            dist2 = xs**2 + ys**2
        crop[sy0 - y0 : sy1 - y0, sx0 - x0 : sx1 - x0] |= dist2 <= r2
    if not crop.any():
        return None
    return crop, (y0, x0)


def _check_points(points: object, name: str = "points") -> np.ndarray:
    try:
        arr = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise EgonetError(f"{name}: expected a list of (x, y) pairs, got {points!r:.80}", field=name) from exc
    if arr.ndim == 1 and arr.size == 2:
        arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] != 2:
        raise EgonetError(f"{name}: expected a list of (x, y) pairs, got shape {arr.shape}", field=name)
    if len(arr) == 0:
        raise EgonetError(f"{name}: a stroke needs at least one (x, y) point", field=name)
    if not np.isfinite(arr).all():
        raise EgonetError(f"{name}: coordinates must be finite numbers", field=name)
    return arr


def _check_radius(radius: object) -> float:
    if isinstance(radius, bool) or not isinstance(radius, (int, float, np.integer, np.floating)):
        raise EgonetError(f"radius: expected a number of pixels, got {radius!r}", field="radius")
    r = float(radius)
    if not math.isfinite(r) or r <= 0:
        raise EgonetError(f"radius: must be a positive number of pixels, got {radius!r}", field="radius")
    return r


def stroke_footprint(shape: tuple[int, int], points: Sequence[Sequence[float]] | np.ndarray,
                     radius: float) -> np.ndarray:
    """The pixels a brush stroke covers.

    A pixel ``(x, y)`` (column ``x``, row ``y``, at integer coordinates) is
    covered when its distance to the polyline through ``points`` is at most
    ``radius``. One point gives a disk.

    Args:
        shape: ``(H, W)`` of the frame.
        points: ``(x, y)`` pixel coordinates of the polyline, at least one.
        radius: Brush radius in pixels, > 0.

    Returns:
        Bool ``(H, W)`` mask of the covered pixels (all False if the stroke
        lies outside the frame).

    Example:
        >>> stroke_footprint((5, 5), [(2, 2)], 1).astype(int).tolist()[1:4]
        [[0, 0, 1, 0, 0], [0, 1, 1, 1, 0], [0, 0, 1, 0, 0]]
    """
    if len(shape) != 2 or min(int(shape[0]), int(shape[1])) <= 0:
        raise EgonetError(f"shape: expected (H, W) with H, W > 0, got {shape!r}", field="shape")
    pts = _check_points(points)
    r = _check_radius(radius)
    out = np.zeros((int(shape[0]), int(shape[1])), bool)
    hit = _polyline_distance_mask(out.shape, pts, r)
    if hit is not None:
        crop, (y0, x0) = hit
        out[y0 : y0 + crop.shape[0], x0 : x0 + crop.shape[1]] = crop
    return out


@dataclasses.dataclass(frozen=True, eq=False)
class _Stroke:
    """One stroke as given (compared and hashed by identity: undo levels share them)."""

    points: np.ndarray  # (K, 2) float64, (x, y) full resolution
    fg: bool
    radius: float
