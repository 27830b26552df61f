"""Depth: the frame's depth checked, on the ROI's grid, and colour-plus-depth models.

With a depth map the cut works on four features per pixel: the three colour
channels (0-255) and the depth in metres times ``_Z_SCALE``. Each side
(background, foreground) is a 5-component Gaussian mixture over those four
features, so a colour can belong to the object at one depth and to the
background at another (a white chair in front of a white wall). A pixel
without depth is scored by the mixtures' colour marginals, i.e. by colour
only. A session stores the pair as a ``(2, 105)`` array, background first:
per component the weights (5), means (5x4) and covariances (5x4x4).

The pairwise term (``_DepthGuide.links``, from ``graph._links``) is OpenCV
grabCut's contrast term multiplied by a factor that falls towards 0 where
depth jumps between neighbours, so the cut runs cheaply along depth edges
even where the colours on both sides agree.
"""

from __future__ import annotations

import dataclasses
import math

import cv2
import numpy as np

from egonet.errors import EgonetError
from egonet.grabcut.colour import _COMPONENTS, _SAMPLES, _best_rows, _kmeans_labels, _log_sum_exp
from egonet.grabcut.geometry import _Geometry
from egonet.grabcut.graph import _links

_FEATURES = 4  # r, g, b, scaled depth
_DEPTH_MODEL_SIZE = _COMPONENTS * (1 + _FEATURES + _FEATURES * _FEATURES)
_Z_SCALE = 200.0  # feature units per metre: 5 mm of depth weigh like one colour level
_Z_VAR_FLOOR = 4.0  # least depth variance per component (feature units^2): ~1 cm of sensor noise
_Z_UNKNOWN_VAR = 1e4  # depth variance of a component fitted without depth samples (0.5 m)
_MIN_DEPTH_SAMPLES = 8  # a component needs this many pixels with depth to model depth
_VALID_SHARE = 0.5  # a low-resolution pixel has depth when this share of its footprint has


def _check_depth(depth: object, shape: tuple[int, int]) -> np.ndarray | None:
    """The frame's depth as float32 metres with NaN where missing, or None.

    Raises:
        EgonetError: (field ``depth``) if ``depth`` is not a real ``(H, W)``
            array of the image's size, or has negative or infinite values.
    """
    if depth is None:
        return None
    if not isinstance(depth, np.ndarray):
        raise EgonetError(f"depth: expected a numpy array of metres, got {type(depth).__name__}", field="depth")
    if depth.ndim != 2 or depth.shape != tuple(shape) or not np.issubdtype(depth.dtype, np.floating):
        integer = np.issubdtype(depth.dtype, np.integer)
        hint = " (integer depth is usually millimetres: divide by 1000)" if integer else ""
        raise EgonetError(f"depth: expected a float (H, W) = {tuple(shape)} array in metres (0 or NaN where "
                          f"missing), got {depth.dtype} {depth.shape}{hint}", field="depth")
    # A read-only float32 array (a memory-mapped file, say) is taken as it is
    # unless it has zeros to mark as missing; anything else is copied.
    shared = depth.dtype == np.float32 and not depth.flags.writeable and depth.flags.c_contiguous
    z = depth if shared else depth.astype(np.float32)
    # fmin/fmax skip NaN (missing); one pass each over the frame.
    lo, hi = (float(np.fmin.reduce(z, axis=None)), float(np.fmax.reduce(z, axis=None))) if z.size else (0.0, 0.0)
    if lo < 0 or math.isinf(hi):
        raise EgonetError("depth: values must be metres >= 0 (0 or NaN where missing), got negative or "
                          "infinite ones", field="depth")
    if hi > 1000:
        raise EgonetError(f"depth: expected metres, got values up to {hi:.0f} (millimetres? divide "
                          "by 1000)", field="depth")
    zeros = z == 0
    if zeros.any():
        if z is depth:
            z = z.copy()
        z[zeros] = np.nan
    return z


