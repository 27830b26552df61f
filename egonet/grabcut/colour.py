"""Colour models: the foreground and background Gaussian mixtures of a cut.

Each model is a 5-component colour GMM in OpenCV grabCut's ``(1, 65)`` layout
(weights, means, covariances), so ``cv2.grabCut`` can take it, re-estimate it
and hand it back. A session stores the pair as a ``(2, 65)`` array:
background first, foreground second. The first models of a box come from
k-means on a fixed-seed sample of each side (plain grabCut runs k-means on
every pixel, which is most of its cost).
"""

from __future__ import annotations

import cv2
import numpy as np

_COMPONENTS = 5  # OpenCV's grabCut uses 5 Gaussians per colour model
_MODEL_SIZE = 13 * _COMPONENTS  # weights (5), means (5x3), covariances (5x3x3)
_SAMPLES = 4000  # pixels per class for the initial k-means


def _kmeans_labels(x: np.ndarray, k: int, rng: np.random.Generator, iterations: int = 10) -> np.ndarray:
    """k-means++ then Lloyd iterations on ``(N, 3)`` samples; returns labels."""
    centres = [x[rng.integers(len(x))]]
    d2 = ((x - centres[0]) ** 2).sum(axis=1)
    for _ in range(1, k):
        total = d2.sum()
        if total <= 0:
            break
        centres.append(x[rng.choice(len(x), p=d2 / total)])
        d2 = np.minimum(d2, ((x - centres[-1]) ** 2).sum(axis=1))
    c = np.array(centres)
    labels = np.full(len(x), -1, np.intp)
    norms = np.einsum("nd,nd->n", x, x)[:, None]
    for _ in range(iterations):
        # |x - c|^2 = |x|^2 - 2 x.c + |c|^2, all centres in one product.
        new = (norms - 2 * (x @ c.T) + np.einsum("kd,kd->k", c, c)).argmin(axis=1)
        if np.array_equal(new, labels):
            break
        labels = new
        counts = np.bincount(labels, minlength=len(c))
        for d in range(x.shape[1]):
            sums = np.bincount(labels, x[:, d], minlength=len(c))
            c[counts > 0, d] = sums[counts > 0] / counts[counts > 0]
    return labels


