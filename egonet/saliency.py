"""Graph-based visual saliency (GBVS; Harel, Koch & Perona, NIPS 2006), one of the paper's baselines.

Written from the paper:

1. **Feature maps.** The frame is shrunk to ``work_width`` pixels wide and
   filtered into a Gaussian pyramid; at each of ``levels`` (a level ``k``
   is ``2**k`` times smaller) we take intensity ``(r + g + b) / 3``, two
   colour opponencies ``|r - g| / max(r, g, b)`` and
   ``|b - min(r, g)| / max(r, g, b)`` (zero where the pixel is dark, as
   Itti et al. do), and orientation energy at 0, 45, 90 and 135 degrees
   (a quadrature pair of Gabor filters on the intensity). Every map is
   resized to one grid ``grid_width`` cells wide: its nodes.
2. **Activation.** A fully connected graph on a map's nodes, the edge from
   ``i`` to ``j`` weighted ``w = d(i, j) * F(i - j)``: dissimilarity times a
   Gaussian of the grid distance, ``F(a) = exp(-|a|^2 / (2 s^2))`` with
   ``s = sigma_activation * grid_width``. The dissimilarity is
   ``|M(i) - M(j)|``, which the paper notes works as well as its
   ``|log(M(i) / M(j))|`` and does not need strictly positive maps. The
   activation map is the equilibrium distribution of the Markov chain
   whose transitions are the normalised outgoing weights: mass gathers at
   nodes unlike their surroundings.
3. **Normalisation.** A second chain with weights ``A(j) * F(i - j)``
   (``s = sigma_normalization * grid_width``) concentrates that mass on a
   few peaks; its equilibrium is the normalised map.
4. The normalised maps are averaged within each channel (intensity,
   colour, orientation), the channels summed, the sum resized to the frame
   and blurred; like the spectral-residual baseline, the map is then
   min-max normalised to [0, 1] (saliency has no probabilistic scale).

Both chains are *reversible* (a symmetric kernel times node weights), so
their equilibria have closed forms, checked in the tests against power
iteration: the first is proportional to each node's total weight
``sum_j w(i, j)``, the second to ``A(i) * sum_j A(j) F(i - j)``. A frame
costs a few dense ``n x n`` products (``n`` = 32 x 24 nodes by default),
tens of milliseconds, whatever its size.

Example:
    >>> import numpy as np
    >>> rgb = np.full((48, 64, 3), 128, np.uint8); rgb[20:28, 40:48] = (220, 30, 30)
    >>> s = GraphSaliency().predict(rgb)
    >>> s.shape, bool(s[24, 44] > s[10, 10])
    ((48, 64), True)
"""

from __future__ import annotations

import math
from functools import lru_cache

import cv2
import numpy as np

from egonet.errors import EgonetError
from egonet.io import check_rgb

__all__ = ["GraphSaliency", "activation_equilibrium", "check_frame", "feature_maps", "normalization_equilibrium"]

ORIENTATIONS_DEG = (0, 45, 90, 135)
CHANNELS = ("intensity", "color", "orientation")


def check_frame(rgb: np.ndarray, dhg: np.ndarray | None) -> tuple[int, int]:
    """Validate a predictor's inputs (every baseline's, ``egonet.baselines``) and return (H, W)."""
    h, w = check_rgb(rgb, "rgb")
    if dhg is not None:
        if not isinstance(dhg, np.ndarray) or dhg.dtype != np.uint8 or dhg.shape != rgb.shape:
            desc = f"{dhg.dtype} {dhg.shape}" if isinstance(dhg, np.ndarray) else type(dhg).__name__
            raise EgonetError(f"dhg must be None or a uint8 array shaped like rgb {rgb.shape}, got {desc}", field="dhg")
    return h, w


