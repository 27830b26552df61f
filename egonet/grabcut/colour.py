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
    for _ in range(iterations):
        new = ((x[:, None, :] - c[None, :, :]) ** 2).sum(axis=2).argmin(axis=1)
        if np.array_equal(new, labels):
            break
        labels = new
        for j in range(len(c)):
            members = x[labels == j]
            if len(members):
                c[j] = members.mean(axis=0)
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
