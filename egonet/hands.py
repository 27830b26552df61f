"""Where the wearer's hands are: a pixel-level hand detector, and the skin-colour prior it falls back on.

After Li & Kitani, "Pixel-level hand detection in ego-centric videos" (CVPR
2013): every pixel is described by its colour and the texture around it and
classified hand or not by a model trained on frames whose hands are labelled.
The Handled+Viewed-Obj baseline (``egonet.baselines``) finds its hands here.

What is faithful: per-pixel classification; colour in three spaces (RGB, HSV,
CIE Lab, as the paper's best features) at the pixel and averaged around it at
two scales; texture (gradient magnitude at two scales, Laplacian of Gaussian
at two scales, local contrast); a classifier trained on the pixels of frames
with labelled hands, negatives from the same frames.

What stands in: a small multilayer perceptron (scikit-learn's, one hidden
layer) for the paper's random-forest regressor, predicted with numpy from its
plain weight arrays (what :meth:`HandModel.state` saves); local means for the
paper's local colour histograms; one model, where the paper picks among
models trained under different lighting by the frame's global appearance;
Gabor, HOG and BRIEF descriptors are left out. Added for our RGB-D frames:
depth, height above the floor and local depth contrast from DHG (hands lie
within arm's reach and above the floor; the paper's videos had no depth).
Pixels are classified on a copy ``width`` pixels wide, and the probability
resized back.

Without labelled hands (fewer than ``min_frames`` frames with any), the model
is the skin-colour prior :func:`skin_probability` (Chai & Ngan, 1999: skin
falls in a box of the YCrCb plane), and :attr:`HandModel.source` says so.

Example:
    >>> rgb = np.full((24, 32, 3), (60, 90, 160), np.uint8); rgb[12:, 10:22] = (200, 140, 110)
    >>> hands = np.zeros((24, 32), bool); hands[12:, 10:22] = True
    >>> model = HandModel(width=32, min_frames=1).fit([(rgb, None, hands)])
    >>> p = model.predict(rgb)
    >>> model.source, bool(p[18, 16] > 0.5), bool(p[4, 4] < 0.5)
    ('learned', True, True)
"""

from __future__ import annotations

import warnings
from collections.abc import Iterable, Mapping

import cv2
import numpy as np

from egonet.errors import EgonetError
from egonet.saliency import check_frame

__all__ = ["HAND_LABEL", "HandModel", "hand_features", "skin_probability"]

HAND_LABEL = "hand"
"""The label of an instance that outlines the wearer's hands (and forearms): the detector's training masks."""

FEATURES = (
    "r", "g", "b", "hue cos", "hue sin", "saturation", "value", "L", "a", "b*",
    "L mean 2", "a mean 2", "b* mean 2", "L mean 6", "a mean 6", "b* mean 6",
    "gradient 1", "gradient 3", "LoG 1.5", "LoG 4", "contrast 4",
    "has depth", "depth", "height", "depth contrast 4",
)  # fmt: skip
"""The per-pixel features of :func:`hand_features`, in order (numbers: scales in pixels of the working copy)."""


def _blur(x: np.ndarray, sigma: float) -> np.ndarray:
    return cv2.GaussianBlur(x, (0, 0), sigma, borderType=cv2.BORDER_REFLECT)


def hand_features(rgb: np.ndarray, dhg: np.ndarray | None = None) -> np.ndarray:
    """Colour, texture and depth features of every pixel, float32 ``(H, W, len(FEATURES))``.

    Args:
        rgb: uint8 ``(H, W, 3)``.
        dhg: uint8 ``(H, W, 3)`` DHG (gray, height, depth), or None (its features are then 0 and "has depth" 0).

    Raises:
        EgonetError: A frame that is not uint8 ``(H, W, 3)``, or a DHG of another shape.
    """
    h, w = check_frame(rgb, dhg)
    x = rgb.astype(np.float32) / 255.0
    hsv = cv2.cvtColor(x, cv2.COLOR_RGB2HSV)  # H in degrees, S and V in [0, 1]
    hue = np.deg2rad(hsv[..., 0])
    lab = cv2.cvtColor(x, cv2.COLOR_RGB2Lab) / np.float32(100.0)
    gray = lab[..., 0]
    parts = [x, (np.cos(hue) * hsv[..., 1])[..., None], (np.sin(hue) * hsv[..., 1])[..., None], hsv[..., 1:], lab,
             _blur(lab, 2.0), _blur(lab, 6.0)]  # fmt: skip
    for sigma in (1.0, 3.0):
        g = _blur(gray, sigma)
        parts.append(np.hypot(cv2.Sobel(g, cv2.CV_32F, 1, 0), cv2.Sobel(g, cv2.CV_32F, 0, 1))[..., None])
    for sigma in (1.5, 4.0):
        parts.append((sigma**2 * cv2.Laplacian(_blur(gray, sigma), cv2.CV_32F))[..., None])
    parts.append(_local_std(gray, 4.0)[..., None])
    if dhg is None:
        parts.append(np.zeros((h, w, 4), np.float32))
    else:
        depth, height = dhg[..., 2].astype(np.float32) / 255.0, dhg[..., 1].astype(np.float32) / 255.0
        parts += [np.ones((h, w, 1), np.float32), depth[..., None], height[..., None], _local_std(depth, 4.0)[..., None]]
    return np.concatenate(parts, axis=2).astype(np.float32, copy=False)


