"""Baselines that share one prediction interface with the trained models.

Every predictor answers ``predict(rgb, dhg) -> float32 (H, W)`` in [0, 1] at
the input's own resolution, so the scoring code (``egonet.metrics``) treats a
baseline and a trained EgoNet alike. Baselines that do not look at depth
accept ``dhg=None``.

* ``"aop"``: :class:`ActionObjectPrior`, the paper's Action-Object Prior, the
  mean of the training masks. Under leave-one-activity-out it is fitted
  inside each fold on the six training activities only
  (:func:`aop_fold_priors` fits every fold at once).
* ``"center"``: :class:`CenterPrior`, an isotropic Gaussian at the image
  centre (first-person cameras tend to centre what the wearer attends to).
* ``"saliency"``: :class:`SpectralResidualSaliency`, bottom-up saliency of
  Hou & Zhang (CVPR 2007).
* ``"gbvs"``: :class:`~egonet.saliency.GraphSaliency`, graph-based visual
  saliency (Harel, Koch & Perona 2006), one of the paper's baselines.
* ``"handled"``: :class:`HandledViewedObject`, the paper's "handled +
  viewed object": the object region nearest the hands (given as a mask by
  the caller: a hand detector's, or the labelled tactile objects), else
  nearest the image centre.

:data:`BASELINES` maps these names to constructors and :func:`build_baseline`
builds one by name.

Example:
    >>> import numpy as np
    >>> rgb = np.zeros((48, 64, 3), dtype=np.uint8)
    >>> build_baseline("center").predict(rgb, None).shape
    (48, 64)
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator, Mapping
from typing import Protocol, runtime_checkable

import cv2
import numpy as np

from egonet.errors import EgonetError
from egonet.saliency import GraphSaliency
from egonet.saliency import check_frame as _check_frame

__all__ = [
    "BASELINES",
    "ActionObjectPrior",
    "CenterPrior",
    "GraphSaliency",
    "HandledViewedObject",
    "Predictor",
    "SpectralResidualSaliency",
    "aop_fold_priors",
    "build_baseline",
]


@runtime_checkable
class Predictor(Protocol):
    """Anything that maps a frame to an action-object probability map."""

    def predict(self, rgb: np.ndarray, dhg: np.ndarray | None) -> np.ndarray:
        """Predict the action-object probability of every pixel.

        Args:
            rgb: Colour frame, uint8 (H, W, 3), RGB order.
            dhg: Depth/height/gray frame, uint8 (H, W, 3), or None for
                predictors that do not use it.

        Returns:
            Probabilities in [0, 1], float32 (H, W).
        """
        ...


def _check_positive(value: float, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise EgonetError(f"{name} must be a positive number, got {value!r}", field=name)
    if not np.isfinite(value) or value <= 0:
        raise EgonetError(f"{name} must be a positive finite number, got {value}", field=name)
    return float(value)


def _check_size(size: tuple[int, int], name: str) -> tuple[int, int]:
    if (
        not isinstance(size, (tuple, list))
        or len(size) != 2
        or any(isinstance(s, bool) or not isinstance(s, (int, np.integer)) or s < 1 for s in size)
    ):
        raise EgonetError(f"{name} must be (height, width) with positive ints, got {size!r}", field=name)
    return int(size[0]), int(size[1])


class ActionObjectPrior:
    """Action-Object Prior (AOP): the mean training mask.

    The prior lives on a small fixed grid; :meth:`predict` resizes it
    bilinearly to the frame, so it ignores the frame's content.

    Args:
        prior: Mean mask in [0, 1], float (h, w).

    Raises:
        ValueError: If ``prior`` is not a 2-D map in [0, 1].

    Example:
        >>> masks = [np.eye(2, dtype=bool), np.ones((2, 2), dtype=bool)]
        >>> ActionObjectPrior.fit(masks, size=(2, 2)).prior
        array([[1. , 0.5],
               [0.5, 1. ]], dtype=float32)
    """

    def __init__(self, prior: np.ndarray) -> None:
        prior = np.asarray(prior, dtype=np.float32)
        if prior.ndim != 2 or prior.size == 0:
            raise EgonetError(f"prior must be a non-empty 2-D map (h, w), got shape {prior.shape}", field="prior")
        if not np.all(np.isfinite(prior)) or prior.min() < 0 or prior.max() > 1:
            raise EgonetError("prior must hold finite values in [0, 1]", field="prior")
        self.prior = prior

    @classmethod
    def fit(cls, masks: Iterable[np.ndarray], *, size: tuple[int, int] = (60, 80)) -> ActionObjectPrior:
        """Average training masks on a common grid.

        Each mask, of any size, is resized to ``size`` with area
        interpolation (the fraction of each grid cell the mask covers), and
        the resized masks are averaged. Masks are consumed one at a time.

        Args:
            masks: Training masks, bool (H_i, W_i) each; sizes may differ.
            size: The grid as (height, width); (60, 80) keeps the 4:3 frames'
                aspect ratio.

        Returns:
            The fitted prior.

        Raises:
            ValueError: If there are no masks, a mask is not a 2-D bool
                array (the message names its index), or ``size`` is invalid.
        """
        h, w = _check_size(size, "size")
        total = np.zeros((h, w), dtype=np.float64)
        n = 0
        for i, mask in enumerate(masks):
            mask = np.asarray(mask)
            if mask.dtype != np.bool_ or mask.ndim != 2 or mask.size == 0:
                raise EgonetError(f"masks[{i}] must be a non-empty bool (H, W) mask, got {mask.dtype} {mask.shape}", field="masks")
            cover = mask.astype(np.float32)
            if cover.shape != (h, w):
                cover = cv2.resize(cover, (w, h), interpolation=cv2.INTER_AREA)
            total += cover
            n += 1
        if n == 0:
            raise EgonetError("masks is empty: fit the prior on at least one training mask", field="masks")
        return cls(np.clip(total / n, 0.0, 1.0))

    def predict(self, rgb: np.ndarray, dhg: np.ndarray | None = None) -> np.ndarray:
        """Return the prior resized (bilinear) to the frame, float32 (H, W).

        Args:
            rgb: Colour frame, uint8 (H, W, 3); only its size is used.
            dhg: Ignored; may be None.

        Returns:
            Probabilities in [0, 1], float32 (H, W).
        """
        h, w = _check_frame(rgb, dhg)
        if self.prior.shape == (h, w):
            return self.prior.copy()
        out = cv2.resize(self.prior, (w, h), interpolation=cv2.INTER_LINEAR)
        return np.clip(out, 0.0, 1.0, out=out)


class CenterPrior:
    """An isotropic Gaussian centred on the image, peak 1.

    ``p(x, y) = exp(-d^2 / (2 s^2))`` where ``d`` is the distance in pixels to
    the image centre ``((W - 1) / 2, (H - 1) / 2)`` and ``s = sigma *
    sqrt(H^2 + W^2)``: ``sigma`` is a fraction of the image **diagonal**, so
    the prior is round in pixels and scales with the frame.

    Args:
        sigma: Standard deviation as a fraction of the image diagonal, > 0.

    Raises:
        ValueError: If ``sigma`` is not positive.

    Example:
        >>> p = CenterPrior(sigma=0.25).predict(np.zeros((3, 3, 3), np.uint8), None)
        >>> float(p[1, 1])
        1.0
    """

    def __init__(self, *, sigma: float = 0.25) -> None:
        self.sigma = _check_positive(sigma, "sigma")

    def predict(self, rgb: np.ndarray, dhg: np.ndarray | None = None) -> np.ndarray:
        """Return the centre prior at the frame's size, float32 (H, W).

        Args:
            rgb: Colour frame, uint8 (H, W, 3); only its size is used.
            dhg: Ignored; may be None.

        Returns:
            Values in (0, 1], float32 (H, W), largest at the centre.
        """
        h, w = _check_frame(rgb, dhg)
        s = self.sigma * float(np.hypot(h, w))
        gy = np.exp(-((np.arange(h) - (h - 1) / 2.0) ** 2) / (2 * s * s)).astype(np.float32)
        gx = np.exp(-((np.arange(w) - (w - 1) / 2.0) ** 2) / (2 * s * s)).astype(np.float32)
        return np.outer(gy, gx)


class SpectralResidualSaliency:
    """Spectral-residual saliency (Hou & Zhang, CVPR 2007).

    The frame is converted to grayscale and downscaled (area interpolation)
    to ``width`` pixels wide, keeping its aspect ratio. With ``F`` its
    Fourier transform, ``L = log |F|`` and ``P`` its phase, the spectral
    residual is ``R = L - mean3x3(L)`` and the saliency is
    ``|IFFT(exp(R + iP))|^2``, smoothed with a Gaussian of ``blur_sigma``
    (in downscaled pixels). The map is then min-max normalised to [0, 1]
    per image and resized bilinearly to the frame. Normalising is part of
    how this baseline is defined (saliency has no probabilistic scale);
    a uniform frame (or one whose saliency is constant) gives zeros.

    Args:
        width: Width of the working image in pixels (the paper uses 64).
        blur_sigma: Standard deviation of the final smoothing, in working
            pixels, > 0.

    Raises:
        ValueError: If ``width`` < 8 or ``blur_sigma`` is not positive.
    """

    def __init__(self, *, width: int = 64, blur_sigma: float = 2.5) -> None:
        if isinstance(width, bool) or not isinstance(width, (int, np.integer)) or width < 8:
            raise EgonetError(f"width must be an int >= 8, got {width!r}", field="width")
        self.width = int(width)
        self.blur_sigma = _check_positive(blur_sigma, "blur_sigma")

    def predict(self, rgb: np.ndarray, dhg: np.ndarray | None = None) -> np.ndarray:
        """Return the normalised saliency map, float32 (H, W) in [0, 1].

        Args:
            rgb: Colour frame, uint8 (H, W, 3).
            dhg: Ignored; may be None.

        Returns:
            Saliency in [0, 1], float32 (H, W).
        """
        h, w = _check_frame(rgb, dhg)
        gray = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY).astype(np.float32)
        ww = min(self.width, w)
        wh = max(1, round(h * ww / w))
        small = cv2.resize(gray, (ww, wh), interpolation=cv2.INTER_AREA) / 255.0
        if float(small.max() - small.min()) < 1e-6:
            # A uniform frame has no residual, only rounding noise: say so.
            return np.zeros((h, w), dtype=np.float32)
        spectrum = np.fft.fft2(small)
        log_amp = np.log(np.abs(spectrum) + 1e-8)
        phase = np.angle(spectrum)
        residual = log_amp - cv2.blur(log_amp, (3, 3), borderType=cv2.BORDER_REFLECT)
        sal = np.abs(np.fft.ifft2(np.exp(residual + 1j * phase))) ** 2
        sal = cv2.GaussianBlur(sal.astype(np.float32), (0, 0), self.blur_sigma, borderType=cv2.BORDER_REFLECT)
        lo, hi = float(sal.min()), float(sal.max())
        if not hi - lo > 1e-6 * hi:
            return np.zeros((h, w), dtype=np.float32)
        sal = (sal - lo) / (hi - lo)
        out = cv2.resize(sal, (w, h), interpolation=cv2.INTER_LINEAR)
        return np.clip(out, 0.0, 1.0, out=out).astype(np.float32, copy=False)


class HandledViewedObject:
    """"Handled + viewed object" (the paper's baseline): the object region nearest the hands, else nearest the centre.

    Object regions are Felzenszwalb-Huttenlocher segments (scikit-image) of
    a copy ``width`` pixels wide, kept when they cover between
    ``min_area`` and ``max_area`` of the frame (smaller are specks, larger
    are the floor, walls and tables). Each kept region scores
    ``exp(-d^2 / (2 sigma^2))``, ``d`` being its nearest pixel's distance to
    ``near`` (the hands, or what they hold) or, without it, to the image
    centre, as a fraction of the diagonal: the nearest object scores about
    1 and farther ones less, which gives a ranking for the PR curve.

    Args:
        width: Width of the working copy, pixels.
        scale: Felzenszwalb's ``scale`` (larger: larger segments).
        min_area: Smallest region kept, a fraction of the frame.
        max_area: Largest region kept, a fraction of the frame.
        sigma: Fall-off of the score with distance, a fraction of the diagonal.

    Example:
        >>> rgb = np.full((48, 64, 3), 200, np.uint8); rgb[18:30, 26:38] = (200, 40, 40)
        >>> p = HandledViewedObject().predict(rgb)
        >>> float(p[24, 32]), float(p[2, 2])
        (1.0, 0.0)
    """

    def __init__(
        self, *, width: int = 160, scale: float = 50.0, min_area: float = 0.002, max_area: float = 0.05, sigma: float = 0.1
    ) -> None:
        if isinstance(width, bool) or not isinstance(width, (int, np.integer)) or width < 16:
            raise EgonetError(f"width must be an int >= 16, got {width!r}", field="width")
        self.width = int(width)
        self.scale = _check_positive(scale, "scale")
        self.min_area, self.max_area = _check_positive(min_area, "min_area"), _check_positive(max_area, "max_area")
        if not self.min_area < self.max_area <= 1:
            raise EgonetError(f"need 0 < min_area < max_area <= 1, got {min_area}, {max_area}", field="max_area")
        self.sigma = _check_positive(sigma, "sigma")

    def regions(self, rgb: np.ndarray) -> np.ndarray:
        """The object regions' labels on the working copy, int32 ``(h, w)``; -1 where no object region is."""
        from skimage.segmentation import felzenszwalb

        h, w = rgb.shape[:2]
        ww = min(self.width, w)
        small = cv2.resize(rgb, (ww, max(1, round(h * ww / w))), interpolation=cv2.INTER_AREA)
        labels = felzenszwalb(small, scale=self.scale, sigma=0.8, min_size=max(4, round(self.min_area * small[..., 0].size)))
        area = np.bincount(labels.ravel()) / labels.size
        keep = (area >= self.min_area) & (area <= self.max_area)
        return np.where(keep[labels], labels, -1).astype(np.int32)

    def predict(
        self, rgb: np.ndarray, dhg: np.ndarray | None = None, *, near: np.ndarray | None = None, exclude: np.ndarray | None = None
    ) -> np.ndarray:
        """Score every object region by its distance to ``near`` (or the centre), float32 ``(H, W)`` in [0, 1].

        Args:
            rgb: uint8 ``(H, W, 3)``.
            dhg: Ignored; may be None.
            near: bool ``(H, W)``: the hands (a detector's), or the handled
                objects (labelled tactile objects); None or empty: the centre.
            exclude: bool ``(H, W)`` of pixels that are no object (the hands
                themselves): a region at least half inside it is dropped.

        Raises:
            EgonetError: A bad frame, or a mask not bool ``(H, W)``.
        """
        h, w = _check_frame(rgb, dhg)
        for name, mask in (("near", near), ("exclude", exclude)):
            if mask is not None and (not isinstance(mask, np.ndarray) or mask.dtype != np.bool_ or mask.shape != (h, w)):
                raise EgonetError(f"{name} must be None or a bool ({h}, {w}) mask", field=name)
        labels = self.regions(rgb)
        sh, sw = labels.shape
        shrink = lambda m: cv2.resize(m.astype(np.uint8), (sw, sh), interpolation=cv2.INTER_NEAREST).astype(bool)  # noqa: E731
        target = np.zeros((sh, sw), bool)
        if near is not None and near.any():
            target = shrink(near) | _shrunk_points(near, (sh, sw))
        else:
            target[(sh - 1) // 2 : sh // 2 + 1, (sw - 1) // 2 : sw // 2 + 1] = True
        distance = cv2.distanceTransform((~target).astype(np.uint8), cv2.DIST_L2, 5) / float(np.hypot(sh, sw))
        n = int(labels.max()) + 1
        if n == 0:
            return np.zeros((h, w), np.float32)
        inside = labels >= 0
        nearest = np.full(n, np.inf)
        np.minimum.at(nearest, labels[inside], distance[inside])
        score = np.exp(-(nearest**2) / (2 * self.sigma**2))
        if exclude is not None and exclude.any():
            covered = np.bincount(labels[inside], weights=shrink(exclude)[inside], minlength=n)
            score[covered >= 0.5 * np.bincount(labels[inside], minlength=n)] = 0.0
        out = np.where(inside, score[np.maximum(labels, 0)], 0.0).astype(np.float32)
        return cv2.resize(out, (w, h), interpolation=cv2.INTER_NEAREST)


def _shrunk_points(mask: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """A mask's pixels on a smaller grid (a thin mask can vanish under nearest-neighbour resizing)."""
    ys, xs = np.nonzero(mask)
    out = np.zeros(size, bool)
    out[(ys * size[0]) // mask.shape[0], (xs * size[1]) // mask.shape[1]] = True
    return out


def aop_fold_priors(
    masks_by_activity: Mapping[str, Iterable[np.ndarray]], *, size: tuple[int, int] = (60, 80)
) -> dict[str, ActionObjectPrior | None]:
    """The AOP of each leave-one-activity-out fold: the mean mask of the *other* activities.

    Each activity's masks are averaged once (:meth:`ActionObjectPrior.fit`,
    on its fixed grid); the prior of the fold that tests activity A is the
    frame-weighted mean of the other activities' means, which is the mean of
    their masks, without reading every mask once per fold.

    Args:
        masks_by_activity: Each activity's ground-truth masks, bool (H, W)
            each, consumed once.
        size: The prior's grid as (height, width), as in :meth:`ActionObjectPrior.fit`.

    Returns:
        The prior by activity; None for an activity when no other activity
        has masks.

    Raises:
        ValueError: As :meth:`ActionObjectPrior.fit` (an activity without
            masks, a mask that is not bool (H, W), a bad ``size``).

    Example:
        >>> empty, full = np.zeros((2, 2), bool), np.ones((2, 2), bool)
        >>> priors = aop_fold_priors({"a": [empty], "b": [full, full, empty]}, size=(2, 2))
        >>> priors["a"].prior
        array([[0.6666667, 0.6666667],
               [0.6666667, 0.6666667]], dtype=float32)
        >>> float(priors["b"].prior.max())
        0.0
    """
    fitted = {}
    for activity, masks in masks_by_activity.items():
        counted = _Counted(masks)
        fitted[activity] = (ActionObjectPrior.fit(counted, size=size).prior.astype(np.float64), counted.n)
    priors: dict[str, ActionObjectPrior | None] = {}
    for activity in fitted:
        others = [(p, n) for a, (p, n) in fitted.items() if a != activity]
        total = sum(n for _, n in others)
        priors[activity] = ActionObjectPrior(sum(p * n for p, n in others) / total) if total else None
    return priors


class _Counted:
    """An iterable that counts what it yields (how many masks a fit averaged)."""

    def __init__(self, items: Iterable[np.ndarray]):
        self.items = items
        self.n = 0

    def __iter__(self) -> Iterator[np.ndarray]:
        for item in self.items:
            self.n += 1
            yield item


BASELINES: dict[str, Callable[..., Predictor]] = {
    "aop": ActionObjectPrior.fit,
    "center": CenterPrior,
    "saliency": SpectralResidualSaliency,
    "gbvs": GraphSaliency,
    "handled": HandledViewedObject,
}
"""Baseline names and their constructors. ``"aop"`` is fitted: call it with
the training masks of the fold (``BASELINES["aop"](masks, size=...)``); the
others take keyword options only."""


def build_baseline(name: str, *, masks: Iterable[np.ndarray] | None = None) -> Predictor:
    """Build a baseline by name with its default options.

    Args:
        name: A key of :data:`BASELINES` (``"aop"``, ``"center"``, ``"saliency"``, ``"gbvs"``, ``"handled"``).
        masks: Training masks, bool (H, W) each; required by ``"aop"`` (the
            fold's training masks), refused by the others.

    Returns:
        A :class:`Predictor`.

    Raises:
        ValueError: If ``name`` is unknown (the message lists valid names),
            or ``masks`` is missing for ``"aop"`` or given to a baseline that
            does not learn.

    Example:
        >>> type(build_baseline("saliency")).__name__
        'SpectralResidualSaliency'
    """
    if name not in BASELINES:
        raise EgonetError(f"unknown baseline {name!r}; valid names: {', '.join(sorted(BASELINES))}", field="name")
    if name == "aop":
        if masks is None:
            raise EgonetError("masks is required for 'aop': pass the training masks of the fold", field="masks")
        return ActionObjectPrior.fit(masks)
    if masks is not None:
        raise EgonetError(f"masks must be None for {name!r}, which does not learn from training masks", field="masks")
    return BASELINES[name]()