def _check_int(value: object, name: str, low: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
        raise EgonetError(f"{name} must be an int >= {low}, got {value!r}", field=name)
    return int(value)


def _check_fraction(value: object, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 < value <= 1:
        raise EgonetError(f"{name} must be a number in (0, 1], got {value!r}", field=name)
    return float(value)


def feature_maps(rgb: np.ndarray, *, work_width: int = 256, levels: tuple[int, ...] = (2, 3, 4)) -> dict[str, list[np.ndarray]]:
    """GBVS's feature maps at several pyramid levels.

    Args:
        rgb: uint8 ``(H, W, 3)``.
        work_width: Width the frame is shrunk to before the pyramid.
        levels: Pyramid levels; level ``k`` is ``work_width / 2**k`` wide.

    Returns:
        ``{"intensity": [...], "color": [...], "orientation": [...]}``, float32
        maps of the levels' sizes (1, 2 and 4 maps per level).
    """
    h, w = rgb.shape[:2]
    ww = min(work_width, w)
    work = cv2.resize(rgb, (ww, max(1, round(h * ww / w))), interpolation=cv2.INTER_AREA).astype(np.float32) / 255.0
    pyramid = [work]
    for _ in range(max(levels)):
        if min(pyramid[-1].shape[:2]) < 2:
            pyramid.append(pyramid[-1])
            continue
        # Gaussian pyramid: blur, then average 2x2 blocks (symmetric about the centre, unlike
        # pyrDown's even-pixel sampling, so a mirrored frame gives a mirrored map).
        blurred = cv2.GaussianBlur(pyramid[-1], (5, 5), 1.0, borderType=cv2.BORDER_REFLECT)
        ph, pw = pyramid[-1].shape[:2]
        pyramid.append(cv2.resize(blurred, (max(1, pw // 2), max(1, ph // 2)), interpolation=cv2.INTER_AREA))
    maps: dict[str, list[np.ndarray]] = {c: [] for c in CHANNELS}
    for level in levels:
        image = pyramid[level]
        r, g, b = image[..., 0], image[..., 1], image[..., 2]
        intensity = (r + g + b) / 3.0
        brightest = np.maximum(np.maximum(r, g), b)
        lit = brightest > 0.1  # hue is undefined in the dark
        scale = np.where(lit, 1.0 / np.maximum(brightest, 1e-6), 0.0)
        maps["intensity"].append(intensity)
        maps["color"] += [np.abs(r - g) * scale, np.abs(b - np.minimum(r, g)) * scale]
        maps["orientation"] += [_gabor_energy(intensity, theta) for theta in ORIENTATIONS_DEG]
    return maps


def _gabor_energy(intensity: np.ndarray, theta_deg: float) -> np.ndarray:
    """Energy of a quadrature pair of Gabor filters (wavelength 4 px, sigma 2 px) at ``theta_deg``."""
    theta = math.radians(theta_deg)
    even = cv2.getGaborKernel((9, 9), 2.0, theta, 4.0, 1.0, 0.0, ktype=cv2.CV_32F)
    odd = cv2.getGaborKernel((9, 9), 2.0, theta, 4.0, 1.0, math.pi / 2, ktype=cv2.CV_32F)
    even -= even.mean()  # no response to flat regions
    a = cv2.filter2D(intensity, cv2.CV_32F, even, borderType=cv2.BORDER_REFLECT)
    b = cv2.filter2D(intensity, cv2.CV_32F, odd, borderType=cv2.BORDER_REFLECT)
    return np.sqrt(a * a + b * b)


@lru_cache(maxsize=8)
def _distance_kernel(rows: int, cols: int, sigma: float) -> np.ndarray:
    """``F(i - j) = exp(-|p_i - p_j|^2 / (2 sigma^2))`` over a grid's nodes (row-major), float64 ``(n, n)``."""
    y, x = np.mgrid[0:rows, 0:cols]
    points = np.stack([y.ravel(), x.ravel()], axis=1).astype(np.float64)
    d2 = ((points[:, None, :] - points[None, :, :]) ** 2).sum(axis=2)
    kernel = np.exp(-d2 / (2.0 * sigma * sigma))
    kernel.setflags(write=False)
    return kernel


def activation_equilibrium(values: np.ndarray, kernel: np.ndarray) -> np.ndarray:
    """Equilibrium of the chain with weights ``|M(i) - M(j)| F(i - j)``: each node's total weight, normalised.

    Args:
        values: The map's nodes, ``(n,)``.
        kernel: ``F``, symmetric ``(n, n)``.

    Returns:
        ``(n,)`` summing to 1 (uniform when the map is flat: no node stands out).
    """
    degree = (np.abs(values[:, None] - values[None, :]) * kernel).sum(axis=1)
    total = degree.sum()
    return degree / total if total > 0 else np.full_like(degree, 1.0 / len(degree))


def normalization_equilibrium(activation: np.ndarray, kernel: np.ndarray) -> np.ndarray:
    """Equilibrium of the chain with weights ``A(j) F(i - j)``: ``A(i) * sum_j A(j) F(i - j)``, normalised."""
    mass = activation * (kernel @ activation)
    total = mass.sum()
    return mass / total if total > 0 else np.full_like(mass, 1.0 / len(mass))


class GraphSaliency:
    """Graph-based visual saliency (Harel, Koch & Perona 2006); see the module docstring.

    Args:
        grid_width: Nodes across the activation grid (its height follows the frame's aspect).
        work_width: Width of the frame before the pyramid, in pixels.
        levels: Pyramid levels of the feature maps.
        sigma_activation: Distance Gaussian of the activation graph, a fraction of ``grid_width``.
        sigma_normalization: Distance Gaussian of the normalisation graph, a fraction of ``grid_width``.
        blur: Final blur, a fraction of the frame's width.

    Raises:
        EgonetError: An option out of range (named).
    """

    name, version = "GBVS", 1

    def __init__(
        self,
        *,
        grid_width: int = 32,
        work_width: int = 256,
        levels: tuple[int, ...] = (2, 3, 4),
        sigma_activation: float = 0.15,
        sigma_normalization: float = 0.06,
        blur: float = 0.02,
    ) -> None:
        self.grid_width = _check_int(grid_width, "grid_width", 4)
        self.work_width = _check_int(work_width, "work_width", 16)
        if not levels or any(isinstance(k, bool) or not isinstance(k, int) or not 0 <= k <= 6 for k in levels):
            raise EgonetError(f"levels must be pyramid levels in 0..6, got {levels!r}", field="levels")
        self.levels = tuple(levels)
        self.sigma_activation = _check_fraction(sigma_activation, "sigma_activation")
        self.sigma_normalization = _check_fraction(sigma_normalization, "sigma_normalization")
        self.blur = _check_fraction(blur, "blur")

    def grid(self, height: int, width: int) -> tuple[int, int]:
        """The activation grid ``(rows, cols)`` for a frame."""
        cols = min(self.grid_width, width)
        return max(2, round(height * cols / width)), cols

    def predict(self, rgb: np.ndarray, dhg: np.ndarray | None = None) -> np.ndarray:
        """The saliency map, float32 ``(H, W)`` in [0, 1] (zeros for a uniform frame).

        Args:
            rgb: uint8 ``(H, W, 3)``.
            dhg: Ignored; may be None.
        """
        h, w = check_frame(rgb, dhg)
        rows, cols = self.grid(h, w)
        act_kernel = _distance_kernel(rows, cols, self.sigma_activation * cols)
        norm_kernel = _distance_kernel(rows, cols, self.sigma_normalization * cols)
        total = np.zeros(rows * cols)
        for maps in feature_maps(rgb, work_width=self.work_width, levels=self.levels).values():
            channel = np.zeros(rows * cols)
            for feature in maps:
                nodes = cv2.resize(feature, (cols, rows), interpolation=cv2.INTER_AREA).astype(np.float64).ravel()
                if np.ptp(nodes) < 1e-6:  # a flat map says nothing (its chain would be uniform)
                    continue
                channel += normalization_equilibrium(activation_equilibrium(nodes, act_kernel), norm_kernel)
            total += channel / len(maps)
        if np.ptp(total) <= 1e-12:
            return np.zeros((h, w), np.float32)
        out = cv2.resize(total.reshape(rows, cols).astype(np.float32), (w, h), interpolation=cv2.INTER_LINEAR)
        out = cv2.GaussianBlur(out, (0, 0), max(self.blur * w, 0.5), borderType=cv2.BORDER_REFLECT)
        lo, hi = float(out.min()), float(out.max())
        if not hi - lo > 1e-9 * max(hi, 1e-30):
            return np.zeros((h, w), np.float32)
        return np.clip((out - lo) / (hi - lo), 0.0, 1.0).astype(np.float32)