@dataclasses.dataclass(frozen=True, eq=False)
class _DepthGuide:
    """The ROI's features and pairwise weights at low resolution, with depth.

    Attributes:
        geom: The geometry this guide belongs to.
        features: float64 ``(low_h, low_w, 4)``: colour (0-255) and scaled
            depth (0 where missing).
        valid: bool ``(low_h, low_w)``, where the depth is known.
        links: The 8-neighbour pairwise links ``(p, q, weight)``: flat pixel
            indices ``(M,)`` of each linked pair (each pair once) and its
            float64 weight ``(M,)``.
    """

    geom: _Geometry
    features: np.ndarray
    valid: np.ndarray
    links: tuple[np.ndarray, np.ndarray, np.ndarray]

    @property
    def nbytes(self) -> int:
        return self.features.nbytes + self.valid.nbytes + sum(a.nbytes for a in self.links)

    @classmethod
    def build(cls, geom: _Geometry, image: np.ndarray, depth: np.ndarray) -> _DepthGuide:
        """Args: the geometry, its low-resolution uint8 ROI ``(low_h, low_w, 3)``,
        and the full frame's depth ``(H, W)`` (NaN where missing)."""
        z, valid = _low_depth(depth, geom)
        features = np.empty(image.shape[:2] + (_FEATURES,), np.float64)
        features[..., :3] = image
        features[..., 3] = np.where(valid, z * _Z_SCALE, 0.0)
        return cls(geom, features, valid, _links(features[..., :3], np.where(valid, z, np.nan)))


def _low_depth(depth: np.ndarray, geom: _Geometry) -> tuple[np.ndarray, np.ndarray]:
    """The ROI's depth on the low-resolution grid: the mean of each footprint's known depths.

    Returns:
        ``(z, valid)``: float64 metres ``(low_h, low_w)`` and where at least
        ``_VALID_SHARE`` of the footprint had depth (``z`` is 0 elsewhere).
    """
    rx0, ry0, rx1, ry1 = geom.roi
    crop = depth[ry0:ry1, rx0:rx1]
    known = np.isfinite(crop)
    size = (geom.low_w, geom.low_h)
    total = cv2.resize(np.where(known, crop, 0).astype(np.float32), size, interpolation=cv2.INTER_AREA)
    share = cv2.resize(known.astype(np.float32), size, interpolation=cv2.INTER_AREA)
    valid = share >= _VALID_SHARE
    z = np.where(valid, total / np.maximum(share, 1e-6), 0.0).astype(np.float64)
    return z, valid


# ------------------------------------------------------------------ models