def _local_std(x: np.ndarray, sigma: float) -> np.ndarray:
    mean = _blur(x, sigma)
    return np.sqrt(np.maximum(_blur(x * x, sigma) - mean * mean, 0.0))


def skin_probability(rgb: np.ndarray) -> np.ndarray:
    """The skin-colour prior: how far inside the YCrCb skin box of Chai & Ngan (1999) each pixel is, float32 ``(H, W)``.

    The box is Cr in [133, 173] and Cb in [77, 127] (8-bit); each bound is a
    logistic step 4 levels wide, so a pixel well inside scores about 1, one
    on a bound 0.5, one far outside about 0.

    Example:
        >>> p = skin_probability(np.array([[[200, 140, 110], [60, 90, 160]]], np.uint8))
        >>> bool(p[0, 0] > 0.9), bool(p[0, 1] < 0.01)
        (True, True)
    """
    check_frame(rgb, None)
    ycrcb = cv2.cvtColor(rgb, cv2.COLOR_RGB2YCrCb).astype(np.float32)
    cr, cb = ycrcb[..., 1], ycrcb[..., 2]
    step = lambda t: 1.0 / (1.0 + np.exp(-t / 4.0))  # noqa: E731
    return (step(cr - 133) * step(173 - cr) * step(cb - 77) * step(127 - cb)).astype(np.float32)