def _fit_model(pixels: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A 5-component colour GMM in OpenCV grabCut's (1, 65) layout."""
    if len(pixels) > _SAMPLES:
        pixels = pixels[rng.choice(len(pixels), _SAMPLES, replace=False)]
    x = pixels.astype(np.float64)
    labels = _kmeans_labels(x, min(_COMPONENTS, len(x)), rng)
    weights = np.zeros(_COMPONENTS)
    means = np.zeros((_COMPONENTS, 3))
    covs = np.zeros((_COMPONENTS, 3, 3))
    for j in range(_COMPONENTS):
        members = x[labels == j]
        if len(members) == 0:
            covs[j] = np.eye(3)
            continue
        weights[j] = len(members) / len(x)
        means[j] = members.mean(axis=0)
        centred = members - means[j]
        covs[j] = centred.T @ centred / len(members) + 0.01 * np.eye(3)
    return np.concatenate([weights, means.ravel(), covs.ravel()])[None, :]


def _first_models(image: np.ndarray, gc: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """``(2, 65)`` background and foreground models of a box's first cut, from
    its ``GC_BGD`` and ``GC_PR_FGD`` pixels."""
    pixels = image.reshape(-1, 3)
    flat = gc.ravel()
    return np.concatenate([_fit_model(pixels[flat == cv2.GC_BGD], rng), _fit_model(pixels[flat == cv2.GC_PR_FGD], rng)])


def _unpack_model(model: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(65,)`` -> weights ``(5,)``, means ``(5, 3)``, covariances ``(5, 3, 3)``."""
    k = _COMPONENTS
    return model[:k], model[k : 4 * k].reshape(k, 3), model[4 * k :].reshape(k, 3, 3)


def _component_logs(model: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``log N_k(x)`` of every non-empty component and sample, and those components.

    Without the mixture's weights and without the ``(2 pi)^-3/2`` every
    component shares (OpenCV's ``GMM::operator()(ci, color)``, in logs).

    Returns:
        ``(logs, live)``: ``(k, N)`` in ``x``'s type, component-major, and
        the indices ``(k,)`` of the components with weight (k >= 1 for a
        fitted model).
    """
    weights, means, covs = _unpack_model(model)
    live = np.flatnonzero(weights > 0)
    k = len(live)
    # With C = L L^T the Mahalanobis distance is |L^-1 (x - mu)|^2: all
    # components in one product (3k, 3) @ (3, N). Component-major rows make
    # the sums over a component's squares, and the maxima and sums over
    # components, elementwise operations on whole rows (several times faster
    # than reductions over a short last axis). The products run in the
    # samples' type: float32 for the session's pixels (integers, so exact),
    # twice as fast as float64.
    chol = np.linalg.cholesky(covs[live])
    whiten = np.linalg.inv(chol)  # (k, 3, 3)
    y = whiten.reshape(3 * k, 3).astype(x.dtype) @ x.T
    y -= np.einsum("kij,kj->ki", whiten, means[live]).reshape(-1, 1).astype(x.dtype)
    y *= y
    y = y.reshape(k, 3, -1)
    logs = y[:, 0] + y[:, 1]
    logs += y[:, 2]
    logs += (2 * np.log(np.diagonal(chol, axis1=1, axis2=2)).sum(axis=1)).astype(x.dtype)[:, None]
    logs *= -0.5
    return logs, live


def _best_rows(scores: np.ndarray) -> np.ndarray:
    """``scores.argmax(axis=0)`` of a few rows ``(k, N)``, a row at a time (the first best wins ties, as argmax)."""
    best = scores[0].copy()
    index = np.zeros(scores.shape[1], np.intp)
    for j in range(1, len(scores)):
        better = scores[j] > best
        index[better] = j
        np.maximum(best, scores[j], out=best)
    return index


def _log_sum_exp(scores: np.ndarray) -> np.ndarray:
    """``log(sum(exp(scores), axis=0))`` (float64) of component-major scores ``(k, N)``; changes ``scores``."""
    top = scores.max(axis=0)
    scores -= top
    np.exp(scores, out=scores)
    return top.astype(np.float64) + np.log(scores.sum(axis=0), dtype=np.float64)


def _costs(model: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``-log p(x)`` (float64) of each sample ``(N, 3)`` under the mixture ``model`` (65,): cv2.grabCut's data term."""
    logs, live = _component_logs(model, x)
    logs += np.log(model[live]).astype(logs.dtype)[:, None]
    return -_log_sum_exp(logs)


def _refit(x: np.ndarray, model: np.ndarray) -> np.ndarray:
    """One side's mixture re-estimated from its samples ``x (N, 3)`` (``N`` > 0), starting from ``model``.

    OpenCV grabCut's learning step: each sample joins its most likely
    component (by density, not weighted), and each component is refitted
    from its members; a component's covariance gets 0.01 on its diagonal
    when it is (nearly) singular.
    """
    logs, live = _component_logs(model, x)
    labels = live[_best_rows(logs)]
    counts = np.bincount(labels, minlength=_COMPONENTS).astype(np.float64)
    weights = counts / len(x)
    means = np.zeros((_COMPONENTS, 3))
    covs = np.zeros((_COMPONENTS, 3, 3))
    live = counts > 0
    for i in range(3):
        means[:, i] = np.bincount(labels, x[:, i], minlength=_COMPONENTS)
        for j in range(i, 3):
            covs[:, i, j] = covs[:, j, i] = np.bincount(labels, x[:, i] * x[:, j], minlength=_COMPONENTS)
    means[live] /= counts[live, None]
    covs[live] = covs[live] / counts[live, None, None] - means[live, :, None] * means[live, None, :]
    singular = live & (np.linalg.det(covs) <= 1e-6)
    covs[singular] += 0.01 * np.eye(3)
    return np.concatenate([weights, means.ravel(), covs.ravel()])


def _learn(x: np.ndarray, bg: np.ndarray, fg: np.ndarray, models: np.ndarray) -> np.ndarray:
    """Both ``(2, 65)`` models re-estimated from the samples ``x (N, 3)``: ``x[bg]`` and ``x[fg]`` (both non-empty)."""
    return np.stack([_refit(x[bg], models[0]), _refit(x[fg], models[1])])