def _unpack_model(model: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(105,)`` -> weights ``(5,)``, means ``(5, 4)``, covariances ``(5, 4, 4)``."""
    k, f = _COMPONENTS, _FEATURES
    return model[:k], model[k : k + k * f].reshape(k, f), model[k + k * f :].reshape(k, f, f)


def _pack_model(weights: np.ndarray, means: np.ndarray, covs: np.ndarray) -> np.ndarray:
    return np.concatenate([weights, means.ravel(), covs.ravel()])


def _fit_components(x: np.ndarray, valid: np.ndarray, labels: np.ndarray, fallback_z: float) -> np.ndarray:
    """A ``(105,)`` mixture from samples ``x (N, 4)`` assigned to components by ``labels (N,)``.

    A component's statistics come from its samples with depth (``valid``);
    one with too few of those models colour from all its samples and depth
    as unknown (a broad Gaussian around ``fallback_z``).
    """
    k, f = _COMPONENTS, _FEATURES
    weights = np.zeros(k)
    means = np.zeros((k, f))
    covs = np.tile(np.eye(f), (k, 1, 1))
    n = max(len(x), 1)
    for j in range(k):
        member = labels == j
        count = int(np.count_nonzero(member))
        if count == 0:
            continue
        weights[j] = count / n
        with_depth = member & valid
        if np.count_nonzero(with_depth) >= _MIN_DEPTH_SAMPLES:
            s = x[with_depth]
            means[j] = s.mean(axis=0)
            c = s - means[j]
            covs[j] = c.T @ c / len(s)
        else:
            s = x[member, :3]
            means[j, :3] = s.mean(axis=0)
            c = s - means[j, :3]
            covs[j] = 0.0
            covs[j, :3, :3] = c.T @ c / len(s)
            means[j, 3] = fallback_z
            covs[j, 3, 3] = _Z_UNKNOWN_VAR
        covs[j, :3, :3] += 0.01 * np.eye(3)  # as OpenCV: keeps a flat colour component invertible
        covs[j, 3, 3] = max(covs[j, 3, 3], _Z_VAR_FLOOR)
    return _pack_model(weights, means, covs)


def _first_model(x: np.ndarray, valid: np.ndarray, fallback_z: float, rng: np.random.Generator) -> np.ndarray:
    """A side's first mixture: k-means on a fixed-seed sample of its pixels."""
    if len(x) > _SAMPLES:
        pick = rng.choice(len(x), _SAMPLES, replace=False)
        x, valid = x[pick], valid[pick]
    if len(x) == 0:
        return _fit_components(np.zeros((1, _FEATURES)), np.zeros(1, bool), np.zeros(1, np.intp), fallback_z)
    # Cluster on the samples with depth when there are enough, so the depth
    # feature shapes the components; the others join their nearest colour.
    use = valid if np.count_nonzero(valid) >= _COMPONENTS * _MIN_DEPTH_SAMPLES else np.ones(len(x), bool)
    dims = slice(None) if use is valid else slice(0, 3)
    labels_used = _kmeans_labels(x[use][:, dims], min(_COMPONENTS, int(np.count_nonzero(use))), rng)
    labels = np.empty(len(x), np.intp)
    labels[use] = labels_used
    if not use.all():
        centres = np.array([x[use][labels_used == j, :3].mean(axis=0) if (labels_used == j).any()
                            else np.full(3, np.inf) for j in range(_COMPONENTS)])
        rest = x[~use, :3]
        labels[~use] = ((rest[:, None, :] - centres[None]) ** 2).sum(axis=2).argmin(axis=1)
    return _fit_components(x, valid, labels, fallback_z)


def _component_scores(model: np.ndarray, x: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """``log(weight_k * N_k(x))`` for every component and sample, float32 ``(5, N)``, component-major.

    Samples with depth use all four features, the others the colour
    marginal (the first three). The per-pixel products run in float32
    (twice as fast; the scores only rank components and feed the cut's
    weights). Component-major as ``colour._component_logs``.
    """
    weights, means, covs = _unpack_model(model)
    out = np.full((_COMPONENTS, len(x)), -np.inf, np.float32)
    live = np.flatnonzero(weights > 0)
    if not len(live):
        return out
    for rows, dims in ((valid, _FEATURES), (~valid, 3)):
        every = bool(rows.all())
        picked = None if every else np.flatnonzero(rows)
        if picked is not None and not len(picked):
            continue
        # Whitening: with C = L L^T, the Mahalanobis distance is |L^-1 (x - mu)|^2.
        # All components in one product: (k * dims, dims) @ (dims, n).
        chol = np.linalg.cholesky(covs[live][:, :dims, :dims])
        whiten = np.linalg.inv(chol)  # (k, dims, dims)
        shift = np.einsum("kij,kj->ki", whiten, means[live, :dims])
        samples = x[:, :dims] if every else x[picked, :dims]
        y = whiten.reshape(-1, dims).astype(np.float32) @ samples.astype(np.float32).T
        y -= shift.reshape(-1, 1).astype(np.float32)
        y *= y
        y = y.reshape(len(live), dims, -1)
        scores = y.sum(axis=1)
        scores *= np.float32(-0.5)
        scores += (np.log(weights[live]) - np.log(np.diagonal(chol, axis1=1, axis2=2)).sum(axis=1)
                   - 0.5 * dims * math.log(2 * math.pi)).astype(np.float32)[:, None]
        if every and len(live) == _COMPONENTS:
            return scores
        if every:
            out[live] = scores
        else:
            out[np.ix_(live, picked)] = scores
    return out


def _neg_log_likelihood(scores: np.ndarray) -> np.ndarray:
    """``-log p(x)`` (float64) of a mixture from its component scores ``(5, N)`` (changed)."""
    return -_log_sum_exp(scores)


def _fallback_z(guide: _DepthGuide) -> float:
    return float(guide.features[..., 3][guide.valid].mean()) if guide.valid.any() else 0.0


def _learn_depth(guide: _DepthGuide, bg: np.ndarray, fg: np.ndarray, models: np.ndarray) -> np.ndarray:
    """Both ``(2, 105)`` models re-estimated from the ROI's flat pixels ``bg`` and ``fg`` (both non-empty).

    Each pixel joins its most likely component of its own side and the
    models are refitted from those (OpenCV's learning step, with depth).
    """
    x = guide.features.reshape(-1, _FEATURES)
    valid = guide.valid.ravel()
    fallback = _fallback_z(guide)
    out = []
    for model, side in ((models[0], bg), (models[1], fg)):
        xs, vs = x[side], valid[side]
        out.append(_fit_components(xs, vs, _best_rows(_component_scores(model, xs, vs)), fallback))
    return np.stack(out)


def _depth_costs(guide: _DepthGuide, models: np.ndarray, pixels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``-log p`` of the flat ``pixels`` under the background and the foreground model."""
    x = guide.features.reshape(-1, _FEATURES)[pixels]
    valid = guide.valid.ravel()[pixels]
    return (_neg_log_likelihood(_component_scores(models[0], x, valid)),
            _neg_log_likelihood(_component_scores(models[1], x, valid)))