class HandModel:
    """A pixel-level hand detector trained on frames with labelled hands (see the module docstring).

    Args:
        width: Width of the working copy the pixels are classified on.
        hidden: Units of the perceptron's hidden layer.
        pixels_per_frame: Pixels drawn from each training frame (half from
            its hands where it has that many, the rest from elsewhere).
        min_frames: Frames with labelled hands needed to learn; with fewer,
            the skin-colour prior.
        max_iter: Training epochs of the perceptron (Adam).
        seed: Seed of the pixel draws and of the perceptron's start.

    Attributes:
        source: ``"learned"`` or ``"skin colour"`` (set by :meth:`fit`).
        frames: Frames with labelled hands it was trained on (0 for the prior).
    """

    version = 2
    """Bumped whenever what a fitted model predicts changes (part of a cache key)."""

    def __init__(
        self, *, width: int = 80, hidden: int = 24, pixels_per_frame: int = 240, min_frames: int = 5,
        max_iter: int = 40, seed: int = 0,
    ) -> None:  # fmt: skip
        for name, value, low in (("width", width, 16), ("hidden", hidden, 1), ("pixels_per_frame", pixels_per_frame, 2),
                                 ("min_frames", min_frames, 1), ("max_iter", max_iter, 1), ("seed", seed, 0)):  # fmt: skip
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
                raise EgonetError(f"{name} must be an int >= {low}, got {value!r}", field=name)
        self.width, self.hidden, self.pixels_per_frame = int(width), int(hidden), int(pixels_per_frame)
        self.min_frames, self.max_iter, self.seed = int(min_frames), int(max_iter), int(seed)
        self.source = "skin colour"
        self.frames = 0
        self._net: dict[str, np.ndarray] | None = None

    @property
    def name(self) -> str:
        """What the hands come from, for a row's name: ``"skin colour"`` or ``"learned, n frames"``."""
        return self.source if self.source != "learned" else f"learned, {self.frames} frames"

    def _small(self, image: np.ndarray, *, nearest: bool = False) -> np.ndarray:
        h, w = image.shape[:2]
        ww = min(self.width, w)
        size = (ww, max(1, round(h * ww / w)))
        if nearest:
            return cv2.resize(image.astype(np.uint8), size, interpolation=cv2.INTER_NEAREST).astype(bool)
        return cv2.resize(image, size, interpolation=cv2.INTER_AREA)

    def summarize(self, rgb: np.ndarray, dhg: np.ndarray | None, hands: np.ndarray | None) -> dict[str, np.ndarray]:
        """One frame's training pixels: ``x`` float32 ``(n, len(FEATURES))`` and ``y`` bool ``(n,)``.

        Only frames whose hands were labelled teach the model (a frame
        without a hand label says nothing about where hands are not): for
        others ``n`` is 0. The draw depends on the settings, not on which
        other frames are fitted with it.

        Raises:
            EgonetError: A bad frame, or a hand mask not bool ``(H, W)``.
        """
        h, w = check_frame(rgb, dhg)
        if hands is not None and (not isinstance(hands, np.ndarray) or hands.dtype != np.bool_ or hands.shape != (h, w)):
            raise EgonetError(f"hands must be None or a bool ({h}, {w}) mask", field="hands")
        if hands is None or not hands.any():
            return {"x": np.zeros((0, len(FEATURES)), np.float32), "y": np.zeros(0, bool)}
        features = hand_features(self._small(rgb), None if dhg is None else self._small(dhg))
        labels = self._small(hands, nearest=True).ravel()
        flat = features.reshape(-1, len(FEATURES))
        # Seeded by the frame's content, so a frame gives the same pixels whatever fold it is in.
        rng = np.random.default_rng([self.seed, int(labels.sum()), int(features[..., 0].sum() * 1000) % 2**32])
        k = self.pixels_per_frame // 2
        chosen = np.concatenate([rng.choice(part, min(k, part.size), replace=False)
                                 for part in (np.flatnonzero(labels), np.flatnonzero(~labels)) if part.size])  # fmt: skip
        return {"x": flat[chosen], "y": labels[chosen]}

    def fit_summaries(self, summaries: Iterable[Mapping[str, np.ndarray]]) -> HandModel:
        """Fit on frames' :meth:`summarize` pixels; the skin-colour prior with fewer than ``min_frames`` hand frames."""
        from sklearn.exceptions import ConvergenceWarning
        from sklearn.neural_network import MLPClassifier

        used = [s for s in summaries if len(s["y"])]
        self.frames = len(used)
        if self.frames < self.min_frames or all(s["y"].all() for s in used):
            self.source, self._net = "skin colour", None
            return self
        x, y = np.concatenate([s["x"] for s in used]), np.concatenate([s["y"] for s in used])
        mean, std = x.mean(axis=0), x.std(axis=0) + 1e-6
        mlp = MLPClassifier(hidden_layer_sizes=(self.hidden,), max_iter=self.max_iter, random_state=self.seed,
                            alpha=1e-3, batch_size=min(256, len(y)), learning_rate_init=3e-3)  # fmt: skip
        with warnings.catch_warnings():  # a short budget of epochs is the point, not a problem
            warnings.simplefilter("ignore", ConvergenceWarning)
            mlp.fit((x - mean) / std, y)
        self.source = "learned"
        (w0, w1), (b0, b1) = mlp.coefs_, mlp.intercepts_
        self._net = {k: v.astype(np.float32) for k, v in
                     {"mean": mean, "std": std, "w0": w0, "b0": b0, "w1": w1[:, 0], "b1": b1}.items()}  # fmt: skip
        return self

    def fit(self, frames: Iterable[tuple[np.ndarray, np.ndarray | None, np.ndarray | None]]) -> HandModel:
        """Learn from ``(rgb, dhg or None, hands bool (H, W) or None)`` triples (:meth:`summarize`, then :meth:`fit_summaries`).

        Returns:
            self.
        """
        return self.fit_summaries([self.summarize(rgb, dhg, hands) for rgb, dhg, hands in frames])

    def predict(self, rgb: np.ndarray, dhg: np.ndarray | None = None) -> np.ndarray:
        """The probability that each pixel is a hand, float32 ``(H, W)`` in [0, 1].

        Raises:
            EgonetError: A bad frame.
        """
        h, w = check_frame(rgb, dhg)
        if self._net is None:
            return skin_probability(rgb)
        small = self._small(rgb)
        features = hand_features(small, None if dhg is None else self._small(dhg))
        net = self._net
        z = (features.reshape(-1, len(FEATURES)) - net["mean"]) / net["std"]
        logit = (np.maximum(z @ net["w0"] + net["b0"], 0.0) @ net["w1"] + net["b1"]).reshape(small.shape[:2])
        p = (1.0 / (1.0 + np.exp(-np.clip(logit, -30, 30)))).astype(np.float32)
        return np.clip(cv2.resize(p, (w, h), interpolation=cv2.INTER_LINEAR), 0.0, 1.0)

    def state(self) -> dict[str, np.ndarray]:
        """What was fitted, as named plain arrays: ``frames``, and for a learned model the standardisation and weights."""
        return {"frames": np.array(self.frames), **(self._net or {})}

    def load_state(self, state: Mapping[str, np.ndarray]) -> HandModel:
        """Restore what :meth:`state` returned (with this model's settings); returns self.

        Raises:
            EgonetError: A state with some of the weights missing or of the wrong shapes.
        """
        names = ("mean", "std", "w0", "b0", "w1", "b1")
        self.frames = int(np.asarray(state["frames"]))
        if not any(k in state for k in names):
            self.source, self._net = "skin colour", None
            return self
        net = {k: np.asarray(state[k], np.float32) for k in names if k in state}
        shapes = {k: v.shape for k, v in net.items()}
        f = len(FEATURES)
        if shapes != {"mean": (f,), "std": (f,), "w0": (f, self.hidden), "b0": (self.hidden,), "w1": (self.hidden,), "b1": (1,)}:
            raise EgonetError(f"not a hand model state of {f} features and {self.hidden} hidden units: {shapes}", field="state")
        self.source, self._net = "learned", net
        return self
